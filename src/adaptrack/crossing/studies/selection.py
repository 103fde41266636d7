"""Design-time adaptation to a site: tune every candidate family, choose on validation runs.

Seed 001 adapts the motion model to a particular crossing at design time. Here every candidate
family (:mod:`.families`: CV, CA, Singer, M1, M2, the IMM of CV and CA) is tuned on *training*
runs of the site, every tuned candidate is scored on separate *validation* runs, and the best
one there is deployed. (The compliance verdict is then computed on *test* runs that neither
step has seen.) Each set has its own seed stream and covers every class x case of the site.

Criterion, normalised by the requirements: for each class x case the requirement ratio
``r = max(position RMS / 0.7 m, speed RMS / 2 km/h, relative speed RMS / 2 %)`` (speed up to
100 km/h, relative speed above; ``r <= 1`` meets the requirement). ``criterion="tail"`` (the
default) is the mean of the largest 10 % of the ratios over the site's pairs (at least 3): the
worst cases decide, as in the requirement, but not the single worst alone, which is often set
by a physical floor no motion model moves (a bus's reflection-point scatter on position).
``"worst"`` is the largest ratio; spec B.7's pooled ``J_pos`` (``"pooled_position"``: the
criterion of seed 001's J(lambda) figure) and ``J_req`` (``"pooled_requirement"``) are kept.
On validation runs, candidates whose worst ratio exceeds 1 rank after every candidate that
meets the requirement. Searches (:func:`adaptrack.tuning.search.
minimise_log`): bounded Brent on one parameter, bounded Nelder-Mead on several, M1 as a
profile over a grid of ``lambda`` with Brent on ``accel_psd`` at each point (``lambda = 0`` is
the CV member, so M1 is never worse than CV on the training runs).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..._backend import Backend
from ..._toml import load_toml
from ...filters.kalman import CovarianceError
from ...parallel import TaskPool
from ...tuning.search import minimise_log
from ..simulation.radar import CrossingRuns, simulate_site_case
from ..site.model import Site, builtin_sites, load_site
from ..site.traffic import Case, VehicleClass
from .compliance import (
    LIMITS,
    ComplianceResult,
    ComplianceRow,
    RunSums,
    evaluate_site,
    requirement_ratio,
    run_sums,
    runs_of,
)
from .families import FAMILIES, M1_LAMBDAS, Family
from .trackers import Tracker

Criterion = Literal["tail", "worst", "pooled_position", "pooled_requirement"]
CRITERIA: tuple[str, ...] = ("tail", "worst", "pooled_position", "pooled_requirement")
TAIL_SHARE, TAIL_MIN = 0.10, 3
CRITERION_TEXT = {
    "tail": "mean requirement ratio of the worst 10 % of class x case pairs",
    "worst": "worst-case requirement ratio",
    "pooled_position": "pooled position RMS [m] (J_pos)",
    "pooled_requirement": "pooled requirement-normalised RMS (J_req)",
}
SEARCH_XATOL = 0.05  # 5 % in a parameter: finer than the Monte-Carlo noise of the criterion
MAX_EVALUATIONS = 60
Training = list[tuple[Case, VehicleClass, CrossingRuns]]


def criterion_value(
    per_pair: list[tuple[float, float, float, float, float]], criterion: Criterion
) -> float:
    """Return the criterion of per-pair results (see the module docstring).

    ``per_pair``: ``(position RMS [m], speed RMS [km/h], relative speed RMS [%], position
    epochs, speed epochs)`` of every class x case.
    """
    if criterion in ("tail", "worst"):
        ratios = sorted(
            (v for v in (requirement_ratio(*p[:3]) for p in per_pair) if math.isfinite(v)),
            reverse=True,
        )
        if len(ratios) < len(per_pair) or not ratios:
            return math.inf  # a pair without any scored epoch: the estimator lost the vehicle
        if criterion == "worst":
            return ratios[0]
        k = min(len(ratios), max(TAIL_MIN, math.ceil(TAIL_SHARE * len(ratios))))
        return float(np.mean(ratios[:k]))
    arr = np.array(per_pair, dtype=float)
    pos = math.sqrt(float(np.nansum(arr[:, 0] ** 2 * arr[:, 3]) / arr[:, 3].sum()))
    if criterion == "pooled_position":
        return pos
    spd = math.sqrt(float(np.nansum(arr[:, 1] ** 2 * arr[:, 4]) / arr[:, 4].sum()))
    return math.sqrt(((pos / LIMITS[0]) ** 2 + (spd / LIMITS[1]) ** 2) / 2)


def _from_sums(sums: RunSums) -> tuple[float, float, float, float, float]:
    pos, spd, rel = sums.rms()
    return (
        float(pos),
        float(spd),
        100 * float(rel),
        float(sums.counts[:, 0].sum()),
        float(sums.counts[:, 1].sum()),
    )


def _from_row(r: ComplianceRow) -> tuple[float, float, float, float, float]:
    return (
        r.position_rms_m,
        r.speed_rms_kmh,
        r.speed_rel_rms_pct,
        float(r.n_epochs),
        float(r.n_speed_epochs),
    )


def training_set(site: Site, n_runs: int, seed: int) -> Training:
    """Simulate ``n_runs`` of every class x case of the site (their own seed stream).

    Random approaches get :data:`~.compliance.RANDOM_RUNS_FACTOR` times the runs.
    """
    pairs = site.pairs()
    seeds = np.random.SeedSequence([seed, 7919]).spawn(len(pairs))
    return [
        (
            case,
            veh,
            simulate_site_case(
                site, case, veh, n_runs=runs_of(case, n_runs), rng=np.random.default_rng(s)
            ),
        )
        for (case, veh), s in zip(pairs, seeds, strict=True)
    ]


def training_criterion(
    tracker: Tracker, site: Site, training: Training, criterion: Criterion = "tail"
) -> float:
    """Criterion of a tracker over training runs (``inf`` if a filter breaks down)."""
    per_pair = []
    for case, veh, runs in training:
        try:
            est = tracker(runs, site, case, veh)
        except CovarianceError:  # the filter breaks down with these parameters
            return math.inf
        per_pair.append(_from_sums(run_sums(est, runs, site.zone_m)))
    return criterion_value(per_pair, criterion)


@dataclass(frozen=True)
class Candidate:
    """A tuned family: its parameters, criterion on training and validation runs.

    ``worst_ratio``/``worst_case``: its largest requirement ratio on the validation runs and
    the class / case where it occurs.
    """

    family: str
    label: str
    parameters: dict[str, float]
    training_criterion: float
    evaluations: int
    validation_criterion: float = math.nan
    worst_ratio: float = math.nan
    worst_case: str = ""

    @property
    def meets_requirement(self) -> bool:
        """Whether every class x case of the validation runs has a ratio <= 1."""
        return self.worst_ratio <= 1.0

    def tracker(self, backend: Backend = "auto") -> Tracker:
        """Return the tuned tracker."""
        return FAMILIES[self.family].tracker(self.parameters, backend)


def tune_family(
    key: str,
    site: Site,
    training: Training,
    criterion: Criterion = "tail",
    max_evaluations: int = MAX_EVALUATIONS,
) -> tuple[Candidate, dict[str, list[float]]]:
    """Tune one family on the training runs; returns the candidate and (M1) its profile."""
    family = FAMILIES[key]

    def score(values: dict[str, float]) -> float:
        return training_criterion(family.tracker(values, "numba"), site, training, criterion)

    if key == "m1":
        return _tune_m1(family, score)
    names = [p.name for p in family.parameters]
    res = minimise_log(
        lambda v: score(dict(zip(names, v, strict=True))),
        [p.start for p in family.parameters],
        [(p.lower, p.upper) for p in family.parameters],
        xatol=SEARCH_XATOL,
        max_evaluations=max_evaluations,
    )
    params = dict(zip(names, res.values, strict=True))
    return Candidate(key, family.label, params, res.criterion, res.evaluations), {}


def _tune_m1(
    family: Family, score: Callable[[dict[str, float]], float]
) -> tuple[Candidate, dict[str, list[float]]]:
    """M1 profile ``J(lambda) = min_q J(lambda, q)`` on ``M1_LAMBDAS`` (spec B.7 steps 2-3)."""
    q = family.parameters[1]
    fits = []
    evaluations = 0
    for lam in M1_LAMBDAS:

        def at_lambda(v: tuple[float, ...], lam: float = lam) -> float:
            return score({"lambda_per_s2": lam, "accel_psd": v[0]})

        res = minimise_log(
            at_lambda,
            [q.start],
            [(q.lower, q.upper)],
            xatol=SEARCH_XATOL,
        )
        fits.append(res)
        evaluations += res.evaluations
    best = int(np.argmin([f.criterion for f in fits]))
    params = {"lambda_per_s2": M1_LAMBDAS[best], "accel_psd": fits[best].values[0]}
    profile = {
        "lambda_per_s2": list(M1_LAMBDAS),
        "criterion": [f.criterion for f in fits],
        "accel_psd": [f.values[0] for f in fits],
    }
    return Candidate("m1", family.label, params, fits[best].criterion, evaluations), profile


@dataclass(frozen=True)
class SiteTuning:
    """The outcome of design-time selection for a site (what ``tuned.toml`` records)."""

    site: str
    criterion: str
    seed: int
    training_runs: int
    validation_runs: int
    candidates: tuple[Candidate, ...]
    deployed: str
    reason: str
    m1_profile: dict[str, list[float]] = field(default_factory=dict)
    site_fingerprint: str = ""  # :attr:`Site.fingerprint` of the site tuned for ("": unknown)

    def candidate(self, key: str) -> Candidate:
        """Return the candidate of a family."""
        for c in self.candidates:
            if c.family == key:
                return c
        raise KeyError(key)

    @property
    def winner(self) -> Candidate:
        """The deployed candidate."""
        return self.candidate(self.deployed)

    def tracker(self, backend: Backend = "auto") -> Tracker:
        """Return the deployed tracker."""
        return self.winner.tracker(backend)

    def to_json(self) -> dict[str, Any]:
        """Plain data (the demo's summary carries it)."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> SiteTuning:
        """Read back :meth:`to_json` output."""
        fields = dict(data)
        fields["candidates"] = tuple(Candidate(**c) for c in data["candidates"])
        return cls(**fields)

    def to_toml(self) -> str:
        """Serialise as TOML (read back with :func:`load_tuning`)."""

        def num(v: float) -> str:
            return repr(float(v)) if math.isfinite(v) else ("nan" if math.isnan(v) else "inf")

        def arr(vs: list[float]) -> str:
            return "[" + ", ".join(num(v) for v in vs) + "]"

        lines = [
            "# adaptrack design-time selection: the deployed road estimator and every candidate",
            f"site = {_q(self.site)}",
            *([f"site_fingerprint = {_q(self.site_fingerprint)}"] if self.site_fingerprint else []),
            f"criterion = {_q(self.criterion)}",
            f"seed = {self.seed}",
            f"training_runs = {self.training_runs}",
            f"validation_runs = {self.validation_runs}",
            "",
            "[deployed]",
            f"family = {_q(self.deployed)}",
            f"reason = {_q(self.reason)}",
        ]
        for c in self.candidates:
            lines += [
                "",
                f"[candidates.{c.family}]",
                f"label = {_q(c.label)}",
                f"training_criterion = {num(c.training_criterion)}",
                f"validation_criterion = {num(c.validation_criterion)}",
                f"worst_ratio = {num(c.worst_ratio)}",
                f"worst_case = {_q(c.worst_case)}",
                f"evaluations = {c.evaluations}",
                f"[candidates.{c.family}.parameters]",
                *(f"{k} = {num(v)}" for k, v in c.parameters.items()),
            ]
        if self.m1_profile:
            lines += ["", "[m1_profile]"]
            lines += [f"{k} = {arr(v)}" for k, v in self.m1_profile.items()]
        return "\n".join(lines) + "\n"


def _q(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def load_tuning(path: str | Path) -> SiteTuning:
    """Read a ``tuned.toml`` written by ``adaptrack tune`` or ``adaptrack demo``.

    Raises
    ------
    ValueError
        Naming the file and the key, if the file is not a tuned configuration.
    """
    data = load_toml(Path(path))
    try:
        candidates = []
        for key, c in data["candidates"].items():
            if key not in FAMILIES:
                raise ValueError(f"unknown family {key!r}; families are {', '.join(FAMILIES)}")
            params = {k: float(v) for k, v in c["parameters"].items()}
            FAMILIES[key].tracker(params)  # every parameter present and valid
            candidates.append(
                Candidate(
                    key,
                    str(c["label"]),
                    params,
                    float(c["training_criterion"]),
                    int(c["evaluations"]),
                    float(c["validation_criterion"]),
                    float(c["worst_ratio"]),
                    str(c["worst_case"]),
                )
            )
        tuning = SiteTuning(
            str(data["site"]),
            str(data["criterion"]),
            int(data["seed"]),
            int(data["training_runs"]),
            int(data["validation_runs"]),
            tuple(candidates),
            str(data["deployed"]["family"]),
            str(data["deployed"]["reason"]),
            {k: [float(x) for x in v] for k, v in data.get("m1_profile", {}).items()},
            str(data.get("site_fingerprint", "")),
        )
        tuning.winner  # noqa: B018 - the deployed family must be a candidate
    except KeyError as exc:
        raise ValueError(f"{path}: not a tuned configuration (missing {exc})") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a tuned configuration ({exc})") from None
    return tuning


def site_for(site: str | None, config: str | Path | None) -> Site:
    """Return the site a command runs on: ``site`` (a name or a file) or the config's.

    A tuned configuration (``tuned.toml``) records the site it was tuned for; without
    ``site`` that one is used (a built-in site by name; a site file must be given), and a
    ``site`` other than it, or a changed version of it (another fingerprint), is refused: the
    estimator was tuned for another place. Raises ValueError saying which.
    """
    tuned_for = fingerprint = None
    if config is not None:
        if not Path(config).is_file():
            raise ValueError(f"configuration file {config} does not exist")
        data = load_toml(Path(config))
        tuned_for, fingerprint = data.get("site"), data.get("site_fingerprint")
    if site is None:
        if tuned_for is None:
            raise ValueError(
                "--site is required: the site the detections come from (a built-in name, see "
                "'adaptrack site list', or a site .toml), or a --config tuned.toml that records it"
            )
        if str(tuned_for) not in builtin_sites():
            raise ValueError(
                f"{config} was tuned for site {tuned_for!r}, which is not built in: pass its "
                "file with --site"
            )
        site = str(tuned_for)
    st = load_site(site)
    if tuned_for is not None and st.name != tuned_for:
        raise ValueError(
            f"{config} was tuned for site {tuned_for!r}, not {st.name!r}: tune for this site "
            "('adaptrack tune') or pass the site it was tuned for"
        )
    if fingerprint and fingerprint != st.fingerprint:
        raise ValueError(
            f"{config} was tuned for another version of site {st.name!r} (its definition has "
            "changed since): tune again"
        )
    return st


def select_estimator(
    site: Site,
    *,
    seed: int = 0,
    training_runs: int = 3,
    validation_runs: int = 20,
    criterion: Criterion = "tail",
    families: tuple[str, ...] = tuple(FAMILIES),
    pool: TaskPool | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[SiteTuning, ComplianceResult]:
    """Tune ``families`` on training runs, score them on validation runs, deploy the best.

    The training and validation runs come from two streams of ``seed``. Families are the
    tasks of ``pool`` (in-process when None), then the validation Monte Carlo (with the
    road-aligned PCRLB, for the report's ratios); the result does not depend on the pool.
    Returns the selection and the validation result (one row per candidate x class x case).
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {', '.join(CRITERIA)}; got {criterion!r}")
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or not families:
        raise ValueError(f"families must be among {', '.join(FAMILIES)}; got {families}")
    train_seed, valid_seed = (
        int(s.generate_state(1)[0]) for s in np.random.SeedSequence([seed, 11]).spawn(2)
    )
    pool = TaskPool() if pool is None else pool
    training = pool.share(training_set(site, training_runs, train_seed))
    site_handle = pool.share(site)
    tuned = pool.map(
        tune_family,
        [(key, site_handle, training, criterion) for key in families],
        progress=(lambda i: progress(f"tuned {families[i]}")) if progress else None,
    )
    trackers = {c.label: c.tracker() for c, _ in tuned}
    validation = evaluate_site(
        site, validation_runs, valid_seed, trackers=trackers, pool=pool, progress=progress,
        baseline=None,
    )  # fmt: skip
    candidates = []
    for c, _ in tuned:
        mine = [r for r in validation.rows if r.filter == c.label]
        worst = max(mine, key=lambda r: r.requirement_ratio)
        candidates.append(
            replace(
                c,
                validation_criterion=criterion_value([_from_row(r) for r in mine], criterion),
                worst_ratio=worst.requirement_ratio,
                worst_case=f"{worst.vehicle_class} / {worst.case}",
            )
        )
    ranked = sorted(candidates, key=lambda c: (not c.meets_requirement, c.validation_criterion))
    profile = next((p for _, p in tuned if p), {})
    tuning = SiteTuning(
        site.name,
        criterion,
        seed,
        training_runs,
        validation_runs,
        tuple(candidates),
        ranked[0].family,
        _reason(ranked, criterion),
        profile,
        site.fingerprint,
    )
    return tuning, validation


def _reason(ranked: list[Candidate], criterion: str) -> str:
    best = ranked[0]
    what = f"the lowest {CRITERION_TEXT[criterion]} on the validation runs"
    if best.meets_requirement:
        text = (
            f"{best.label} has {what} among the candidates that meet the requirement: "
            f"{best.validation_criterion:.3f}; its worst class x case is {best.worst_case} "
            f"at {best.worst_ratio:.3f} of the limits"
        )
    else:
        text = (
            f"no candidate meets the requirement on the validation runs; {best.label} has "
            f"{what}: {best.validation_criterion:.3f} (worst {best.worst_case} at "
            f"{best.worst_ratio:.3f} of the limits)"
        )
    if len(ranked) > 1:
        nxt = ranked[1]
        excess = 100 * (nxt.validation_criterion / best.validation_criterion - 1)
        text += f"; next {nxt.label} at {nxt.validation_criterion:.3f} ({excess:+.1f} %)"
    return text + "."


__all__ = [
    "CRITERIA",
    "Candidate",
    "SiteTuning",
    "criterion_value",
    "load_tuning",
    "select_estimator",
    "training_criterion",
    "training_set",
    "tune_family",
]
