"""Search of positive model parameters in log space (design-time tuning, spec B.7).

One parameter: bounded Brent on its logarithm. Several: Nelder-Mead on the logarithms,
bounded, with an initial simplex of half a unit in each log coordinate. Both count the
criterion's evaluations and stop at ``max_evaluations``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize, minimize_scalar


@dataclass(frozen=True)
class SearchResult:
    """Best parameters found, the criterion there and the number of evaluations."""

    values: tuple[float, ...]
    criterion: float
    evaluations: int


def minimise_log(
    criterion: Callable[[tuple[float, ...]], float],
    start: Sequence[float],
    bounds: Sequence[tuple[float, float]],
    *,
    xatol: float = 1e-3,
    max_evaluations: int = 200,
) -> SearchResult:
    """Minimise ``criterion(values)`` over positive ``values`` within ``bounds``.

    Parameters
    ----------
    criterion : callable
        Takes a tuple of parameter values (all > 0) and returns a float (``inf``/NaN count as
        ``1e300``).
    start : sequence of float
        Starting values (Nelder-Mead) or ignored (one parameter: Brent uses the bounds).
    bounds : sequence of (lower, upper)
        Positive bounds of each parameter.
    xatol : float
        Tolerance in the logarithm of the parameters.
    max_evaluations : int
        Budget of criterion evaluations.

    Examples
    --------
    >>> res = minimise_log(lambda v: math.log(v[0] / 3.0) ** 2, [1.0], [(0.01, 100.0)])
    >>> round(res.values[0], 2)
    3.0
    """
    if len(start) != len(bounds) or not bounds:
        raise ValueError("start and bounds need one entry per parameter")
    for lo, hi in bounds:
        if not 0 < lo < hi:
            raise ValueError(f"bounds must satisfy 0 < lower < upper; got ({lo}, {hi})")
    count = 0

    def f(u: np.ndarray) -> float:
        nonlocal count
        count += 1
        j = float(criterion(tuple(float(math.exp(v)) for v in np.atleast_1d(u))))
        return j if math.isfinite(j) else 1e300

    logb = np.log(np.asarray(bounds, dtype=float))
    if len(bounds) == 1:
        res = minimize_scalar(
            f,
            bounds=(float(logb[0, 0]), float(logb[0, 1])),
            method="bounded",
            options={"xatol": xatol, "maxiter": max_evaluations},
        )
        return SearchResult((math.exp(float(res.x)),), float(res.fun), count)
    x0 = np.clip(np.log(np.asarray(start, dtype=float)), logb[:, 0], logb[:, 1])
    simplex = np.clip(x0 + np.vstack([np.zeros(x0.size), 0.5 * np.eye(x0.size)]), *logb.T)
    res = minimize(
        f,
        x0,
        method="Nelder-Mead",
        bounds=[tuple(b) for b in logb],
        options={
            "xatol": xatol,
            "fatol": 1e-3,
            "initial_simplex": simplex,
            "maxfev": max_evaluations,
        },
    )
    return SearchResult(tuple(float(v) for v in np.exp(res.x)), float(res.fun), count)


__all__ = ["SearchResult", "minimise_log"]
