"""Error metrics: RMSE, NEES and chi-square consistency bands."""

from __future__ import annotations

import numpy as np
from scipy.special import chdtri

from .._linalg import solve_vec
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array


def nees(error: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Normalised estimation error squared ``e^T P^-1 e`` over leading axes.

    Parameters
    ----------
    error : array_like, shape (..., n)
        Estimate minus truth.
    cov : array_like, shape (..., n, n)
        Covariance the estimator reports.

    Returns
    -------
    ndarray, shape (...)
        ``inf`` where ``cov`` is singular and the error has a component outside its range.
    """
    e = as_float_array(error, "error", min_ndim=1)
    p = as_float_array(cov, "cov", min_ndim=2)
    if p.shape[-2:] != (e.shape[-1], e.shape[-1]):
        raise ValueError(
            f"cov must have shape (..., {e.shape[-1]}, {e.shape[-1]}) to match error; got {p.shape}"
        )
    try:
        return np.einsum("...i,...i->...", e, solve_vec(p, e))
    except np.linalg.LinAlgError:
        # a singular covariance: error components outside its range give an infinite NEES
        w, v = np.linalg.eigh(p)
        proj = np.einsum("...ji,...j->...i", v, e) ** 2
        tiny = np.finfo(float).eps * np.abs(w).max(axis=-1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = np.where(
                w > tiny, proj / np.where(w > tiny, w, 1.0), np.where(proj > 0, np.inf, 0.0)
            )
        return terms.sum(axis=-1)


def rmse(error: ArrayLike, axis: int | tuple[int, ...] | None = None) -> FloatArray:
    """Root mean square of the Euclidean norm of ``error`` (..., d) over ``axis``."""
    e = as_float_array(error, "error", min_ndim=1)
    return np.sqrt(np.mean(np.sum(e**2, axis=-1), axis=axis))


def anees_band(dof: int, n_runs: int, prob: float = 0.95) -> tuple[float, float]:
    """Two-sided ``prob`` interval of the ANEES over ``n_runs`` runs of a ``dof``-state NEES.

    ``n_runs * ANEES ~ chi2(n_runs * dof)`` for a consistent estimator.

    Examples
    --------
    >>> [round(v, 2) for v in anees_band(4, 100)]
    [3.46, 4.57]
    """
    lo, hi = chdtri(dof * n_runs, [(1 + prob) / 2, (1 - prob) / 2])  # chi2 quantiles
    return float(lo) / n_runs, float(hi) / n_runs


__all__ = ["anees_band", "nees", "rmse"]
