"""Chi-square gating of detections against predicted tracks."""

from __future__ import annotations

import numpy as np
from scipy.special import chdtri

from .._typing import FloatArray


def gate_threshold(dim: int, probability: float = 0.999) -> float:
    """Return the chi-square gate: squared Mahalanobis distance of a ``probability`` quantile.

    A true detection of dimension ``dim`` stays within it with that probability.
    """
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must lie in (0, 1); got {probability}")
    return float(chdtri(dim, 1.0 - probability))  # the chi-square quantile, as chi2.ppf


def mahalanobis_squared(residuals: FloatArray, covariance: FloatArray) -> FloatArray:
    """Squared Mahalanobis distances (T, D) of residuals (T, D, m) under covariances (T, m, m).

    Raises ``ValueError`` naming the track whose covariance is not positive definite.
    """
    try:
        chol = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        bad = [i for i, c in enumerate(covariance) if np.any(np.linalg.eigvalsh(c) <= 0)]
        raise ValueError(
            f"innovation covariance of track row {bad[:1]} is not positive definite"
        ) from None
    # solve L y = r for every (track, detection): y = L^-1 r
    y = np.linalg.solve(chol[:, None, :, :], residuals[..., None])[..., 0]
    return np.einsum("tdm,tdm->td", y, y)


__all__ = ["gate_threshold", "mahalanobis_squared"]
