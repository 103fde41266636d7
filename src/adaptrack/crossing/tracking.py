"""Tracking vehicles from radar detections (range, azimuth, radial speed), batched over runs.

Two extended Kalman filters, both using the radial speed and coasting (prediction only)
through missed detections:

* :func:`track_free_2d`: planar position and velocity ``[x, y, vx, vy]`` with a motion model
  for two axes (default nearly constant velocity);
* :func:`track_on_road`: the along-road coordinate as the generalised coordinate of seed 001
  (any one-axis motion model: constant acceleration, M1, M2, ...) plus the vehicle's lateral
  offset in its lane (a slow random walk), mapped to the plane with the known road geometry.
  Approaching vehicles do not reverse: a predicted along-road speed of the wrong sign (a track
  coasting through a stop hidden by the Doppler gate) is held at standstill.

The measurement noise knows the class-dependent wander of the reflection point along the body
(a rank-one term ``sigma_b^2 J u u^T J^T``, ``u`` the direction of travel). A track starts at
its first detection (position from range and azimuth with the known radar height, speed from
the radial speed along the line of sight); before that its estimates are NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._backend import Backend, use_compiled
from .._typing import BoolArray, FloatArray
from ..filters.kalman import CovarianceError, _update, predict
from ..models.continuous import ConstantVelocity, MotionModel
from ..models.discretize import discretize
from ..models.series_table import SeriesTable, model_series_table
from ..types import GaussianState, _trusted
from ._ekf_kernels import FREE, ROAD
from .road import Road
from .site import RadarSpec

CROSS_LOS_SPEED_STD_MPS = 10.0
COMPILED_MIN_RUN_STEPS = 5_000  # "auto" runs the compiled EKF from this many run-steps on


@dataclass(frozen=True, eq=False)
class TrackEstimates:
    """Estimated planar position (N, T, 2), velocity (N, T, 2) and speed (N, T).

    NaN before a track starts. ``position_cov`` (N, T, 2, 2) is the filter's position
    covariance.
    """

    position: FloatArray
    velocity: FloatArray
    speed: FloatArray
    position_cov: FloatArray


def _polar_jacobian(
    pos: FloatArray, vel: FloatArray, radar: RadarSpec
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted (r, az, vr) (N, 3) and its Jacobians w.r.t. position and velocity (N, 3, 2)."""
    rel = pos - np.asarray(radar.position_m)
    h2 = rel[..., 0] ** 2 + rel[..., 1] ** 2
    r = np.sqrt(h2 + radar.height_m**2)
    rv = np.einsum("...i,...i->...", rel, vel)
    z = np.stack([r, np.arctan2(rel[..., 0], rel[..., 1]), rv / r], -1)
    jp = np.zeros(pos.shape[:-1] + (3, 2))
    jp[..., 0, :] = rel / r[..., None]
    jp[..., 1, 0] = rel[..., 1] / h2
    jp[..., 1, 1] = -rel[..., 0] / h2
    jp[..., 2, :] = vel / r[..., None] - (rv / r**3)[..., None] * rel
    jv = np.zeros_like(jp)
    jv[..., 2, :] = rel / r[..., None]
    return z, jp, jv


def _wrap(a: FloatArray) -> FloatArray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _measurement_cov(
    radar: RadarSpec, jp: FloatArray, direction: FloatArray, scatter_std_m: float
) -> FloatArray:
    r0 = np.diag([radar.range_std_m**2, radar.azimuth_std_rad**2, radar.radial_speed_std_mps**2])
    b = np.einsum("...ij,...j->...i", jp, direction)
    return r0 + scatter_std_m**2 * b[..., :, None] * b[..., None, :]


def _initial_point(z: FloatArray, radar: RadarSpec) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Planar position, line-of-sight unit vector and horizontal range of detections (N, 3)."""
    rho = np.sqrt(np.maximum(z[..., 0] ** 2 - radar.height_m**2, 0.01))
    los = np.stack([np.sin(z[..., 1]), np.cos(z[..., 1])], -1)
    return np.asarray(radar.position_m) + rho[..., None] * los, los, rho


@dataclass(frozen=True)
class _Compiled:
    """What the compiled EKF needs to evaluate a tracker's measurement model."""

    kind: int  # _ekf_kernels.ROAD or FREE
    k: int  # along-road model size (ROAD)
    radar: FloatArray  # x, y, height, range / azimuth / radial-speed standard deviations
    road: FloatArray  # (5, S) centreline s, x, y, heading, curvature (ROAD)
    half_width_m: float
    scatter_std_m: float


def _compiled_spec(
    kind: int, radar: RadarSpec, scatter_std_m: float, k: int = 0, road: Road | None = None
) -> _Compiled:
    radar_arr = np.array(
        [
            *radar.position_m,
            radar.height_m,
            radar.range_std_m,
            radar.azimuth_std_rad,
            radar.radial_speed_std_mps,
        ]
    )
    if road is None:
        return _Compiled(kind, k, radar_arr, np.zeros((5, 2)), 0.0, scatter_std_m)
    table = np.stack([road.s, road.xy[:, 0], road.xy[:, 1], road.heading, road.curvature])
    return _Compiled(kind, k, radar_arr, table, 0.5 * road.lane_width_m, scatter_std_m)


def _run(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    n: int,
    transition: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    measure: Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]],
    initial: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    constrain: Callable[[FloatArray], FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Run the batched EKF loop (NumPy reference); each run starts at its first detection.

    Returns the state means (N, T, n) and covariances (N, T, n, n), NaN before the start.
    """
    n_runs, n_steps = detected.shape
    means = np.full((n_runs, n_steps, n), np.nan)
    covs = np.full((n_runs, n_steps, n, n), np.nan)
    # all transitions at once (before a track starts its state is replaced at initialisation)
    phis, qds = transition(np.diff(times, axis=1, prepend=times[:, :1]))
    mean = np.zeros((n_runs, n))
    cov = np.broadcast_to(np.eye(n), (n_runs, n, n)).copy()
    started = np.zeros(n_runs, dtype=bool)
    t_prev = times[:, 0]
    for k in range(n_steps):
        t = times[:, k]
        phi, qd = phis[:, k], qds[:, k]
        state = predict(_trusted(GaussianState, mean=mean, cov=cov, time=t_prev), phi, qd, time=t)
        if constrain is not None:
            state = _trusted(GaussianState, mean=constrain(state.mean), cov=state.cov, time=t)
        zpred, h, r = measure(state.mean)
        upd = detected[:, k] & started
        z_eff = z[:, k].copy()
        z_eff[~upd] = zpred[~upd]
        resid = z_eff - zpred
        resid[:, 1] = _wrap(resid[:, 1])
        lin = resid + np.einsum("nij,nj->ni", h, state.mean)
        post, _ = _update(state, lin, h, r, np.broadcast_to(upd[:, None], (n_runs, 3)), "joseph")
        mean, cov = np.array(post.mean), np.array(post.cov)
        new = detected[:, k] & ~started
        if new.any():
            m0, p0 = initial(z[new, k])
            mean[new], cov[new] = m0, p0
            started |= new
        means[started, k], covs[started, k] = mean[started], cov[started]
        t_prev = t
    return means, covs


def _series(
    model: MotionModel, times: FloatArray, extra_random_walk_psd: tuple[float, ...] = ()
) -> SeriesTable:
    """Series table of ``model`` covering the longest step of ``times`` without doublings.

    The step bound is rounded up to a power of two, so that runs sampled alike share one
    table shape (and one generated kernel).
    """
    steps = np.diff(times, axis=1)
    longest = float(steps.max()) if steps.size else 1.0
    bound = 2.0 ** math.ceil(math.log2(longest)) if longest > 0 else 1.0
    return model_series_table(model, bound, extra_random_walk_psd)


def _run_compiled(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    table: SeriesTable,
    initial: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    spec: _Compiled,
    n: int,
) -> TrackEstimates:
    """Run the compiled EKF (:mod:`._ekf_codegen`); the planar estimates come from the kernel."""
    from ._ekf_codegen import ekf_kernel

    n_runs, n_steps = detected.shape
    started = np.asarray(detected.any(axis=1), dtype=bool)
    first = np.where(started, np.argmax(detected, axis=1), -1)
    m0, p0 = np.zeros((n_runs, n)), np.zeros((n_runs, n, n))
    if started.any():
        m0[started], p0[started] = initial(z[started, first[started]])
    status = np.zeros(n_runs, dtype=np.int64)
    out = TrackEstimates(
        np.full((n_runs, n_steps, 2), np.nan),
        np.full((n_runs, n_steps, 2), np.nan),
        np.full((n_runs, n_steps), np.nan),
        np.full((n_runs, n_steps, 2, 2), np.nan),
    )
    c = np.ascontiguousarray
    ekf_kernel(n, table.phi_coef, table.qd_coef)(
        spec.kind,
        c(times, dtype=float),
        *table,
        c(z, dtype=float),
        c(detected),
        first,
        m0,
        p0,
        spec.k,
        spec.radar,
        c(spec.road),
        spec.half_width_m,
        spec.scatter_std_m,
        out.position,
        out.velocity,
        out.speed,
        out.position_cov,
        status,
    )
    if status.any():
        i = int(np.flatnonzero(status)[0])
        raise CovarianceError(
            f"innovation covariance is not positive definite at step {int(status[i]) - 1}, run {i}"
        )
    return out


def _check_no_input(model: MotionModel) -> None:
    blocks, _ = model.blocks()
    if any(np.any(b.control) for b in blocks):
        raise ValueError("the trackers need a motion model without a known input")


def track_free_2d(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    radar: RadarSpec,
    *,
    model: MotionModel | None = None,
    scatter_std_m: float = 0.0,
    backend: Backend = "auto",
) -> TrackEstimates:
    """Planar EKF ``[x, y, vx, vy]`` on (range, azimuth, radial speed) detections.

    ``backend``: ``"numpy"`` (reference), ``"numba"`` (compiled, same numbers to rounding) or
    ``"auto"`` (compiled from 5,000 run-steps on).
    """
    model = ConstantVelocity(accel_psd=10.0, n_axes=2) if model is None else model
    if model.state_names[:4] != ("x", "y", "vx", "vy"):
        raise ValueError("track_free_2d needs a 2-axis model whose first states are x, y, vx, vy")
    _check_no_input(model)
    n = model.state_dim

    def transition(dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        return discretize(model, dt, method="auto")

    def measure(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        zp, jp, jv = _polar_jacobian(x[:, :2], x[:, 2:4], radar)
        h = np.zeros((x.shape[0], 3, n))
        h[:, :, :2], h[:, :, 2:4] = jp, jv
        speed = np.linalg.norm(x[:, 2:4], axis=-1, keepdims=True)
        rel = x[:, :2] - np.asarray(radar.position_m)
        u = np.where(
            speed > 0.5,
            x[:, 2:4] / np.maximum(speed, 1e-9),
            -rel / np.linalg.norm(rel, axis=-1, keepdims=True),
        )
        return zp, h, _measurement_cov(radar, jp, u, scatter_std_m)

    def initial(zk: FloatArray) -> tuple[FloatArray, FloatArray]:
        p, los, rho = _initial_point(zk, radar)
        m = zk.shape[0]
        mean = np.zeros((m, n))
        mean[:, :2] = p
        mean[:, 2:4] = (zk[:, 2] * zk[:, 0] / rho)[:, None] * los
        perp = np.stack([los[:, 1], -los[:, 0]], -1)
        jac = np.stack([los * (zk[:, 0] / rho)[:, None], rho[:, None] * perp], -1)
        pos_cov = (
            jac
            @ np.diag([radar.range_std_m**2 + scatter_std_m**2, radar.azimuth_std_rad**2])
            @ np.swapaxes(jac, -1, -2)
        )
        cov = np.zeros((m, n, n))
        cov[:, :2, :2] = pos_cov
        cov[:, 2:4, 2:4] = ((radar.radial_speed_std_mps * zk[:, 0] / rho) ** 2)[:, None, None] * (
            los[:, :, None] * los[:, None, :]
        ) + CROSS_LOS_SPEED_STD_MPS**2 * (perp[:, :, None] * perp[:, None, :])
        for i in range(4, n):
            cov[:, i, i] = 9.0
        return mean, cov

    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        spec = _compiled_spec(FREE, radar, scatter_std_m)
        return _run_compiled(times, z, detected, _series(model, times), initial, spec, n)
    means, covs = _run(times, z, detected, n, transition, measure, initial)
    vel = means[..., 2:4]
    return TrackEstimates(means[..., :2], vel, np.linalg.norm(vel, axis=-1), covs[..., :2, :2])


def _road_transition(
    model: MotionModel, lateral_psd: float
) -> Callable[[FloatArray], tuple[FloatArray, FloatArray]]:
    """Transitions of ``[model states, lateral offset]`` for steps ``dt`` (...,)."""
    k = model.state_dim
    n = k + 1

    def transition(dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        phi_a, q_a = discretize(model, dt, method="auto")
        phi = np.zeros(dt.shape + (n, n))
        qd = np.zeros(dt.shape + (n, n))
        phi[..., :k, :k], qd[..., :k, :k] = phi_a, q_a
        phi[..., k, k] = 1.0
        qd[..., k, k] = lateral_psd * dt
        return phi, qd

    return transition


def _road_measure(
    road: Road, radar: RadarSpec, k: int, scatter_std_m: float
) -> Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]]:
    """Build the measurement function of road states ``[s, ds/dt, ..., d]`` (N, k + 1).

    It returns the predicted detection, its Jacobian (analytic through the road geometry) and
    the scatter-aware noise covariance.
    """
    n = k + 1

    def measure(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        s, vs, d = x[:, 0], x[:, 1], x[:, k]
        pos, tangent, right, kappa = road.lane_geometry(s, d)
        vel = vs[:, None] * tangent
        zp, jp, jv = _polar_jacobian(pos, vel, radar)
        lever = 1.0 + kappa * (0.5 * road.lane_width_m + d)
        dpos_ds = lever[:, None] * tangent
        dvel_ds = -(vs * kappa)[:, None] * right
        h = np.zeros((x.shape[0], 3, n))
        h[:, :, 0] = np.einsum("nij,nj->ni", jp, dpos_ds) + np.einsum("nij,nj->ni", jv, dvel_ds)
        h[:, :, 1] = np.einsum("nij,nj->ni", jv, tangent)
        h[:, :, k] = np.einsum("nij,nj->ni", jp, right)
        return zp, h, _measurement_cov(radar, jp, -tangent, scatter_std_m)

    return measure


def track_on_road(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    radar: RadarSpec,
    road: Road,
    *,
    model: MotionModel,
    scatter_std_m: float = 0.0,
    lateral_psd: float = 0.01,
    lateral_std_m: float = 0.5,
    backend: Backend = "auto",
) -> TrackEstimates:
    """Road-constrained EKF: one-axis ``model`` for the along-road coordinate + lateral offset.

    ``model`` states are ``[s, ds/dt, ...]`` (e.g. ``ConstantAcceleration()``,
    ``ShapingFilter(...)``); ``ds/dt`` is negative while the vehicle approaches. ``backend`` as
    in :func:`track_free_2d`.
    """
    k = model.state_dim
    if model.state_names[:2] != ("x", "vx"):
        raise ValueError("track_on_road needs a one-axis model with states (x, vx, ...)")
    _check_no_input(model)
    n = k + 1
    transition = _road_transition(model, lateral_psd)
    measure = _road_measure(road, radar, k, scatter_std_m)

    def initial(zk: FloatArray) -> tuple[FloatArray, FloatArray]:
        p, _, _ = _initial_point(zk, radar)
        s0, d0 = road.project(p)
        tangent = -road.inbound_direction(s0)
        rel = road.lane_point(s0, d0) - np.asarray(radar.position_m)
        r = np.sqrt(np.sum(rel**2, -1) + radar.height_m**2)
        along = np.einsum("ni,ni->n", rel, tangent) / r
        ok = np.abs(along) > 0.3
        vs0 = np.where(ok, zk[:, 2] / np.where(ok, along, 1.0), 0.0)
        m = zk.shape[0]
        mean = np.zeros((m, n))
        mean[:, 0], mean[:, 1], mean[:, k] = s0, vs0, np.clip(d0, -1.0, 1.0)
        cov = np.zeros((m, n, n))
        cov[:, 0, 0] = 1.0 + scatter_std_m**2
        cov[:, 1, 1] = np.where(
            ok, (radar.radial_speed_std_mps / np.where(ok, np.abs(along), 1.0)) ** 2 + 1.0, 30.0**2
        )
        for i in range(2, k):
            cov[:, i, i] = 9.0 if model.state_names[i].startswith("a") else 25.0
        cov[:, k, k] = lateral_std_m**2
        return mean, cov

    def no_reversal(x: FloatArray) -> FloatArray:
        # an approaching vehicle does not reverse: a track whose predicted speed changes sign
        # (coasting through a stop hidden by the Doppler gate) is held at standstill
        out = np.array(x)
        rev = out[:, 1] > 0
        out[rev, 1:k] = 0.0
        return out

    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        spec = _compiled_spec(ROAD, radar, scatter_std_m, k, road)
        table = _series(model, times, (lateral_psd,))
        return _run_compiled(times, z, detected, table, initial, spec, n)
    means, covs = _run(times, z, detected, n, transition, measure, initial, no_reversal)
    return _road_estimates(means, covs, road, k)


def _road_estimates(means: FloatArray, covs: FloatArray, road: Road, k: int) -> TrackEstimates:
    """Planar estimates of road states ``[s, ds/dt, ..., d]`` (as the compiled kernel's)."""
    s, vs, d = means[..., 0], means[..., 1], means[..., k]
    pos, tangent, right, kappa = road.lane_geometry(np.nan_to_num(s), np.nan_to_num(d))
    pos[np.isnan(s)] = np.nan
    # dp/ds = (1 + kappa (w/2 + d)) t, dp/dd = right
    jac = np.stack([(1.0 + kappa * (0.5 * road.lane_width_m + d))[..., None] * tangent, right], -1)
    sub = covs[..., [0, k], :][..., :, [0, k]]
    return TrackEstimates(
        pos, vs[..., None] * tangent, np.abs(vs), jac @ sub @ np.swapaxes(jac, -1, -2)
    )


def track_converted(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    radar: RadarSpec,
    *,
    model: MotionModel | None = None,
    scatter_std_m: float = 0.0,
) -> TrackEstimates:
    """Converted-measurement Kalman filter: range and azimuth to the plane, no radial speed.

    Each detection becomes a planar position ``s + rho_c (sin az, cos az)`` with the horizontal
    range ``rho = sqrt(r^2 - h^2)`` debiased for the azimuth noise (``rho_c = rho
    exp(sigma_az^2 / 2)``, since ``E[sin(az + n)] = sin(az) exp(-sigma^2 / 2)``) and covariance
    ``J diag(sigma_r^2 + sigma_b^2, sigma_az^2) J^T`` (body scatter counted along the line of
    sight); then a linear Kalman filter (default nearly constant velocity, 2 axes) from a vague
    prior. The radial speed is not used: speed comes from differentiated positions.
    """
    from ..filters.run import kalman_filter

    model = ConstantVelocity(accel_psd=10.0, n_axes=2) if model is None else model
    n = model.state_dim
    zz = np.nan_to_num(z)
    rho = np.sqrt(np.maximum(zz[..., 0] ** 2 - radar.height_m**2, 0.01))
    debias = np.exp(radar.azimuth_std_rad**2 / 2)
    los = np.stack([np.sin(zz[..., 1]), np.cos(zz[..., 1])], -1)
    perp = np.stack([los[..., 1], -los[..., 0]], -1)
    pos = np.asarray(radar.position_m) + (debias * rho)[..., None] * los
    jac = np.stack([los * (zz[..., 0] / rho)[..., None], rho[..., None] * perp], -1)
    cov = (
        jac
        @ np.diag([radar.range_std_m**2 + scatter_std_m**2, radar.azimuth_std_rad**2])
        @ np.swapaxes(jac, -1, -2)
    )
    cov = np.where(detected[..., None, None], cov, np.eye(2))
    h = np.zeros((2, n))
    h[0, 0] = h[1, 1] = 1.0
    p0 = np.diag([1e6, 1e6] + [1e4] * (n - 2))
    prior = GaussianState(
        np.zeros((times.shape[0], n)), np.broadcast_to(p0, (times.shape[0], n, n)), times[:, 0]
    )
    res = kalman_filter(
        times,
        np.where(detected[..., None], pos, np.nan),
        model,
        h,
        cov,
        prior,
        mask=detected,
        method="auto",
    )
    started = np.cumsum(detected, axis=1) > 0
    mean = np.where(started[..., None], res.filtered.mean, np.nan)
    vel = mean[..., 2:4]
    return TrackEstimates(
        mean[..., :2],
        vel,
        np.linalg.norm(vel, axis=-1),
        np.where(started[..., None, None], res.filtered.cov[..., :2, :2], np.nan),
    )


def road_pcrlb(
    runs_times: FloatArray,
    detected: BoolArray,
    along_road_m: FloatArray,
    speed: FloatArray,
    lateral_offset_m: FloatArray,
    radar: RadarSpec,
    road: Road,
    *,
    model: MotionModel,
    scatter_std_m: float = 0.0,
    lateral_psd: float = 0.01,
    lateral_std_m: float = 0.5,
    backend: Backend = "auto",
) -> tuple[FloatArray, FloatArray]:
    """Posterior Cramer-Rao bound of the road-constrained model along true trajectories.

    Information recursion (covariance form) with the Jacobians at the true state and each
    run's own detection sequence, started at its first detection with the tracker's prior.
    Returns the bound variance of the planar position [m^2] and of the speed [m^2/s^2],
    shapes (N, T) (NaN before the first detection). The truth here is deterministic, so a
    filter can beat this bound: it is the design reference of a target that really moves
    like ``model``. ``backend`` as in :func:`track_free_2d`.
    """
    _check_no_input(model)
    k = model.state_dim
    n = k + 1
    n_runs, n_steps = detected.shape
    truth = np.zeros((n_runs, n_steps, n))
    truth[..., 0], truth[..., 1] = along_road_m, -speed
    truth[..., k] = lateral_offset_m[:, None]
    p0 = np.diag([1.0 + scatter_std_m**2, 1.0] + [9.0] * (k - 2) + [lateral_std_m**2])
    pos_var = np.full((n_runs, n_steps), np.nan)
    spd_var = np.full((n_runs, n_steps), np.nan)
    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        from ._ekf_kernels import pcrlb_kernel

        spec = _compiled_spec(ROAD, radar, scatter_std_m, k, road)
        c = np.ascontiguousarray
        pcrlb_kernel(
            c(runs_times, dtype=float),
            *_series(model, runs_times, (lateral_psd,)),
            truth,
            c(detected),
            p0,
            k,
            spec.radar,
            c(spec.road),
            spec.half_width_m,
            spec.scatter_std_m,
            pos_var,
            spd_var,
        )
        return pos_var, spd_var
    measure = _road_measure(road, radar, k, scatter_std_m)
    phis, qds = _road_transition(model, lateral_psd)(
        np.diff(runs_times, axis=1, prepend=runs_times[:, :1])
    )
    cov = np.broadcast_to(p0, (n_runs, n, n)).copy()
    started = np.zeros(n_runs, dtype=bool)
    for i in range(n_steps):
        cov = np.where(
            started[:, None, None],
            phis[:, i] @ cov @ np.swapaxes(phis[:, i], -1, -2) + qds[:, i],
            p0,
        )
        _, h, r = measure(truth[:, i])
        upd = detected[:, i]
        s_mat = h @ cov @ np.swapaxes(h, -1, -2) + r
        gain = np.swapaxes(np.linalg.solve(s_mat, h @ cov), -1, -2)
        ikh = np.eye(n) - gain @ h
        new = ikh @ cov @ np.swapaxes(ikh, -1, -2) + gain @ r @ np.swapaxes(gain, -1, -2)
        cov = np.where(upd[:, None, None], 0.5 * (new + np.swapaxes(new, -1, -2)), cov)
        started |= upd
        pos_var[started, i] = cov[started, 0, 0] + cov[started, k, k]
        spd_var[started, i] = cov[started, 1, 1]
    return pos_var, spd_var


__all__ = ["TrackEstimates", "road_pcrlb", "track_converted", "track_free_2d", "track_on_road"]
