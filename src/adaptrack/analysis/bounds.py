"""Posterior Cramer-Rao lower bound for linear-Gaussian models (Riccati recursion).

For a linear-Gaussian model the PCRLB (Tichavsky et al. 1998) equals the covariance of the
Kalman filter that knows the model: ``J_k = (Q + F J_{k-1}^-1 F^T)^-1 + H^T R^-1 H``, i.e.
``P_k|k`` of the covariance recursion. No data enter it.
"""

from __future__ import annotations

import numpy as np

from .._linalg import symmetrize
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_symmetric_pd, check_times
from ..filters._measurement import masked_model
from ..filters.kalman import _component_mask, _covariance_update, _gain
from ..models.continuous import MotionModel, as_motion_model
from ..models.discretize import discretize


def pcrlb_linear(
    model: MotionModel,
    times: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    initial_cov: ArrayLike,
    *,
    mask: ArrayLike | None = None,
) -> FloatArray:
    """Bound covariances (T, n, n) at ``times`` for measurements ``z = H x + v``.

    Parameters
    ----------
    model : MotionModel
        The true motion model (exactly discretised).
    times : array_like, shape (T,)
        Measurement times [s]; the prior ``initial_cov`` applies at ``times[0]``.
    measurement_matrix, measurement_cov : array_like, shapes (m, n), (m, m)
    initial_cov : array_like, shape (n, n)
        Prior covariance (symmetric positive semi-definite).
    mask : array_like of bool, shape (T,) or (T, m), optional
        Which measurements exist.

    Returns
    -------
    ndarray, shape (T, n, n)
        ``inv(J_k)``: no unbiased estimator has a smaller error covariance.
    """
    model = as_motion_model(model)
    t = as_float_array(times, "times", min_ndim=1)
    check_times(t, "times")
    h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
    r = as_float_array(measurement_cov, "measurement_cov", min_ndim=2)
    p = as_float_array(initial_cov, "initial_cov", min_ndim=2)
    n = model.state_dim
    if h.shape[1] != n or r.shape != (h.shape[0], h.shape[0]) or p.shape != (n, n):
        raise ValueError(
            f"measurement_matrix (m, {n}), measurement_cov (m, m) and initial_cov "
            f"({n}, {n}) must match the model; got {h.shape}, {r.shape}, {p.shape}"
        )
    check_symmetric_pd(r, "measurement_cov")
    check_symmetric_pd(p, "initial_cov", semidefinite=True)
    mk = _component_mask(mask, (t.size, h.shape[0]), "mask")
    phi, qd = discretize(model, np.diff(t, prepend=t[0]))
    out = np.empty((t.size, n, n))
    for k in range(t.size):
        p = symmetrize(phi[k] @ p @ phi[k].T + qd[k])
        hm, rm = masked_model(h, r, None if mk[k].all() else mk[k])
        gain, _, _ = _gain(p, hm, rm)
        out[k] = p = _covariance_update(p, gain, hm, rm, "joseph")
    return out


__all__ = ["pcrlb_linear"]
