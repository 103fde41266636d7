"""Seed 000's reduced model: speed-only Kalman filter plus dead reckoning of distance (spec A.8).

When only speed is measured, distance is unobservable (spec A.7). The reduced filter
estimates ``[v, w]`` (speed, acceleration) with the ``[v, w]`` block of the Singer model,
and distance is dead-reckoned with the distance row of the selected transition:
``r_n = r_{n-1} + Phi[r,v] v_{n-1} + Phi[r,w] w_{n-1}`` (seed (18) for the source
transition, where ``Phi[r,w] = 0``). Its variance is that of the 3-state filter whose
distance-row gain is forced to zero (Joseph form), started from ``Var(r_0)`` and no
correlation between ``r_0`` and ``(v, w)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import mT, symmetrize
from .._typing import ArrayLike, FloatArray
from .._validation import (
    as_float_array,
    check_positive_scalar,
    check_symmetric_pd,
    check_times,
)
from ..models.continuous import Singer
from ..models.discretize import Method, discretize_with_input
from ..types import GaussianState, StepInfo, _trusted, as_gaussian_state
from .kalman import _update, predict


@dataclass(frozen=True, slots=True, eq=False)
class DeadReckoningResult:
    """Output of :func:`dead_reckoning_filter`.

    Attributes
    ----------
    filtered : GaussianState
        Speed and acceleration ``[v, w]`` after each measurement, shapes (..., T, 2).
    distance_m : ndarray, shape (..., T)
        Dead-reckoned distance [m].
    distance_var_m2 : ndarray, shape (..., T)
        Its variance [m^2].
    info : StepInfo
        Innovation statistics of the speed filter per step.
    """

    filtered: GaussianState
    distance_m: FloatArray
    distance_var_m2: FloatArray
    info: StepInfo


def dead_reckoning_filter(
    times: ArrayLike,
    speeds: ArrayLike,
    model: Singer,
    speed_var: float,
    initial: GaussianState,
    *,
    initial_distance_m: ArrayLike = 0.0,
    initial_distance_var_m2: float = 0.0,
    speed_scale: float = 1.0,
    method: Method = "expm",
) -> DeadReckoningResult:
    """Speed-only reduced Kalman filter with dead reckoning of distance (seed 000, A.8).

    Parameters
    ----------
    times : array_like, shape (T,) or (N, T)
        Measurement times [s], strictly increasing.
    speeds : array_like, shape (T,) or (N, T)
        Measured ``y = c2 (v + eta)`` [m/s].
    model : Singer
        One-axis Singer model (spec A.3).
    speed_var : float
        Variance of ``eta`` [m^2/s^2]; the measurement variance is ``c2^2 speed_var``.
    initial : GaussianState
        Prior over ``[v, w]`` at the first measurement time (step 0 is update-only).
    initial_distance_m : float or array_like, shape (N,)
        Known distance at the first measurement time [m].
    initial_distance_var_m2 : float
        Its variance (default 0: known exactly, as in the source).
    speed_scale : float
        Scale factor ``c2`` (default 1).
    method : {"expm", "analytic", "taylor", "source"}
        Discretisation; ``"source"`` reproduces the seed's printed transition.

    Returns
    -------
    DeadReckoningResult
    """
    if not isinstance(model, Singer) or model.n_axes != 1:
        raise TypeError("model must be a one-axis adaptrack.models.Singer")
    initial = as_gaussian_state(initial, "initial")
    if initial.dim != 2:
        raise ValueError(f"initial must be over [v, w] (2 states); got {initial.dim} states")
    check_symmetric_pd(initial.cov, "initial.cov", semidefinite=True)
    t = as_float_array(times, "times", min_ndim=1)
    y = as_float_array(speeds, "speeds", min_ndim=1)
    if y.shape != t.shape and t.shape != y.shape[-1:]:
        raise ValueError(f"speeds must have shape {t.shape} to match times; got {y.shape}")
    check_times(t, "times")
    var = check_positive_scalar(speed_var, "speed_var")
    scale = as_float_array(speed_scale, "speed_scale")
    if scale.ndim != 0 or scale == 0.0:
        raise ValueError(f"speed_scale must be a non-zero real number; got {speed_scale!r}")
    c2 = float(scale)
    var_r0 = check_positive_scalar(
        initial_distance_var_m2, "initial_distance_var_m2", allow_zero=True
    )
    batch = y.shape[:-1]
    n_steps = y.shape[-1]
    tb = np.broadcast_to(t, batch + (n_steps,))
    prev = np.concatenate([np.broadcast_to(initial.time, batch)[..., None], tb[..., :-1]], -1)
    dt = tb - prev
    if np.any(dt < 0):
        raise ValueError("initial.time must not be after the first measurement time")
    phi3, qd3, _ = discretize_with_input(model, dt, method)  # (..., T, 3, 3), order [r, v, w]
    h2 = np.array([[c2, 0.0]])
    h3 = np.array([[0.0, c2, 0.0]])
    r_meas = np.array([[c2**2 * var]])
    r0 = np.broadcast_to(as_float_array(initial_distance_m, "initial_distance_m"), batch)
    state = _trusted(
        GaussianState,
        mean=np.broadcast_to(initial.mean, batch + (2,)),
        cov=np.broadcast_to(initial.cov, batch + (2, 2)),
        time=np.broadcast_to(initial.time, batch),
    )
    # 3-state covariance [r, v, w] of the zero-distance-gain filter
    p3: FloatArray = np.zeros(batch + (3, 3))
    p3[..., 0, 0] = var_r0
    p3[..., 1:, 1:] = state.cov
    dist, dist_var = np.empty(batch + (n_steps,)), np.empty(batch + (n_steps,))
    fm, fc = np.empty(batch + (n_steps, 2)), np.empty(batch + (n_steps, 2, 2))
    infos = []
    r_hat: FloatArray = np.array(r0, dtype=np.float64)
    mask = np.ones(batch + (1,), dtype=bool)
    for k in range(n_steps):
        sv = (Ellipsis, k)
        ph, qd = phi3[..., k, :, :], qd3[..., k, :, :]
        r_hat = r_hat + ph[..., 0, 1] * state.mean[..., 0] + ph[..., 0, 2] * state.mean[..., 1]
        prior = predict(state, ph[..., 1:, 1:], qd[..., 1:, 1:], time=tb[sv])
        state, info = _update(prior, y[sv][..., None], h2, r_meas, mask, "joseph")
        p3 = symmetrize(ph @ p3 @ mT(ph) + qd)
        k3 = np.concatenate([np.zeros(batch + (1, 1)), info.gain], axis=-2)
        ikc = np.eye(3) - k3 @ h3
        p3 = symmetrize(ikc @ p3 @ mT(ikc) + k3 @ r_meas @ mT(k3))
        dist[sv], dist_var[sv] = r_hat, p3[..., 0, 0]
        fm[..., k, :], fc[..., k, :, :] = state.mean, state.cov
        infos.append(info)
    stack = {
        f: np.stack([getattr(i, f) for i in infos], axis=len(batch))
        for f in ("innovation", "innovation_cov", "nis", "log_likelihood", "gain", "n_observed")
    }
    filtered = _trusted(GaussianState, mean=fm, cov=fc, time=tb)
    return DeadReckoningResult(filtered, dist, dist_var, _trusted(StepInfo, **stack))


__all__ = ["DeadReckoningResult", "dead_reckoning_filter"]
