"""Gate stage of a scan: which detections each track may take, and the unambiguous pairs."""

from __future__ import annotations

import math

import numba
import numpy as np

from ..._borrowed import on_stack
from ...filters._kernels import cholesky_into
from ..estimators.kernels import doppler_usable, innovation_into
from ..site.geometry import RADAR_MIN_RANGE, curve_at, in_view, off_boresight
from .body import (
    BODY_HALF_SPREADS,
    N_STATE,
    body_model,
    ground_point,
    model_scratch,
    nearer_occluders,
    sight_lines,
    store_lane,
    visible_part,
)
from .rows import rows_where

CLUTTER_VIEW = 29  # a frozen track's stored view of one radar (_store_view)


@numba.njit(cache=True)
def detections_in_view(z, radar, fields):  # type: ignore[no-untyped-def]
    """Whether each detection (range, azimuth, ...) of ``z`` (n, 3) lies in the radar's view."""
    seen = np.zeros(z.shape[0], dtype=np.bool_)
    for j in range(z.shape[0]):
        seen[j] = in_view(z[j, 0], off_boresight(z[j, 1], radar), fields, radar[RADAR_MIN_RANGE])
    return seen


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
    t, starting, road_user, moving, occluder, site, view, cfg, z, d2, logdet, gated, clutter, views,
):  # fmt: skip
    """Fill ``d2`` (T, D) with each detection's squared Mahalanobis distance to each track.

    ``clutter`` rows are frozen (:func:`update_tracks`): their view of the radar (visible
    part, predicted detection, factored innovation covariance) is stored in ``views`` (T,
    ``CLUTTER_VIEW``) the first time and read back after (:func:`_store_view`).

    ``logdet`` (T,) receives the log-determinant of each track's innovation covariance
    (``inf`` where ``d2`` is). ``gated`` (T, 9) holds each track's lane frame at its ``u`` in
    columns 4:9 (:func:`..site.geometry.lane_at`) and receives its :func:`visible_part` in
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
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``view`` (the scan's radar, :class:`~.bundles.RadarView`),
    ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting named here is the field of
    ``cfg``.
    """
    x, p, spread, direction, corridor = t.x, t.p, t.spread, t.direction, t.corridor
    roads, bounds = site.roads, site.bounds
    radar, noise_tab, noise_cnt, fields = view.radar, view.noise_tab, view.noise_cnt, view.fields
    across_std, start_speed_max = cfg.body_across_std_m, cfg.start_speed_max_mps
    extent_gate, passing_gate, beside_m = cfg.body_extent_gate, cfg.passing_gate, cfg.beside_m
    gate = cfg.gate
    n_t, n_d = x.shape[0], z.shape[0]
    seen = np.zeros(n_t, dtype=np.bool_)
    # buffers passed per track: on the stack
    zp, h, rm, jp, jv = model_scratch()
    xv, s, lo = on_stack(N_STATE), on_stack((3, 3)), on_stack((3, 3))
    w, w0 = on_stack(3), on_stack(3)
    ground = np.zeros((n_d, 6))  # ground point, sight line, range and cross variances
    for j in range(n_d):
        gx, gy, rho = ground_point(z[j], radar)
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
            part = visible_part(x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane)
            gated[i, 0], gated[i, 1], gated[i, 2], gated[i, 3] = part
            if not part[3]:  # else wholly out of view, its predicted detection too (not seen)
                part_spread, cx, cy, tx, ty = body_model(
                    i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields,
                    across_std, xv, zp, h, rm, jp, jv, part, lane,
                )  # fmt: skip
                seen[i] = in_view(
                    zp[0], off_boresight(zp[1], radar), fields, radar[RADAR_MIN_RANGE]
                )
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
def associate_scan(t, clutter, r, site, view, cfg, z, ids):  # type: ignore[no-untyped-def]
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
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``view`` (the scan's radar, :class:`~.bundles.RadarView`),
    ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting named here is the field of
    ``cfg``.
    """
    x, spread, stopped, moved, confirmed = t.x, t.spread, t.stopped, t.moved, t.confirmed
    corridor = t.corridor
    sensor_id = t.sensor_id[:, r]
    views = t.clutter_views[:, r]
    roads, bounds = site.roads, site.bounds
    radar = view.radar
    occlusion_gate, gate, clutter_gate = cfg.occlusion_gate, cfg.gate, cfg.clutter_gate
    id_bonus = cfg.sensor_id_bonus
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
            store_lane(lanes, i, roads, bounds, corridor, x)
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
        t,
        starting,
        road_user,
        moving,
        behind,
        site,
        view,
        cfg,
        z,
        d2,
        logdet,
        gated,
        clutter,
        views,
    )
    if n_d == 0:
        none = np.zeros(0, np.int64)
        return seen, d2, logdet, gated, True, none, none, sight
    reserve_clutter(d2, clutter, clutter_gate)
    if id_bonus != 0.0:
        favour_sensor_ids(d2, sensor_id, ids, id_bonus, gate)
    simple, tracks, dets = unambiguous_assignment(d2, gate)
    return seen, d2, logdet, gated, simple, tracks, dets, sight
