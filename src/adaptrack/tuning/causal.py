"""Causal self-tuning: maximum likelihood refitted from a recording's own past measurements.

Parameters tuned on other recordings may suit a new one badly: on the shared flights, an IMM
fitted on an arrival and a helicopter gave a calibration flight's long radials a CV PSD 300
times too large. The new recording's own measurements tell, without truth.
:func:`refit_online` runs a filter over a recording (one or more segments, e.g. the stretches
that different radars see) in time order and refits its parameters by maximum likelihood
(:func:`~adaptrack.tuning.fit_by_likelihood`, started at the last fit) of every measurement
received so far: first once ``first`` measurements have arrived, then each time their count
has grown by the factor ``growth``. Each estimate uses only the measurements up to its own
time, with the parameters of the last refit before it, so the run is causal, as a live
tracker's would be.

>>> import numpy as np, adaptrack as at
>>> from adaptrack.models import ConstantVelocity
>>> rng = np.random.default_rng(1)
>>> t = np.arange(300.0)
>>> v = 2.0 + np.cumsum(rng.normal(0.0, 0.1, t.size))  # white acceleration, PSD 0.01
>>> x = np.cumsum(v)
>>> z = (x + rng.normal(0.0, 3.0, t.size))[:, None]  # position, sigma 3 m
>>> def run(times, meas, p):
...     prior = at.GaussianState([meas[0, 0], 0.0], np.diag([9.0, 100.0]), times[0])
...     res = at.kalman_filter(times, meas, ConstantVelocity(p["q"]), ["x"], [[9.0]], prior)
...     return res.info.log_likelihood, res.filtered.mean
>>> online = refit_online([(t, z)], run, {"q": 10.0}, first=40)  # 1000 times too large
>>> online.fit_times, [round(f.value("q"), 4) for f in online.fits]
(array([ 39.,  79., 159.]), [0.0, 0.0023, 0.003])
>>> rms = lambda est: float(np.sqrt(np.mean((est[100:, 0] - x[100:]) ** 2)))
>>> round(rms(online.estimates[0]), 2), round(rms(run(t, z, {"q": 10.0})[1]), 2)  # from 100 s
(1.68, 2.59)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .._typing import FloatArray
from .likelihood import LikelihoodFit, fit_by_likelihood

SegmentRun = Callable[[FloatArray, FloatArray, dict[str, float]], tuple[ArrayLike, ArrayLike]]
"""``run(times, measurements, params) -> (log_likelihood (T,), estimates (T, n))`` of one
segment's first T measurements: a causal filter, whose estimate k depends on measurements
0..k only."""

PER_PARAMETER = 20  # measurements per parameter before the first refit (default ``first``)


@dataclass(frozen=True)
class OnlineFit:
    """Estimates of a causal self-tuning run and the fits it made.

    ``estimates[i]`` (T_i, n) are segment i's estimates; ``refit[i]`` (T_i,) the index of
    the refit whose parameters each one used (-1: the starting values). ``fits[j]`` is refit
    j's maximum-likelihood fit, ``params[j]`` the parameters it put in force (the fit's
    values where the data fix them), ``fit_times[j]`` [s] the time of the last measurement
    it saw.
    """

    estimates: list[FloatArray]
    refit: list[np.ndarray]
    fits: list[LikelihoodFit]
    params: list[dict[str, float]]
    fit_times: FloatArray


def refit_online(
    segments: Sequence[tuple[ArrayLike, ArrayLike]],
    run: SegmentRun,
    initial: Mapping[str, float],
    *,
    first: int | None = None,
    growth: float = 2.0,
    max_relative_error: float = 1.0,
) -> OnlineFit:
    """Filter ``segments`` in time order, refitting the parameters from the past as it goes.

    Parameters
    ----------
    segments : sequence of (times (T,), measurements (T, ...))
        The recording's tracks; times [s] strictly increasing within each. Measurements of
        different segments at one time are taken in segment order.
    run : callable
        :data:`SegmentRun`: the filter, run on a segment's first measurements. It judges the
        measurements: NaN is an error or a missing value as the filter it wraps says (e.g.
        ``kalman_filter``'s ``nan_policy``).
    initial : mapping of str to float
        Starting parameters (> 0), e.g. fitted on other recordings; they name the parameters.
    first : int, optional
        Measurements before the first refit (default ``20`` per parameter).
    growth : float
        Each later refit comes when the count of measurements has grown by this factor (> 1).
    max_relative_error : float
        A refitted parameter whose standard error exceeds this fraction of its value, or that
        has none (at a bound, or rough), is not yet fixed by the data and keeps the value it
        had (default 1: the 95 % interval spans more than a factor of 50). Short records
        otherwise drive a PSD to 0, and the filter then trusts its motion model for good.

    Refit j maximises the log-likelihood of the measurements before it (each segment's
    prefix), starting from refit j - 1's values. Segment i's estimate k then comes from
    ``run`` over its first k + 1 measurements with the parameters in force when measurement
    k arrived.
    """
    data = [_segment(i, times, meas) for i, (times, meas) in enumerate(segments)]
    if not data:
        raise ValueError("segments is empty: give at least one (times, measurements)")
    first = PER_PARAMETER * len(initial) if first is None else first
    if isinstance(first, bool) or not isinstance(first, int) or first < 2:
        raise ValueError(f"first must be an int >= 2 (measurements); got {first!r}")
    if isinstance(growth, bool) or not math.isfinite(growth) or growth <= 1.0:
        raise ValueError(f"growth must be a finite number > 1; got {growth!r}")
    if not max_relative_error > 0.0:
        raise ValueError(f"max_relative_error must be > 0; got {max_relative_error!r}")
    order = sorted((float(t), i, k) for i, (times, _) in enumerate(data)
                   for k, t in enumerate(times))  # fmt: skip
    marks = _refit_counts(len(order), first, growth)
    params = {n: float(v) for n, v in initial.items()}
    estimates = [np.full((0,), np.nan)] * len(data)  # each filled by its first block
    refit = [np.full(times.size, -1) for times, _ in data]
    fits: list[LikelihoodFit] = []
    used: list[dict[str, float]] = []
    fit_times = []
    for j, (lo, hi) in enumerate(zip([0, *marks], [*marks, len(order)], strict=True)):
        if lo:
            fit = fit_by_likelihood(_past_likelihood(run, data, _prefixes(order[:lo])), params)
            fits.append(fit)
            fit_times.append(order[lo - 1][0])
            params = {
                n: v if fit.std_error(n) <= max_relative_error * v else params[n]
                for n, v in zip(fit.names, fit.values.tolist(), strict=True)
            }
            used.append(params)
        block = order[lo:hi]
        for i, n in _prefixes(block).items():
            start = min(k for _, s, k in block if s == i)
            times, meas = data[i]
            est = np.asarray(run(times[:n], meas[:n], params)[1], dtype=float)
            if not start:
                estimates[i] = np.full((times.size, *est.shape[1:]), np.nan)
            estimates[i][start:n] = est[start:n]
            refit[i][start:n] = j - 1
    return OnlineFit(estimates, refit, fits, used, np.array(fit_times))


def _past_likelihood(
    run: SegmentRun, data: list[tuple[FloatArray, FloatArray]], past: dict[int, int]
) -> Callable[[dict[str, float]], float]:
    """Return the log-likelihood of each segment's first ``past[i]`` measurements."""

    def loglik(params: dict[str, float]) -> float:
        return sum(float(np.sum(run(data[i][0][:n], data[i][1][:n], params)[0]))
                   for i, n in past.items())  # fmt: skip

    return loglik


def _segment(i: int, times: ArrayLike, meas: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """One segment's times and measurements, checked."""
    t = np.asarray(times, dtype=float)
    z = np.asarray(meas, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"segments[{i}]: times must be 1-D and not empty; got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"segments[{i}]: time {int(np.argmin(np.isfinite(t)))} is not finite")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise ValueError(f"segments[{i}]: times must increase strictly; time {bad[0] + 1} "
                         f"({t[bad[0] + 1]} s) follows {t[bad[0]]} s")  # fmt: skip
    if z.ndim == 0 or z.shape[0] != t.size:
        raise ValueError(f"segments[{i}]: measurements must have {t.size} rows, one per time; "
                         f"got shape {z.shape}")  # fmt: skip
    return t, z


def _refit_counts(total: int, first: int, growth: float) -> list[int]:
    """Return the counts of measurements at which refits come: ``first``, then ``growth`` times."""
    marks: list[int] = []
    n = float(first)
    while n < total:
        if not marks or math.ceil(n) > marks[-1]:
            marks.append(math.ceil(n))
        n *= growth
    return marks


def _prefixes(events: Sequence[tuple[float, int, int]]) -> dict[int, int]:
    """Segment -> how many of its measurements ``events`` reach (its largest index + 1)."""
    out: dict[int, int] = {}
    for _, i, k in events:
        out[i] = max(out.get(i, 0), k + 1)
    return dict(sorted(out.items()))


__all__ = ["OnlineFit", "SegmentRun", "refit_online"]
