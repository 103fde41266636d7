"""Fuzzing of the public functions: random valid and broken inputs, outcomes by category.

Every case is a call of one public function (or of two paths that must agree: the NumPy and
compiled backends, ``shared_gain_filter`` and ``kalman_filter``, ``OnlineFilter`` and
``kalman_filter``) on inputs drawn from a :class:`Source`. A *valid* case lies in the domain
the functions are specified for (steps 1e-6 to 1e4 s, measurement covariances of condition
number up to 1e12, priors from 1e-6 to 1e8, semi-definite priors, missing components); a
*broken* case is a valid one with one argument spoiled (NaN/inf, wrong shape or type, unsorted
or duplicate times, an asymmetric or indefinite covariance, an unknown option). Outcomes:

- ``ok``: a valid case returned finite, symmetric PSD results on which all paths agree within
  the problem's own rounding sensitivity (below);
- ``rejected``: a broken case raised ``ValueError``/``TypeError`` from adaptrack's own code
  with a message naming the spoiled argument;
- defects: ``deep exception`` (any other exception, or one raised inside numpy/scipy/numba),
  ``silent non-finite``, ``non-PSD covariance``, ``disagreement``, ``valid rejected``,
  ``broken accepted``, ``misleading message`` (the message does not name the argument).

Agreement. A backward-stable algorithm returns the exact answer to inputs changed at the rounding
level, so two correct paths may differ by as much as the answer moves under such changes, and
on an ill-conditioned problem (a measurement covariance of condition 1e12 whose large
innovations are weighted by its tiny eigenvalue) that is a sigma or more: a 60-digit reference
moves by 0.3 to 6.6 posterior sigma when ``R`` changes by one ulp. Every agreement check
therefore measures it: the reference path runs again on inputs (times, measurements, ``R``,
priors) changed elementwise by ``ROUNDING`` relative, and two paths must agree within
``MEAN_TOL_SIGMA`` (``COV_TOL``) plus ``SPREAD_FACTOR`` times the largest change seen.

The Hypothesis properties in ``tests/stress/test_fuzz.py`` draw cases through the same
generators (the fast profile); the long profile is this module::

    python -m tests.stress.fuzz --cases 100000
"""

from __future__ import annotations

import argparse
import time
import traceback
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

import adaptrack as at
from adaptrack import coords
from adaptrack.filters.adaptive import innovation_adaptive_filter
from adaptrack.filters.imm import imm_filter
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    FunctionMeasurement,
    PositionMeasurement,
    Singer,
)
from adaptrack.smoothers.batch_ls import fit_polynomial

PACKAGE = str(Path(at.__file__).parent)
DEFECTS = (
    "deep exception",
    "silent non-finite",
    "non-PSD covariance",
    "disagreement",
    "valid rejected",
    "broken accepted",
    "misleading message",
)
# Agreement of two paths on a valid case: on a well-conditioned problem both are within ~1e-8
# sigma of each other; the floor leaves room for the square-root and Joseph forms of
# moderately conditioned ones. On top: the measured rounding sensitivity (module docstring).
MEAN_TOL_SIGMA = 1e-2
COV_TOL = 1e-3  # of sigma_i sigma_j
# Relative input change of the sensitivity runs: the backward error of the filters' steps is a
# few n * eps (n <= 6 states); two draws, and a factor for the directions they miss.
ROUNDING = 8 * np.finfo(float).eps
SPREAD_FACTOR = 10.0
# Where inputs changed at the rounding level move the reference by more than one posterior
# sigma, double precision does not determine the answer (e.g. a 978 s gap of a constant-
# acceleration model under a prior of 1.6e5 m^2/s^4 and an R of condition 1e12: the largest
# trace(S) is 1e29 times the smallest measurement variance; both backends are 30-450 sigma
# off a 60-digit reference). Two paths cannot be compared there: the case counts as
# "ok, undetermined" (finite, symmetric and PSD are still required).
UNDETERMINED_SIGMA = 1.0


class Source:
    """Random choices of one case: from a NumPy generator, or (subclass) from Hypothesis."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng  # bulk arrays always come from here

    def integer(self, lo: int, hi: int) -> int:
        """Integer in [lo, hi]."""
        return int(self.rng.integers(lo, hi + 1))

    def real(self, lo: float, hi: float) -> float:
        """Real in [lo, hi]."""
        return float(self.rng.uniform(lo, hi))

    def choice(self, options: Sequence[Any]) -> Any:
        """One of ``options``."""
        return options[self.integer(0, len(options) - 1)]

    def log_real(self, lo: float, hi: float) -> float:
        """Real log-uniform in [lo, hi]."""
        return float(10.0 ** self.real(np.log10(lo), np.log10(hi)))


@dataclass
class Outputs:
    """What a call returned: arrays that must be finite, covariances that must be PSD, pairs
    that must agree ``(label, a, b, sigma)`` with ``sigma`` the scale of the comparison."""

    finite: list[np.ndarray] = field(default_factory=list)
    covs: list[np.ndarray] = field(default_factory=list)
    agree: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    probabilities: list[np.ndarray] = field(default_factory=list)
    spread: dict[str, float] = field(default_factory=dict)  # sensitivity per agreement label

    def state(self, mean: np.ndarray, cov: np.ndarray) -> None:
        """A Gaussian result: mean finite, covariance finite and PSD."""
        self.finite += [mean, cov]
        self.covs.append(cov)

    def compare(self, label: str, a: Any, b: Any) -> None:
        """Two Gaussian results (``.mean``/``.cov``) that must agree in their sigmas."""
        self.agree += _pairs(label, a, b)

    def sensitivity(self, label: str, perturbed: Any, b: Any) -> None:
        """Record how far the reference ``b`` moves on inputs changed at the rounding level."""
        for name, x, y, sigma in _pairs(label, perturbed, b):
            self.spread[name] = max(self.spread.get(name, 0.0), float(np.max(_err(x, y, sigma))))


def _pairs(label: str, a: Any, b: Any) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    sigma = np.sqrt(np.clip(np.diagonal(b.cov, axis1=-2, axis2=-1), 0.0, None))
    return [
        (label + " mean", a.mean, b.mean, sigma),
        (label + " cov", a.cov, b.cov, sigma[..., :, None] * sigma[..., None, :]),
    ]


def _err(a: np.ndarray, b: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``|a - b|`` in units of ``sigma``, zero where it is within 1e-12 of ``b``'s scale."""
    diff = np.abs(a - b)
    diff = np.where(diff > 1e-12 * np.abs(b).max(initial=0.0), diff, 0.0)
    return diff / np.where(sigma > 0, sigma, 1.0)


@dataclass(frozen=True)
class Case:
    """One call: ``run()`` returns :class:`Outputs`; a broken case names the spoiled argument."""

    target: str
    run: Callable[[], Outputs]
    broken: str | None = None  # argument the message must name; None for a valid case
    what: str = ""


def outcome(case: Case) -> tuple[str, str]:
    """Category of ``case`` and a one-line detail."""
    try:
        out = case.run()
    except (ValueError, TypeError) as exc:
        where = traceback.extract_tb(exc.__traceback__)[-1].filename
        if not where.startswith(PACKAGE) or "/_vendor" in where:
            return "deep exception", f"{type(exc).__name__} in {where}: {exc}"
        if case.broken is None:
            return "valid rejected", f"{type(exc).__name__}: {exc}"
        if case.broken not in str(exc):
            return "misleading message", f"{case.broken} ({case.what}): {exc}"
        return "rejected", ""
    except Exception as exc:  # every other exception is the defect counted
        return "deep exception", f"{type(exc).__name__}: {exc}"
    if case.broken is not None:
        return "broken accepted", f"{case.broken}: {case.what}"
    return check(out)


def check(out: Outputs) -> tuple[str, str]:
    """Category of a valid case's outputs."""
    for a in out.finite:
        if not np.all(np.isfinite(a)):
            return "silent non-finite", f"shape {np.shape(a)}"
    for c in out.covs:
        if c.size == 0:
            continue
        if np.any(c != np.swapaxes(c, -1, -2)):
            return "non-PSD covariance", "not symmetric"
        scale = np.abs(c).max(axis=(-2, -1))
        low = np.linalg.eigvalsh(c)[..., 0]
        if np.any(low < -1e-12 * scale):
            return "non-PSD covariance", f"eigenvalue {low.min():.3g} of scale {scale.max():.3g}"
    for p in out.probabilities:
        if np.any(p < 0) or np.any(np.abs(p.sum(-1) - 1.0) > 1e-9):
            return "disagreement", "mode probabilities are not a distribution"
    undetermined = [
        label for label, _, _, _ in out.agree if out.spread.get(label, 0.0) > UNDETERMINED_SIGMA
    ]
    if undetermined:
        spread = max(out.spread[label] for label in undetermined)
        return "ok, undetermined", f"{undetermined[0]}: rounding sensitivity {spread:.3g}"
    for label, a, b, sigma in out.agree:
        floor = MEAN_TOL_SIGMA if label.endswith("mean") else COV_TOL
        spread = out.spread.get(label, 0.0)
        err = _err(a, b, sigma).max(initial=0.0)
        if err > floor + SPREAD_FACTOR * spread:
            return "disagreement", f"{label}: {err:.3g} (rounding sensitivity {spread:.3g})"
    return "ok", ""


# ---------------------------------------------------------------------------- problems


@dataclass(frozen=True)
class Problem:
    """A valid linear-Gaussian filtering problem (batch of tracks or one track)."""

    times: np.ndarray
    z: np.ndarray
    model: Any
    h: np.ndarray
    r: np.ndarray
    prior: at.GaussianState
    mask: np.ndarray
    offset: np.ndarray | None


def spd(src: Source, m: int, condition: float, scale: float) -> np.ndarray:
    """Random symmetric positive definite (m, m) of the given condition number."""
    q, _ = np.linalg.qr(src.rng.normal(size=(m, m)))
    eig = scale * np.geomspace(1.0, 1.0 / condition, m) if m > 1 else np.array([scale])
    a = (q * eig) @ q.T
    return 0.5 * (a + a.T)


def problem(src: Source, *, shared: bool = False, tracks: int | None = None) -> Problem:
    """A random valid problem; ``shared``: every track on the same times, R, mask and prior cov."""
    axes = src.integer(1, 2)
    model = src.choice(
        [
            ConstantVelocity(accel_psd=src.log_real(1e-4, 1e2), n_axes=axes),
            ConstantAcceleration(jerk_psd=src.log_real(1e-4, 1e2), n_axes=axes),
            Singer(
                time_constant_s=src.log_real(0.1, 100.0),
                accel_std_mps2=src.log_real(1e-2, 30.0),
                n_axes=axes,
            ),
        ]
    )
    n, m = model.state_dim, axes
    n_tracks = src.integer(1, 3) if tracks is None else tracks
    n_steps = src.integer(1, 25)
    batch = (n_tracks,)
    dt_shape = (n_steps,) if shared or src.integer(0, 1) else batch + (n_steps,)
    lo, hi = sorted((src.log_real(1e-6, 1e4), src.log_real(1e-6, 1e4)))
    times = np.cumsum(10.0 ** src.rng.uniform(np.log10(lo), np.log10(hi), dt_shape), axis=-1)
    h = np.zeros((m, n))
    h[np.arange(m), [model.state_names.index(s) for s in model.state_names[:m]]] = 1.0
    r = spd(src, m, src.log_real(1.0, 1e12), src.log_real(1e-6, 1e6))
    p0 = np.diag(10.0 ** src.rng.uniform(-6, 8, n))
    if src.integer(0, 4) == 0:
        p0[n - 1, n - 1] = 0.0  # a known component: semi-definite prior
    mean0 = src.rng.normal(size=batch + (n,)) * 10.0
    prior = at.GaussianState(mean0, np.broadcast_to(p0, batch + (n, n)), 0.0)
    truth = src.rng.normal(size=batch + (n_steps, m)) * np.sqrt(np.diag(r)) * 3.0
    z = truth + 5.0 * np.broadcast_to(times, batch + (n_steps,))[..., None]
    mask = src.rng.uniform(size=(n_steps, m) if shared else z.shape) > src.real(0.0, 0.5)
    offset = src.rng.normal(size=m) if src.integer(0, 3) == 0 else None
    return Problem(times, z, model, h, r, prior, mask, offset)


def perturbed(p: Problem) -> list[Problem]:
    """Two copies of ``p`` with times, measurements, ``R`` and prior changed by ``ROUNDING``."""
    rng = np.random.default_rng(0)
    return [
        replace(
            p,
            times=_change(p.times, rng),  # absolute times: steps known to ~eps * t
            z=_change(p.z, rng),
            r=_change(p.r, rng, symmetric=True),
            prior=at.GaussianState(
                _change(p.prior.mean, rng), _change(p.prior.cov, rng, True), p.prior.time
            ),
        )
        for _ in range(2)
    ]


def _change(a: np.ndarray, rng: np.random.Generator, symmetric: bool = False) -> np.ndarray:
    d = a * ROUNDING * rng.uniform(-1.0, 1.0, a.shape)
    return a + (0.5 * (d + np.swapaxes(d, -1, -2)) if symmetric else d)


def _filter(p: Problem, **kw: Any) -> Any:
    return at.kalman_filter(
        p.times, p.z, p.model, p.h, p.r, p.prior, mask=p.mask,
        measurement_noise_mean=p.offset, **kw,
    )  # fmt: skip


# ----------------------------------------------------------------- spoiling an argument

SPOILS = ("nan", "inf", "shape", "string", "complex", "none", "empty")


def spoil(value: Any, how: str, src: Source) -> Any:
    """``value`` (array-like) spoiled in one generic way."""
    a = np.array(value, dtype=float)
    if how in ("nan", "inf") and a.size:
        idx = tuple(src.integer(0, s - 1) for s in a.shape)
        a[idx] = np.nan if how == "nan" else -np.inf
        return a
    if how == "shape":
        return a[..., :-1] if a.ndim and a.shape[-1] > 1 else a[..., None, None]
    if how == "string":
        return "1.0"
    if how == "complex":
        return a + 1j
    if how == "none":
        return None
    return np.zeros((0,) * max(a.ndim, 1))


def spoil_cov(r: np.ndarray, how: str) -> np.ndarray:
    """A covariance made asymmetric or indefinite."""
    r = r.copy()
    if how == "asymmetric" and r.shape[-1] > 1:
        r[..., 0, 1] += 1e-3 * np.abs(r).max() + 1.0
        return r
    return r - 2.0 * np.abs(np.linalg.eigvalsh(r)).max() * np.eye(r.shape[-1])


def spoil_times(t: np.ndarray, how: str) -> np.ndarray:
    """Times made unsorted or duplicated (needs at least two steps)."""
    t = t.copy()
    if how == "duplicate":
        t[..., 1] = t[..., 0]
    else:
        t[..., [0, 1]] = t[..., [1, 0]]
    return t


# --------------------------------------------------------------------------- targets


def kalman_filter_case(src: Source) -> Case:
    """``kalman_filter`` on both backends (and the smoother on both), or a spoiled call."""
    p = problem(src)
    if src.integer(0, 2):

        def run() -> Outputs:
            out = Outputs()
            a, b = (_filter(p, backend=bk) for bk in ("numpy", "numba"))
            for res in (a, b):
                out.state(res.filtered.mean, res.filtered.cov)
                out.state(res.predicted.mean, res.predicted.cov)
            out.compare("kalman_filter numpy/numba", b.filtered, a.filtered)
            sa, sb = (at.rts_smooth(a, backend=bk) for bk in ("numpy", "numba"))
            out.state(sa.mean, sa.cov)
            out.state(sb.mean, sb.cov)
            out.compare("rts_smooth numpy/numba", sb, sa)
            for q in perturbed(p):
                c = _filter(q, backend="numpy")
                out.sensitivity("kalman_filter numpy/numba", c.filtered, a.filtered)
                out.sensitivity("rts_smooth numpy/numba", at.rts_smooth(c, backend="numpy"), sa)
            return out

        return Case("kalman_filter", run)
    return spoiled_filter_case(src, p, "kalman_filter", _filter_call)


def _filter_call(p: Problem, **kw: Any) -> Outputs:
    args = dict(
        times=p.times, measurements=p.z, model=p.model, measurement_matrix=p.h,
        measurement_cov=p.r, initial=p.prior, mask=p.mask, measurement_noise_mean=p.offset,
    )  # fmt: skip
    args.update(kw)
    res = at.kalman_filter(**args)
    out = Outputs()
    out.state(res.filtered.mean, res.filtered.cov)
    return out


def spoiled_filter_case(src: Source, p: Problem, target: str, call: Callable[..., Outputs]) -> Case:
    """``call(p, **{argument: spoiled})`` for one argument of the filter API spoiled."""
    arg = src.choice(
        ["times", "measurements", "measurement_matrix", "measurement_cov", "initial", "mask",
         "measurement_noise_mean", "form", "method"]
    )  # fmt: skip
    how = src.choice(SPOILS)
    value: Any
    if arg == "times":
        how = src.choice(SPOILS + ("unsorted", "duplicate")) if p.times.shape[-1] > 1 else how
        value = spoil_times(p.times, how) if how in ("unsorted", "duplicate") else None
        value = spoil(p.times, how, src) if value is None else value
    elif arg == "measurements":
        if how == "nan":  # a NaN where the mask says missing is fine: spoil a present one
            z, idx = p.z.copy(), np.argwhere(np.broadcast_to(p.mask, p.z.shape))
            if not len(idx):
                return Case(target, lambda: call(p), None, "no present measurement")
            z[tuple(idx[src.integer(0, len(idx) - 1)])] = np.nan
            value = z
        else:
            value = spoil(p.z, how, src)
    elif arg == "measurement_matrix":
        value = spoil(p.h, how, src)
    elif arg == "measurement_cov":
        how = src.choice(SPOILS + ("asymmetric", "indefinite"))
        spoilt = how in ("asymmetric", "indefinite")
        value = spoil_cov(p.r, how) if spoilt else spoil(p.r, how, src)
        if how == "shape":  # (m, m) -> (m + 1, m + 1): no valid shape
            value = np.eye(p.r.shape[-1] + 1)
        if how == "asymmetric" and p.r.shape[-1] == 1:
            how, value = "indefinite", spoil_cov(p.r, "indefinite")
    elif arg == "initial":
        how = src.choice(("indefinite", "mean shape", "late"))
        pr = p.prior
        if how == "indefinite":
            value = at.GaussianState(pr.mean, spoil_cov(np.asarray(pr.cov), how), pr.time)
        elif how == "mean shape":
            value = at.GaussianState(pr.mean[..., :-1], pr.cov[..., :-1, :-1], pr.time)
            if pr.mean.shape[-1] == 1:
                value = at.GaussianState(pr.mean[..., None], pr.cov[..., None, :, :], pr.time)
        else:
            value = at.GaussianState(pr.mean, pr.cov, float(np.max(p.times)) + 1.0)
    elif arg == "mask":
        how = src.choice(("shape", "string", "float"))
        value = {"shape": np.ones((3, 7, 5), bool), "string": "yes", "float": p.mask + 0.5}[how]
    elif arg == "measurement_noise_mean":
        value = spoil(np.zeros(p.h.shape[0]), how, src) if how != "none" else np.zeros(99)
    else:
        value = src.choice(("", "Joseph", "exact", 3))
        how = f"option {value!r}"
    return Case(target, lambda: call(p, **{arg: value}), arg, how)


def shared_gain_case(src: Source) -> Case:
    """``shared_gain_filter`` equals ``kalman_filter`` and rejects what it rejects."""
    p = problem(src, shared=True)
    mask = p.mask

    def call(q: Problem, compare: bool = False, **kw: Any) -> Outputs:
        args = dict(
            times=q.times, measurements=q.z, model=q.model, measurement_matrix=q.h,
            measurement_cov=q.r, initial=q.prior, mask=mask, measurement_noise_mean=q.offset,
        )  # fmt: skip
        args.update(kw)
        res = at.shared_gain_filter(**args)
        out = Outputs()
        out.state(res.mean, res.cov)
        if not compare:
            return out
        args["mask"] = np.broadcast_to(mask, q.z.shape)  # (T, m) would read as (N, T) if N = T
        ref = at.kalman_filter(**args)
        shape = ref.filtered.cov.shape
        got = at.GaussianState(res.mean, np.broadcast_to(res.cov, shape), ref.filtered.time)
        out.compare("shared_gain_filter/kalman_filter", got, ref.filtered)
        for c in perturbed(q):
            args.update(times=c.times, measurements=c.z, measurement_cov=c.r, initial=c.prior)
            moved = at.kalman_filter(**args).filtered
            out.sensitivity("shared_gain_filter/kalman_filter", moved, ref.filtered)
        return out

    if src.integer(0, 2):
        return Case("shared_gain_filter", lambda: call(p, compare=True))
    return spoiled_filter_case(src, p, "shared_gain_filter", call)


def online_case(src: Source) -> Case:
    """``OnlineFilter`` fed one track equals ``kalman_filter`` on it; bad updates are rejected."""
    p = problem(src, tracks=1)
    t, z, mask = np.broadcast_to(p.times, p.z.shape[:-1])[0], p.z[0], p.mask[0]
    prior = p.prior[0]

    def make() -> at.OnlineFilter:
        return at.OnlineFilter(
            p.model, p.h, p.r, prior, measurement_noise_mean=p.offset, cache_size=4
        )

    if src.integer(0, 2):

        def run() -> Outputs:
            f = make()
            for k in range(t.size):
                f.update(t[k], z[k], mask=mask[k])
            out = Outputs()
            out.state(f.mean, f.cov)
            ref = _filter(p)
            last = at.GaussianState(ref.filtered.mean[0, -1], ref.filtered.cov[0, -1], t[-1])
            out.compare("OnlineFilter/kalman_filter", f.state, last)
            for q in perturbed(p):
                c = _filter(q)
                moved = at.GaussianState(c.filtered.mean[0, -1], c.filtered.cov[0, -1], t[-1])
                out.sensitivity("OnlineFilter/kalman_filter", moved, last)
            return out

        return Case("OnlineFilter", run)
    arg = src.choice(("time", "measurement", "mask"))
    how = src.choice(("nan", "past", "string", "shape", "none", "array"))
    bad: Any = {
        "nan": np.nan, "past": -1.0, "string": "soon", "shape": np.ones(3), "none": None,
        "array": np.array([t[0]]),
    }[how] if arg == "time" else (
        spoil(z[0], how if how in SPOILS else "inf", src) if arg == "measurement"
        else {"nan": "yes", "past": np.ones(z.shape[1] + 1, bool)}.get(how, mask[0] + 0.5)
    )  # fmt: skip
    if arg == "time" and how == "array":
        return Case("OnlineFilter", lambda: _online_state(make(), t[0], z[0], mask[0]))
    args = {"time": t[0], "measurement": z[0], "mask": np.ones_like(mask[0]), arg: bad}
    return Case("OnlineFilter", lambda: _online_state(make(), **args), arg, how)


def _online_state(f: at.OnlineFilter, time: Any, measurement: Any, mask: Any) -> Outputs:
    out = Outputs()
    f.update(time, measurement, mask=mask)
    out.state(f.mean, f.cov)
    return out


def discretize_case(src: Source) -> Case:
    """``discretize`` over the step domain: finite, PSD, exact methods agree."""
    p = problem(src)
    dt = np.concatenate([[0.0], 10.0 ** src.rng.uniform(-6, 4, src.integer(1, 8))])
    if src.integer(0, 3):

        def run() -> Outputs:
            out = Outputs()
            a = at.discretize(p.model, dt, "expm")
            b = at.discretize(p.model, dt, "auto")
            for d in (a, b):
                out.finite += [d.transition]
                out.state(d.transition[..., 0], d.process_cov)
            sig = np.sqrt(np.diagonal(a.process_cov, axis1=-2, axis2=-1))
            out.agree.append(
                (
                    "discretize expm/auto Qd",
                    b.process_cov,
                    a.process_cov,
                    sig[..., :, None] * sig[..., None, :],
                )
            )
            return out

        return Case("discretize", run)
    how = src.choice(SPOILS + ("negative",))
    bad = -dt - 1.0 if how == "negative" else spoil(dt, how, src)
    if how in ("shape", "empty"):  # any shape is valid, an empty one too
        return Case("discretize", lambda: _disc(p.model, bad))
    return Case("discretize", lambda: _disc(p.model, bad), "dt", how)


def _disc(model: Any, dt: Any) -> Outputs:
    d = at.discretize(model, dt)
    out = Outputs()
    out.state(d.transition, d.process_cov)
    return out


def imm_case(src: Source) -> Case:
    """``imm_filter`` on both backends: agreeing, mode probabilities a distribution."""
    p = problem(src)
    axes = p.h.shape[0]
    models = [
        ConstantVelocity(accel_psd=src.log_real(1e-3, 1.0), n_axes=axes),
        ConstantAcceleration(jerk_psd=src.log_real(1e-2, 10.0), n_axes=axes),
    ]
    names = models[0].state_names[:axes]
    priors = [
        at.GaussianState(
            np.zeros(mo.state_dim), np.diag(10.0 ** src.rng.uniform(0, 6, mo.state_dim)), 0.0
        )
        for mo in models
    ]
    stay = src.real(0.5, 0.999)
    pi = np.array([[stay, 1 - stay], [1 - stay, stay]])
    p0 = np.array([0.5, 0.5])
    z = np.where(p.mask, p.z, np.nan)

    def call(**kw: Any) -> Outputs:
        args = dict(
            times=p.times, measurements=z, models=models, measured_states=names,
            measurement_cov=p.r, initial=priors, transition_probs=pi, initial_probs=p0,
            mask=p.mask,
        )  # fmt: skip
        args.update(kw)
        out = Outputs()
        a, b = (imm_filter(**args, backend=bk) for bk in ("numpy", "numba"))
        for res in (a, b):
            out.state(res.filtered.mean, res.filtered.cov)
            out.probabilities.append(res.mode_probabilities)
        out.compare("imm_filter numpy/numba", b.filtered, a.filtered)
        rng = np.random.default_rng(1)
        for q in perturbed(replace(p, z=z)):
            moved_priors = [
                at.GaussianState(*(_change(v, rng, v.ndim == 2) for v in (st.mean, st.cov)), 0.0)
                for st in priors
            ]
            args.update(times=q.times, measurements=q.z, measurement_cov=q.r, initial=moved_priors)
            moved = imm_filter(**args, backend="numpy").filtered
            out.sensitivity("imm_filter numpy/numba", moved, a.filtered)
        return out

    if src.integer(0, 2):
        return Case("imm_filter", call)
    arg = src.choice(("transition_probs", "initial_probs", "measurement_cov", "times"))
    how = src.choice(SPOILS + ("not stochastic",))
    if how == "not stochastic":
        bad: Any = {"transition_probs": pi * 1.5, "initial_probs": p0 - 1.0}.get(arg)
        if bad is None:
            how, bad = "indefinite", spoil_cov(p.r, "indefinite")
    elif how == "shape" and arg == "measurement_cov":  # (1, 1, 1, 1) is a valid per-step R
        bad = np.eye(p.r.shape[-1] + 1)
    else:
        bad = spoil({"transition_probs": pi, "initial_probs": p0, "measurement_cov": p.r,
                     "times": p.times}[arg], how, src)  # fmt: skip
    return Case("imm_filter", lambda: call(**{arg: bad}), arg, how)


def nonlinear_case(src: Source) -> Case:
    """``ekf_filter`` with a linear measurement model equals ``kalman_filter`` (both ``auto``:
    Joseph, or the square root where Joseph would lose digits), and its compiled kernel its
    NumPy steps; so does the IMM-EKF of two copies of the model (a user's measurement
    function: the IMM's EKF path, square root where needed); spoiled times, measurements,
    noise or prior are rejected by name.

    The UKF is not compared here: its sigma points' measurement differences cancel digits
    where a sigma is 1e-7 to 1e-11 of the mean, and on 1,500 of these random problems its
    default (square-root where needed) is more than 0.01 posterior sigma (at most 0.13) off
    the Kalman filter on 5, a documented limit of ``ukf_filter``; ``turn_case`` fuzzes it
    for finite, PSD results.
    """
    p = replace(problem(src), offset=None)
    names = p.model.state_names[: p.h.shape[0]]
    measure = PositionMeasurement(p.r, names)
    run = at.ekf_filter
    z = np.where(p.mask, p.z, np.nan)

    def call(**kw: Any) -> Outputs:
        args = dict(times=p.times, measurements=z, model=p.model, measurement_model=measure,
                    initial=p.prior, mask=p.mask)  # fmt: skip
        args.update(kw)
        res = run(**args)
        out = Outputs()
        out.state(res.filtered.mean, res.filtered.cov)
        if not kw:
            ref = at.kalman_filter(p.times, z, p.model, p.h, p.r, p.prior, mask=p.mask,
                                   backend="numpy")  # fmt: skip
            imm = imm_filter(p.times, z, [p.model, p.model], _identity(names), p.r,
                             [p.prior, p.prior], initial_probs=[0.5, 0.5],
                             transition_probs=[[0.9, 0.1], [0.1, 0.9]], mask=p.mask)  # fmt: skip
            labels = (f"{run.__name__}/kalman_filter", "imm_filter(EKF)/kalman_filter")
            for label, got in zip(labels, (res, imm), strict=True):
                out.compare(label, got.filtered, ref.filtered)
            for q in perturbed(replace(p, z=z)):  # the reference's rounding sensitivity
                moved = at.kalman_filter(q.times, q.z, q.model, q.h, q.r, q.prior, mask=q.mask,
                                         backend="numpy")  # fmt: skip
                for label in labels:
                    out.sensitivity(label, moved.filtered, ref.filtered)
            compiled_agrees(out, "ekf_filter numpy/numba", run, args, lambda q: dict(
                times=q.times, measurements=q.z, measurement_model=PositionMeasurement(q.r, names),
                initial=q.prior), replace(p, z=z))  # fmt: skip
        return out

    if src.integer(0, 2):
        return Case(run.__name__, call)
    arg = src.choice(("times", "measurements", "measurement_cov", "initial"))
    how = src.choice(SPOILS)
    bad: Any
    if arg == "initial":
        how = "indefinite"
        bad = at.GaussianState(p.prior.mean, spoil_cov(np.asarray(p.prior.cov), how), 0.0)
    elif arg == "measurement_cov":
        how = src.choice(("indefinite", "nan", "shape"))
        bad = spoil_cov(p.r, how) if how == "indefinite" else (
            np.eye(p.r.shape[-1] + 1) if how == "shape" else spoil(p.r, how, src))  # fmt: skip
    else:
        bad = spoil({"times": p.times, "measurements": p.z}[arg], how, src)
        if arg == "measurements" and how == "nan":
            idx = np.argwhere(np.broadcast_to(p.mask, p.z.shape))
            if not len(idx):
                return Case(run.__name__, call, None, "no present measurement")
            bad = p.z.copy()
            bad[tuple(idx[src.integer(0, len(idx) - 1)])] = np.nan
    return Case(run.__name__, lambda: call(**{arg: bad}), arg, how)


def _identity(names: tuple[str, ...]) -> FunctionMeasurement:
    """The states ``names`` measured directly, as a user's measurement function (the EKF
    path, not the Kalman one a :class:`PositionMeasurement` takes in ``imm_filter``)."""
    m = len(names)

    def unit(s: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.eye(m), s.shape[:-1] + (m, m))

    return FunctionMeasurement(lambda s: s, names, names, np.eye(m), unit)


def compiled_agrees(
    out: Outputs, label: str, run: Callable[..., Any], args: dict[str, Any],
    changed: Callable[[Problem], dict[str, Any]], p: Problem,
) -> None:  # fmt: skip
    """Record ``run(**args)`` on both backends (they must agree) and how far the NumPy result
    moves on the rounding-perturbed copies of ``p`` (``changed`` gives their arguments).

    The default form (``auto``) on both: the compiled Joseph form where it keeps its digits,
    else the NumPy square root. (Forced to Joseph past that limit, each backend loses digits
    its own way: both strayed from the square-root filter by up to hundreds of sigmas.)
    """
    a = run(**args, backend="numpy")
    b = run(**args, backend="numba")
    out.state(b.filtered.mean, b.filtered.cov)
    out.compare(label, b.filtered, a.filtered)
    for q in perturbed(p):
        out.sensitivity(label, run(**{**args, **changed(q)}, backend="numpy").filtered, a.filtered)


def turn_case(src: Source) -> Case:
    """``ekf_filter`` and ``ukf_filter`` with a :class:`CoordinatedTurn`: finite and PSD over
    random steps (1e-6 to 1e4 s), turn rates (up to 10 rad/s) and noise; with a known zero
    turn rate and no turn noise the EKF equals the CV Kalman filter. Spoiled model
    parameters, times or prior are rejected by name."""
    axes = src.integer(2, 3)
    q, q_turn = src.log_real(1e-4, 1e2), src.log_real(1e-8, 1.0)
    n_tracks, n_steps = src.integer(1, 3), src.integer(1, 25)
    lo, hi = sorted((src.log_real(1e-6, 1e4), src.log_real(1e-6, 1e4)))
    times = np.cumsum(10.0 ** src.rng.uniform(np.log10(lo), np.log10(hi), (n_tracks, n_steps)), -1)
    r = spd(src, axes, src.log_real(1.0, 1e12), src.log_real(1e-4, 1e4))
    n = 2 * axes + 1
    straight = src.integer(0, 2) == 0  # the CV oracle: turn rate known to be 0, no turn noise
    var = 10.0 ** src.rng.uniform(-4, 6, n)
    var[-1] = 0.0 if straight else src.log_real(1e-8, 1.0)
    mean0 = src.rng.normal(size=(n_tracks, n)) * 10.0
    mean0[:, -1] = 0.0 if straight else src.rng.normal(size=n_tracks) * src.log_real(1e-4, 10.0)
    prior = at.GaussianState(mean0, np.broadcast_to(np.diag(var), (n_tracks, n, n)), 0.0)
    z = src.rng.normal(size=(n_tracks, n_steps, axes)) * 3.0 + 5.0 * times[..., None]
    names = ("x", "y", "z")[:axes]
    run = src.choice((at.ekf_filter, at.ukf_filter))

    def call(turn_psd: Any = 0.0 if straight else q_turn, **kw: Any) -> Outputs:
        ct = CoordinatedTurn(q, turn_psd, q, axes)
        args = dict(times=times, measurements=z, model=ct,
                    measurement_model=PositionMeasurement(r, names), initial=prior)  # fmt: skip
        args.update(kw)
        res = run(**args)
        out = Outputs()
        out.state(res.filtered.mean, res.filtered.cov)
        if straight and not kw and run is at.ekf_filter:
            keep = list(range(n - 1))
            cv = ConstantVelocity(q, n_axes=axes)
            p0 = at.GaussianState(mean0[:, keep], np.broadcast_to(np.diag(var[keep]),
                                  (n_tracks, n - 1, n - 1)), 0.0)  # fmt: skip
            cv_problem = Problem(
                times, z, cv, np.eye(n - 1)[:axes], r, p0, np.ones(z.shape, bool), None
            )
            ref = _filter(cv_problem, form="joseph", backend="numpy").filtered
            f = res.filtered
            res_cv = at.GaussianState(f.mean[..., keep], f.cov[..., keep, :][..., keep], f.time)
            label = "ekf_filter(CT)/kalman_filter(CV)"
            out.compare(label, res_cv, ref)
            for moved in perturbed(cv_problem):
                out.sensitivity(label, _filter(moved, form="joseph", backend="numpy").filtered, ref)
        if run is at.ekf_filter and not kw:
            same = Problem(times, z, ct, np.eye(n)[:axes], r, prior, np.ones(z.shape, bool), None)
            compiled_agrees(out, "ekf_filter(CT) numpy/numba", run, args, lambda q: dict(
                times=q.times, measurements=q.z, initial=q.prior,
                measurement_model=PositionMeasurement(q.r, names)), same)  # fmt: skip
        return out

    label = f"{run.__name__}(CT)"
    if src.integer(0, 2):
        return Case(label, call)
    arg = src.choice(("turn_psd", "times", "initial"))
    how = src.choice(SPOILS)
    bad: Any
    if arg == "turn_psd":
        how = src.choice(("nan", "negative"))
        bad = np.nan if how == "nan" else -q_turn
    elif arg == "initial":
        how = "indefinite"
        bad = at.GaussianState(prior.mean, spoil_cov(np.asarray(prior.cov), how), 0.0)
    else:
        bad = spoil(times, how, src)
    return Case(label, lambda: call(**{arg: bad}), arg, how)


def coords_case(src: Source) -> Case:
    """Radar polar <-> ENU with covariance: finite, symmetric PSD."""
    n = src.integer(1, 5)
    polar = np.column_stack(
        [
            10.0 ** src.rng.uniform(-3, 6, n) * (src.rng.uniform(size=n) > 0.1),
            src.rng.uniform(-np.pi, np.pi, n),
            src.rng.uniform(-1.5, 1.5, n),
        ]
    )
    cov = np.stack([spd(src, 3, src.log_real(1.0, 1e8), src.log_real(1e-8, 1e2)) for _ in range(n)])

    def run(polar: Any = polar, polar_cov: Any = cov) -> Outputs:
        out = Outputs()
        enu = coords.polar_to_enu(polar)
        c = coords.polar_to_enu_cov(polar, polar_cov)
        out.state(enu, c)
        return out

    if src.integer(0, 2):
        return Case("coords", run)
    arg = src.choice(("polar", "polar_cov"))
    how = src.choice(SPOILS + ("asymmetric", "indefinite") if arg == "polar_cov" else SPOILS)
    value = polar if arg == "polar" else cov
    bad = spoil_cov(cov, how) if how in ("asymmetric", "indefinite") else spoil(value, how, src)
    return Case("coords", lambda: run(**{arg: bad}), arg, how)


def geodetic_case(src: Source) -> Case:
    """Geodetic <-> ECEF <-> ENU: finite, round trips within the documented accuracy."""
    n = src.integer(1, 5)
    lat = src.rng.uniform(-np.pi / 2, np.pi / 2, n)
    lat[src.rng.uniform(size=n) < 0.1] = np.pi / 2  # a pole
    lon = src.rng.uniform(-np.pi, np.pi, n)
    height = src.choice([1.0, -1.0]) * 10.0 ** src.rng.uniform(-3, 4, n)
    height[src.rng.uniform(size=n) < 0.2] = 10.0 ** src.rng.uniform(4, 8)  # orbits
    site = (src.real(-1.5, 1.5), src.real(-np.pi, np.pi), src.real(-100.0, 5e3))
    enu = src.rng.normal(size=(n, 3)) * 10.0 ** src.real(-3, 5)
    cov = np.stack([spd(src, 3, src.log_real(1.0, 1e8), src.log_real(1e-8, 1e4)) for _ in range(n)])

    def run(lat: Any = lat, lon: Any = lon, height: Any = height, enu: Any = enu,
            cov: Any = cov) -> Outputs:  # fmt: skip
        out = Outputs()
        ecef = coords.geodetic_to_ecef(lat, lon, height)
        back = coords.ecef_to_geodetic(ecef)
        there = coords.enu_to_ecef(enu, *site)
        again = coords.ecef_to_enu(there, *site)
        rotated = coords.rotate_cov(cov, coords.enu_to_ecef_rotation(*site[:2]))
        out.state(ecef, rotated)
        lat, lon, height = np.broadcast_arrays(lat, lon, height)  # as the functions did
        out.finite += [*back, there, again]
        # documented accuracy: 1e-12 rad and 1e-6 m (sigma = 100 x, the floor is 1e-2 sigma)
        away = np.abs(lat) < np.pi / 2 - 1e-9  # longitude is undefined at a pole
        tiny, lon_tiny = np.full(lat.shape, 1e-10), np.full(away.sum(), 1e-10)
        out.agree.append(("latitude round trip mean", back[0], lat, tiny))
        out.agree.append(("longitude round trip mean", back[1][away], lon[away], lon_tiny))
        out.agree.append(("height round trip mean", back[2], height, 1e4 * tiny))
        scale = 1e-6 + 1e-13 * np.abs(enu)  # 1e-8 m: rounding of ECEF positions ~6.4e6 m
        out.agree.append(("ENU round trip mean", again, enu, scale))
        return out

    if src.integer(0, 2):
        return Case("geodetic", run)
    arg = src.choice(("lat", "lon", "height", "enu", "cov"))
    how = src.choice(SPOILS + ("degrees",) if arg == "lat" else SPOILS)
    value = {"lat": lat, "lon": lon, "height": height, "enu": enu, "cov": cov}[arg]
    bad = np.degrees(lat) + 100.0 if how == "degrees" else spoil(value, how, src)
    if how == "shape" and arg == "cov":
        bad = cov[..., :2, :2]
    if arg in ("lat", "lon", "height") and how in ("shape", "empty"):
        try:  # e.g. (1,) or (0,) against (1,): broadcasts, a valid call
            np.broadcast_shapes(np.shape(bad), lat.shape)
            return Case("geodetic", lambda: run(**{arg: bad}))
        except ValueError:
            pass
    return Case("geodetic", lambda: run(**{arg: bad}), arg, how)


def adaptive_case(src: Source) -> Case:
    """``innovation_adaptive_filter`` on both backends; bad arguments rejected by name."""
    n_tracks, n_steps, d = src.integer(1, 3), src.integer(3, 150), src.integer(1, 3)
    step = src.log_real(1e-3, 10.0)
    t = src.real(0.0, 100.0) + step * np.arange(n_steps)
    var = src.log_real(1e-4, 1e4)
    accel_var = src.log_real(1e-4, 1e2)
    z = src.rng.normal(size=(n_tracks, n_steps, d)) * np.sqrt(var) + 5.0 * t[:, None]
    mask = src.rng.uniform(size=(n_tracks, n_steps)) > src.real(0.0, 0.3)
    mask[:, :2] = True  # two-point initialisation
    options = dict(
        identification=src.choice(("published", "mehra")),
        averaging=src.choice(("ewma", "window")),
        memory=src.integer(5, 60),
        warmup=src.integer(2, 60),
        difference_order=src.integer(2, 4),
    )

    def call(times: Any = t, measurements: Any = z, measurement_var: Any = var,
             dwna_accel_var: Any = accel_var, mask: Any = mask, backend: str = "numpy",
             ) -> Any:  # fmt: skip
        return innovation_adaptive_filter(
            times, measurements, measurement_var=measurement_var,
            dwna_accel_var=dwna_accel_var, mask=mask, backend=backend, **options,
        )  # fmt: skip

    def run(**kw: Any) -> Outputs:
        out = Outputs()
        a, b = (call(**kw, backend=bk).filtered for bk in ("numpy", "numba"))
        for res in (a, b):  # velocity (and its covariance) is undefined at the first epoch
            out.state(res.mean[..., 1:, :], res.cov[..., 1:, :, :])
        first, rest = (lambda g: g[..., :1, :d]), (lambda g: g[..., 1:, :])
        out.finite += [first(a.mean), first(b.mean)]
        tail = [at.GaussianState(rest(g.mean), g.cov[..., 1:, :, :], 0.0) for g in (a, b)]
        out.compare("innovation_adaptive_filter numpy/numba", tail[1], tail[0])
        rng = np.random.default_rng(2)
        for _ in range(2):
            moved = call(measurements=_change(z, rng)).filtered
            moved_tail = at.GaussianState(rest(moved.mean), moved.cov[..., 1:, :, :], 0.0)
            out.sensitivity("innovation_adaptive_filter numpy/numba", moved_tail, tail[0])
        return out

    if src.integer(0, 2):
        return Case("innovation_adaptive_filter", run)
    arg = src.choice(("times", "measurements", "measurement_var", "dwna_accel_var", "mask"))
    how = src.choice(SPOILS + ("negative",) if arg.endswith("var") else SPOILS)
    value = {"times": t, "measurements": z, "measurement_var": var,
             "dwna_accel_var": accel_var, "mask": mask}[arg]  # fmt: skip
    if how == "negative":
        bad: Any = -value
    elif arg == "times" and how == "shape":
        bad = t[:-1]
    elif arg == "measurements" and how == "shape":
        bad = z[..., None]
    elif arg == "measurements" and how == "nan":  # NaN is missing where the mask says so
        bad = z.copy()
        bad[..., src.integer(0, 1), :] = np.nan
    elif arg == "mask":
        bad = {"nan": mask.astype(float), "shape": mask[..., :-1]}.get(how, "yes")
    else:
        bad = spoil(value, how, src)
    if arg.endswith("var") and how == "shape":  # a (d,) variance per axis is valid
        bad = np.full(d + 1, value)
    return Case("innovation_adaptive_filter", lambda: _valid_call(call, **{arg: bad}), arg, how)


def _valid_call(call: Callable[..., Any], **kw: Any) -> Outputs:
    res = call(**kw).filtered
    out = Outputs()
    out.state(res.mean[..., 1:, :], res.cov[..., 1:, :, :])
    return out


def batch_ls_case(src: Source) -> Case:
    """``fit_polynomial``: monomial and Legendre bases agree; bad nodes rejected by name."""
    degree = src.integer(0, 4)
    n_pos = src.integer(degree + 1, 12)
    n_other = src.integer(0, 8)
    k = n_pos + n_other
    span = src.log_real(1e-2, 1e4)
    times = np.concatenate(
        [np.sort(src.rng.uniform(0, span, n_pos)), src.rng.uniform(0, span, n_other)]
    )
    orders = np.concatenate([np.zeros(n_pos, int), src.rng.integers(1, 3, n_other)])
    coef = src.rng.normal(size=(degree + 1, 3)) * 10.0 ** src.real(0.0, 4.0)
    u = times / span - 0.5  # positions of up to ~10 km over the span
    values = np.stack([sum(coef[j] * u[i] ** j for j in range(degree + 1)) for i in range(k)])
    covs = np.stack(
        [spd(src, 3, src.log_real(1.0, 1e6), src.log_real(1e-6, 1e4)) for _ in range(k)]
    )
    values = values + src.rng.normal(size=values.shape) * np.sqrt(
        np.diagonal(covs, axis1=1, axis2=2)
    )
    joint = bool(src.integer(0, 1))
    t_eval = src.rng.uniform(0, span, 3)

    def fit(times: Any = times, orders: Any = orders, values: Any = values, covs: Any = covs,
            basis: str = "monomial") -> Any:  # fmt: skip
        return fit_polynomial(times, orders, values, covs, degree=degree, joint=joint, basis=basis)

    def run() -> Outputs:
        out = Outputs()
        a, b = (fit(basis=basis).evaluate(t_eval) for basis in ("legendre", "monomial"))
        out.state(a.mean, a.cov)
        out.state(b.mean, b.cov)
        out.compare("fit_polynomial legendre/monomial", b, a)
        rng = np.random.default_rng(3)
        for _ in range(2):
            moved = fit(
                values=_change(values, rng), covs=_change(covs, rng, True), basis="legendre"
            )
            out.sensitivity("fit_polynomial legendre/monomial", moved.evaluate(t_eval), a)
        return out

    if src.integer(0, 2):
        return Case("batch_ls", run)
    arg = src.choice(("times", "orders", "values", "covs"))
    how = src.choice(SPOILS + (("asymmetric", "indefinite") if arg == "covs" else ()))
    value = {"times": times, "orders": orders, "values": values, "covs": covs}[arg]
    bad = spoil_cov(covs, how) if how in ("asymmetric", "indefinite") else spoil(value, how, src)
    if arg == "orders" and how in ("nan", "inf"):
        how, bad = "out of range", np.concatenate([orders[:-1], [7]])
    return Case("batch_ls", lambda: _fit_state(fit(**{arg: bad}), t_eval), arg, how)


def _fit_state(fit: Any, t_eval: np.ndarray) -> Outputs:
    out = Outputs()
    g = fit.evaluate(t_eval)
    out.state(g.mean, g.cov)
    return out


def kalman_step_case(src: Source) -> Case:
    """``kalman_step`` fed a batch step by step equals ``kalman_filter``; bad steps rejected."""
    p = problem(src)
    n_steps = p.z.shape[-2]
    times = np.broadcast_to(p.times, p.z.shape[:-1])
    mask = np.broadcast_to(p.mask, p.z.shape)
    z = p.z - (0.0 if p.offset is None else p.offset)  # kalman_step takes no noise mean

    def steps(q: Problem, **kw: Any) -> at.GaussianState:
        state = q.prior
        tq = np.broadcast_to(q.times, q.z.shape[:-1])
        zq = q.z - (0.0 if q.offset is None else q.offset)
        for k in range(n_steps):
            args = dict(time=tq[:, k], mask=mask[:, k])
            args.update(kw)
            state, _ = at.kalman_step(state, zq[:, k], q.model, q.h, q.r, **args)
        return state

    if src.integer(0, 2):

        def run() -> Outputs:
            out = Outputs()
            end = steps(p)
            out.state(end.mean, end.cov)
            ref = _filter(p).filtered
            last = at.GaussianState(ref.mean[:, -1], ref.cov[:, -1], times[:, -1])
            out.compare("kalman_step/kalman_filter", end, last)
            for q in perturbed(p):
                c = _filter(q).filtered
                moved = at.GaussianState(c.mean[:, -1], c.cov[:, -1], times[:, -1])
                out.sensitivity("kalman_step/kalman_filter", moved, last)
            return out

        return Case("kalman_step", run)
    arg = src.choice(("time", "measurement", "measurement_cov", "measurement_matrix", "state",
                      "mask", "form"))  # fmt: skip
    how = src.choice(SPOILS)
    args: dict[str, Any] = dict(
        state=p.prior, measurement=z[:, 0], model=p.model, measurement_matrix=p.h,
        measurement_cov=p.r, time=times[:, 0], mask=mask[:, 0],
    )  # fmt: skip
    if arg == "time":
        how = src.choice(("nan", "past", "string", "complex", "none"))
        args["time"] = {"nan": np.nan, "past": -1.0, "string": "soon", "complex": 1j,
                        "none": None}[how]  # fmt: skip
    elif arg == "measurement_cov":
        how = src.choice(("nan", "asymmetric", "indefinite", "shape", "string"))
        args[arg] = (
            spoil_cov(p.r, how) if how in ("asymmetric", "indefinite")
            else np.eye(p.r.shape[-1] + 1) if how == "shape" else spoil(p.r, how, src)
        )  # fmt: skip
        if how == "asymmetric" and p.r.shape[-1] == 1:
            how, args[arg] = "indefinite", spoil_cov(p.r, "indefinite")
    elif arg == "state":
        how = "late"
        args[arg] = at.GaussianState(p.prior.mean, p.prior.cov, float(np.max(p.times)) + 1.0)
    elif arg == "mask":
        how = src.choice(("shape", "string", "float"))
        args[arg] = {"shape": np.ones((3, 7, 5), bool), "string": "yes",
                     "float": mask[:, 0] + 0.5}[how]  # fmt: skip
    elif arg == "form":
        how = "option"
        args[arg] = src.choice(("", "Joseph", 3))
    elif how == "nan" and arg == "measurement":  # a NaN under a False mask is fine
        args["mask"] = np.ones_like(mask[:, 0])
        args[arg] = spoil(z[:, 0], how, src)
    elif how == "shape" and arg == "measurement":  # (N, 1, 1, 1) would broadcast: m + 1
        args[arg] = np.ones(z.shape[:1] + (z.shape[-1] + 1,))
    else:
        args[arg] = spoil(args[arg], how, src)
    name = "time" if arg == "state" else arg  # a late state is reported against the time

    def spoiled() -> Outputs:
        state, _ = at.kalman_step(**args)
        out = Outputs()
        out.state(state.mean, state.cov)
        return out

    return Case("kalman_step", spoiled, name, how)


def dead_reckoning_case(src: Source) -> Case:
    """``dead_reckoning_filter``: its [v, w] filter equals the 3-state ``kalman_filter``'s
    marginal (distance is never measured and never feeds back); bad inputs rejected."""
    tau, sigma_a = src.log_real(0.1, 100.0), src.log_real(1e-2, 30.0)
    model = Singer(time_constant_s=tau, accel_std_mps2=sigma_a)
    n_tracks, n_steps = src.integer(1, 3), src.integer(1, 25)
    lo, hi = sorted((src.log_real(1e-6, 1e4), src.log_real(1e-6, 1e4)))
    times = np.cumsum(10.0 ** src.rng.uniform(np.log10(lo), np.log10(hi), n_steps))
    speed_var = src.log_real(1e-6, 1e4)
    scale = src.choice((1.0, src.real(0.5, 2.0), -src.real(0.5, 2.0)))
    speeds = scale * (10.0 + np.sqrt(speed_var) * src.rng.normal(size=(n_tracks, n_steps)))
    p0 = np.diag(10.0 ** src.rng.uniform(-6, 6, 2))
    prior = at.GaussianState(src.rng.normal(size=2), p0, times[0])
    dist_var0 = src.choice((0.0, src.log_real(1e-6, 1e6)))
    args: dict[str, Any] = dict(
        times=times, speeds=speeds, model=model, speed_var=speed_var, initial=prior,
        initial_distance_var_m2=dist_var0, speed_scale=scale,
    )  # fmt: skip

    def call(**kw: Any) -> Outputs:
        res = at.dead_reckoning_filter(**{**args, **kw})
        out = Outputs()
        out.state(res.filtered.mean, res.filtered.cov)
        out.finite += [res.distance_m, res.distance_var_m2]
        if np.any(res.distance_var_m2 < 0):
            out.covs.append(res.distance_var_m2[..., None, None])  # counted as non-PSD
        return out

    def reference(t: np.ndarray, y: np.ndarray, var: float, pr: at.GaussianState) -> Any:
        cov3 = np.zeros((3, 3))
        cov3[0, 0], cov3[1:, 1:] = dist_var0, pr.cov
        init = at.GaussianState(np.concatenate([[0.0], pr.mean]), cov3, t[0])
        res = at.kalman_filter(t, y[..., None], model, [[0.0, scale, 0.0]],
                               [[scale**2 * var]], init).filtered  # fmt: skip
        return at.GaussianState(res.mean[..., 1:], res.cov[..., 1:, 1:], res.time)

    if src.integer(0, 2):

        def run() -> Outputs:
            out = call()
            res = at.dead_reckoning_filter(**args)
            ref = reference(times, speeds, speed_var, prior)
            out.compare("dead_reckoning/kalman_filter", res.filtered, ref)
            rng = np.random.default_rng(0)
            for _ in range(2):
                moved_prior = at.GaussianState(
                    _change(prior.mean, rng), _change(prior.cov, rng, True), times[0]
                )
                moved = reference(
                    _change(times, rng), _change(speeds, rng),
                    speed_var * (1 + ROUNDING * rng.uniform(-1, 1)), moved_prior,
                )  # fmt: skip
                out.sensitivity("dead_reckoning/kalman_filter", moved, ref)
            return out

        return Case("dead_reckoning_filter", run)
    arg = src.choice(("times", "speeds", "speed_var", "speed_scale", "initial",
                      "initial_distance_var_m2", "method"))  # fmt: skip
    how = src.choice(SPOILS)
    if arg == "times" and n_steps > 1 and src.integer(0, 1):
        how = src.choice(("unsorted", "duplicate"))
        bad: Any = spoil_times(times, how)
    elif arg in ("speed_var", "initial_distance_var_m2", "speed_scale"):
        how = src.choice(("nan", "inf", "string", "none", "negative", "zero"))
        bad = {"nan": np.nan, "inf": np.inf, "string": "1", "none": None, "negative": -1.0,
               "zero": 0.0}[how]  # fmt: skip
        if (arg, how) in (("initial_distance_var_m2", "zero"), ("speed_scale", "negative")):
            return Case("dead_reckoning_filter", lambda: call(**{arg: bad}))  # valid
    elif arg == "initial":
        how = src.choice(("indefinite", "three states", "late"))
        bad = {
            "indefinite": at.GaussianState(prior.mean, spoil_cov(p0, "indefinite"), times[0]),
            "three states": at.GaussianState(np.zeros(3), np.eye(3), times[0]),
            "late": at.GaussianState(prior.mean, p0, times[-1] + 1.0),
        }[how]
    elif arg == "method":
        how = "option"
        bad = src.choice(("", "Euler", 3))
    elif how == "shape" and arg == "speeds":  # (N, 1, 1, 1) is a valid batch of one step
        bad = np.ones((n_tracks, n_steps + 1))
    else:
        bad = spoil(args[arg], how, src)
    name = "initial" if (arg, how) == ("initial", "late") else arg
    return Case("dead_reckoning_filter", lambda: call(**{arg: bad}), name, how)


def observability_case(src: Source) -> Case:
    """Observability of ``(Phi, H)``: rank in range, basis orthonormal and in the null space."""
    p = problem(src, tracks=1)
    dt = 10.0 ** src.rng.uniform(-6, 4, src.integer(1, 6))
    phi = at.discretize(p.model, dt).transition
    phi = phi[0] if src.integer(0, 1) else phi
    n = phi.shape[-1]
    h = p.h if src.integer(0, 1) else src.rng.normal(size=(src.integer(1, 3), n))
    h = h * (src.rng.uniform(size=h.shape) > 0.3)

    def call(transition: Any = phi, measurement_matrix: Any = h) -> Outputs:
        o = at.observability_matrix(transition, measurement_matrix)
        rank = at.observability_rank(o)
        basis = at.unobservable_directions(o)
        out = Outputs()
        out.finite += [o, basis]
        eye = np.eye(n - rank)
        if not 0 <= rank <= n or basis.shape != (n, n - rank):
            out.finite.append(np.array([np.nan]))  # counted: inconsistent outputs
        elif not np.allclose(basis.T @ basis, eye, atol=1e-10):
            out.finite.append(np.array([np.nan]))
        if at.is_observable(transition, measurement_matrix) != (rank == n):
            out.finite.append(np.array([np.nan]))
        return out

    if src.integer(0, 2):
        return Case("observability", call)
    arg = src.choice(("transition", "measurement_matrix"))
    how = src.choice(SPOILS)
    if how == "shape" and arg == "measurement_matrix":
        bad: Any = np.ones((1, n + 1))
    elif how == "shape":
        bad = np.ones((n, n + 1))
    else:
        bad = spoil(phi if arg == "transition" else h, how, src)
    return Case("observability", lambda: call(**{arg: bad}), arg, how)


TARGETS: dict[str, Callable[[Source], Case]] = {
    "kalman_filter": kalman_filter_case,
    "shared_gain_filter": shared_gain_case,
    "OnlineFilter": online_case,
    "discretize": discretize_case,
    "imm_filter": imm_case,
    "ekf_filter": nonlinear_case,
    "coordinated_turn": turn_case,
    "coords": coords_case,
    "geodetic": geodetic_case,
    "innovation_adaptive_filter": adaptive_case,
    "batch_ls": batch_ls_case,
    "kalman_step": kalman_step_case,
    "dead_reckoning_filter": dead_reckoning_case,
    "observability": observability_case,
}


def campaign(n_cases: int, seed: int, progress: bool = False) -> tuple[Counter, dict[str, str]]:
    """Run ``n_cases`` cases spread over the targets; counts by (target, category), examples."""
    counts: Counter = Counter()
    examples: dict[str, str] = {}
    names = list(TARGETS)
    start = time.perf_counter()
    for i in range(n_cases):
        name = names[i % len(names)]
        case_seed = (seed, i)
        case = TARGETS[name](Source(np.random.default_rng(case_seed)))
        category, detail = outcome(case)
        counts[(case.target, category)] += 1
        if category in DEFECTS and (case.target, category) not in examples:
            examples[(case.target, category)] = f"seed {case_seed}: {detail}"
        if progress and (i + 1) % 1000 == 0:
            defects = sum(v for (_, c), v in counts.items() if c in DEFECTS)
            print(
                f"{i + 1} cases, {defects} defects, {time.perf_counter() - start:.0f} s", flush=True
            )
    return counts, examples


def main() -> None:
    """Command line: run the campaign, print counts by category; exit 1 on any defect."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    counts, examples = campaign(args.cases, args.seed, progress=True)
    print(f"{sum(counts.values())} cases")
    for category in ("ok", "ok, undetermined", "rejected", *DEFECTS):
        total = sum(v for (_, c), v in counts.items() if c == category)
        by = ", ".join(f"{t} {v}" for (t, c), v in sorted(counts.items()) if c == category)
        print(f"{category}: {total}" + (f" ({by})" if by else ""))
    for key, text in examples.items():
        print(f"example {key}: {text}")
    raise SystemExit(1 if any(c in DEFECTS for (_, c) in counts) else 0)


if __name__ == "__main__":
    main()
