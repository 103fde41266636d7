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

A missed detection is information too. Inside the radar's field of view a scan without a
detection is either a miss (probability ``1 - P_D``) or a target below the Doppler gate ``g``
(``|v_r| < g``: a stopped or crossing vehicle). With the predicted radial speed
``N(mu, sigma^2)``, ``p_g = P(|v_r| < g)``; a moving target misses ``m`` scans in a row with
probability ``q = max(prod (1 - P_D), 1e-4)`` (the run of misses so far, reset by a
detection; the floor stands for causes the sensor model does not know, such as occlusion or
interference), a gated one with probability about 1. Where the gate is the likelier explanation
(``p_g > q (1 - p_g)``) the filter applies it as a pseudo-measurement of the radial speed, 0
with variance ``g^2 / 3`` (uniform on ``(-g, g)``). Only where the radial speed measures the
speed, ``|d v_r / d speed| = |cos theta| >= 0.3``: where the line of sight runs across the
road (the vehicle passing close by the radar), a radial speed below the gate is geometry, not
a stop, and such misses neither update the filter nor extend the run of misses. A vehicle
stopped behind the gate is thus held, with a bounded covariance, instead of coasting away.
The IMM uses
``P(no detection | mode) = p_g + (1 - P_D)(1 - p_g)`` as the mode likelihood.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from ..._backend import Backend, use_compiled
from ..._linalg import symmetrize
from ..._typing import BoolArray, FloatArray
from ...angles import wrap
from ...filters.kalman import CovarianceError, _update, predict
from ...models.continuous import ConstantVelocity, MotionModel
from ...models.discretize import discretize
from ...models.series_table import SeriesTable, model_series_table
from ...types import GaussianState, _trusted
from ..site.geometry import polar_jacobian
from ..site.road import Road
from ..site.sensor import Curve, RadarSpec, curve_tables
from .kernels import FREE, GATE_MIN_COS, MISS_RUN_FLOOR, ROAD, UNFOLD_SIGMAS

CROSS_LOS_SPEED_STD_MPS = 10.0
VAGUE_SPEED_STD_MPS = 30.0  # a first detection that cannot tell the speed (road across, folding)
COMPILED_MIN_RUN_STEPS = 0  # "auto" always runs the compiled EKFs (the kernel wins at any size)


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


def _polar_cov(jac: FloatArray, range_var: FloatArray, azimuth_var: FloatArray) -> FloatArray:
    """Planar covariance ``J diag(range_var, azimuth_var) J^T`` (..., 2, 2) of a detection."""
    return np.einsum("...ik,...k,...jk->...ij", jac, np.stack([range_var, azimuth_var], -1), jac)


def _measurement_cov(
    radar: RadarSpec, zp: FloatArray, jp: FloatArray, direction: FloatArray, scatter_std_m: float
) -> FloatArray:
    """Radar noise at the predicted geometry ``zp`` (N, 3) plus the rank-one body scatter."""
    std = np.stack(radar.noise_std(zp[..., 0], zp[..., 1]), -1)
    b = np.einsum("...ij,...j->...i", jp, direction)
    return std[..., :, None] ** 2 * np.eye(3) + scatter_std_m**2 * b[..., :, None] * b[..., None, :]


def _initial_point(z: FloatArray, radar: RadarSpec) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Planar position, line-of-sight unit vector and horizontal range of detections (N, 3)."""
    rho = np.sqrt(np.maximum(z[..., 0] ** 2 - radar.height_m**2, 0.01))
    los = np.stack([np.sin(z[..., 1]), np.cos(z[..., 1])], -1)
    return np.asarray(radar.position_m) + rho[..., None] * los, los, rho


@dataclass(frozen=True)
class _Compiled:
    """What the compiled EKF needs to evaluate a tracker's measurement model."""

    kind: int  # kernels.ROAD or FREE
    k: int  # along-road model size (ROAD)
    radar: FloatArray  # x, y, height, boresight, min range, Doppler gate
    noise_tab: FloatArray  # (3, 2, K) range / azimuth / radial-speed sigma curves
    noise_cnt: np.ndarray  # (3,) their point counts
    fields: FloatArray  # (F, 2) fields of view: max range, half angle
    pd_tab: FloatArray  # (1, 2, K) detection probability against range
    pd_cnt: np.ndarray  # (1,)
    road: FloatArray  # (5, S) centreline s, x, y, heading, curvature (ROAD)
    half_width_m: float
    scatter_std_m: float


def _compiled_spec(
    kind: int, misses: _Misses, scatter_std_m: float, k: int = 0, road: Road | None = None
) -> _Compiled:
    radar = misses.radar
    radar_arr = radar.kernel_row()
    sensor = (*radar.noise_table(), radar.field_table(), *curve_tables((misses.detection,)))
    if road is None:
        return _Compiled(kind, k, radar_arr, *sensor, np.zeros((5, 2)), 0.0, scatter_std_m)
    table = np.stack([road.s, road.xy[:, 0], road.xy[:, 1], road.heading, road.curvature])
    return _Compiled(kind, k, radar_arr, *sensor, table, 0.5 * road.lane_width_m, scatter_std_m)


@dataclass(frozen=True)
class _Misses:
    """What a scan without a detection tells: the radar's view and Doppler gate, and P_D."""

    radar: RadarSpec
    detection: Curve
    kind: int

    def speed_sensitivity(self, x: FloatArray, h_vr: FloatArray) -> FloatArray:
        """``|d v_r / d speed|`` (N,) at states ``x`` with radial-speed Jacobian rows ``h_vr``."""
        if self.kind == ROAD:
            return np.abs(h_vr[:, 1])
        sp = np.hypot(x[:, 2], x[:, 3])
        along = np.abs(h_vr[:, 2] * x[:, 2] + h_vr[:, 3] * x[:, 3]) / np.maximum(sp, 1e-12)
        return np.where(sp > 0.5, along, 1.0)


def _misses(radar: RadarSpec, detection_probability: Curve | None, kind: int) -> _Misses:
    curve = (
        radar.detection_curve("default") if detection_probability is None else detection_probability
    )
    return _Misses(radar, curve, kind)


def _doppler_usable(
    h: FloatArray, cov: FloatArray, r: FloatArray, radar: RadarSpec
) -> tuple[BoolArray, FloatArray, FloatArray]:
    """Where a folded radial speed can be used (N,), and ``h``, ``r`` with it left out elsewhere.

    NumPy form of :func:`.kernels.doppler_usable`: the prediction tells the alias while
    the radial speed's innovation sigma is below ``fold / UNFOLD_SIGMAS``; elsewhere its
    Jacobian row and its noise cross terms are zeroed (returned copies).
    """
    fold = radar.max_unambiguous_speed_mps or 0.0
    if fold <= 0:
        return np.ones(h.shape[0], dtype=bool), h, r
    var = np.einsum("na,nab,nb->n", h[:, 2], cov, h[:, 2]) + r[:, 2, 2]
    usable = var * UNFOLD_SIGMAS**2 < fold**2
    h, r = h.copy(), r.copy()
    h[~usable, 2] = 0.0
    r[~usable, 2, :2] = r[~usable, :2, 2] = 0.0
    return usable, h, r


def _detection_step(
    prior: GaussianState,
    zpred: FloatArray,
    h: FloatArray,
    r: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    started: BoolArray,
    misses: _Misses,
    miss_run: FloatArray,
) -> tuple[GaussianState, FloatArray, FloatArray]:
    """Update tracks on their detections (N, 3), or on the Doppler gate where it explains a miss.

    ``zpred``, ``h`` (N, 3, n), ``r`` are the measurement model at the prior mean;
    ``miss_run`` (N,) the probability of the current run of misses for a moving target. Returns
    the posterior, the log-likelihood of the scan per run (of the detection, or of the miss
    inside the field of view; 0 otherwise) and the updated ``miss_run``.
    """
    n_runs = detected.shape[0]
    upd = detected & started
    z_eff = np.where(upd[:, None], np.nan_to_num(z), zpred)
    resid = z_eff - zpred
    resid[:, 1] = wrap(resid[:, 1])
    doppler, h_upd, r_upd = _doppler_usable(h, prior.cov, r, misses.radar)
    fold = misses.radar.max_unambiguous_speed_mps or 0.0
    if fold > 0:
        resid[:, 2] = np.where(doppler, wrap(resid[:, 2], fold), 0.0)
    lin = resid + np.einsum("nij,nj->ni", h_upd, prior.mean)
    post, info = _update(
        prior, lin, h_upd, r_upd, np.broadcast_to(upd[:, None], (n_runs, 3)), "joseph"
    )
    loglik = np.where(upd, info.log_likelihood, 0.0)
    if fold > 0:  # a left-out folded radial speed is uniform over the folding interval
        gap = 0.5 * np.log(2 * np.pi * r[:, 2, 2]) - np.log(2 * fold)
        loglik = np.where(upd & ~doppler, loglik + gap, loglik)
    miss_run = np.where(detected, 1.0, miss_run)
    miss = started & ~detected & misses.radar.in_view(zpred[:, 0], zpred[:, 1])
    if not miss.any():
        return post, loglik, miss_run
    h_vr = h[:, 2, :]
    # a miss tells on the speed where the radial speed measures it, once its alias is known
    informs = (misses.speed_sensitivity(prior.mean, h_vr) >= GATE_MIN_COS) & doppler
    var = np.einsum("na,nab,nb->n", h_vr, prior.cov, h_vr)
    sd = np.sqrt(np.maximum(var, 1e-24))
    gate = misses.radar.min_radial_speed_mps
    mu = zpred[:, 2]
    p_gate = ndtr((gate - mu) / sd) - ndtr((-gate - mu) / sd)
    p_det = misses.detection(zpred[:, 0])
    p_miss = p_gate + (1.0 - p_det) * (1.0 - p_gate)
    miss_run = np.where(
        miss & informs, np.maximum(miss_run * (1.0 - p_det), MISS_RUN_FLOOR), miss_run
    )
    gated = miss & informs & (p_gate > miss_run * (1.0 - p_gate)) & (gate > 0)
    lin1 = -mu + np.einsum("na,na->n", h_vr, prior.mean)  # pseudo-measurement v_r = 0
    post, _ = _update(
        post, lin1[:, None], h[:, 2:3, :], np.full((n_runs, 1, 1), gate**2 / 3), gated[:, None],
        "joseph",
    )  # fmt: skip
    with np.errstate(divide="ignore"):
        return post, np.where(miss, np.log(p_miss), loglik), miss_run


def _run(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    n: int,
    transition: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    measure: Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]],
    initial: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    misses: _Misses,
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
    miss_run: FloatArray = np.ones(n_runs)
    t_prev = times[:, 0]
    for k in range(n_steps):
        t = times[:, k]
        phi, qd = phis[:, k], qds[:, k]
        state = predict(_trusted(GaussianState, mean=mean, cov=cov, time=t_prev), phi, qd, time=t)
        if constrain is not None:
            state = _trusted(GaussianState, mean=constrain(state.mean), cov=state.cov, time=t)
        zpred, h, r = measure(state.mean)
        post, _, miss_run = _detection_step(
            state, zpred, h, r, z[:, k], detected[:, k], started, misses, miss_run
        )
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
    key = (repr(model), bound, extra_random_walk_psd)  # the model's parameters, not its id
    if key not in _SERIES_CACHE:
        if len(_SERIES_CACHE) >= 256:
            _SERIES_CACHE.clear()
        _SERIES_CACHE[key] = model_series_table(model, bound, extra_random_walk_psd)
    return _SERIES_CACHE[key]


# Series tables by model parameters and step bound. No kernel writes to a table (read-only
# arrays would be a second numba type, compiled again for every kernel).
_SERIES_CACHE: dict[tuple[str, float, tuple[float, ...]], SeriesTable] = {}


def _run_compiled(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    table: SeriesTable,
    initial: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    spec: _Compiled,
    n: int,
) -> TrackEstimates:
    """Run the compiled EKF (:mod:`.codegen`); the planar estimates come from the kernel."""
    from .codegen import ekf_kernel

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
        spec.noise_tab,
        spec.noise_cnt,
        spec.fields,
        spec.pd_tab,
        spec.pd_cnt,
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
    detection_probability: Curve | None = None,
    backend: Backend = "auto",
) -> TrackEstimates:
    """Planar EKF ``[x, y, vx, vy]`` on (range, azimuth, radial speed) detections.

    ``detection_probability``: P_D against range of the tracked class (default: the radar's
    ``default`` curve), for the meaning of a missed detection. ``backend``: ``"numpy"``
    (reference), ``"numba"`` (compiled, same numbers to rounding) or ``"auto"`` (the
    compiled kernel, once numba has compiled and cached it).
    """
    model = ConstantVelocity(accel_psd=10.0, n_axes=2) if model is None else model
    if model.state_names[:4] != ("x", "y", "vx", "vy"):
        raise ValueError("track_free_2d needs a 2-axis model whose first states are x, y, vx, vy")
    _check_no_input(model)
    n = model.state_dim

    def transition(dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        return discretize(model, dt, method="auto")

    def measure(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        zp, jp, jv = polar_jacobian(x[:, :2], x[:, 2:4], radar.position_m, radar.height_m)
        h = np.zeros((x.shape[0], 3, n))
        h[:, :, :2], h[:, :, 2:4] = jp, jv
        speed = np.linalg.norm(x[:, 2:4], axis=-1, keepdims=True)
        rel = x[:, :2] - np.asarray(radar.position_m)
        u = np.where(
            speed > 0.5,
            x[:, 2:4] / np.maximum(speed, 1e-9),
            -rel / np.linalg.norm(rel, axis=-1, keepdims=True),
        )
        return zp, h, _measurement_cov(radar, zp, jp, u, scatter_std_m)

    def initial(zk: FloatArray) -> tuple[FloatArray, FloatArray]:
        p, los, rho = _initial_point(zk, radar)
        m = zk.shape[0]
        mean = np.zeros((m, n))
        mean[:, :2] = p
        mean[:, 2:4] = (zk[:, 2] * zk[:, 0] / rho)[:, None] * los
        perp = np.stack([los[:, 1], -los[:, 0]], -1)
        jac = np.stack([los * (zk[:, 0] / rho)[:, None], rho[:, None] * perp], -1)
        sr, saz, svr = radar.noise_std(zk[:, 0], zk[:, 1])
        pos_cov = _polar_cov(jac, sr**2 + scatter_std_m**2, saz**2)
        cov = np.zeros((m, n, n))
        cov[:, :2, :2] = pos_cov
        if radar.max_unambiguous_speed_mps is None:
            cov[:, 2:4, 2:4] = ((svr * zk[:, 0] / rho) ** 2)[:, None, None] * (
                los[:, :, None] * los[:, None, :]
            ) + CROSS_LOS_SPEED_STD_MPS**2 * (perp[:, :, None] * perp[:, None, :])
        else:  # a folded radial speed does not tell the speed: the next positions will
            mean[:, 2:4] = 0.0
            cov[:, 2:4, 2:4] = VAGUE_SPEED_STD_MPS**2 * np.eye(2)
        for i in range(4, n):
            cov[:, i, i] = 9.0
        return mean, cov

    misses = _misses(radar, detection_probability, FREE)
    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        spec = _compiled_spec(FREE, misses, scatter_std_m)
        return _run_compiled(times, z, detected, _series(model, times), initial, spec, n)
    means, covs = _run(times, z, detected, n, transition, measure, initial, misses)
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
        lever = 1.0 + kappa * (0.5 * road.lane_width_m + d)  # lane point speed / ds/dt
        along = lever[:, None] * tangent
        zp, jp, jv = polar_jacobian(pos, vs[:, None] * along, radar.position_m, radar.height_m)
        dvel_ds = -(vs * lever * kappa)[:, None] * right
        dvel_dd = (vs * kappa)[:, None] * tangent
        h = np.zeros((x.shape[0], 3, n))
        h[:, :, 0] = np.einsum("nij,nj->ni", jp, along) + np.einsum("nij,nj->ni", jv, dvel_ds)
        h[:, :, 1] = np.einsum("nij,nj->ni", jv, along)
        h[:, :, k] = np.einsum("nij,nj->ni", jp, right) + np.einsum("nij,nj->ni", jv, dvel_dd)
        return zp, h, _measurement_cov(radar, zp, jp, -tangent, scatter_std_m)

    return measure


def _check_road_model(model: MotionModel) -> None:
    if model.state_names[:2] != ("x", "vx"):
        raise ValueError("the road trackers need one-axis models with states (x, vx, ...)")
    _check_no_input(model)


def _road_initial(
    zk: FloatArray,
    radar: RadarSpec,
    road: Road,
    model: MotionModel,
    scatter_std_m: float,
    lateral_std_m: float,
) -> tuple[FloatArray, FloatArray]:
    """Road state ``[model states, d]`` (m, k + 1) and covariance of first detections (m, 3).

    Along-road position and lateral offset from the projected detection, speed from the
    radial speed along the line of sight (vague where the road runs across it, or where the
    radar folds radial speeds: the first detections' positions then tell the alias).
    """
    k = model.state_dim
    n = k + 1
    p, _, _ = _initial_point(zk, radar)
    s0, d0 = road.project(p)
    tangent = -road.inbound_direction(s0)
    rel = road.lane_point(s0, d0) - np.asarray(radar.position_m)
    r = np.sqrt(np.sum(rel**2, -1) + radar.height_m**2)
    along = np.einsum("ni,ni->n", rel, tangent) / r * road.lane_speed_factor(s0, d0)
    ok = (np.abs(along) > 0.3) & (radar.max_unambiguous_speed_mps is None)
    vs0 = np.where(ok, zk[:, 2] / np.where(ok, along, 1.0), 0.0)
    m = zk.shape[0]
    mean = np.zeros((m, n))
    mean[:, 0], mean[:, 1], mean[:, k] = s0, vs0, np.clip(d0, -1.0, 1.0)
    cov = np.zeros((m, n, n))
    cov[:, 0, 0] = 1.0 + scatter_std_m**2
    svr = radar.noise_std(zk[:, 0], zk[:, 1])[2]
    speed_var = (svr / np.where(ok, np.abs(along), 1.0)) ** 2 + 1.0
    cov[:, 1, 1] = np.where(ok, speed_var, VAGUE_SPEED_STD_MPS**2)
    for i in range(2, k):
        cov[:, i, i] = 9.0 if model.state_names[i].startswith("a") else 25.0
    cov[:, k, k] = lateral_std_m**2
    return mean, cov


def _no_reversal(k: int) -> Callable[[FloatArray], FloatArray]:
    """Hold a track whose predicted along-road speed changes sign at standstill.

    An approaching vehicle does not reverse: a track coasting through a stop hidden by the
    Doppler gate would otherwise drive backwards.
    """

    def constrain(x: FloatArray) -> FloatArray:
        out = np.array(x)
        rev = out[:, 1] > 0
        out[rev, 1:k] = 0.0
        return out

    return constrain


def track_on_road(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    radar: RadarSpec,
    road: Road,
    *,
    model: MotionModel,
    scatter_std_m: float = 0.0,
    detection_probability: Curve | None = None,
    lateral_psd: float = 0.01,
    lateral_std_m: float = 0.5,
    backend: Backend = "auto",
) -> TrackEstimates:
    """Road-constrained EKF: one-axis ``model`` for the along-road coordinate + lateral offset.

    ``model`` states are ``[s, ds/dt, ...]`` (e.g. ``ConstantAcceleration()``,
    ``ShapingFilter(...)``); ``ds/dt`` is negative while the vehicle approaches.
    ``detection_probability`` and ``backend`` as in :func:`track_free_2d`.
    """
    _check_road_model(model)
    k = model.state_dim
    n = k + 1

    def initial(zk: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _road_initial(zk, radar, road, model, scatter_std_m, lateral_std_m)

    misses = _misses(radar, detection_probability, ROAD)
    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        spec = _compiled_spec(ROAD, misses, scatter_std_m, k, road)
        table = _series(model, times, (lateral_psd,))
        return _run_compiled(times, z, detected, table, initial, spec, n)
    transition = _road_transition(model, lateral_psd)
    measure = _road_measure(road, radar, k, scatter_std_m)
    means, covs = _run(times, z, detected, n, transition, measure, initial, misses, _no_reversal(k))
    return _road_estimates(means, covs, road, k)


@dataclass(frozen=True, eq=False)
class RoadIMMEstimates(TrackEstimates):
    """:class:`TrackEstimates` of the road IMM with its mode probabilities (N, T, M)."""

    mode_probabilities: FloatArray = field(default_factory=lambda: np.zeros((0, 0, 0)))


def switching_generator(sojourn_s: tuple[float, ...]) -> FloatArray:
    """Return the generator ``L`` (M, M) of a mode chain with mean sojourn times [s].

    Mode i is left at rate ``1 / sojourn_s[i]`` towards each other mode alike; over a step
    ``dt`` the switching probabilities are ``expm(L dt)`` (so irregular steps keep their
    meaning). The stationary probabilities are proportional to the sojourn times.
    """
    rates = 1.0 / np.asarray(sojourn_s, dtype=float)
    m = rates.size
    if m == 1:
        return np.zeros((1, 1))
    gen = np.repeat(rates[:, None] / (m - 1), m, axis=1)
    np.fill_diagonal(gen, -rates)
    return gen


def track_on_road_imm(
    times: FloatArray,
    z: FloatArray,
    detected: BoolArray,
    radar: RadarSpec,
    road: Road,
    *,
    models: tuple[MotionModel, ...],
    sojourn_s: tuple[float, ...],
    scatter_std_m: float = 0.0,
    detection_probability: Curve | None = None,
    lateral_psd: float = 0.01,
    lateral_std_m: float = 0.5,
    backend: Backend = "auto",
) -> RoadIMMEstimates:
    """Interacting multiple model (IMM) of road-constrained EKFs.

    Each mode is an along-road model (e.g. constant velocity, constant acceleration) with the
    lateral offset in the lane.

    Modes switch as a continuous-time Markov chain (:func:`switching_generator`) with mean
    sojourn times ``sojourn_s`` [s]; the chain starts in its stationary distribution at the
    first detection. Modes with different states mix by state name (a state a mode lacks is
    taken from the receiving mode, as :func:`adaptrack.filters.imm.imm_filter` does); the
    output combines the common states ``[s, ds/dt, d]``. Every mode uses the no-reversal
    hold of :func:`track_on_road`; a missed detection's likelihood under each mode weighs the
    modes (module docstring). ``detection_probability`` and ``backend`` as in
    :func:`track_free_2d`.
    """
    if len(models) < 1 or len(models) != len(sojourn_s):
        raise ValueError("models and sojourn_s need one entry per mode (at least one)")
    if not all(np.isfinite(v) and v > 0 for v in sojourn_s):
        raise ValueError(f"sojourn_s must be > 0 [s]; got {tuple(sojourn_s)}")
    for m in models:
        _check_road_model(m)
    names = [m.state_names + ("d",) for m in models]
    common = tuple(v for v in names[0] if all(v in nm for nm in names))
    gen = switching_generator(tuple(sojourn_s))
    mu0 = np.asarray(sojourn_s, dtype=float) / float(np.sum(sojourn_s))

    def initial(zk: FloatArray) -> list[tuple[FloatArray, FloatArray]]:
        return [_road_initial(zk, radar, road, m, scatter_std_m, lateral_std_m) for m in models]

    misses = _misses(radar, detection_probability, ROAD)
    problem = _RoadIMM(
        times, z, detected, misses, road, tuple(models), gen, mu0, names, common, initial,
        scatter_std_m, lateral_psd,
    )  # fmt: skip
    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        return _road_imm_compiled(problem)
    return _road_imm_numpy(problem)


@dataclass(frozen=True, eq=False)
class _RoadIMM:
    """A road-IMM problem as :func:`track_on_road_imm` prepares it for either backend."""

    times: FloatArray
    z: FloatArray
    detected: BoolArray
    misses: _Misses
    road: Road
    models: tuple[MotionModel, ...]
    gen: FloatArray  # (M, M) switching generator
    mu0: FloatArray  # (M,) mode probabilities at the first detection
    names: list[tuple[str, ...]]  # every mode's state names
    common: tuple[str, ...]  # the combined states
    initial: Callable[[FloatArray], list[tuple[FloatArray, FloatArray]]]
    scatter_std_m: float
    lateral_psd: float


def _road_imm_numpy(p: _RoadIMM) -> RoadIMMEstimates:
    """NumPy reference of :func:`track_on_road_imm` (loop over scans, batched over runs)."""
    from scipy.linalg import expm

    from ...filters.imm import _embed, _mix

    times, z, detected, misses, road = p.times, p.z, p.detected, p.misses, p.road
    models, gen, mu0, names, common = p.models, p.gen, p.mu0, p.names, p.common
    initial, scatter_std_m, lateral_psd = p.initial, p.scatter_std_m, p.lateral_psd

    n_runs, n_steps = detected.shape
    n_modes = len(models)
    sizes = [len(nm) for nm in names]
    emb = [[_embed(names[i], names[j]) for j in range(n_modes)] for i in range(n_modes)]
    out_idx = [[nm.index(v) for v in common] for nm in names]
    transitions = [_road_transition(m, lateral_psd) for m in models]
    measures = [_road_measure(road, misses.radar, n - 1, scatter_std_m) for n in sizes]
    dts = np.diff(times, axis=1, prepend=times[:, :1])
    disc = [tr(dts) for tr in transitions]
    states = [
        _trusted(GaussianState, mean=np.zeros((n_runs, n)), cov=np.tile(np.eye(n), (n_runs, 1, 1)),
                 time=times[:, 0])
        for n in sizes
    ]  # fmt: skip
    log_mu = np.tile(np.log(mu0), (n_runs, 1))
    started = np.zeros(n_runs, dtype=bool)
    miss_runs: list[FloatArray] = [np.ones(n_runs) for _ in models]
    n_out = len(common)
    means = np.full((n_runs, n_steps, n_out), np.nan)
    covs = np.full((n_runs, n_steps, n_out, n_out), np.nan)
    probs = np.full((n_runs, n_steps, n_modes), np.nan)
    for k in range(n_steps):
        t = times[:, k]
        if k > 0:
            chain = np.stack([expm(gen * dt) for dt in dts[:, k]])
            with np.errstate(divide="ignore"):
                log_pi = np.log(np.maximum(chain, 1e-300))
            mixed, log_c = _mix(states, log_mu, log_pi, emb)
        else:
            mixed, log_c = states, log_mu
        lls = []
        for j in range(n_modes):
            kj = sizes[j] - 1
            prior = predict(mixed[j], disc[j][0][:, k], disc[j][1][:, k], time=t)
            x = _no_reversal(kj)(prior.mean)
            prior = _trusted(GaussianState, mean=x, cov=prior.cov, time=t)
            zpred, h, r = measures[j](x)
            states[j], ll, miss_runs[j] = _detection_step(
                prior, zpred, h, r, z[:, k], detected[:, k], started, misses, miss_runs[j]
            )
            lls.append(ll)
        joint = np.stack(lls, -1) + log_c
        total = np.log(np.sum(np.exp(joint - joint.max(-1, keepdims=True)), -1)) + joint.max(-1)
        log_mu = joint - total[:, None]
        new = detected[:, k] & ~started
        if new.any():
            for j, (m0, p0) in enumerate(initial(z[new, k])):
                mean, cov = np.array(states[j].mean), np.array(states[j].cov)
                mean[new], cov[new] = m0, p0
                states[j] = _trusted(GaussianState, mean=mean, cov=cov, time=t)
            log_mu[new] = np.log(mu0)
            started |= new
        mu = np.exp(log_mu)
        xs = np.stack([states[j].mean[:, out_idx[j]] for j in range(n_modes)], 1)
        ps = np.stack([states[j].cov[:, out_idx[j]][:, :, out_idx[j]] for j in range(n_modes)], 1)
        xm = np.einsum("nj,nja->na", mu, xs)
        d = xs - xm[:, None]
        pm = np.einsum("nj,njab->nab", mu, ps + d[..., :, None] * d[..., None, :])
        means[started, k], covs[started, k] = xm[started], symmetrize(pm)[started]
        probs[started, k] = mu[started]
    est = _road_estimates(means, covs, road, n_out - 1)
    return RoadIMMEstimates(
        est.position, est.velocity, est.speed, est.position_cov, mode_probabilities=probs
    )


def _road_imm_compiled(p: _RoadIMM) -> RoadIMMEstimates:
    """Run :func:`track_on_road_imm` in :mod:`.imm_kernel`."""
    from ...filters.imm import _embed
    from ...models.series_table import series_table
    from .imm_kernel import road_imm_kernel

    times, z, detected, misses, road = p.times, p.z, p.detected, p.misses, p.road
    models, gen, mu0, names, common = p.models, p.gen, p.mu0, p.names, p.common
    initial, scatter_std_m, lateral_psd = p.initial, p.scatter_std_m, p.lateral_psd

    n_runs, n_steps = detected.shape
    n_modes = len(models)
    sizes = np.array([len(nm) for nm in names], dtype=np.int64)
    nmax = int(sizes.max())
    tables = [_series(m, times, (lateral_psd,)) for m in models]
    n_phi = max(t.phi_coef.shape[0] for t in tables)
    n_qd = max(t.qd_coef.shape[0] for t in tables)
    phi_coef = np.zeros((n_modes, n_phi, nmax, nmax))
    qd_coef = np.zeros((n_modes, n_qd, nmax, nmax))
    for j, t in enumerate(tables):  # leading zero terms leave Horner's sums unchanged
        n = sizes[j]
        phi_coef[j, : t.phi_coef.shape[0], :n, :n] = t.phi_coef
        qd_coef[j, : t.qd_coef.shape[0], :n, :n] = t.qd_coef
    steps = np.diff(times, axis=1)
    chain = series_table(gen.T, np.zeros_like(gen), float(steps.max()) if steps.size else 1.0)
    emb_dst = np.zeros((n_modes, n_modes, nmax), dtype=np.int64)
    emb_src = np.zeros_like(emb_dst)
    emb_cnt = np.zeros((n_modes, n_modes), dtype=np.int64)
    for i in range(n_modes):
        for j in range(n_modes):
            dst, src = _embed(names[i], names[j])
            emb_cnt[i, j] = dst.size
            emb_dst[i, j, : dst.size], emb_src[i, j, : dst.size] = dst, src
    out_idx = np.array([[nm.index(v) for v in common] for nm in names], dtype=np.int64)
    started = np.asarray(detected.any(axis=1), dtype=bool)
    first = np.where(started, np.argmax(detected, axis=1), -1)
    m0 = np.zeros((n_modes, n_runs, nmax))
    p0 = np.zeros((n_modes, n_runs, nmax, nmax))
    if started.any():
        for j, (mj, pj) in enumerate(initial(z[started, first[started]])):
            m0[j, started, : sizes[j]], p0[j, started, : sizes[j], : sizes[j]] = mj, pj
    spec = _compiled_spec(ROAD, misses, scatter_std_m, 0, road)
    out = RoadIMMEstimates(
        np.full((n_runs, n_steps, 2), np.nan),
        np.full((n_runs, n_steps, 2), np.nan),
        np.full((n_runs, n_steps), np.nan),
        np.full((n_runs, n_steps, 2, 2), np.nan),
        np.full((n_runs, n_steps, n_modes), np.nan),
    )
    status = np.zeros(n_runs, dtype=np.int64)
    c = np.ascontiguousarray
    road_imm_kernel(
        c(times, dtype=float), sizes, phi_coef, qd_coef,
        np.array([t.h_max for t in tables]), chain.phi_coef, chain.h_max, np.log(mu0),
        emb_dst, emb_src, emb_cnt, out_idx, c(z, dtype=float), c(detected), first, m0, p0,
        spec.radar, spec.noise_tab, spec.noise_cnt, spec.fields, spec.pd_tab, spec.pd_cnt,
        c(spec.road), spec.half_width_m, spec.scatter_std_m, out.position, out.velocity,
        out.speed, out.position_cov, out.mode_probabilities, status,
    )  # fmt: skip
    if status.any():
        i = int(np.flatnonzero(status)[0])
        raise CovarianceError(
            f"innovation covariance is not positive definite at step {int(status[i]) - 1}, run {i}"
        )
    return out


def _road_estimates(means: FloatArray, covs: FloatArray, road: Road, k: int) -> TrackEstimates:
    """Planar estimates of road states ``[s, ds/dt, ..., d]`` (as the compiled kernel's)."""
    s, vs, d = means[..., 0], means[..., 1], means[..., k]
    pos, tangent, right, kappa = road.lane_geometry(np.nan_to_num(s), np.nan_to_num(d))
    pos[np.isnan(s)] = np.nan
    # dp/ds = (1 + kappa (w/2 + d)) t, dp/dd = right; the lane point moves at lever * ds/dt
    lever = 1.0 + kappa * (0.5 * road.lane_width_m + d)
    jac = np.stack([lever[..., None] * tangent, right], -1)
    sub = covs[..., [0, k], :][..., :, [0, k]]
    return TrackEstimates(
        pos,
        (vs * lever)[..., None] * tangent,
        np.abs(vs * lever),
        jac @ sub @ np.swapaxes(jac, -1, -2),
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
    from ...filters.run import kalman_filter

    model = ConstantVelocity(accel_psd=10.0, n_axes=2) if model is None else model
    n = model.state_dim
    zz = np.nan_to_num(z)
    rho = np.sqrt(np.maximum(zz[..., 0] ** 2 - radar.height_m**2, 0.01))
    sr, saz, _ = radar.noise_std(zz[..., 0], zz[..., 1])
    debias = np.exp(saz**2 / 2)
    los = np.stack([np.sin(zz[..., 1]), np.cos(zz[..., 1])], -1)
    perp = np.stack([los[..., 1], -los[..., 0]], -1)
    pos = np.asarray(radar.position_m) + (debias * rho)[..., None] * los
    jac = np.stack([los * (zz[..., 0] / rho)[..., None], rho[..., None] * perp], -1)
    cov = _polar_cov(jac, sr**2 + scatter_std_m**2, saz**2)
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
        backend="numba",
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
    run's own detection sequence, started at its first detection with the tracker's prior; a
    scan without a detection, in view and with the true radial speed below the Doppler gate,
    adds the gate's information as the trackers do (module docstring).
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
    lever = road.lane_speed_factor(along_road_m, lateral_offset_m[:, None])
    truth[..., 0], truth[..., 1] = along_road_m, -speed / lever
    truth[..., k] = lateral_offset_m[:, None]
    p0 = np.diag([1.0 + scatter_std_m**2, 1.0] + [9.0] * (k - 2) + [lateral_std_m**2])
    pos_var = np.full((n_runs, n_steps), np.nan)
    spd_var = np.full((n_runs, n_steps), np.nan)
    if use_compiled(backend, detected.size, threshold=COMPILED_MIN_RUN_STEPS):
        from .kernels import pcrlb_kernel

        spec = _compiled_spec(ROAD, _misses(radar, None, ROAD), scatter_std_m, k, road)
        c = np.ascontiguousarray
        pcrlb_kernel(
            c(runs_times, dtype=float),
            *_series(model, runs_times, (lateral_psd,)),
            truth,
            c(detected),
            p0,
            k,
            spec.radar,
            spec.noise_tab,
            spec.noise_cnt,
            spec.fields,
            c(spec.road),
            spec.half_width_m,
            spec.scatter_std_m,
            pos_var,
            spd_var,
        )
        return pos_var, spd_var * lever**2
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
        zt, h, r = measure(truth[:, i])
        upd = detected[:, i]
        gate = radar.min_radial_speed_mps
        gated = (
            started
            & ~upd
            & radar.in_view(zt[:, 0], zt[:, 1])
            & (np.abs(zt[:, 2]) < gate)
            & (np.abs(h[:, 2, 1]) >= GATE_MIN_COS)
            & (gate > 0)
        )
        for use, hh, rr in (
            (upd, h, r),
            (gated, h[:, 2:3], np.full((n_runs, 1, 1), gate**2 / 3)),
        ):
            s_mat = hh @ cov @ np.swapaxes(hh, -1, -2) + rr
            gain = np.swapaxes(np.linalg.solve(s_mat, hh @ cov), -1, -2)
            ikh = np.eye(n) - gain @ hh
            new = ikh @ cov @ np.swapaxes(ikh, -1, -2) + gain @ rr @ np.swapaxes(gain, -1, -2)
            cov = np.where(use[:, None, None], 0.5 * (new + np.swapaxes(new, -1, -2)), cov)
        started |= upd
        pos_var[started, i] = cov[started, 0, 0] + cov[started, k, k]
        spd_var[started, i] = cov[started, 1, 1]
    return pos_var, spd_var * lever**2


__all__ = [
    "RoadIMMEstimates",
    "TrackEstimates",
    "road_pcrlb",
    "switching_generator",
    "track_converted",
    "track_free_2d",
    "track_on_road",
    "track_on_road_imm",
]
