"""Exact simulation of linear-Gaussian motion models and linear measurements."""

from __future__ import annotations

import numpy as np

from .._linalg import matvec, psd_sqrt
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_symmetric_pd, check_times
from ..models.continuous import MotionModel, as_motion_model
from ..models.discretize import Method, discretize_with_input


def _require_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    return rng


def simulate_linear_trajectory(
    model: MotionModel,
    times: ArrayLike,
    initial_mean: ArrayLike,
    initial_cov: ArrayLike,
    *,
    n_runs: int | None = None,
    rng: np.random.Generator,
    method: Method = "expm",
) -> FloatArray:
    """Sample state trajectories of a linear SDE exactly at the given times.

    ``x_0 ~ N(initial_mean, initial_cov)`` at ``times[..., 0]``, then
    ``x_k = Phi_k x_{k-1} + u_k + w_k`` with ``w_k ~ N(0, Qd_k)`` (exact discretisation).

    Parameters
    ----------
    model : MotionModel
    times : array_like, shape (T,) or (N, T)
        Strictly increasing sample times [s].
    initial_mean : array_like, shape (n,)
    initial_cov : array_like, shape (n, n)
        Symmetric positive semi-definite.
    n_runs : int, optional
        Number of independent runs for shared 1-D ``times`` (leading axis of the output).
    rng : numpy.random.Generator
    method : discretisation method (default exact ``"expm"``).

    Returns
    -------
    ndarray, shape (N, T, n) or (T, n)
    """
    model = as_motion_model(model)
    rng = _require_rng(rng)
    t = as_float_array(times, "times", min_ndim=1)
    check_times(t, "times")
    n = model.state_dim
    m0 = as_float_array(initial_mean, "initial_mean", min_ndim=1)
    p0 = as_float_array(initial_cov, "initial_cov", min_ndim=2)
    if m0.shape != (n,) or p0.shape != (n, n):
        raise ValueError(
            f"initial_mean and initial_cov must have shapes ({n},) and ({n}, {n}); "
            f"got {m0.shape} and {p0.shape}"
        )
    check_symmetric_pd(p0, "initial_cov", semidefinite=True)
    batch: tuple[int, ...] = t.shape[:-1]
    if n_runs is not None:
        if t.ndim != 1:
            raise ValueError("n_runs applies to shared 1-D times only")
        batch = (int(n_runs),)
    n_steps = t.shape[-1]
    tb = np.broadcast_to(t, batch + (n_steps,))
    dt = np.diff(tb, axis=-1)
    phi, qd, u = discretize_with_input(model, dt, method)
    sq = psd_sqrt(qd)
    out = np.empty(batch + (n_steps, n))
    x = m0 + matvec(psd_sqrt(p0), rng.standard_normal(batch + (n,)))
    out[..., 0, :] = x
    for k in range(1, n_steps):
        i = (Ellipsis, k - 1, slice(None), slice(None))
        x = matvec(phi[i], x) + u[..., k - 1, :] + matvec(sq[i], rng.standard_normal(batch + (n,)))
        out[..., k, :] = x
    return out


def simulate_linear_measurements(
    states: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    *,
    rng: np.random.Generator,
) -> FloatArray:
    """Measurements ``z = H x + v``, ``v ~ N(0, R)``, for states (..., n); returns (..., m)."""
    rng = _require_rng(rng)
    x = as_float_array(states, "states", min_ndim=1)
    h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
    r = as_float_array(measurement_cov, "measurement_cov", min_ndim=2)
    if h.shape[1] != x.shape[-1] or r.shape != (h.shape[0], h.shape[0]):
        raise ValueError(
            f"measurement_matrix (m, {x.shape[-1]}) and measurement_cov (m, m) "
            f"must match the states; got {h.shape} and {r.shape}"
        )
    check_symmetric_pd(r, "measurement_cov")
    noise = matvec(np.linalg.cholesky(r), rng.standard_normal(x.shape[:-1] + (h.shape[0],)))
    return np.einsum("ij,...j->...i", h, x) + noise


__all__ = ["simulate_linear_measurements", "simulate_linear_trajectory"]
