"""Compiled (numba) per-scan steps of :class:`adaptrack.crossing.scene_tracker.SceneTracker`.

Tracks are rows of arrays: state ``x`` (T, 4) = ``[u, du/dt, d2u/dt2, d]`` in corridor
coordinates, covariance ``p`` (T, 4, 4), the corridor index of each row and the learnt body
spread. Corridors are packed as one (5, S) table of centreline samples (``u``, east, north,
heading, curvature) with ``bounds`` (C, 2) the column range of each. The radar row is
``x, y, height, boresight, min range, Doppler gate, folding speed`` as in
:mod:`._ekf_kernels`, whose measurement model (:func:`._ekf_kernels.measure`, lane half
width 0) and radial-speed unfolding they evaluate.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._borrowed import on_stack
from ..filters._kernels import cholesky_into, update_into
from ..tracking.assignment import cluster_labels
from ..tracking.lifecycle import expired_rows, record_hits
from ._ekf_kernels import (
    GATE_MIN_COS,
    ROAD,
    centreline_span,
    doppler_usable,
    gate_update_into,
    innovation_into,
    lane_at,
    measure_span,
    off_boresight,
    road_measure,
)
from ._radar_kernel import curve_at, in_view, wrapped

N_STATE = 4
BIAS_MIN_SPEED_MPS = 6.0  # azimuth alignment on vehicles, not on cyclists at the lane's edge
GHOST_SPEED_MPS = 2.0  # a multipath ghost moves with the body that makes it (within this)
BODY_HALF_SPREADS = 2.0  # a body reaches this many spreads either side of its centre
DETECTION_D_RATE = 0.2  # moving-average rate of a track's detections' offset across
VISIBLE_SAMPLES = 17  # points over a body tested against a field of view
CLUTTER_VIEW = 29  # a frozen track's stored view of one radar (_store_view)
NEAREST_BLOCK = 32  # centreline samples searched as a block once it may hold the nearest
NEAREST_GROUP = 32  # blocks tested as a group first
# a road user's width [m] from its length [m]: pedestrian, motorcycle, car, truck, bus (the
# classes of DOMAIN 3 / crossing.traffic), linear between them, the legal 2.55 m beyond
BODY_LENGTHS_M = np.array([0.5, 2.2, 5.0, 7.1, 12.0])
BODY_WIDTHS_M = np.array([0.5, 0.8, 1.8, 2.5, 2.55])


@numba.njit(cache=True, inline="always")
def _model_scratch():  # type: ignore[no-untyped-def]
    """Buffers of the measurement model (stack): detection, Jacobian, noise, polar Jacobians."""
    return (
        on_stack(3), on_stack((3, N_STATE)), on_stack((3, 3)), on_stack((3, 2)), on_stack((3, 2))
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _update_scratch(m):  # type: ignore[no-untyped-def]
    """Buffers of an ``m``-dimensional EKF update (``update_into``) and its posterior (stack)."""
    return (
        on_stack((m, N_STATE)), on_stack((m, m)), on_stack((m, m)), on_stack((m, N_STATE)),
        on_stack(m), on_stack((N_STATE, N_STATE)), on_stack((N_STATE, N_STATE)),
        on_stack(N_STATE), on_stack((N_STATE, N_STATE)),
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def rows_where(mask, value):  # type: ignore[no-untyped-def]
    """Return the rows whose ``mask`` (bool array) is ``value``: one array, no temporaries."""
    rows = np.empty(mask.size, np.int64)
    k = 0
    for i in range(mask.size):
        if mask[i] == value:
            rows[k] = i
            k += 1
    return rows[:k]


@numba.njit(cache=True, inline="always")
def _rows_and_not(a, b):  # type: ignore[no-untyped-def]
    """Return the rows with ``a`` and not ``b`` (bool arrays): one array, no temporaries."""
    rows = np.empty(a.size, np.int64)
    k = 0
    for i in range(a.size):
        if a[i] and not b[i]:
            rows[k] = i
            k += 1
    return rows[:k]


@numba.njit(cache=True)
def predict_tracks(  # type: ignore[no-untyped-def]
    x, p, t, stopped, direction, frozen, time_s, accel_psd, lateral_psd, stopped_psd
):
    """Predict every track to ``time_s`` in place (white-jerk CA; stopped rows held).

    A track with a known ``direction`` (+1 / -1 along ``u``) does not reverse: a predicted
    speed against it becomes a standstill (speed and acceleration 0), as a braking vehicle.
    ``frozen`` rows (learnt clutter: :func:`update_tracks`) keep their state and covariance.
    """
    q_moving, q_stopped = on_stack((N_STATE, N_STATE)), on_stack((N_STATE, N_STATE))
    tmp = on_stack((N_STATE, N_STATE))
    moving_dt, stopped_dt = -1.0, -1.0  # the steps q_moving, q_stopped were made for
    for i in range(x.shape[0]):
        dt = max(time_s - t[i], 0.0)
        t[i] = max(t[i], time_s)
        if dt == 0.0 or frozen[i]:
            continue
        if stopped[i]:
            if dt != stopped_dt:  # tracks mostly share the step
                stopped_dt = dt
                _process_noise_into(dt, True, accel_psd, lateral_psd, stopped_psd, q_stopped)
            _predict_row(x, p, i, dt, True, q_stopped, tmp)
        else:
            if dt != moving_dt:
                moving_dt = dt
                _process_noise_into(dt, False, accel_psd, lateral_psd, stopped_psd, q_moving)
            _predict_row(x, p, i, dt, False, q_moving, tmp)
        if direction[i] != 0 and x[i, 1] * direction[i] < 0.0:
            x[i, 1] = x[i, 2] = 0.0


@numba.njit(cache=True, inline="always")
def _process_noise_into(dt, stopped, accel_psd, lateral_psd, stopped_psd, q):  # type: ignore[no-untyped-def]
    """Fill the process noise ``q`` (4, 4) of a step ``dt`` [s]: white jerk along, walk across."""
    q[:, :] = 0.0
    if stopped:
        q[0, 0] = q[3, 3] = stopped_psd * dt
    else:
        q[0, 0] = accel_psd * dt**5 / 20.0
        q[0, 1] = q[1, 0] = accel_psd * dt**4 / 8.0
        q[0, 2] = q[2, 0] = accel_psd * dt**3 / 6.0
        q[1, 1] = accel_psd * dt**3 / 3.0
        q[1, 2] = q[2, 1] = accel_psd * dt**2 / 2.0
        q[2, 2] = accel_psd * dt
        q[3, 3] = lateral_psd * dt


@numba.njit(cache=True, inline="always")
def _predict_row(x, p, i, dt, stopped, q, tmp):  # type: ignore[no-untyped-def]
    """Predict row ``i`` over ``dt`` [s] in place: ``x = Phi x``, ``P = Phi P Phi^T + q``.

    ``Phi`` is CA along (``[[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]``) and 1 across, or the
    identity when ``stopped``. The sums of :func:`adaptrack.filters._kernels.predict_into`,
    in its order, with the terms of zero ``Phi`` entries left out: the same values to the last
    bit for finite states (a test compares the two). ``tmp`` (4, 4) scratch.
    """
    if stopped:
        for a in range(N_STATE):
            x[i, a] = (0.0 + x[i, a]) + 0.0
            for b in range(N_STATE):
                tmp[a, b] = 0.0 + p[i, a, b]
        for a in range(N_STATE):
            for b in range(N_STATE):
                p[i, a, b] = (0.0 + tmp[a, b]) + q[a, b]
    else:
        h = 0.5 * dt * dt
        x0, x1, x2, x3 = x[i, 0], x[i, 1], x[i, 2], x[i, 3]
        x[i, 0] = (((0.0 + x0) + dt * x1) + h * x2) + 0.0
        x[i, 1] = ((0.0 + x1) + dt * x2) + 0.0
        x[i, 2] = (0.0 + x2) + 0.0
        x[i, 3] = (0.0 + x3) + 0.0
        for b in range(N_STATE):
            tmp[0, b] = ((0.0 + p[i, 0, b]) + dt * p[i, 1, b]) + h * p[i, 2, b]
            tmp[1, b] = (0.0 + p[i, 1, b]) + dt * p[i, 2, b]
            tmp[2, b] = 0.0 + p[i, 2, b]
            tmp[3, b] = 0.0 + p[i, 3, b]
        for a in range(N_STATE):
            p[i, a, 0] = (((0.0 + tmp[a, 0]) + tmp[a, 1] * dt) + tmp[a, 2] * h) + q[a, 0]
            p[i, a, 1] = ((0.0 + tmp[a, 1]) + tmp[a, 2] * dt) + q[a, 1]
            p[i, a, 2] = (0.0 + tmp[a, 2]) + q[a, 2]
            p[i, a, 3] = (0.0 + tmp[a, 3]) + q[a, 3]
    for a in range(N_STATE):
        for b in range(a + 1, N_STATE):
            v = 0.5 * (p[i, a, b] + p[i, b, a])
            p[i, a, b] = v
            p[i, b, a] = v


@numba.njit(cache=True, inline="always")
def _lane_frame(roads, bounds, c, u, d):  # type: ignore[no-untyped-def]
    """Corridor ``c`` at ``u``: centreline point, unit tangent, curvature, point at offset ``d``.

    Returns ``(cx, cy, tx, ty, kappa, px, py)``; ``(-ty, tx)`` is the offsets' direction.
    """
    cx, cy, kappa, tx, ty = lane_at(roads, bounds[c, 0], bounds[c, 1], u)
    return cx, cy, tx, ty, kappa, cx - d * ty, cy + d * tx


@numba.njit(cache=True, inline="always")
def _store_lane(lanes, i, roads, bounds, corridor, x):  # type: ignore[no-untyped-def]
    """Set row ``i`` of ``lanes`` (T, 5) to track ``i``'s lane frame at its ``u`` (``lane_at``)."""
    c = corridor[i]
    lanes[i, 0], lanes[i, 1], lanes[i, 2], lanes[i, 3], lanes[i, 4] = lane_at(
        roads, bounds[c, 0], bounds[c, 1], x[i, 0]
    )


@numba.njit(cache=True, inline="always")
def _ground_point(z_row, radar):  # type: ignore[no-untyped-def]
    """Ground point (x, y) and horizontal range of a detection (range, azimuth, ...)."""
    rho = math.sqrt(max(z_row[0] ** 2 - radar[2] ** 2, 0.01))
    return radar[0] + rho * math.sin(z_row[1]), radar[1] + rho * math.cos(z_row[1]), rho


@numba.njit(cache=True, inline="always")
def _view_uniform(lane, d, half, radar, fields):  # type: ignore[no-untyped-def]
    """Whether the lane points within ``half`` [m] of ``(u, d)`` are all in view (1), all out (-1).

    ``lane``: the lane frame at ``u`` (:func:`._ekf_kernels.lane_at`). 0 when it cannot
    tell. A sufficient test from the centre point alone: the points lie within ``half`` of it
    (the arc is no shorter than its chord), so their slant ranges differ from its by at most
    ``half`` and their bearings by at most ``asin(half / ground range)``.
    """
    cx, cy, _, tx, ty = lane
    ex = cx - d * ty - radar[0]
    ey = cy + d * tx - radar[1]
    ground = math.sqrt(ex * ex + ey * ey)
    if ground <= half:
        return 0
    rng = math.sqrt(ground * ground + radar[2] * radar[2])
    if rng + half < radar[4]:
        return -1  # all nearer than the minimum range
    off = off_boresight(math.atan2(ex, ey), radar)
    widen = math.asin(half / ground)
    all_in = rng - half >= radar[4]
    some_field = False
    for f in range(fields.shape[0]):
        if rng + half <= fields[f, 0] and off + widen <= fields[f, 1]:
            return 1 if all_in else 0
        some_field |= rng - half <= fields[f, 0] and off - widen <= fields[f, 1]
    return 0 if some_field else -1


@numba.njit(cache=True, inline="always")
def _visible_part(u, d, spread, lo, hi, roads, radar, fields, lane):  # type: ignore[no-untyped-def]
    """Locate the part of a body inside the radar's field of view.

    The body's centre lies ``u`` [m] along the road in columns ``lo:hi`` of ``roads`` (its
    lane frame there ``lane``: :func:`._ekf_kernels.lane_at`) and ``d`` [m] across; it spans
    ``BODY_HALF_SPREADS`` times ``spread`` [m] either side of its centre along the lane.
    ``VISIBLE_SAMPLES`` points over it are tested against the field of view (``fields``, the
    radar's minimum range ``radar[4]``). Returns ``(offset, spread, slope, out)``: the
    visible part's centre along the lane from the body's centre [m], its spread [m] (the
    body's, in proportion to the part's length), ``d offset / d u`` (-1/2 when one end is cut:
    the cut stays put while the body moves; -1 when both are), and whether the body is known
    to lie wholly out of view (then its centre, the point its detection is predicted at, is
    out of view too). A body wholly in view, or wholly out of it, gives
    ``(0, spread, 0, out)``.
    """
    half = BODY_HALF_SPREADS * spread
    uniform = _view_uniform(lane, d, half, radar, fields)
    if uniform != 0:
        return 0.0, spread, 0.0, uniform < 0
    n_in, total = 0, 0.0
    first_in = last_in = False
    for k in range(VISIBLE_SAMPLES):
        a = half * (2.0 * k / (VISIBLE_SAMPLES - 1) - 1.0)
        cx, cy, th, _ = centreline_span(roads, lo, hi, u + a)
        ex = cx - d * math.cos(th) - radar[0]
        ey = cy + d * math.sin(th) - radar[1]
        rng = math.sqrt(ex * ex + ey * ey + radar[2] * radar[2])
        if in_view(rng, off_boresight(math.atan2(ex, ey), radar), fields, radar[4]):
            n_in += 1
            total += a
            first_in |= k == 0
            last_in |= k == VISIBLE_SAMPLES - 1
    if n_in == 0 or n_in == VISIBLE_SAMPLES:
        return 0.0, spread, 0.0, False
    slope = -0.5 if first_in != last_in else (-1.0 if not first_in else 0.0)
    return total / n_in, spread * n_in / VISIBLE_SAMPLES, slope, False


@numba.njit(cache=True, inline="always")
def _model(  # type: ignore[no-untyped-def]
    i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields, across_std,
    xv, zp, h, rm, jp, jv, visible, lane,
):  # fmt: skip
    """Predicted detection, Jacobian and noise of track ``i`` (body spread along and across).

    A body partly outside the field of view is detected over its visible part only
    (``visible``: :func:`_visible_part` of the track): the detection is predicted at that
    part's centre, with its spread. ``lane``: the lane frame at the track's ``u``. ``xv``
    (4,): scratch; it holds the state at the visible part's centre after the call. Returns the
    visible part's spread [m] and the corridor's centreline point and unit tangent there
    (``cx, cy, tx, ty``).
    """
    lo, hi = bounds[corridor[i], 0], bounds[corridor[i], 1]
    offset, part_spread, slope, _ = visible
    for a in range(N_STATE):
        xv[a] = x[i, a]
    xv[0] += offset
    if offset == 0.0:  # at the track's u
        cx, cy, tx, ty = road_measure(
            xv, 3, radar, noise_tab, noise_cnt, lane, 0.0, part_spread, zp, h, rm, jp, jv
        )
    else:
        cx, cy, tx, ty = measure_span(
            ROAD, xv, 3, radar, noise_tab, noise_cnt, roads, lo, hi, 0.0, part_spread, zp, h,
            rm, jp, jv,
        )  # fmt: skip
    for a in range(3):
        h[a, 0] *= 1.0 + slope
    rx, ry = -ty, tx
    b0 = jp[0, 0] * rx + jp[0, 1] * ry
    b1 = jp[1, 0] * rx + jp[1, 1] * ry
    b2 = jp[2, 0] * rx + jp[2, 1] * ry
    bb = (b0, b1, b2)
    s2 = across_std * across_std
    for a in range(3):
        for c in range(3):
            rm[a, c] += s2 * bb[a] * bb[c]
    return part_spread, cx, cy, tx, ty


@numba.njit(cache=True)
def detections_in_view(z, radar, fields):  # type: ignore[no-untyped-def]
    """Whether each detection (range, azimuth, ...) of ``z`` (n, 3) lies in the radar's view."""
    seen = np.zeros(z.shape[0], dtype=np.bool_)
    for j in range(z.shape[0]):
        seen[j] = in_view(z[j, 0], off_boresight(z[j, 1], radar), fields, radar[4])
    return seen


@numba.njit(cache=True, inline="always")
def bodies_overlap(x, spread, a, b):  # type: ignore[no-untyped-def]
    """Whether the bodies of tracks ``a`` and ``b`` (``BODY_HALF_SPREADS`` spreads) overlap."""
    return abs(x[a, 0] - x[b, 0]) < BODY_HALF_SPREADS * (spread[a] + spread[b])


@numba.njit(cache=True)
def confirmed_rows(  # type: ignore[no-untyped-def]
    confirmed, time_s, last_hit_s, stopped, moved, x, spread, corridor, lateral_m, coasting_s,
    codes,
):  # fmt: skip
    """Rows of the confirmed tracks and their status codes.

    ``codes``: the codes of confirmed, coasting (no detection for more than ``coasting_s``
    [s]), stopped, static (stopped, never moved) and tentative. A confirmed track that has not
    moved yet and lies on the body of an established track (one that has moved or stopped) of
    its corridor (within ``lateral_m`` across, ``BODY_HALF_SPREADS`` spreads either side
    along) is reported tentative: most such tracks are a body's far reflections or a ghost,
    which :func:`merged_rows` drops once they have moved; one that outlives that test is
    another road user.
    """
    rows = rows_where(confirmed, True)
    status = np.empty(rows.size, np.int64)
    for k in range(rows.size):
        i = rows[k]
        if stopped[i]:
            status[k] = codes[2] if moved[i] else codes[3]
            continue
        status[k] = codes[1] if time_s[i] - last_hit_s[i] > coasting_s else codes[0]
        if moved[i]:
            continue
        for j in rows:
            if (
                j != i and (moved[j] or stopped[j]) and corridor[j] == corridor[i]
                and abs(x[i, 3] - x[j, 3]) < lateral_m
                and bodies_overlap(x, spread, i, j)
            ):  # fmt: skip
                status[k] = codes[4]
                break
    return rows, status


@numba.njit(cache=True, inline="always")
def _whitened_square(lo, w):  # type: ignore[no-untyped-def]
    """Squared norm of ``lo^-1 w`` (``lo`` lower triangular, 3 x 3); ``w`` is overwritten."""
    acc = 0.0
    for a in range(3):
        v = w[a]
        for c in range(a):
            v -= lo[a, c] * w[c]
        w[a] = v / lo[a, a]
        acc += w[a] * w[a]
    return acc


@numba.njit(cache=True, inline="always")
def _store_view(  # type: ignore[no-untyped-def]
    views, i, gated, seen, logdet, usable, doppler, zp, lo, s00, px, py, tx, ty, half
):  # fmt: skip
    """Store track ``i``'s view of the radar as :func:`gate_scan` made it, in ``views[i]``.

    For a frozen track (learnt clutter: neither predicted nor updated) it is the same at every
    scan of the radar. Layout (``CLUTTER_VIEW`` values): 1 (stored), ``gated[i]`` (9), seen,
    log det S, usable (S factored), Doppler usable, the predicted detection (3), the lower
    Cholesky factor of S (6), ``S_rr``, the body's centre point (2), the lane's tangent (2)
    and the body's half length.
    """
    v = views[i]
    v[0] = 1.0
    for c in range(9):
        v[1 + c] = gated[i, c]
    v[10], v[11] = 1.0 if seen else 0.0, logdet
    v[12], v[13] = 1.0 if usable else 0.0, 1.0 if doppler else 0.0
    v[14], v[15], v[16] = zp[0], zp[1], zp[2]
    v[17], v[18], v[19] = lo[0, 0], lo[1, 0], lo[1, 1]
    v[20], v[21], v[22] = lo[2, 0], lo[2, 1], lo[2, 2]
    v[23], v[24], v[25], v[26], v[27], v[28] = s00, px, py, tx, ty, half


@numba.njit(cache=True, inline="always")
def _stored_view(views, i, gated, seen, logdet, zp, lo):  # type: ignore[no-untyped-def]
    """Restore track ``i``'s view stored by :func:`_store_view`.

    Sets its ``gated`` row, ``seen``, ``logdet``, ``zp`` and ``lo``; returns ``(usable,
    doppler, S_rr, px, py, tx, ty, half)``.
    """
    v = views[i]
    for c in range(9):
        gated[i, c] = v[1 + c]
    seen[i], logdet[i] = v[10] != 0.0, v[11]
    zp[0], zp[1], zp[2] = v[14], v[15], v[16]
    lo[0, 0], lo[1, 0], lo[1, 1] = v[17], v[18], v[19]
    lo[2, 0], lo[2, 1], lo[2, 2] = v[20], v[21], v[22]
    return v[12] != 0.0, v[13] != 0.0, v[23], v[24], v[25], v[26], v[27], v[28]


@numba.njit(cache=True)
def gate_scan(  # type: ignore[no-untyped-def]
    x, p, spread, starting, road_user, moving, occluder, direction, corridor, roads, bounds,
    radar, noise_tab, noise_cnt, fields, across_std, start_speed_max, extent_gate,
    passing_gate, beside_m, gate, z, d2, logdet, gated, clutter, views,
):  # fmt: skip
    """Fill ``d2`` (T, D) with each detection's squared Mahalanobis distance to each track.

    ``clutter`` rows are frozen (:func:`update_tracks`): their view of the radar (visible
    part, predicted detection, factored innovation covariance) is stored in ``views`` (T,
    ``CLUTTER_VIEW``) the first time and read back after (:func:`_store_view`).

    ``logdet`` (T,) receives the log-determinant of each track's innovation covariance
    (``inf`` where ``d2`` is). ``gated`` (T, 9) holds each track's lane frame at its ``u`` in
    columns 4:9 (:func:`._ekf_kernels.lane_at`) and receives its :func:`_visible_part` in
    columns 0:4 (the flag as 0 / 1), for its update (:func:`update_tracks`).
    A body's reflections lie on it: with ``extent_gate``, a detection that lies on a road
    user's body (a ``road_user`` track: confirmed, it has moved; within ``BODY_HALF_SPREADS``
    of its spreads along the lane from its centre, and within ``gate``) costs a track whose
    (visible) body ends before it the excess squared over the variance of its along-lane
    position (the sensor's range and azimuth noise projected on the lane, and the track's):
    the Gaussian body model's tail would otherwise reach into the next body of a queue. A
    detection on no body is left as it is (a long vehicle's far reflections are how its track
    learns its spread), except by a stopped road user (``starting``), whose spread is not
    learnt while it stands: such a detection costs it the excess all the same (a queued bus
    whose own reflections are missed in a scan would take the rear reflections of the truck
    ahead that fall between the two tracks' bodies). A track hidden behind a road user
    (``occluder``: the row of the nearer road user on its line of sight, -1 none) is seen, if
    at all, over its own body past the occluder: a detection in the occluder's gate that lies
    beyond the hidden track's body is the occluder's (the hidden track's ``d2`` is ``inf``; a
    car queued behind a bus would otherwise creep onto the bus's rear reflections, the
    nearest in its gate).
    A stopped vehicle may be starting (``starting`` rows): its held zero speed is replaced by
    the speed in ``[0, start_speed_max]`` along its ``direction`` that best explains the
    detection's radial speed (a road user passing by in the other direction does not fit).
    With ``passing_gate``, a detection in the gate of a road user moving beside it (a
    ``moving`` row on its corridor, ``beside_m`` [m] or more across)
    starts no stopped track: it keeps its held zero speed for it (a motorcycle in a queue
    whose own reflection is missed would otherwise take the next reflection of a car driving
    past it, and follow the car).
    Rows of tracks whose predicted detection lies outside
    the radar's view are ``inf``; returns whether each track is in view (T,).
    """
    n_t, n_d = x.shape[0], z.shape[0]
    seen = np.zeros(n_t, dtype=np.bool_)
    # buffers passed per track: on the stack
    zp, h, rm, jp, jv = _model_scratch()
    xv, s, lo = on_stack(N_STATE), on_stack((3, 3)), on_stack((3, 3))
    w, w0 = on_stack(3), on_stack(3)
    ground = np.zeros((n_d, 6))  # ground point, sight line, range and cross variances
    for j in range(n_d):
        gx, gy, rho = _ground_point(z[j], radar)
        sr = curve_at(noise_tab, noise_cnt, 0, z[j, 0])
        sa = rho * curve_at(noise_tab, noise_cnt, 1, off_boresight(z[j, 1], radar))
        ground[j, 0], ground[j, 1] = gx, gy
        ground[j, 2], ground[j, 3] = math.sin(z[j, 1]), math.cos(z[j, 1])
        ground[j, 4], ground[j, 5] = sr * sr, sa * sa
    penalty = np.zeros((n_t, n_d))  # beyond the body's end along the lane (see above)
    held = np.full((n_t, n_d), np.inf)  # a starting row's d2 at its held zero speed
    for i in range(n_t):
        logdet[i] = np.inf
        if clutter[i] and views[i, 0] == 1.0:  # a frozen track: its view of this radar, stored
            usable, doppler, s00, px, py, tx, ty, half = _stored_view(
                views, i, gated, seen, logdet, zp, lo
            )
        else:
            usable, doppler, s00, px, py, tx, ty, half = False, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            cx = cy = part_spread = 0.0
            lo_i, hi_i = bounds[corridor[i], 0], bounds[corridor[i], 1]
            lane = gated[i, 4], gated[i, 5], gated[i, 6], gated[i, 7], gated[i, 8]
            part = _visible_part(
                x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane
            )
            gated[i, 0], gated[i, 1], gated[i, 2], gated[i, 3] = part
            if not part[3]:  # else wholly out of view, its predicted detection too (not seen)
                part_spread, cx, cy, tx, ty = _model(
                    i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields,
                    across_std, xv, zp, h, rm, jp, jv, part, lane,
                )  # fmt: skip
                seen[i] = in_view(zp[0], off_boresight(zp[1], radar), fields, radar[4])
            if seen[i]:
                doppler = doppler_usable(h, p[i], rm, radar)
                for a in range(3):
                    for b in range(3):
                        acc = rm[a, b]
                        for c in range(N_STATE):
                            for e in range(N_STATE):
                                acc += h[a, c] * p[i, c, e] * h[b, e]
                        s[a, b] = acc
                usable = cholesky_into(s, lo)
            if usable:
                logdet[i] = 2.0 * (math.log(lo[0, 0]) + math.log(lo[1, 1]) + math.log(lo[2, 2]))
                s00 = s[0, 0]
                px, py = cx - xv[3] * ty, cy + xv[3] * tx
                half = BODY_HALF_SPREADS * part_spread
            if clutter[i]:
                _store_view(
                    views, i, gated, seen[i], logdet[i], usable, doppler, zp, lo, s00, px, py,
                    tx, ty, half,
                )  # fmt: skip
        if not usable or n_d == 0:
            d2[i, :] = np.inf
            continue
        for j in range(n_d):
            wr = z[j, 0] - zp[0]  # range alone: d2 >= wr^2 / S_rr (start fitting keeps wr)
            if wr * wr > gate * s00:
                d2[i, j] = np.inf  # beyond the gate; no penalty: every use compares to it
                continue
            innovation_into(z[j], zp, radar, doppler, w)
            if starting[i] and passing_gate:
                w0[:] = w
                held[i, j] = _whitened_square(lo, w0)
            if starting[i] and h[2, 1] != 0.0:
                v = min(max(direction[i] * w[2] / h[2, 1], 0.0), start_speed_max)
                for a in range(3):
                    w[a] -= h[a, 1] * direction[i] * v
            d2[i, j] = _whitened_square(lo, w)
            along = (ground[j, 0] - px) * tx + (ground[j, 1] - py) * ty
            excess = abs(along) - half
            if excess > 0.0:
                c = ground[j, 2] * tx + ground[j, 3] * ty
                var = ground[j, 4] * c * c + ground[j, 5] * (1.0 - c * c) + p[i, 0, 0]
                penalty[i, j] = excess * excess / var
    if passing_gate:
        for j in range(n_d):
            for i in range(n_t):
                if not starting[i] or d2[i, j] >= held[i, j]:
                    continue
                for k in range(n_t):
                    if (
                        moving[k] and d2[k, j] <= gate and corridor[k] == corridor[i]
                        and abs(x[k, 3] - x[i, 3]) >= beside_m
                    ):  # fmt: skip
                        d2[i, j] = held[i, j]
                        break
    hidden = np.zeros((n_t, n_d), dtype=np.bool_)
    for i in range(n_t):
        k = occluder[i]
        if k >= 0:
            for j in range(n_d):
                hidden[i, j] = d2[k, j] <= gate and penalty[i, j] > 0.0
    for i in range(n_t):
        for j in range(n_d):
            if hidden[i, j]:
                d2[i, j] = np.inf
    if extent_gate:
        for j in range(n_d):
            on_a_body = False
            for i in range(n_t):
                on_a_body |= road_user[i] and d2[i, j] <= gate and penalty[i, j] == 0.0
            for i in range(n_t):
                if on_a_body or starting[i]:
                    d2[i, j] += penalty[i, j]
    return seen


@numba.njit(cache=True)
def reserve_clutter(d2, clutter, clutter_gate):  # type: ignore[no-untyped-def]
    """Give the detections within ``clutter_gate`` of a ``clutter`` row to clutter alone.

    The other rows of ``d2`` (T, D) are set to ``inf`` for them, in place; nothing changes
    when no row, or every row, is clutter.
    """
    n_t, n_d = d2.shape
    n_clutter = 0
    for i in range(n_t):
        n_clutter += clutter[i]
    if n_clutter == 0 or n_clutter == n_t:
        return
    for j in range(n_d):
        mine = False
        for i in range(n_t):
            mine |= clutter[i] and d2[i, j] <= clutter_gate
        if mine:
            for i in range(n_t):
                if not clutter[i]:
                    d2[i, j] = np.inf


@numba.njit(cache=True)
def favour_sensor_ids(d2, sensor_id, ids, bonus, gate):  # type: ignore[no-untyped-def]
    """Take ``bonus`` off gated ``d2`` (T, D) where a detection's id ``ids`` (D,) is a track's.

    ``sensor_id`` (T,): the id the radar last gave each track; -1 is no id. In place, not
    below 0.
    """
    for j in range(ids.size):
        if ids[j] >= 0:
            for i in range(sensor_id.size):
                if sensor_id[i] == ids[j] and d2[i, j] <= gate:
                    d2[i, j] = max(d2[i, j] - bonus, 0.0)


@numba.njit(cache=True)
def associate_scan(  # type: ignore[no-untyped-def]
    x, p, spread, stopped, moved, confirmed, clutter, direction, corridor, sensor_id, roads,
    bounds, radar, noise_tab, noise_cnt, fields, across_std, start_speed_max, extent_gate,
    occlusion_gate, passing_gate, beside_m, gate, clutter_gate, id_bonus, z, ids, views,
):  # fmt: skip
    """Gate a scan's detections ``z`` (D, 3) to the predicted tracks; try the simple assignment.

    In a standing queue a stopped track's gate is narrowed behind the stopped road user that
    hides it (with ``occlusion_gate``; :func:`nearer_occluders`, :func:`gate_scan`). A detection in
    ``clutter_gate`` of an old static object (``clutter`` rows: never moved, older than the
    clutter age) is its reflection alone (the other rows' ``d2`` set to ``inf``: a road user
    passing over a barrier post would take it and leave a track behind on it:
    :func:`reserve_clutter`; their stored views of the radar: ``views``, see
    :func:`gate_scan`). With ``id_bonus`` > 0, a gated detection whose sensor id
    (``ids`` (D,), -1 none) is the one this radar last gave a track (``sensor_id`` (T,))
    costs that much less (:func:`favour_sensor_ids`).
    Returns ``(seen, d2, logdet, gated, simple, tracks, detections, sight)``: each track in
    view, distances (T, D), log-determinants (T,), visible parts and lane frames (T, 9)
    (:func:`gate_scan`),
    if ``simple`` the
    one-to-one assignment (:func:`unambiguous_assignment`), and the tracks' lines of sight
    if the occlusion gate computed them (:func:`sight_lines`: when a road user stands, of the
    queued tracks and the road users, NaN rows for the rest; else no rows).
    """
    n_t, n_d = x.shape[0], z.shape[0]
    d2 = np.empty((n_t, n_d))
    logdet = np.empty(n_t)
    gated = np.empty((n_t, 9))  # visible parts (gate_scan) and lane frames of the tracks
    lanes = gated[:, 4:]
    for i in range(n_t):
        if clutter[i] and views[i, 0] == 1.0:  # stored (gate_scan)
            for c in range(5):
                lanes[i, c] = views[i, 5 + c]
        else:
            _store_lane(lanes, i, roads, bounds, corridor, x)
    road_user = np.empty(n_t, np.bool_)
    starting = np.empty(n_t, np.bool_)  # stopped road users (may start: gate_scan)
    moving = np.empty(n_t, np.bool_)  # moving road users
    standing = False
    for i in range(n_t):
        road_user[i] = moved[i] and confirmed[i]
        starting[i] = stopped[i] and moved[i]
        moving[i] = road_user[i] and not stopped[i]
        standing |= stopped[i] and road_user[i]
    behind = np.full(n_t, -1, dtype=np.int64)  # the stopped road user hiding a queued track
    sight = np.zeros((0, 3))  # the tracks' lines of sight, if needed (:func:`sight_lines`)
    if occlusion_gate and standing:
        queued = rows_where(stopped, True)
        # of the queued tracks and the road users (the rest NaN: not needed here)
        sight = np.full((n_t, 3), np.nan)
        sight_lines(np.flatnonzero(stopped | road_user), x, spread, lanes, radar, sight)
        nearest = nearer_occluders(queued, x, spread, corridor, sight, road_user)
        for k in range(queued.size):
            if nearest[k] >= 0 and stopped[nearest[k]]:  # else the nearest is moving
                behind[queued[k]] = nearest[k]
    seen = gate_scan(
        x, p, spread, starting, road_user, moving, behind, direction,
        corridor, roads, bounds, radar, noise_tab, noise_cnt, fields, across_std,
        start_speed_max, extent_gate, passing_gate, beside_m, gate, z, d2, logdet, gated,
        clutter, views,
    )  # fmt: skip
    if n_d == 0:
        none = np.zeros(0, np.int64)
        return seen, d2, logdet, gated, True, none, none, sight
    reserve_clutter(d2, clutter, clutter_gate)
    if id_bonus != 0.0:
        favour_sensor_ids(d2, sensor_id, ids, id_bonus, gate)
    simple, tracks, dets = unambiguous_assignment(d2, gate)
    return seen, d2, logdet, gated, simple, tracks, dets, sight


@numba.njit(cache=True)
def apply_scan(  # type: ignore[no-untyped-def]
    time_s, seen, clutter, d2, logdet, gated, sight, gate, tracks, dets, z, ids, radar_col, x, p,
    spread, along_m2, along_m4, stopped, moved, direction, slow_since, corridor, miss_run, occluded,
    anchor_u, doppler_seen_s, detection_d, sensor_id, history, misses, last_hit_s, confirmed, roads,
    bounds, radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt, across_std, moving_radial,
    start_speed_var, learning_rate, shape_rate, spread_lo, spread_hi, align, lane_half_width, bias,
    bias_stats, bias_forget, bias_gate, confirm_speed_var, window_mask, confirm_hits, shadow_spread,
):  # fmt: skip
    """Update the tracks with a gated scan (:func:`associate_scan`, its ``gated``, ``sight``).

    Every gated detection goes to its owner (:func:`owners`: the assignment's, then the likeliest
    track) and updates it (:func:`update_tracks`, which sets ``doppler_seen_s``; ``clutter``
    rows stay as they are); the assigned
    detection's sensor id becomes its track's (column ``radar_col`` of ``sensor_id``). A track
    in view without a detection is hidden if a nearer track covers it (:func:`nearer_occluders`; its
    miss tells nothing), else takes what the miss tells (:func:`miss_updates`, moving ones). A
    static object (stopped, never moved) whose spread is below ``shadow_spread`` [m] hides
    nothing: a post, a barrier arm or a rail is thin or low, and the radar sees past it (a
    false alarm behind a post near the radar would otherwise keep a tentative track for
    seconds, its misses telling nothing).
    Tracks in view and not hidden record the hit or miss in the track book's arrays
    (:func:`adaptrack.tracking.lifecycle.record_hits`; confirmed once their speed variance is
    below ``confirm_speed_var``), and one confirmed now anchors where it is. A moving body
    whose spread is below ``shadow_spread`` [m] (a car: the radar on its pole sees over it)
    casts no radar shadow over a tentative track behind it on its corridor that moves with
    it (within ``GHOST_SPEED_MPS``): that track's miss counts against its confirmation,
    though not towards its deletion (a multipath ghost lies behind the body that made it,
    moves with it, and is seen rarely). Returns which
    detections were used (D,).
    """
    n_t, n_d = d2.shape
    used = np.zeros(n_d, dtype=np.bool_)
    hit = np.zeros(n_t, dtype=np.bool_)
    if n_d:
        owner, order = owners(d2, logdet, gate, tracks, dets)
        update_tracks(
            time_s, order, owner, clutter, gated, z, x, p, spread, along_m2, along_m4, stopped,
            moved, direction, slow_since, doppler_seen_s, detection_d, corridor, roads, bounds,
            radar, noise_tab, noise_cnt, fields, across_std, moving_radial, start_speed_var,
            learning_rate, shape_rate, spread_lo, spread_hi, align, lane_half_width, bias,
            bias_stats, bias_forget, bias_gate,
        )  # fmt: skip
        for j in order:
            used[j] = True
            hit[owner[j]] = True
        for k in range(tracks.size):
            sensor_id[tracks[k], radar_col] = ids[dets[k]]  # its own, not a body's other
    for i in range(n_t):
        if hit[i]:
            miss_run[i] = 1.0
    missed = _rows_and_not(seen, hit)
    nearer = np.full(missed.size, -1, np.int64)
    if missed.size:  # lines of sight after the updates: those of the updated tracks anew
        lanes = gated[:, 4:]
        for i in range(n_t):
            if hit[i] and not clutter[i]:  # a frozen track's stays
                _store_lane(lanes, i, roads, bounds, corridor, x)
        if sight.shape[0] == n_t:
            stale = np.empty(n_t, np.int64)
            m = 0
            for i in range(n_t):
                if hit[i] or math.isnan(sight[i, 0]):
                    stale[m] = i
                    m += 1
            sight_lines(stale[:m], x, spread, lanes, radar, sight)
        else:
            sight = np.zeros((n_t, 3))
            sight_lines(np.arange(n_t), x, spread, lanes, radar, sight)
        can_hide = np.empty(n_t, np.bool_)  # a static object shorter than a truck: none
        for i in range(n_t):
            can_hide[i] = moved[i] or not stopped[i] or spread[i] >= shadow_spread
        nearer = nearer_occluders(missed, x, spread, corridor, sight, can_hide)
    for i in range(n_t):
        if hit[i]:
            occluded[i] = False
    moving_missed = np.zeros(missed.size, np.int64)
    m = 0
    for k in range(missed.size):
        i = missed[k]
        occluded[i] = nearer[k] >= 0
        o = nearer[k]
        if (
            o >= 0 and not confirmed[i] and not stopped[o] and spread[o] < shadow_spread
            and corridor[o] == corridor[i] and abs(x[i, 1] - x[o, 1]) < GHOST_SPEED_MPS
        ):  # fmt: skip
            history[i] = (history[i] << 1) & window_mask  # no shadow: the miss counts
        if not occluded[i] and not stopped[i]:
            moving_missed[m] = i
            m += 1
    miss_updates(
        moving_missed[:m], x, p, spread, miss_run, corridor, roads, bounds, radar, noise_tab,
        noise_cnt, fields, pd_tab, pd_cnt,
    )  # fmt: skip
    rows = _rows_and_not(seen, occluded)
    ready, row_hit = np.empty(rows.size, np.bool_), np.empty(rows.size, np.bool_)
    for k in range(rows.size):
        ready[k] = p[rows[k], 1, 1] < confirm_speed_var
        row_hit[k] = hit[rows[k]]
    now = record_hits(
        history, misses, last_hit_s, confirmed, rows, row_hit, time_s, ready, window_mask,
        confirm_hits,
    )  # fmt: skip
    for i in now:
        anchor_u[i] = x[i, 0]
    return used


@numba.njit(cache=True)
def owners(d2, logdet, gate, primary_track, primary_det):  # type: ignore[no-untyped-def]
    """Owner track of every detection (-1: none) and the update order.

    ``primary_track``/``primary_det`` is the one-to-one assignment; every further gated
    detection joins the track most likely to have made it (a body's other reflections):
    least ``d2 + logdet``, the negative log-likelihood up to a constant, not least ``d2``
    alone, which favours the wider track (in a queue, a car whose gate has grown over a
    truck's rear would take the truck's detections). The order processes each track's
    detections by increasing distance.
    """
    n_t, n_d = d2.shape
    owner = np.full(n_d, -1, dtype=np.int64)
    for k in range(primary_det.size):
        owner[primary_det[k]] = primary_track[k]
    for j in range(n_d):
        if owner[j] >= 0:
            continue
        best, arg = np.inf, -1
        for i in range(n_t):
            if d2[i, j] <= gate and d2[i, j] + logdet[i] < best:
                best, arg = d2[i, j] + logdet[i], i
        owner[j] = arg
    dist = np.full(n_d, np.inf)
    for j in range(n_d):
        if owner[j] >= 0:
            dist[j] = d2[owner[j], j]
    order = np.argsort(dist, kind="mergesort")
    count = 0
    for j in range(n_d):
        if owner[j] >= 0:
            count += 1
    return owner, order[:count]


@numba.njit(cache=True)
def unambiguous_assignment(d2, gate):  # type: ignore[no-untyped-def]
    """Return the one-to-one assignment if no detection lies in two tracks' gates.

    ``(True, tracks, detections)``, or ``(False, empty, empty)`` when there is a conflict.

    Without shared detections each track's nearest gated detection is the globally cheapest
    assignment (what ``gnn_assign`` would return); otherwise the caller solves it.
    """
    n_t, n_d = d2.shape
    for j in range(n_d):
        k = 0
        for i in range(n_t):
            if d2[i, j] <= gate:
                k += 1
        if k > 1:
            return False, np.zeros(0, np.int64), np.zeros(0, np.int64)
    tracks = np.zeros(n_t, np.int64)
    dets = np.zeros(n_t, np.int64)
    m = 0
    for i in range(n_t):
        best, arg = np.inf, -1
        for j in range(n_d):
            if d2[i, j] <= gate and d2[i, j] < best:
                best, arg = d2[i, j], j
        if arg >= 0:
            tracks[m], dets[m] = i, arg
            m += 1
    return True, tracks[:m], dets[:m]


@numba.njit(cache=True)
def update_tracks(  # type: ignore[no-untyped-def]
    time_s, order, owner, clutter, gated, z, x, p, spread, along_m2, along_m4, stopped, moved,
    direction, slow_since, doppler_seen_s, detection_d, corridor, roads, bounds, radar, noise_tab,
    noise_cnt, fields, across_std, moving_radial, start_speed_var, learning_rate, shape_rate,
    spread_lo, spread_hi, align, lane_half_width, bias, bias_stats, bias_forget, bias_gate,
):  # fmt: skip
    """Update each owning track with its detections in ``order`` (sequential EKF updates).

    ``clutter`` rows (learnt static clutter: :func:`._scene_loop.learnt_clutter`) are frozen:
    after standing longer than any closure, a post's or a rail's place and body are known, and
    its detections only need to be its own (:func:`reserve_clutter`); they are not updated
    (nor predicted: :func:`predict_tracks`), which leaves its gate as it is.

    ``gated`` (T, 9): the tracks' visible parts and lane frames as gated (:func:`gate_scan`),
    those of a track not updated since.

    Azimuth alignment (if ``align``): before its update, a detection of a moving track
    (``moved``, not stopped, ``direction`` known, faster than ``BIAS_MIN_SPEED_MPS``) is
    compared with the centre of the lane it drives in (``lane_half_width`` per corridor to the
    right of travel): its offset across the lane ``lat`` is ``g b`` for an azimuth bias ``b``,
    with ``g`` the offset's derivative with respect to the azimuth. Least squares over the
    detections (the ``bias`` already taken off added back) accumulate in ``bias_stats`` =
    [sum g^2, sum g lat, count] with forgetting factor ``bias_forget`` per detection; a
    detection further than ``bias_gate`` [m] across from the lane centre (another lane, a
    footway) is left out.

    A detection whose radial speed exceeds ``moving_radial`` along the vehicle's ``direction``,
    and measures the speed along the lane (as below), ends the stop of a vehicle that had
    moved (speed and acceleration freed with variance ``start_speed_var``; static objects
    stay): seen across the line of sight, a road user passing beside the queue would start
    it; the body spread follows a moving average (rate ``learning_rate``) of the squared
    along-track residual less the sensor's and the track's share, within ``[spread_lo,
    spread_hi]``, learnt while the whole body is in view and the road user is not stopped
    (queued bodies touch: a neighbour's reflections would stretch it, and its gate with it);
    the second and fourth moments of the along-track residual (``along_m2``, ``along_m4``,
    rate ``shape_rate``: see :func:`split_rows`) are learnt while the whole body is in view,
    stopped or not. A detection whose radial speed measures
    the speed along the lane (the line of sight to its own ground point at least
    ``GATE_MIN_COS`` along the lane, its alias known; not the track's point: a body's
    detection may lie metres away, across the line of sight) sets the track's
    ``doppler_seen_s`` to ``time_s``: it shows whether the road user stands. ``detection_d``
    follows the detections' own offset across the lane (a moving average, rate
    ``DETECTION_D_RATE``; NaN before the first): where its reflections lie, not where the
    track's state says.
    """
    # buffers passed per detection: on the stack
    zp, h, rm, jp, jv = _model_scratch()
    hp, s, lo, kt, w, ikh, tmp, xn, pn = _update_scratch(3)
    xv, nu = on_stack(N_STATE), on_stack(3)
    as_gated = np.ones(gated.shape[0], np.bool_)  # the state the gate saw (gated holds)
    for j in order:
        i = owner[j]
        if clutter[i]:
            continue
        # body spread: along-track residual of the detection's ground point
        lo_i, hi_i = bounds[corridor[i], 0], bounds[corridor[i], 1]
        if as_gated[i]:
            lane = gated[i, 4], gated[i, 5], gated[i, 6], gated[i, 7], gated[i, 8]
        else:
            lane = lane_at(roads, lo_i, hi_i, x[i, 0])
        cx, cy, _, tx, ty = lane
        px, py = cx - x[i, 3] * ty, cy + x[i, 3] * tx
        gx, gy, rho = _ground_point(z[j], radar)
        along = (gx - px) * tx + (gy - py) * ty
        across = (gx - cx) * -ty + (gy - cy) * tx  # the detection's offset (as x[i, 3])
        if math.isnan(detection_d[i]):
            detection_d[i] = across
        else:
            detection_d[i] += DETECTION_D_RATE * (across - detection_d[i])
        fast = abs(x[i, 1]) >= BIAS_MIN_SPEED_MPS
        if align and moved[i] and not stopped[i] and direction[i] != 0.0 and fast:
            # across the lane only (the body's extent along it says nothing on the bias)
            centre = -direction[i] * lane_half_width[corridor[i]]
            nx, ny = -ty, tx
            lat = (gx - (cx + centre * nx)) * nx + (gy - (cy + centre * ny)) * ny
            g = rho * (math.cos(z[j, 1]) * nx - math.sin(z[j, 1]) * ny)  # d lat / d azimuth
            if abs(lat) <= bias_gate:
                bias_stats[0] = bias_forget * bias_stats[0] + g * g
                bias_stats[1] = bias_forget * bias_stats[1] + g * (lat + bias * g)
                bias_stats[2] = bias_forget * bias_stats[2] + 1.0
        sr = curve_at(noise_tab, noise_cnt, 0, z[j, 0])
        sa = curve_at(noise_tab, noise_cnt, 1, off_boresight(z[j, 1], radar))
        if as_gated[i]:
            part = gated[i, 0], gated[i, 1], gated[i, 2], gated[i, 3] != 0.0
        else:
            part = _visible_part(
                x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane
            )
        was_spread = spread[i]
        if part[0] == 0:  # the whole body in view
            if not (stopped[i] and moved[i]):
                sample = max(along * along - sr * sr - (rho * sa) ** 2 - p[i, 0, 0], 0.0)
                var = (1.0 - learning_rate) * spread[i] ** 2 + learning_rate * sample
                spread[i] = math.sqrt(min(max(var, spread_lo**2), spread_hi**2))
            along_m2[i] += shape_rate * (along * along - along_m2[i])
            along_m4[i] += shape_rate * (along**4 - along_m4[i])
        if spread[i] != was_spread:
            part = _visible_part(
                x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane
            )
        _model(  # over the part in view of its body as learnt now
            i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields,
            across_std, xv, zp, h, rm, jp, jv, part, lane,
        )  # fmt: skip
        doppler = doppler_usable(h, p[i], rm, radar)
        innovation_into(z[j], zp, radar, doppler, nu)
        # the radial speed of the detection's own point measures the speed along the lane
        los = ((gx - radar[0]) * tx + (gy - radar[1]) * ty) / z[j, 0]
        measures_speed = doppler and abs(los) >= GATE_MIN_COS
        if measures_speed:
            doppler_seen_s[i] = time_s
        if (
            stopped[i] and moved[i] and measures_speed and abs(z[j, 2]) > moving_radial
            and direction[i] * z[j, 2] * h[2, 1] > 0.0
        ):  # fmt: skip
            stopped[i] = False
            slow_since[i] = np.nan
            p[i, 1, 1] += start_speed_var
            p[i, 2, 2] += start_speed_var
        ok, _, _ = update_into(x[i], p[i], nu, h, rm, True, xn, pn, hp, s, lo, kt, w, ikh, tmp)
        as_gated[i] = False
        if ok:
            x[i] = xn
            p[i] = pn
            if stopped[i]:
                x[i, 1] = x[i, 2] = 0.0


@numba.njit(cache=True)
def split_rows(stopped, moved, along_m2, along_m4, kurtosis_max, min_half_gap):  # type: ignore[no-untyped-def]
    """Find the stopped road users whose reflections come from two bodies, and the bodies.

    Reflections of one body scatter about its centre (a kurtosis ``m4 / m2^2`` of about 2-3;
    a uniform body's is 1.8); two bodies in a queue under one track give two clusters at
    ``+-a`` (kurtosis below ``kurtosis_max``). Moments of a symmetric two-body mixture with
    spread ``s`` each: ``m2 = a^2 + s^2``, ``m4 - 3 m2^2 = -2 a^4``. Returns the rows, ``a``
    and ``s`` [m] of the tracks (``stopped`` and ``moved``: static clutter never splits) with
    ``a >= min_half_gap``.
    """
    rows = np.zeros(0, dtype=np.int64)
    half = np.zeros(0)
    body = np.zeros(0)
    for i in range(stopped.size):
        m2, m4 = along_m2[i], along_m4[i]
        if not (stopped[i] and moved[i] and m4 < kurtosis_max * m2 * m2):
            continue
        a = (0.5 * (3.0 * m2 * m2 - m4)) ** 0.25  # NaN (kurtosis above 3) never passes
        if a >= min_half_gap:
            rows = np.append(rows, i)
            half = np.append(half, a)
            body = np.append(body, math.sqrt(max(m2 - a * a, 0.0)))
    return rows, half, body


@numba.njit(cache=True)
def body_width(length):  # type: ignore[no-untyped-def]
    """Width [m] of a road user ``length`` [m] long (:data:`BODY_WIDTHS_M`, linear between)."""
    if length <= BODY_LENGTHS_M[0]:
        return BODY_WIDTHS_M[0]
    for k in range(1, BODY_LENGTHS_M.size):
        if length <= BODY_LENGTHS_M[k]:
            t = (length - BODY_LENGTHS_M[k - 1]) / (BODY_LENGTHS_M[k] - BODY_LENGTHS_M[k - 1])
            return BODY_WIDTHS_M[k - 1] + t * (BODY_WIDTHS_M[k] - BODY_WIDTHS_M[k - 1])
    return BODY_WIDTHS_M[-1]


@numba.njit(cache=True)
def sight_lines(rows, x, spread, lanes, radar, sight):  # type: ignore[no-untyped-def]
    """Fill ``sight`` (T, 3) rows ``rows``: range, azimuth and apparent half width [m, rad].

    ``lanes`` (T, 5): the tracks' lane frames at their ``u`` (:func:`._ekf_kernels.lane_at`).
    The half width is twice the body spread along the lane's heading and half the width of a
    road user of that length (:data:`BODY_WIDTHS_M`) across, seen from the radar
    (:func:`nearer_occluders`).
    """
    for i in rows:
        cx, cy, tx, ty = lanes[i, 0], lanes[i, 1], lanes[i, 3], lanes[i, 4]
        px, py = cx - x[i, 3] * ty, cy + x[i, 3] * tx
        ex, ey = px - radar[0], py - radar[1]
        rng = math.sqrt(ex * ex + ey * ey)
        ux, uy = ex / max(rng, 1e-9), ey / max(rng, 1e-9)
        half_length = BODY_HALF_SPREADS * spread[i]
        half_width = 0.5 * body_width(2.0 * half_length)
        across = abs(ux * ty - uy * tx) * half_length + abs(ux * tx + uy * ty) * half_width
        sight[i, 0], sight[i, 1] = rng, math.atan2(ex, ey)
        sight[i, 2] = math.atan2(across, max(rng, 1e-9))


@numba.njit(cache=True)
def nearer_occluders(rows, x, spread, corridor, sight, can_hide):  # type: ignore[no-untyped-def]
    """Return the nearer track that may hide each track of ``rows`` from the radar (-1: none).

    ``sight``: the tracks' lines of sight (:func:`sight_lines`). Only tracks with
    ``can_hide`` (bool per track) are taken as occluders. A track hides what lies behind it
    within its apparent half width: twice its body spread along its heading and half its
    width across (:func:`sight_lines`), seen from the radar. It does not hide a track on its
    corridor whose centre lies within its own body (``BODY_HALF_SPREADS`` spreads along): no
    other road user can be there, so that track is a duplicate of its body and its misses
    count. Of several, the nearest to the radar is returned.
    """
    n = x.shape[0]
    out = np.full(rows.size, -1, dtype=np.int64)
    rng, az, half = sight[:, 0], sight[:, 1], sight[:, 2]
    for k in range(rows.size):
        i = rows[k]
        for j in range(n):
            if j == i or rng[j] >= rng[i] or not can_hide[j]:
                continue
            if out[k] >= 0 and rng[j] >= rng[out[k]]:
                continue
            inside = abs(x[i, 0] - x[j, 0]) < BODY_HALF_SPREADS * spread[j]
            if inside and corridor[j] == corridor[i]:
                continue
            d = wrapped(az[i] - az[j], math.pi)
            if abs(d) < half[j]:
                out[k] = j
    return out


@numba.njit(cache=True)
def miss_updates(  # type: ignore[no-untyped-def]
    rows, x, p, spread, miss_run, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields,
    pd_tab, pd_cnt,
):  # fmt: skip
    """Apply what a scan without a detection tells to the tracks in ``rows``.

    :func:`._ekf_kernels.gate_update_into`: a slow vehicle is hidden by the Doppler gate, so a
    run of misses that the gate explains better than ``1 - P_D`` measures a radial speed of
    0 within the gate; ``miss_run`` (T,) is each track's probability of its current run of
    misses for a moving target.
    """
    if rows.size == 0:
        return
    # buffers passed per track: on the stack
    zp, h, rm, jp, jv = _model_scratch()
    hp, s, lo, kt, w, ikh, tmp, xn, pn = _update_scratch(1)
    nu1, r1 = on_stack(1), on_stack((1, 1))
    for i in rows:
        road = roads[:, bounds[corridor[i], 0] : bounds[corridor[i], 1]]
        _, miss_run[i] = gate_update_into(
            ROAD, x[i], p[i], 3, radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt, road,
            0.0, spread[i], miss_run[i], xn, pn, zp, h, rm, jp, jv, hp, s, lo, kt, w, ikh, tmp,
            nu1, r1,
        )  # fmt: skip
        x[i] = xn
        p[i] = pn


@numba.njit(cache=True)
def planar_rows(  # type: ignore[no-untyped-def]
    rows, x, p, corridor, roads, bounds, crossing_u, pos, vel, pos_std, to_cross
):
    """Planar position, velocity, position sigma (trace) and distance to the crossing.

    Of the tracks in ``rows``, written to entry ``k`` for ``rows[k]``.
    """
    for k in range(rows.size):
        i = rows[k]
        d = x[i, 3]
        _, _, tx, ty, kappa, px, py = _lane_frame(roads, bounds, corridor[i], x[i, 0], d)
        pos[k, 0], pos[k, 1] = px, py
        rx, ry = -ty, tx
        lever = 1.0 + kappa * d
        vel[k, 0], vel[k, 1] = x[i, 1] * lever * tx, x[i, 1] * lever * ty
        # position covariance J P J^T with J = [lever t, right] on (u, d)
        a0, a1 = lever * tx, lever * ty
        puu, pud, pdd = p[i, 0, 0], p[i, 0, 3], p[i, 3, 3]
        trace = (a0 * a0 + a1 * a1) * puu + 2.0 * (a0 * rx + a1 * ry) * pud + pdd
        pos_std[k] = math.sqrt(max(trace, 0.0))
        to_cross[k] = abs(crossing_u[corridor[i]] - x[i, 0])


@numba.njit(cache=True, inline="always")
def _beyond(roads, start, stop, px, py, r2):  # type: ignore[no-untyped-def]
    """Whether no centreline sample of columns ``start:stop`` lies nearer than ``sqrt(r2)``.

    None lies nearer than the middle one less the arc to the block's ends (an arc is no
    shorter than its chord); a small margin keeps the test on the safe side of rounding.
    """
    mid = (start + stop - 1) // 2
    reach = max(roads[0, mid] - roads[0, start], roads[0, stop - 1] - roads[0, mid])
    lower = math.sqrt((px - roads[1, mid]) ** 2 + (py - roads[2, mid]) ** 2) - reach
    return lower > 0.0 and lower * lower > r2 * (1.0 + 1e-9) + 1e-12


@numba.njit(cache=True)
def nearest_sample(roads, bounds, px, py):  # type: ignore[no-untyped-def]
    """Corridor whose centreline passes nearest to a point, ``u`` and signed offset ``d``.

    ``u`` is the nearest centreline sample's (the first on a tie); ``d`` is to the right of
    increasing ``u``; the corridor is the one of least ``|d|`` (the first on a tie). Samples
    are searched in blocks of ``NEAREST_BLOCK``, blocks in groups of ``NEAREST_GROUP``: a
    first candidate is the nearest middle of a group, then of that group's blocks; groups and
    blocks that cannot hold a nearer sample than found so far are skipped (:func:`_beyond`).
    """
    best_c, best_u, best_d = 0, 0.0, np.inf
    group = NEAREST_BLOCK * NEAREST_GROUP
    for c in range(bounds.shape[0]):
        lo, hi = bounds[c, 0], bounds[c, 1]
        k_best, r_best = lo, np.inf
        for start in range(lo, hi, group):  # the nearest middle of a group
            mid = (start + min(start + group, hi) - 1) // 2
            r = (px - roads[1, mid]) ** 2 + (py - roads[2, mid]) ** 2
            if r < r_best:
                k_best, r_best = mid, r
        first = lo + (k_best - lo) // group * group
        for start in range(first, min(first + group, hi), NEAREST_BLOCK):  # then of its blocks
            mid = (start + min(start + NEAREST_BLOCK, hi) - 1) // 2
            r = (px - roads[1, mid]) ** 2 + (py - roads[2, mid]) ** 2
            if r < r_best:
                k_best, r_best = mid, r
        for group_start in range(lo, hi, group):
            group_stop = min(group_start + group, hi)
            if _beyond(roads, group_start, group_stop, px, py, r_best):
                continue
            for start in range(group_start, group_stop, NEAREST_BLOCK):
                stop = min(start + NEAREST_BLOCK, group_stop)
                if _beyond(roads, start, stop, px, py, r_best):
                    continue
                for k in range(start, stop):
                    r = (px - roads[1, k]) ** 2 + (py - roads[2, k]) ** 2
                    if r < r_best or (r == r_best and k < k_best):  # the first on a tie
                        k_best, r_best = k, r
        th = roads[3, k_best]
        d = (px - roads[1, k_best]) * -math.cos(th) + (py - roads[2, k_best]) * math.sin(th)
        if abs(d) < abs(best_d):
            best_c, best_u, best_d = c, roads[0, k_best], d
    return best_c, best_u, best_d


@numba.njit(cache=True)
def open_tracks(  # type: ignore[no-untyped-def]
    z, radar, noise_tab, noise_cnt, roads, bounds, radius, initial_speed_var, along_var
):
    """First states of the tentative tracks opened by left-over detections ``z`` (n, 3).

    Detections within ``radius`` [m] of each other on the ground are one body
    (:func:`cluster_labels`); each body's track starts at the corridor point nearest to its
    detections' mean (:func:`nearest_sample`), with the speed along the corridor that its first
    detection's radial speed gives where the line of sight is not across the lane (and the
    radar does not fold), else 0 with variance ``initial_speed_var``; the position along has
    variance ``1 + along_var``. Returns ``(corridor, x, p, labels, first)``: one row per body,
    each detection's body, and each body's first detection.
    """
    n = z.shape[0]
    gx, gy = np.zeros(n), np.zeros(n)
    for j in range(n):
        gx[j], gy[j], _ = _ground_point(z[j], radar)
    labels, m = cluster_labels(gx, gy, radius)
    sx, sy, cnt = np.zeros(m), np.zeros(m), np.zeros(m)
    first = np.full(m, -1, dtype=np.int64)
    for j in range(n):
        g = labels[j]
        sx[g] += gx[j]
        sy[g] += gy[j]
        cnt[g] += 1.0
        if first[g] < 0:
            first[g] = j
    corridor = np.zeros(m, dtype=np.int64)
    x = np.zeros((m, N_STATE))
    p = np.zeros((m, N_STATE, N_STATE))
    for g in range(m):
        c, u, d = nearest_sample(roads, bounds, sx[g] / cnt[g], sy[g] / cnt[g])
        _, _, tx, ty, _, px, py = _lane_frame(roads, bounds, c, u, d)
        ex, ey = px - radar[0], py - radar[1]
        cos = (ex * tx + ey * ty) / math.sqrt(ex * ex + ey * ey + radar[2] * radar[2])
        j = first[g]
        corridor[g] = c
        x[g, 0], x[g, 3] = u, d
        if abs(cos) > 0.3 and radar[6] == 0.0:
            x[g, 1] = z[j, 2] / cos
            p[g, 1, 1] = (curve_at(noise_tab, noise_cnt, 2, z[j, 0]) / abs(cos)) ** 2 + 1.0
        else:
            p[g, 1, 1] = initial_speed_var
        p[g, 0, 0] = 1.0 + along_var
        p[g, 2, 2] = 9.0
        p[g, 3, 3] = 1.0
    return corridor, x, p, labels, first


@numba.njit(cache=True)
def merged_rows(  # type: ignore[no-untyped-def]
    rows, corridor, x, p, spread, static, stopped, moved, ids, confirmed, lateral_m, speed_mps,
    parts_speed, young, settled, settled_lateral_m, born,
):  # fmt: skip
    """Of the tracks ``rows``, those to drop (bool per entry of ``rows``).

    The younger of two tracks on one body (see ``SceneTracker._retire``); the other arrays are
    per track.

    Pairs in row order; a confirmed track outlives an unconfirmed one whatever their ages; a track
    already dropped removes no other. Besides tracks within their spreads of each other, two
    road users that have moved, faster than ``parts_speed``, whose bodies (``BODY_HALF_SPREADS``
    spreads either side) overlap are one long body tracked in two parts (no one drives into
    another): the younger goes, and the body's other reflections, on no body now, teach the
    survivor its length. A ``young`` static object (not yet learnt clutter), ``born`` after the
    road user, whose body overlaps a stopped road user's (``BODY_HALF_SPREADS`` spreads either
    side along, within ``lateral_m`` across) is that road user's reflection: it goes (one that
    stood there before the road user came is clutter under it, e.g. a rail; a bus stopped with
    an under-learnt body would otherwise see its far end taken for a post, which then holds part
    of its reflections, learns their spread and leaves the bus track a shorter body further off;
    a point of clutter learns a small spread and stays off a body beside it). A ``settled``
    track (one followed for a while) is not dropped for a track more than ``settled_lateral_m``
    beside it: two road users side by side (a motorcycle filtering past a queue) stay apart,
    while a duplicate of one body sits in its lane.
    """
    m = rows.size
    drop = np.zeros(m, dtype=np.bool_)  # per entry of rows
    for ka in range(m):
        a = rows[ka]
        for kb in range(ka + 1, m):
            b = rows[kb]
            if corridor[a] != corridor[b]:
                continue
            if static[a] != static[b]:
                s, r = (a, b) if static[a] else (b, a)  # the static one, the road user
                ks, kr = (ka, kb) if static[a] else (kb, ka)
                if (
                    young[s] and born[s] > born[r] and stopped[r] and moved[r] and not drop[kr]
                    and bodies_overlap(x, spread, s, r)
                    and abs(x[s, 3] - x[r, 3]) < lateral_m
                ):  # fmt: skip
                    drop[ks] = True
                continue
            sv = math.sqrt(p[a, 1, 1] + p[b, 1, 1])
            du = abs(x[a, 0] - x[b, 0])
            parts = (
                moved[a] and moved[b] and not (stopped[a] or stopped[b])
                and min(abs(x[a, 1]), abs(x[b, 1])) > parts_speed
                and bodies_overlap(x, spread, a, b)
            )  # fmt: skip
            if not (
                (du < spread[a] + spread[b] + 0.5 or parts)
                and abs(x[a, 3] - x[b, 3]) < lateral_m
                and abs(x[a, 1] - x[b, 1]) < speed_mps + 3.0 * sv
            ):
                continue
            older, younger = (ka, kb) if ids[a] < ids[b] else (kb, ka)
            if confirmed[rows[younger]] and not confirmed[rows[older]]:
                older, younger = younger, older
            if settled[rows[younger]] and abs(x[a, 3] - x[b, 3]) > settled_lateral_m:
                continue
            if not drop[older]:
                drop[younger] = True
    return drop


@numba.njit(cache=True)
def retired_rows(  # type: ignore[no-untyped-def]
    time_s, track_time_s, x, p, corridor, length_m, spread, stopped, moved, occluded, ids,
    confirmed, misses, born_s, last_hit_s, stopped_detectable, tentative_misses,
    max_tentative_s, max_coast_s, max_coast_stopped_s, max_coast_hidden_s, max_position_std_m,
    max_stopped_misses, lateral_m, speed_mps, parts_speed, clutter_age_s, absorb_young_static,
    settled_s, settled_lateral_m,
):  # fmt: skip
    """Tracks to delete after a scan at ``time_s`` (bool per track).

    Those the life-cycle rules expire (:func:`adaptrack.tracking.lifecycle.expired_rows`,
    with the position sigma along and across the corridor), those that left their corridor
    (``length_m`` per corridor) and, of the rest, the younger of two on one body
    (:func:`merged_rows`; a static object younger than ``clutter_age_s`` may be absorbed if
    ``absorb_young_static``; a confirmed road user that has moved and been followed longer
    than ``settled_s`` is settled).
    """
    n = x.shape[0]
    position_std = np.zeros(n)
    for i in range(n):
        position_std[i] = math.sqrt(p[i, 0, 0] + p[i, 3, 3])
    gone = expired_rows(
        confirmed, misses, born_s, last_hit_s, time_s, stopped, occluded, position_std, True,
        stopped_detectable, tentative_misses, max_tentative_s, max_coast_s,
        max_coast_stopped_s, max_coast_hidden_s, max_position_std_m, max_stopped_misses,
    )  # fmt: skip
    dead = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        dead[i] = x[i, 0] < 0 or x[i, 0] > length_m[corridor[i]]
    for i in gone:
        dead[i] = True
    alive = rows_where(dead, False)
    young = np.empty(n, dtype=np.bool_)
    settled = np.empty(n, dtype=np.bool_)
    static = np.empty(n, np.bool_)
    for i in range(n):
        age = track_time_s[i] - born_s[i]
        young[i] = absorb_young_static and age < clutter_age_s
        settled[i] = confirmed[i] and moved[i] and age > settled_s
        static[i] = stopped[i] and not moved[i]
    merged = merged_rows(
        alive, corridor, x, p, spread, static, stopped, moved, ids, confirmed, lateral_m,
        speed_mps, parts_speed, young, settled, settled_lateral_m, born_s,
    )  # fmt: skip
    for k in range(alive.size):
        dead[alive[k]] |= merged[k]
    return dead


@numba.njit(cache=True)
def mode_changes(  # type: ignore[no-untyped-def]
    time_s, x, p, corridor, confirmed, last_hit_s, anchor_u, stopped, moved, direction,
    slow_since, event_raised, doppler_seen_s, crossing_u, half_lane, barrier_m, moved_speed,
    moving_speed_std, moved_distance, stop_speed, stop_exit_sigmas, stop_confirm_s, seen_s,
):  # fmt: skip
    """Update the moving / stopped modes after a scan in place (``SceneTracker._modes``).

    A confirmed track whose speed is known (sigma below half of it and below
    ``moving_speed_std``) to exceed ``moved_speed`` gets its ``direction``; it has ``moved``
    once also ``moved_distance`` from ``anchor_u``. One slower than ``stop_speed`` (sigma
    below 0.5 m/s, detected within ``seen_s``; inf: not required) is slowing to a stop; it
    stays so while its speed is not significantly above (``stop_exit_sigmas`` sigmas) and
    after ``stop_confirm_s`` is ``stopped`` (speed and acceleration zeroed with their
    covariance). Returns the hazard rows (a moved track stopped on the carriageway within
    ``barrier_m`` of the crossing, its standstill shown by a Doppler-measuring detection
    within ``seen_s`` (``doppler_seen_s``), raised once: ``event_raised`` set) and which
    tracks are on the carriageway (bool each). A stop that only misses and radial speeds
    blind to the lane (across the line of sight) suggest raises nothing yet.
    """
    n = x.shape[0]
    hazard = np.zeros(n, dtype=np.bool_)
    on_road = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        speed = abs(x[i, 1])
        sd = math.sqrt(p[i, 1, 1])
        if confirmed[i]:
            if speed > moved_speed and sd < 0.5 * speed and sd < moving_speed_std:
                direction[i] = 1.0 if x[i, 1] > 0.0 else -1.0
                if abs(x[i, 0] - anchor_u[i]) > moved_distance:
                    moved[i] = True
        limit = stop_speed if math.isnan(slow_since[i]) else stop_speed + stop_exit_sigmas * sd
        slow = (
            confirmed[i] and not stopped[i] and speed < limit and sd < 0.5
            and time_s - last_hit_s[i] <= seen_s
        )  # fmt: skip
        if not slow:
            slow_since[i] = np.nan
        elif math.isnan(slow_since[i]):
            slow_since[i] = time_s
        if slow and time_s - slow_since[i] >= stop_confirm_s:
            stopped[i] = True
            x[i, 1] = x[i, 2] = 0.0
            for a in range(1, 3):
                for b in range(N_STATE):
                    p[i, a, b] = p[i, b, a] = 0.0
        on_road[i] = abs(x[i, 3]) <= 2.0 * half_lane[corridor[i]]
        to_cross = abs(crossing_u[corridor[i]] - x[i, 0])
        shown = time_s - doppler_seen_s[i] <= seen_s
        if stopped[i] and moved[i] and on_road[i] and to_cross <= barrier_m and shown:
            hazard[i] = not event_raised[i]
            event_raised[i] = True
    return hazard, on_road
