"""Design-time adaptation of the road-constrained model to a site (seed 001, spec B.7).

The along-road motion model M1 (``lambda``, ``q_a``) is tuned by minimising the
requirement-normalised RMS criterion ``J_req = sqrt(((J_pos / 0.7 m)^2 + (J_speed / 2 km/h)^2)
/ 2)`` over training runs of the site (a set of typical class x case approaches, common random
numbers for every candidate): a profile over a grid of ``lambda`` (``lambda = 0`` is the
constant-velocity baseline) with bounded Brent on ``log q_a`` at each point. Training runs
come from their own seed stream, never from the evaluation runs.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from .._toml import load_toml
from .._typing import FloatArray
from ..models.adaptive import InverseDynamics, ShapingFilter, singer_accel_std
from ..parallel import TaskPool
from .compliance import POSITION_LIMIT_M, SPEED_LIMIT_KMH, RoadTracker, scored_epochs
from .radar_sim import CrossingRuns, simulate_site_case
from .site import Site
from .traffic import DEFAULT_CASES, VEHICLES, Case, VehicleClass

TRAINING = (
    ("car", "pass_60"),
    ("car", "stop_60"),
    ("car", "curve_60"),
    ("truck", "emergency_90"),
    ("bus", "pass_20"),
)


@dataclass(frozen=True)
class RoadTuning:
    """Tuned M1 parameters for a site, the criterion and the profile J(lambda)."""

    site: str
    lambda_per_s2: float
    accel_psd: float
    criterion: float
    baseline_criterion: float
    profile: dict[str, list[float]] = field(default_factory=dict)
    shaping: dict[str, float] = field(default_factory=dict)

    def model(self) -> InverseDynamics | ShapingFilter:
        """Build the tuned along-road model: M2 when tuned and better than M1, else M1."""
        if self.shaping and self.shaping["criterion"] < self.criterion:
            return ShapingFilter(
                lambda_per_s2=self.shaping["lambda_per_s2"],
                alpha_per_s=self.shaping["alpha_per_s"],
                shaping_std=self.shaping["shaping_std"],
            )
        return InverseDynamics(lambda_per_s2=self.lambda_per_s2, accel_psd=self.accel_psd)

    def to_toml(self) -> str:
        """Serialise as TOML (read back with :func:`load_tuning`)."""

        def arr(v: list[float]) -> str:
            return "[" + ", ".join(repr(float(x)) for x in v) + "]"

        return (
            f'site = "{self.site}"\n\n[road_model]\nkind = "inverse_dynamics"\n'
            f"lambda_per_s2 = {self.lambda_per_s2!r}\naccel_psd = {self.accel_psd!r}\n"
            f"criterion = {self.criterion!r}\nbaseline_criterion = "
            f"{self.baseline_criterion!r}\n\n[profile]\n"
            f"lambda_per_s2 = {arr(self.profile['lambda_per_s2'])}\n"
            f"criterion = {arr(self.profile['criterion'])}\n"
            f"accel_psd = {arr(self.profile['accel_psd'])}\n"
            + (
                "\n[shaping_filter]\n" + "".join(f"{k} = {v!r}\n" for k, v in self.shaping.items())
                if self.shaping
                else ""
            )
        )


def load_tuning(path: str | Path) -> RoadTuning:
    """Read a tuned configuration written by ``adaptrack tune``."""
    data = load_toml(Path(path))
    try:
        m = data["road_model"]
        if m["kind"] != "inverse_dynamics":
            raise ValueError(f"unsupported road_model kind {m['kind']!r}")
        return RoadTuning(
            str(data["site"]),
            float(m["lambda_per_s2"]),
            float(m["accel_psd"]),
            float(m["criterion"]),
            float(m["baseline_criterion"]),
            {k: [float(x) for x in v] for k, v in data.get("profile", {}).items()},
            {k: float(v) for k, v in data.get("shaping_filter", {}).items()},
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a tuned configuration ({exc})") from None


def training_runs(
    site: Site, n_runs: int, seed: int
) -> list[tuple[Case, VehicleClass, CrossingRuns]]:
    """Simulate the training approaches (their own seed stream)."""
    cases = {c.name: c for c in DEFAULT_CASES}
    seeds = np.random.SeedSequence([seed, 7919]).spawn(len(TRAINING))
    out = []
    for (cls, case_name), ss in zip(TRAINING, seeds, strict=True):
        case, veh = cases[case_name], VEHICLES[cls]
        runs = simulate_site_case(site, case, veh, n_runs=n_runs, rng=np.random.default_rng(ss))
        out.append((case, veh, runs))
    return out


def road_criterion(
    model: Any, site: Site, training: list[tuple[Case, VehicleClass, CrossingRuns]]
) -> float:
    """``J_req`` of the road-constrained EKF with ``model`` over the training runs."""
    ep, es = [], []
    tracker = RoadTracker(model)
    for case, veh, runs in training:
        est = tracker(runs, site, case, veh)
        zone = scored_epochs(np.isfinite(est.speed), runs, site.zone_m)
        ep.append(np.sum((est.position - runs.position) ** 2, axis=-1)[zone])
        es.append(((est.speed - runs.speed) * 3.6)[zone] ** 2)
    j_pos = math.sqrt(float(np.mean(np.concatenate(ep))))
    j_spd = math.sqrt(float(np.mean(np.concatenate(es))))
    j = math.sqrt(((j_pos / POSITION_LIMIT_M) ** 2 + (j_spd / SPEED_LIMIT_KMH) ** 2) / 2)
    return j if np.isfinite(j) else 1e300


def _best_q(
    lam: float,
    site: Site,
    training: list[tuple[Case, VehicleClass, CrossingRuns]],
    q_bounds: tuple[float, float],
) -> tuple[float, float]:
    """Bounded Brent on ``log q_a`` at one ``lambda``."""
    res = minimize_scalar(
        lambda u: road_criterion(
            InverseDynamics(lambda_per_s2=lam, accel_psd=math.exp(u)), site, training
        ),
        bounds=(math.log(q_bounds[0]), math.log(q_bounds[1])),
        method="bounded",
        options={"xatol": 0.05},
    )
    return math.exp(float(res.x)), float(res.fun)


def tune_road_model(
    site: Site,
    *,
    n_runs: int = 3,
    seed: int = 0,
    lambdas: tuple[float, ...] = (1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0),
    q_bounds: tuple[float, float] = (0.01, 100.0),
    pool: TaskPool | None = None,
    progress: Callable[[str], None] | None = None,
) -> RoadTuning:
    """Profile ``J(lambda) = min_q J(lambda, q)`` including ``lambda = 0`` (CV).

    The grid points are tasks of ``pool`` (in-process when None); the result does not depend
    on the pool.
    """
    training = training_runs(site, n_runs, seed)
    lam_all = [0.0, *lambdas]
    pool = TaskPool() if pool is None else pool
    shared = pool.share(training)
    fits = pool.map(
        _best_q,
        [(lam, site, shared, q_bounds) for lam in lam_all],
        progress=(lambda i: progress(f"tuning: lambda = {lam_all[i]:g}")) if progress else None,
    )
    j_all = [f[1] for f in fits]
    best = int(np.argmin(j_all))
    return RoadTuning(
        site.name,
        lam_all[best],
        fits[best][0],
        j_all[best],
        j_all[0],
        {"lambda_per_s2": lam_all, "criterion": j_all, "accel_psd": [f[0] for f in fits]},
    )


def tune_road_shaping(
    site: Site, tuning: RoadTuning, *, n_runs: int = 3, seed: int = 0, max_evaluations: int = 40
) -> RoadTuning:
    """Add M2 ``(lambda, alpha, sigma_M)`` tuned by bounded Nelder-Mead on the same training runs.

    Starts from ``max(lambda*_M1, 1e-3)``, ``alpha = 1/3`` and Singer's rule (spec B.7 step 4).
    """
    training = training_runs(site, n_runs, seed)
    lam0 = max(tuning.lambda_per_s2, 1e-3)
    x0 = np.log([lam0, 1.0 / 3.0, singer_accel_std(9.0, 0.05, 0.5) / math.sqrt(lam0)])
    bounds = [
        (math.log(1e-4), math.log(10.0)),
        (math.log(1e-2), math.log(10.0)),
        (math.log(0.01), math.log(1e3)),
    ]

    def f(u: FloatArray) -> float:
        lam, al, sm = (float(v) for v in np.exp(u))
        return road_criterion(
            ShapingFilter(lambda_per_s2=lam, alpha_per_s=al, shaping_std=sm), site, training
        )

    res = minimize(
        f,
        np.clip(x0, [b[0] for b in bounds], [b[1] for b in bounds]),
        method="Nelder-Mead",
        bounds=bounds,
        options={"maxfev": max_evaluations, "xatol": 1e-2, "fatol": 1e-3},
    )
    lam, al, sm = (float(v) for v in np.exp(res.x))
    return dataclasses.replace(
        tuning,
        shaping={
            "lambda_per_s2": lam,
            "alpha_per_s": al,
            "shaping_std": sm,
            "criterion": float(res.fun),
        },
    )


__all__ = [
    "TRAINING",
    "RoadTuning",
    "load_tuning",
    "road_criterion",
    "training_runs",
    "tune_road_model",
    "tune_road_shaping",
]
