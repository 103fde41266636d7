"""Truth-free tuning: maximum likelihood of positive parameters, standard errors from curvature.

Recorded data has no truth, but every Kalman filter run gives the log-likelihood of its own
measurements (the innovations'). :func:`fit_by_likelihood` maximises it over positive
parameters (noise spectral densities and variances, time constants, rates) in log space with
``scipy.optimize.minimize``, and takes standard errors from the curvature of the negative
log-likelihood at the maximum (central differences in log space, then the delta method).

>>> import numpy as np, adaptrack as at
>>> from adaptrack.models import ConstantVelocity
>>> rng = np.random.default_rng(0)
>>> t = 0.1 * np.arange(400)
>>> v = 3.0 + np.cumsum(rng.normal(0, np.sqrt(0.5 * 0.1), t.size))  # white acceleration, q 0.5
>>> z = (np.cumsum(0.1 * v) + rng.normal(0, 0.5, t.size))[:, None]  # position, sigma 0.5 m
>>> def loglik(p):
...     prior = at.GaussianState([z[0, 0], 0.0], np.diag([1.0, 100.0]), t[0])
...     res = at.kalman_filter(t, z, ConstantVelocity(accel_psd=p["q"]), ["x"],
...                            [[p["r"]]], prior)
...     return float(res.info.log_likelihood.sum())
>>> fit = fit_by_likelihood(loglik, {"q": 1.0, "r": 1.0})
>>> [bool(abs(fit.value(k) - true) < 3 * fit.std_error(k)) for k, true in (("q", 0.5), ("r", 0.25))]
[True, True]
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from .._typing import FloatArray
from ..filters.kalman import CovarianceError

HESSIAN_STEP = 1e-2  # central-difference step in log parameters (1 % of each value)


@dataclass(frozen=True)
class LikelihoodFit:
    """Maximum-likelihood parameters, their covariance from the curvature, the maximum.

    ``values`` and ``covariance`` are on the parameters' own scale (delta method from the log
    scale the fit works on); ``converged`` and ``message`` are the optimiser's.
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    log_likelihood: float
    converged: bool
    message: str
    signed: tuple[str, ...] = ()  # parameters of either sign, fitted on a linear scale
    rough: tuple[str, ...] = ()  # the log-likelihood is not smooth in these: no std error

    @property
    def std_errors(self) -> FloatArray:
        """Standard error of each parameter (same order as ``names``)."""
        return np.sqrt(np.diag(self.covariance))

    def value(self, name: str) -> float:
        """Return the estimate of one parameter."""
        return float(self.values[self.names.index(name)])

    def std_error(self, name: str) -> float:
        """Return the standard error of one parameter."""
        return float(self.std_errors[self.names.index(name)])

    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Confidence interval of one parameter, symmetric on the scale the fit uses.

        Positive parameters are fitted in log space: estimated from short records they are
        skewed, and on the log scale closer to normal (tested: coverage of a seeded Monte
        Carlo). Signed ones are fitted as they are.
        """
        from scipy.stats import norm

        value, z = self.value(name), norm.ppf(0.5 + level / 2)
        if name in self.signed:
            return value - z * self.std_error(name), value + z * self.std_error(name)
        half = z * self.std_error(name) / value  # huge where the likelihood is nearly flat
        high = math.inf if half > math.log(sys.float_info.max) else value * math.exp(half)
        return value * math.exp(-half), high


def fit_by_likelihood(
    log_likelihood: Callable[[dict[str, float]], float],
    initial: Mapping[str, float],
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    signed: Mapping[str, float] | None = None,
    scales: Mapping[str, float] | None = None,
) -> LikelihoodFit:
    """Maximise ``log_likelihood(params)``; standard errors from the curvature.

    Parameters
    ----------
    log_likelihood : callable
        Total log-likelihood of the data for a dict of parameter values, e.g. the sum of
        ``kalman_filter(...).info.log_likelihood`` over one or many recordings.
    initial : mapping of str to float
        Starting values (> 0), which also name the parameters.
    bounds : mapping of str to (low, high), optional
        Limits (> 0) of some parameters; a standard error at a limit is not meaningful.
    signed : mapping of str to float, optional
        Parameters of either sign (a clock offset, a bias) with their starting values; they
        are fitted on a linear scale.
    scales : mapping of str to float, optional
        Typical size of a signed parameter (default 1; its derivative step is 1 % of it).

    Values at which the log-likelihood is not finite, or at which the filter cannot run (it
    raises :class:`~adaptrack.filters.kalman.CovarianceError`, e.g. an innovation covariance
    not positive definite at extreme noise values), are infinitely unlikely, as are trial
    steps so long that a positive parameter overflows to inf or underflows to 0. Gradient steps
    assume a finite cost everywhere (L-BFGS-B reported convergence far from the maximum when
    a trial step met such values), so once one is met the search goes on from where it
    stopped with the Nelder-Mead simplex, which steps around them, and ends with L-BFGS-B
    from the simplex's best. Where the log-likelihood is rough at the maximum (its curvature
    differs between two step sizes), the parameter is listed in ``rough`` and has no
    standard error (NaN): a curvature there would give a false, often tiny, interval; the
    others' standard errors then hold the rough ones at their values.

    Raises
    ------
    ValueError
        For a non-positive starting value or bound, or a log-likelihood that is not finite at
        the start (a ``CovarianceError`` there is raised as it is).
    """
    positive = tuple(initial)
    start = np.array([float(initial[n]) for n in positive])
    if not np.all(np.isfinite(start)) or np.any(start <= 0):
        raise ValueError(f"initial values must be finite and > 0; got {dict(initial)}")
    free = tuple(signed or {})
    scale = np.array([float((scales or {}).get(n, 1.0)) for n in free])
    start_free = np.array([float((signed or {})[n]) for n in free])
    if not np.all(np.isfinite(start_free)) or not np.all(np.isfinite(scale) & (scale > 0)):
        raise ValueError(f"signed values must be finite and scales > 0; got {dict(signed or {})}")
    names = positive + free
    if names == () or len(set(names)) < len(names):
        raise ValueError(f"give each parameter once, in initial or signed; got {names}")
    for what, keys, allowed in (("bounds", bounds, positive), ("scales", scales, free)):
        stray = sorted(set(keys or {}) - set(allowed))
        if stray:
            raise ValueError(f"{what} names {stray}, which are not among {list(allowed)}")
    box: list[tuple[float | None, float | None]] = []
    for n in positive:
        lo, hi = (bounds or {}).get(n, (0.0, math.inf))
        if not 0 <= lo < hi:
            raise ValueError(f"bounds[{n!r}] must satisfy 0 <= low < high; got {(lo, hi)}")
        box.append((math.log(lo) if lo > 0 else None, math.log(hi) if hi < math.inf else None))
    box += [(None, None)] * len(free)
    k = len(positive)

    def values_of(theta: FloatArray) -> FloatArray:
        return np.concatenate([np.exp(theta[:k]), theta[k:] * scale])

    infeasible = 0

    def cost(theta: FloatArray) -> float:
        nonlocal infeasible
        values = values_of(theta)
        if np.all(np.isfinite(values)) and np.all(values[:k] > 0):
            try:
                value = log_likelihood(dict(zip(names, values.tolist(), strict=True)))
            except CovarianceError:  # values the filter cannot run with
                value = math.nan
        else:  # a step so long that exp over- or underflowed
            value = math.nan
        if np.isfinite(value):
            return -value
        infeasible += 1
        return math.inf

    theta0 = np.concatenate([np.log(start), start_free / scale])
    at_start = dict(zip(names, values_of(theta0).tolist(), strict=True))
    if not math.isfinite(log_likelihood(at_start)):  # errors here are the caller's to see
        raise ValueError(f"the log-likelihood is not finite at the initial values {at_start}")
    with np.errstate(over="ignore", invalid="ignore"):  # inf costs are expected, not noise
        opt = minimize(cost, theta0, method="L-BFGS-B", bounds=box)
        if infeasible:  # L-BFGS-B's differences and line search assume a finite cost
            simplex = minimize(cost, opt.x, method="Nelder-Mead", bounds=box, options=SIMPLEX)
            polished = minimize(cost, simplex.x, method="L-BFGS-B", bounds=box)
            opt = polished if polished.fun <= simplex.fun else simplex
    theta = np.asarray(opt.x, dtype=float)
    hess = _hessian(cost, theta, float(opt.fun))
    rough = _rough(cost, theta, float(opt.fun), np.diag(hess))
    smooth = np.ix_(~rough, ~rough)  # the rough ones held at their values
    cov_theta = np.full_like(hess, np.nan)  # none where there is no maximum to measure
    try:
        cov_theta[smooth] = np.linalg.inv(hess[smooth])
    except np.linalg.LinAlgError:
        pass
    if not np.all(np.isfinite(cov_theta[smooth])) or np.any(np.diag(cov_theta) < 0):
        cov_theta[:] = np.nan  # not a maximum: no curvature to report
    values = values_of(theta)
    jac = np.concatenate([values[:k], scale])  # d value / d theta
    return LikelihoodFit(
        names,
        values,
        cov_theta * np.outer(jac, jac),
        -float(opt.fun),
        bool(opt.success),
        str(opt.message),
        free,
        tuple(n for n, r in zip(names, rough, strict=True) if r),
    )


SIMPLEX = {"xatol": 1e-6, "fatol": 1e-8, "maxfev": 4000}  # Nelder-Mead, log parameters


ROUGH_RATIO = 1.5  # curvatures over two steps further apart than this: a rough likelihood


def _rough(
    cost: Callable[[FloatArray], float], theta: FloatArray, f0: float, curvature: FloatArray
) -> np.ndarray:
    """Parameters in which the log-likelihood is not smooth at the maximum (bool each).

    A smooth maximum has the same curvature over steps of ``HESSIAN_STEP`` and half of it.
    Where they differ by more than :data:`ROUGH_RATIO` (a filter whose estimates jump with
    small parameter changes, such as a turn rate wandering off in a model that does not
    suit the data) the curvature, and the standard error from it, mean nothing.
    """
    h = HESSIAN_STEP / 2.0
    out = np.zeros(theta.size, dtype=bool)
    for i in range(theta.size):
        e_i = np.eye(theta.size)[i] * h
        half = (cost(theta + e_i) - 2.0 * f0 + cost(theta - e_i)) / h**2
        ratio = half / curvature[i] if curvature[i] != 0.0 else math.nan
        out[i] = not (1.0 / ROUGH_RATIO <= ratio <= ROUGH_RATIO)
    return out


def _hessian(cost: Callable[[FloatArray], float], theta: FloatArray, f0: float) -> FloatArray:
    """Central-difference Hessian of ``cost`` at ``theta`` (log parameters)."""
    n, h = theta.size, HESSIAN_STEP
    out = np.empty((n, n))
    for i in range(n):
        e_i = np.eye(n)[i] * h
        out[i, i] = (cost(theta + e_i) - 2.0 * f0 + cost(theta - e_i)) / h**2
        for j in range(i):
            e_j = np.eye(n)[j] * h
            out[i, j] = out[j, i] = (
                cost(theta + e_i + e_j) - cost(theta + e_i - e_j)
                - cost(theta - e_i + e_j) + cost(theta - e_i - e_j)
            ) / (4.0 * h * h)  # fmt: skip
    return out


__all__ = ["LikelihoodFit", "fit_by_likelihood"]
