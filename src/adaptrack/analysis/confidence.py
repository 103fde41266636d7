"""Monte-Carlo uncertainty of a pooled RMS error: confidence bounds from independent runs.

A Monte-Carlo RMS pools squared errors over runs and epochs,
``RMS^2 = sum_i y_i / sum_i x_i`` with ``y_i`` the sum of squared errors of run ``i`` and
``x_i`` its number of scored epochs. Epochs within a run are correlated (one track), runs are
independent, so the run is the sampling unit and ``RMS^2`` is a ratio estimator. Its standard
error (delta method) is

``se = sqrt( sum_i (y_i - R x_i)^2 / (N (N - 1)) ) / mean(x)``, ``R = RMS^2``,

and the one-sided bounds at level ``c`` are taken on the log scale (squared errors are
right-skewed): ``R exp(+- t_{c, N-1} se / R)`` (Student's t with ``N - 1`` degrees of freedom),
then the square root. On skewed, heavy-tailed run errors every such bound covers less often
than its nominal level; :mod:`adaptrack.crossing.studies.compliance` therefore states a lower
confidence than the level it computes with, and a statistical test measures the coverage on
crossing Monte Carlos.
"""

from __future__ import annotations

import numpy as np
from scipy.special import stdtrit

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array


def rms_with_bounds(
    squares: ArrayLike, counts: ArrayLike, confidence: float = 0.95
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pooled RMS over runs with one-sided lower and upper bounds at ``confidence``.

    Parameters
    ----------
    squares : array_like, shape (N, ...)
        Per-run sums of squared errors (run axis first, any trailing quantities).
    counts : array_like, shape (N, ...)
        Per-run numbers of scored epochs (>= 0).
    confidence : float
        Nominal one-sided level of each bound, in (0.5, 1).

    Returns
    -------
    rms, lower, upper : ndarray, shape (...)
        NaN where no epoch was scored; bounds 0 and ``inf`` with fewer than two runs.

    Examples
    --------
    >>> rms, lo, hi = rms_with_bounds([[4.0], [9.0], [1.0]], [[1.0], [1.0], [1.0]])
    >>> rms.round(3), bool(lo[0] < rms[0] < hi[0])
    (array([2.16]), True)
    """
    y = as_float_array(squares, "squares", min_ndim=1)
    x = as_float_array(counts, "counts", min_ndim=1)
    if x.shape != y.shape:
        raise ValueError(f"counts must have the shape of squares {y.shape}; got {x.shape}")
    if np.any(y < 0) or np.any(x < 0):
        raise ValueError("squares and counts must be >= 0")
    if not 0.5 < confidence < 1:
        raise ValueError(f"confidence must lie in (0.5, 1); got {confidence!r}")
    n = y.shape[0]
    total = x.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ratio = y.sum(axis=0) / total
        if n < 2:
            log_half = np.full(ratio.shape, np.inf)
        else:
            resid = y - ratio * x
            se = np.sqrt(np.sum(resid**2, axis=0) / (n * (n - 1))) / (total / n)
            log_half = float(stdtrit(n - 1, confidence)) * np.where(ratio > 0, se / ratio, 0.0)
        empty = total == 0
        rms = np.where(empty, np.nan, np.sqrt(ratio))
        lower = np.where(empty, np.nan, np.sqrt(ratio * np.exp(-log_half)))
        upper = np.where(empty, np.nan, np.sqrt(ratio * np.exp(log_half)))
    return rms, lower, upper


__all__ = ["rms_with_bounds"]
