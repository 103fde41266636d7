"""Expectation-maximisation of a linear model's noise: process-noise scale and ``R``.

For a linear Gaussian model whose discrete process noise scales with one factor
(``Qd = s Qd_unit`` for every step: true of the white-noise kinematic models, whose ``Qd`` is
linear in their PSD), each iteration runs the Kalman filter and the RTS smoother (E-step) and
sets (M-step)

* ``R = mean_k [(z_k - H x_k|T)(z_k - H x_k|T)^T + H P_k|T H^T]`` over the measured steps;
* ``s = sum_k tr(Qd_unit,k^-1 E[w_k w_k^T]) / (n K)`` over the K transitions, with
  ``E[w w^T] = d d^T + P_k|T - C_k Phi_k^T - Phi_k C_k^T + Phi_k P_k-1|T Phi_k^T``,
  ``d = x_k|T - Phi_k x_k-1|T - u_k`` and the lag-one smoothed covariance
  ``C_k = P_k|T G_k-1^T`` (``G`` the smoother gain).

The log-likelihood never decreases from one iteration to the next; EM reaches the same
maximum as :func:`~adaptrack.tuning.fit_by_likelihood` (slower near it, but without
derivatives and never leaving the admissible set). Every track of a batch shares ``s`` and
``R``; missing components are not supported (every step fully measured).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import matvec, mT, symmetrize
from .._typing import ArrayLike, FloatArray
from ..filters.run import kalman_filter
from ..models.continuous import (
    LinearSDE,
    MotionModel,
    drift_matrix,
    noise_input_matrix,
    noise_psd,
)
from ..smoothers.rts import rts_smooth
from ..types import FilterResult, GaussianState


@dataclass(frozen=True)
class EMFit:
    """Result of :func:`em_fit`.

    ``process_scale`` multiplies the model's process noise; ``measurement_cov`` is ``R``;
    ``log_likelihood`` holds the value at the start of every iteration and at the end.
    """

    process_scale: float
    measurement_cov: FloatArray
    log_likelihood: FloatArray
    iterations: int
    converged: bool


def em_fit(
    times: ArrayLike,
    measurements: ArrayLike,
    model: MotionModel,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    initial: GaussianState,
    *,
    max_iterations: int = 200,
    tolerance: float = 1e-6,
) -> EMFit:
    """Fit the process-noise scale and ``R`` of a linear model by EM.

    Parameters
    ----------
    times, measurements, model, measurement_matrix, initial
        As :func:`adaptrack.kalman_filter` (shared times; every component present).
    measurement_cov : array_like, shape (m, m)
        Starting ``R``.
    max_iterations : int
    tolerance : float
        Stop when the log-likelihood gains less than ``tolerance`` times its magnitude.

    Returns
    -------
    EMFit
        The scale ``s`` (the fitted model is ``model`` with its PSD times ``s``) and ``R``.
    """
    z = np.asarray(measurements, dtype=np.float64)
    if not np.all(np.isfinite(z)):
        raise ValueError("em_fit needs every measurement component present (no NaN)")
    r: FloatArray = np.array(measurement_cov, dtype=np.float64)
    scale = 1.0
    history = []
    converged = False
    for _ in range(max_iterations):
        res = kalman_filter(times, z, _scaled(model, scale), measurement_matrix, r, initial,
                            form="joseph", backend="numpy")  # fmt: skip
        ll = float(res.log_likelihood.sum())
        history.append(ll)
        if len(history) > 1 and ll - history[-2] <= tolerance * abs(ll):
            converged = True
            break
        smooth = rts_smooth(res, form="standard", backend="numpy")
        scale, r = _m_step(res, smooth, z, scale)
    return EMFit(scale, r, np.array(history), len(history) - 1, converged)


def _scaled(model: MotionModel, scale: float) -> LinearSDE:
    """``model`` with its noise PSD times ``scale``, as a generic SDE (exact discretisation)."""
    return LinearSDE(drift_matrix(model), noise_input_matrix(model), scale * noise_psd(model),
                     model.state_names)  # fmt: skip


def _m_step(
    res: FilterResult, smooth: GaussianState, z: FloatArray, scale: float
) -> tuple[float, FloatArray]:
    """Return the new scale and ``R`` from the smoothed moments (the module's formulas)."""
    h = np.asarray(res.measurement_matrix)
    x, p = smooth.mean, smooth.cov
    resid = z - matvec(h, x)
    r = np.mean(resid[..., :, None] * resid[..., None, :] + h @ p @ mT(h), axis=tuple(range(
        resid.ndim - 1)))  # fmt: skip
    phi, qd, u = res.transition[..., 1:, :, :], res.process_cov[..., 1:, :, :], res.control[
        ..., 1:, :]  # fmt: skip
    pf, pp = res.filtered.cov[..., :-1, :, :], res.predicted.cov[..., 1:, :, :]
    gain = mT(np.linalg.solve(pp, phi @ pf))  # G_{k-1} = P_{k-1|k-1} Phi^T P_{k|k-1}^-1
    lag = p[..., 1:, :, :] @ mT(gain)  # C_k = P_{k|T} G_{k-1}^T
    d = x[..., 1:, :] - matvec(phi, x[..., :-1, :]) - u
    e_ww = (d[..., :, None] * d[..., None, :] + p[..., 1:, :, :] - lag @ mT(phi)
            - phi @ mT(lag) + phi @ p[..., :-1, :, :] @ mT(phi))  # fmt: skip
    unit = qd / scale
    traces = np.trace(np.linalg.solve(unit, e_ww), axis1=-2, axis2=-1)
    return float(np.mean(traces) / unit.shape[-1]), symmetrize(r)


__all__ = ["EMFit", "em_fit"]
