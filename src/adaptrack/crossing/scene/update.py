"""Update stage of a scan: the assigned detections and the misses applied to the tracks."""

from __future__ import annotations

import math

import numba
import numpy as np

from ..._borrowed import on_stack
from ...filters._kernels import update_into
from ...tracking.lifecycle import record_hits
from ..estimators.kernels import (
    GATE_MIN_COS,
    ROAD,
    doppler_usable,
    gate_update_into,
    innovation_into,
)
from ..site.geometry import RADAR_X, RADAR_Y, curve_at, lane_at, off_boresight
from .body import (
    N_STATE,
    body_model,
    ground_point,
    model_scratch,
    nearer_occluders,
    sight_lines,
    store_lane,
    update_scratch,
    visible_part,
)
from .bundles import BIAS_SAMPLES, BIAS_SUM, BIAS_WEIGHT
from .rows import rows_and_not

BIAS_MIN_SPEED_MPS = 6.0  # azimuth alignment on vehicles, not on cyclists at the lane's edge
GHOST_SPEED_MPS = 2.0  # a multipath ghost moves with the body that makes it (within this)
DETECTION_D_RATE = 0.2  # moving-average rate of a track's detections' offset across


@numba.njit(cache=True)
def apply_scan(  # type: ignore[no-untyped-def]
    time_s, seen, clutter, d2, logdet, gated, sight, tracks, dets, z, ids, r, t, site, view, cfg,
    bias, bias_stats,
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
    Bundles: ``tracks`` (the track rows, :class:`~.bundles.TrackRows`), ``t`` (the track rows,
    :class:`~.bundles.TrackRows`), ``site`` (the site, :class:`~.bundles.SiteTables`), ``view``
    (the scan's radar, :class:`~.bundles.RadarView`), ``cfg`` (the settings,
    :class:`~.bundles.Settings`); a setting named here is the field of ``cfg``.
    """
    gate, confirm_speed_var, window_mask = cfg.gate, cfg.confirm_speed_var, cfg.window_mask
    confirm_hits, shadow_spread = cfg.confirm_hits, cfg.shadow_spread_m
    radar_col = r
    x, p, spread, stopped, moved, corridor = t.x, t.p, t.spread, t.stopped, t.moved, t.corridor
    miss_run, occluded, anchor_u, sensor_id = t.miss_run, t.occluded, t.anchor_u, t.sensor_id
    history, misses, last_hit_s, confirmed = t.history, t.misses, t.last_hit_s, t.confirmed
    roads, bounds = site.roads, site.bounds
    radar = view.radar
    n_t, n_d = d2.shape
    used = np.zeros(n_d, dtype=np.bool_)
    hit = np.zeros(n_t, dtype=np.bool_)
    if n_d:
        owner, order = owners(d2, logdet, gate, tracks, dets)
        update_tracks(time_s, order, owner, clutter, gated, z, t, site, view, cfg, bias, bias_stats)
        for j in order:
            used[j] = True
            hit[owner[j]] = True
        for k in range(tracks.size):
            sensor_id[tracks[k], radar_col] = ids[dets[k]]  # its own, not a body's other
    for i in range(n_t):
        if hit[i]:
            miss_run[i] = 1.0
    missed = rows_and_not(seen, hit)
    nearer = np.full(missed.size, -1, np.int64)
    if missed.size:  # lines of sight after the updates: those of the updated tracks anew
        lanes = gated[:, 4:]
        for i in range(n_t):
            if hit[i] and not clutter[i]:  # a frozen track's stays
                store_lane(lanes, i, roads, bounds, corridor, x)
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
    miss_updates(moving_missed[:m], t, site, view)
    rows = rows_and_not(seen, occluded)
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
def update_tracks(  # type: ignore[no-untyped-def]
    time_s, order, owner, clutter, gated, z, t, site, view, cfg, bias, bias_stats,
):  # fmt: skip
    """Update each owning track with its detections in ``order`` (sequential EKF updates).

    ``clutter`` rows (learnt static clutter: :func:`.scan_loop.learnt_clutter`) are frozen:
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
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``view`` (the scan's radar, :class:`~.bundles.RadarView`),
    ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting named here is the field of
    ``cfg``.
    """
    x, p, spread, stopped, moved, direction = t.x, t.p, t.spread, t.stopped, t.moved, t.direction
    slow_since, doppler_seen_s, detection_d = t.slow_since, t.doppler_seen_s, t.detection_d
    corridor, along_m2, along_m4 = t.corridor, t.along_m2, t.along_m4
    start_speed_var = cfg.start_speed_max_mps**2
    roads, bounds, lane_half_width = site.roads, site.bounds, site.half_lane_m
    radar, noise_tab, noise_cnt, fields = view.radar, view.noise_tab, view.noise_cnt, view.fields
    across_std, moving_radial = cfg.body_across_std_m, cfg.moving_radial_mps
    learning_rate, shape_rate = cfg.spread_learning_rate, cfg.shape_learning_rate
    spread_lo, spread_hi, align = cfg.spread_lo_m, cfg.spread_hi_m, cfg.estimate_azimuth_bias
    bias_forget, bias_gate = cfg.bias_forget, cfg.bias_gate_m
    # buffers passed per detection: on the stack
    zp, h, rm, jp, jv = model_scratch()
    hp, s, lo, kt, w, ikh, tmp, xn, pn = update_scratch(3)
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
        gx, gy, rho = ground_point(z[j], radar)
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
                bias_stats[BIAS_WEIGHT] = bias_forget * bias_stats[BIAS_WEIGHT] + g * g
                bias_stats[BIAS_SUM] = bias_forget * bias_stats[BIAS_SUM] + g * (lat + bias * g)
                bias_stats[BIAS_SAMPLES] = bias_forget * bias_stats[BIAS_SAMPLES] + 1.0
        sr = curve_at(noise_tab, noise_cnt, 0, z[j, 0])
        sa = curve_at(noise_tab, noise_cnt, 1, off_boresight(z[j, 1], radar))
        if as_gated[i]:
            part = gated[i, 0], gated[i, 1], gated[i, 2], gated[i, 3] != 0.0
        else:
            part = visible_part(x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane)
        was_spread = spread[i]
        if part[0] == 0:  # the whole body in view
            if not (stopped[i] and moved[i]):
                sample = max(along * along - sr * sr - (rho * sa) ** 2 - p[i, 0, 0], 0.0)
                var = (1.0 - learning_rate) * spread[i] ** 2 + learning_rate * sample
                spread[i] = math.sqrt(min(max(var, spread_lo**2), spread_hi**2))
            along_m2[i] += shape_rate * (along * along - along_m2[i])
            along_m4[i] += shape_rate * (along**4 - along_m4[i])
        if spread[i] != was_spread:
            part = visible_part(x[i, 0], x[i, 3], spread[i], lo_i, hi_i, roads, radar, fields, lane)
        body_model(  # over the part in view of its body as learnt now
            i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields,
            across_std, xv, zp, h, rm, jp, jv, part, lane,
        )  # fmt: skip
        doppler = doppler_usable(h, p[i], rm, radar)
        innovation_into(z[j], zp, radar, doppler, nu)
        # the radial speed of the detection's own point measures the speed along the lane
        los = ((gx - radar[RADAR_X]) * tx + (gy - radar[RADAR_Y]) * ty) / z[j, 0]
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
def miss_updates(rows, t, site, view):  # type: ignore[no-untyped-def]
    """Apply what a scan without a detection tells to the tracks in ``rows``.

    :func:`~adaptrack.crossing.estimators.kernels.gate_update_into`: a slow
    vehicle is hidden by the Doppler gate, so a
    run of misses that the gate explains better than ``1 - P_D`` measures a radial speed of
    0 within the gate; ``miss_run`` (T,) is each track's probability of its current run of
    misses for a moving target.
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``view`` (the scan's radar, :class:`~.bundles.RadarView`); a
    setting named here is the field of ``cfg``.
    """
    x, p, spread, miss_run, corridor = t.x, t.p, t.spread, t.miss_run, t.corridor
    roads, bounds = site.roads, site.bounds
    radar, noise_tab, noise_cnt, fields = view.radar, view.noise_tab, view.noise_cnt, view.fields
    pd_tab, pd_cnt = view.pd_tab, view.pd_cnt
    if rows.size == 0:
        return
    # buffers passed per track: on the stack
    zp, h, rm, jp, jv = model_scratch()
    hp, s, lo, kt, w, ikh, tmp, xn, pn = update_scratch(1)
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
