"""The scene tracker's scan loop, compiled: many scans in one call, no Python per scan.

:class:`adaptrack.crossing.scene.tracker.SceneTracker` keeps its tracks as rows of arrays
(:class:`TrackRows`: the track book's columns and the filter's). :func:`run_scans` takes them
into arrays with spare rows (a track opened or split is written in place, a deleted one is
compacted away, in the order of creation), processes a run of scans with the per-scan kernels of
the stage modules (predict, gate, update, spawn, prune, modes) and returns them. The global
assignment of an ambiguous scan is solved by :func:`adaptrack.tracking.gnn_assign` (SciPy),
called from the loop in object mode.
Hazard events and, if asked, every scan's confirmed tracks (:class:`RowBuffer`) are written
to buffers that grow as needed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..._borrowed import borrowed
from ...angles import wrapped
from ...tracking import assignment_by_components, gnn_assign
from .body import lane_frame, planar_rows
from .bundles import (
    BIAS_SAMPLES,
    BIAS_SUM,
    BIAS_WEIGHT,
    LOG_JOINED_NEW,
    LOG_OFF_ROAD,
    LOG_OPENED,
    LOG_OUTSIDE_VIEW,
    LOG_UPDATED,
    RadarView,
    RowBuffer,
    SiteTables,
    TrackRows,
)
from .gate import associate_scan, detections_in_view
from .modes import mode_changes
from .predict import predict_tracks
from .prune import confirmed_rows, retired_rows
from .rows import rows_where
from .spawn import open_tracks, split_rows
from .update import apply_scan

EVENT_NAMES = ("stopped_between_barriers", "will_not_stop_before_stop_line")  # by event code
EVENT_FIELDS = 6  # time [s], event code, track id, east [m], north [m], lead [s] (NaN: none)
MAX_CHOICES = 4096  # a scan's conflict with more choices goes to SciPy's assignment


@numba.njit(cache=True)
def _assign(d2, gate):  # type: ignore[no-untyped-def]
    """Global nearest neighbour of a scan's gated distances (SciPy, in object mode)."""
    cost = np.where(d2 <= gate, d2, np.inf)
    with numba.objmode(tracks="int64[:]", dets="int64[:]"):
        tracks, dets = gnn_assign(cost, gate)
        tracks, dets = tracks.astype(np.int64), dets.astype(np.int64)
    return tracks, dets


@numba.njit(cache=True)
def _live(t, n):  # type: ignore[no-untyped-def]
    """Return the first ``n`` rows of every column (borrowed views: while ``t`` is not grown)."""
    return TrackRows(
        borrowed(t.ids[:n]), borrowed(t.history[:n]), borrowed(t.confirmed[:n]),
        borrowed(t.misses[:n]), borrowed(t.last_hit_s[:n]), borrowed(t.born_s[:n]),
        borrowed(t.corridor[:n]), borrowed(t.x[:n]), borrowed(t.p[:n]),
        borrowed(t.time_s[:n]), borrowed(t.stopped[:n]), borrowed(t.slow_since[:n]),
        borrowed(t.moved[:n]), borrowed(t.event_raised[:n]),
        borrowed(t.line_event_raised[:n]), borrowed(t.anchor_u[:n]), borrowed(t.spread[:n]),
        borrowed(t.along_m2[:n]), borrowed(t.along_m4[:n]), borrowed(t.direction[:n]),
        borrowed(t.miss_run[:n]), borrowed(t.occluded[:n]), borrowed(t.doppler_seen_s[:n]),
        borrowed(t.detection_d[:n]), borrowed(t.sensor_id[:n]), borrowed(t.clutter_views[:n]),
    )  # fmt: skip


@numba.njit(cache=True)
def _borrowed_site(site):  # type: ignore[no-untyped-def]
    """Return ``site`` with borrowed views of its tables (while ``site`` is alive)."""
    return SiteTables(
        borrowed(site.roads), borrowed(site.bounds), borrowed(site.crossing_u),
        borrowed(site.length_m), borrowed(site.half_lane_m), site.barrier_m, site.stop_line_m,
        borrowed(site.warning_starts), borrowed(site.warning_ends), borrowed(site.radar),
        borrowed(site.noise_tab), borrowed(site.noise_cnt), borrowed(site.fields),
        borrowed(site.field_count), borrowed(site.pd_tab), borrowed(site.pd_cnt),
        borrowed(site.latency_s),
    )  # fmt: skip


@numba.njit(cache=True)
def _borrowed_tracks(t):  # type: ignore[no-untyped-def]
    """Return ``t`` (:class:`TrackRows`) as borrowed views (while its arrays are alive)."""
    return TrackRows(
        borrowed(t.ids), borrowed(t.history), borrowed(t.confirmed), borrowed(t.misses),
        borrowed(t.last_hit_s), borrowed(t.born_s), borrowed(t.corridor), borrowed(t.x),
        borrowed(t.p), borrowed(t.time_s), borrowed(t.stopped), borrowed(t.slow_since),
        borrowed(t.moved), borrowed(t.event_raised), borrowed(t.line_event_raised),
        borrowed(t.anchor_u), borrowed(t.spread), borrowed(t.along_m2), borrowed(t.along_m4),
        borrowed(t.direction), borrowed(t.miss_run), borrowed(t.occluded),
        borrowed(t.doppler_seen_s), borrowed(t.detection_d), borrowed(t.sensor_id),
        borrowed(t.clutter_views),
    )  # fmt: skip


@numba.njit(cache=True)
def _borrowed_out(o):  # type: ignore[no-untyped-def]
    """Return ``o`` (:class:`RowBuffer`) as borrowed views (while its arrays are alive)."""
    return RowBuffer(
        borrowed(o.track_id), borrowed(o.time_s), borrowed(o.east_m), borrowed(o.north_m),
        borrowed(o.speed_mps), borrowed(o.east_speed_mps), borrowed(o.north_speed_mps),
        borrowed(o.from_crossing_m), borrowed(o.status), borrowed(o.moved),
        borrowed(o.position_std_m), borrowed(o.speed_std_mps),
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _room(rows, t, n, need):  # type: ignore[no-untyped-def]
    """``rows`` (owned) with room for ``need`` rows and ``t``, its borrowed views (renewed)."""
    if need <= rows.ids.shape[0]:
        return rows, t
    rows = with_room(rows, n, need)
    return rows, _borrowed_tracks(rows)


@numba.njit(cache=True)
def _grown(a, n, size):  # type: ignore[no-untyped-def]
    """Return ``a`` with ``size`` rows along its first axis, its first ``n`` kept."""
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[:n] = a[:n]
    return out


@numba.njit(cache=True)
def with_room(t, n, need):  # type: ignore[no-untyped-def]
    """Return ``t`` with room for at least ``need`` rows (capacity doubled as needed)."""
    size = t.ids.shape[0]
    if need <= size:
        return t
    while size < need:
        size = 2 * size + 16
    return TrackRows(
        _grown(t.ids, n, size), _grown(t.history, n, size), _grown(t.confirmed, n, size),
        _grown(t.misses, n, size), _grown(t.last_hit_s, n, size), _grown(t.born_s, n, size),
        _grown(t.corridor, n, size), _grown(t.x, n, size), _grown(t.p, n, size),
        _grown(t.time_s, n, size), _grown(t.stopped, n, size), _grown(t.slow_since, n, size),
        _grown(t.moved, n, size), _grown(t.event_raised, n, size),
        _grown(t.line_event_raised, n, size), _grown(t.anchor_u, n, size),
        _grown(t.spread, n, size), _grown(t.along_m2, n, size), _grown(t.along_m4, n, size),
        _grown(t.direction, n, size), _grown(t.miss_run, n, size), _grown(t.occluded, n, size),
        _grown(t.doppler_seen_s, n, size), _grown(t.detection_d, n, size),
        _grown(t.sensor_id, n, size), _grown(t.clutter_views, n, size),
    )  # fmt: skip


@numba.njit(cache=True)
def _copy_row(t, src, dst):  # type: ignore[no-untyped-def]
    """Copy every column of row ``src`` to row ``dst``."""
    t.ids[dst], t.history[dst], t.confirmed[dst] = t.ids[src], t.history[src], t.confirmed[src]
    t.misses[dst], t.last_hit_s[dst], t.born_s[dst] = (
        t.misses[src],
        t.last_hit_s[src],
        t.born_s[src],
    )
    t.corridor[dst], t.time_s[dst], t.stopped[dst] = t.corridor[src], t.time_s[src], t.stopped[src]
    t.x[dst], t.p[dst], t.sensor_id[dst] = t.x[src], t.p[src], t.sensor_id[src]
    t.slow_since[dst], t.moved[dst] = t.slow_since[src], t.moved[src]
    t.event_raised[dst], t.line_event_raised[dst] = t.event_raised[src], t.line_event_raised[src]
    t.anchor_u[dst], t.spread[dst] = t.anchor_u[src], t.spread[src]
    t.along_m2[dst], t.along_m4[dst] = t.along_m2[src], t.along_m4[src]
    t.direction[dst], t.miss_run[dst], t.occluded[dst] = (
        t.direction[src],
        t.miss_run[src],
        t.occluded[src],
    )
    t.doppler_seen_s[dst], t.detection_d[dst] = t.doppler_seen_s[src], t.detection_d[src]
    t.clutter_views[dst] = t.clutter_views[src]


@numba.njit(cache=True)
def _compacted(t, n, dead):  # type: ignore[no-untyped-def]
    """Remove the ``dead`` rows (bool per live row), keeping order; return the new count."""
    m = 0
    for i in range(n):
        if not dead[i]:
            if m != i:
                _copy_row(t, i, m)
            m += 1
    return m


@numba.njit(cache=True, inline="always")
def one_body_moments(spread):  # type: ignore[no-untyped-def]
    """Second and fourth moments [m^2, m^4] of one body's reflections (Gaussian, ``spread`` [m])."""
    return spread**2, 3.0 * spread**4


@numba.njit(cache=True)
def _place(t, i, u, spread):  # type: ignore[no-untyped-def]
    """Move stopped row ``i`` to ``u`` along its corridor with body ``spread`` [m].

    Its position sigma grows by half a metre; its reflection moments restart at one body's.
    """
    t.x[i, 0] = t.anchor_u[i] = u
    t.p[i, 0, 0] += 0.25
    t.spread[i] = spread
    t.along_m2[i], t.along_m4[i] = one_body_moments(spread)


@numba.njit(cache=True)
def new_row(t, i, track_id, time_s, corridor, x, p, spread, radar_col, sensor_id):  # type: ignore[no-untyped-def]
    """Write a tentative track (its first hit at ``time_s``) into row ``i``."""
    t.ids[i], t.history[i], t.confirmed[i], t.misses[i] = track_id, 1, False, 0
    t.last_hit_s[i] = t.born_s[i] = t.time_s[i] = time_s
    t.corridor[i], t.x[i], t.p[i] = corridor, x, p
    t.stopped[i] = t.moved[i] = t.event_raised[i] = t.line_event_raised[i] = False
    t.slow_since[i] = np.nan
    t.anchor_u[i] = x[0]
    t.spread[i] = spread
    t.along_m2[i], t.along_m4[i] = one_body_moments(spread)
    t.direction[i], t.miss_run[i], t.occluded[i] = 0.0, 1.0, False
    t.doppler_seen_s[i], t.detection_d[i] = -np.inf, np.nan
    t.sensor_id[i] = -1
    t.sensor_id[i, radar_col] = sensor_id
    t.clutter_views[i, :, 0] = 0.0  # none stored


@numba.njit(cache=True)
def _position(t, i, site):  # type: ignore[no-untyped-def]
    """Planar position of row ``i`` [m]."""
    frame = lane_frame(site.roads, site.bounds, t.corridor[i], t.x[i, 0], t.x[i, 3])
    return frame[5], frame[6]


@numba.njit(cache=True)
def _record_event(events, n_events, t, i, site, time_s, code, lead_s):  # type: ignore[no-untyped-def]
    """Append an event of row ``i``; return the buffer (grown if full) and the new count."""
    if n_events == events.shape[0]:
        events = _grown(events, n_events, 2 * n_events + 16)
    east, north = _position(t, i, site)
    e = events[n_events]
    e[0], e[1], e[2], e[3], e[4], e[5] = time_s, code, t.ids[i], east, north, lead_s
    return events, n_events + 1


@numba.njit(cache=True)
def new_objects(t, n, hazard, s, site):  # type: ignore[no-untyped-def]
    """Keep the ``hazard`` rows that are not an object already alarmed: one object, one alarm.

    A track stopped within ``same_object_m`` of a stopped track whose alarm is raised stands on
    that object's body (e.g. a track from the other lane that took a stopped car's
    reflections); it raises no second alarm now (``event_raised`` cleared), and may later if
    the other track is gone. Not one whose own detections (``detection_d``) lie beside that
    track, on its corridor ``beside_m`` across or more: another road user stands there (a
    motorcycle beside a car queued between the barriers). Returns the rows to alarm.
    """
    out = np.zeros(n, np.bool_)
    for i in range(n):
        if not hazard[i]:
            continue
        out[i] = True
        ex, ey = _position(t, i, site)
        for a in range(n):
            if hazard[a] or not (t.event_raised[a] and t.stopped[a]):
                continue
            ax, ay = _position(t, a, site)
            near = math.hypot(ex - ax, ey - ay) < s.same_object_m
            beside = t.corridor[i] == t.corridor[a] and (
                abs(t.detection_d[i] - t.x[a, 3]) >= s.beside_m
            )  # NaN (no detection yet): not beside
            if near and not beside:
                out[i] = False
        if not out[i]:
            t.event_raised[i] = False
    return out


@numba.njit(cache=True)
def stop_line_rows(t, n, time_s, on_road, s, site):  # type: ignore[no-untyped-def]
    """Rows that cannot stop before the stop line now, and their lead times [s].

    A moving confirmed road user on the carriageway (``on_road``), detected within
    ``stop_seen_s``, first in its lane (one who follows another stops behind it), whose front
    needs more than ``stop_decel_mps2`` to stop at the line even at the low end of its speed's
    90 % interval; its lead is the time to reach the line. Each is raised once
    (``line_event_raised`` set).
    """
    ahead = np.empty(n)
    for i in range(n):
        ahead[i] = site.crossing_u[t.corridor[i]] - t.x[i, 0]  # towards the crossing
    cant = np.zeros(n, np.bool_)
    lead = np.zeros(n)
    for i in range(n):
        speed = t.x[i, 1] * np.sign(ahead[i])  # > 0 approaching
        front = math.sqrt(3.0) * t.spread[i]  # half a uniform body of that spread
        to_line = abs(ahead[i]) - site.stop_line_m - front
        if not (
            t.confirmed[i] and t.moved[i] and not t.stopped[i] and not t.line_event_raised[i]
            and on_road[i] and speed > 0.5 and to_line > -front
            and time_s - t.last_hit_s[i] <= s.stop_seen_s
        ):  # fmt: skip
            continue
        slow_bound = speed - 1.645 * math.sqrt(t.p[i, 1, 1])  # at least this fast (95 %)
        if not slow_bound > math.sqrt(2.0 * s.stop_decel_mps2 * max(to_line, 0.0)):
            continue
        followed = False
        for k in range(n):  # a road user ahead of it in its lane, same way
            if (
                t.confirmed[k] and not (t.stopped[k] and not t.moved[k])
                and t.corridor[k] == t.corridor[i]
                and abs(t.x[k, 3] - t.x[i, 3]) < site.half_lane_m[t.corridor[i]]
                and (t.x[k, 0] - t.x[i, 0]) * np.sign(ahead[i]) > 0
                and np.sign(ahead[k]) == np.sign(ahead[i])
            ):  # fmt: skip
                followed = True
                break
        if not followed:
            cant[i] = True
            lead[i] = max(to_line, 0.0) / speed
    for i in range(n):
        t.line_event_raised[i] |= cant[i]
    return cant, lead


@numba.njit(cache=True)
def warning_on(site, time_s):  # type: ignore[no-untyped-def]
    """Whether the crossing's lights flash or its barriers are down at ``time_s``."""
    k = np.searchsorted(site.warning_starts, time_s, side="right") - 1
    return k >= 0 and time_s < site.warning_ends[k]


@numba.njit(cache=True)
def learnt_clutter(stopped, moved, time_s, born_s, clutter_age_s):  # type: ignore[no-untyped-def]
    """Return the static objects older than ``clutter_age_s`` [s] (bool per track).

    Barrier posts, rails: their detections are their own (:func:`.gate.reserve_clutter`);
    a young one may be a vehicle waiting at a closure.
    """
    clutter = np.empty(stopped.size, np.bool_)
    for i in range(stopped.size):
        clutter[i] = stopped[i] and not moved[i] and time_s[i] - born_s[i] >= clutter_age_s
    return clutter


@numba.njit(cache=True)
def _out_room(o, n_out, more):  # type: ignore[no-untyped-def]
    """Return the row buffer ``o`` (``n_out`` rows used) with room for ``more`` rows."""
    if n_out + more <= o.track_id.shape[0]:
        return o
    size = 2 * (n_out + more) + 1024
    return RowBuffer(
        _grown(o.track_id, n_out, size), _grown(o.time_s, n_out, size),
        _grown(o.east_m, n_out, size), _grown(o.north_m, n_out, size),
        _grown(o.speed_mps, n_out, size), _grown(o.east_speed_mps, n_out, size),
        _grown(o.north_speed_mps, n_out, size), _grown(o.from_crossing_m, n_out, size),
        _grown(o.status, n_out, size), _grown(o.moved, n_out, size),
        _grown(o.position_std_m, n_out, size), _grown(o.speed_std_mps, n_out, size),
    )  # fmt: skip


@numba.njit(cache=True)
def write_rows(t, n, time_s, s, site, rows_out, n_out):  # type: ignore[no-untyped-def]
    """Append the confirmed tracks at ``time_s``; return the buffer (grown if full), count."""
    rows_out = _out_room(rows_out, n_out, n)
    v = _live(t, n)
    return rows_out, _write_rows_into(v, time_s, s, site, _borrowed_out(rows_out), n_out)


@numba.njit(cache=True)
def _write_rows_into(v, time_s, s, site, rows_out, n_out):  # type: ignore[no-untyped-def]
    """:func:`write_rows` of the live rows ``v`` into a buffer with room; return its count."""
    rows, status = confirmed_rows(
        v.confirmed, v.time_s, v.last_hit_s, v.stopped, v.moved, v.x, v.spread, v.corridor,
        s.merge_lateral_m, s.coasting_s, s.status_codes,
    )  # fmt: skip
    m = rows.size
    pos, vel, pos_std, to_cross = np.zeros((m, 2)), np.zeros((m, 2)), np.zeros(m), np.zeros(m)
    planar_rows(
        rows, v.x, v.p, v.corridor, site.roads, site.bounds, site.crossing_u, pos, vel, pos_std,
        to_cross,
    )  # fmt: skip
    o, ids, moved, p = rows_out, v.ids, v.moved, v.p  # columns taken once, not per row
    track_id, time_col, status_col, moved_col = o.track_id, o.time_s, o.status, o.moved
    east, north, speed, east_speed = o.east_m, o.north_m, o.speed_mps, o.east_speed_mps
    north_speed, from_crossing = o.north_speed_mps, o.from_crossing_m
    position_std, speed_std = o.position_std_m, o.speed_std_mps
    for k in range(m):
        i, r = rows[k], n_out + k
        track_id[r], time_col[r], status_col[r], moved_col[r] = ids[i], time_s, status[k], moved[i]
        east[r], north[r] = pos[k, 0], pos[k, 1]
        speed[r] = math.hypot(vel[k, 0], vel[k, 1])
        east_speed[r], north_speed[r] = vel[k, 0], vel[k, 1]
        from_crossing[r], position_std[r] = to_cross[k], pos_std[k]
        speed_std[r] = math.sqrt(p[i, 1, 1])
    return n_out + m


@numba.njit(cache=True)
def run_scans(  # type: ignore[no-untyped-def]
    t, n, next_id, s, site, radars, log, z_all, ids_all, starts, scan_radar, scan_stamp,
    outside, events, n_events, record, rows_out, n_out,
):  # fmt: skip
    """Process scans in order; return ``(t, n, next_id, events, n_events, rows_out, n_out)``.

    ``t`` (:class:`TrackRows`, ``n`` live rows, more may be spare), ``next_id`` the next track
    id. Scan ``k`` is the detections ``z_all[starts[k]:starts[k+1]]`` (range, azimuth, radial
    speed) with their sensor ids, of radar ``scan_radar[k]``, stamped ``scan_stamp[k]`` [s]
    (made at that less the radar's latency). ``radars`` (:class:`RadarState`) and ``log``
    (counts of :data:`LOG_FIELDS`) are updated in place; ``outside`` (bool per detection) is set
    for the detections beyond every field of view (rejected). Events go to ``events`` (E,
    :data:`EVENT_FIELDS`); with ``record``, each scan's confirmed tracks to ``rows_out``.
    Each scan is the steps of :meth:`adaptrack.crossing.scene.tracker.SceneTracker.step`.
    """
    site = _borrowed_site(site)  # the caller's site outlives the call
    # the track rows and the output buffer are grown here as needed: the owners (returned),
    # and views without reference counting for the scans
    rows_own, t = t, _borrowed_tracks(t)
    out_own, out = rows_out, _borrowed_out(rows_out)
    v = _live(t, n)  # the live rows' views, renewed whenever the rows change or grow
    for k in range(scan_radar.size):
        r = scan_radar[k]
        radars.last_stamp_s[r] = scan_stamp[k]
        time_s = scan_stamp[k] - site.latency_s[r]
        a, b = starts[k], starts[k + 1]
        z = z_all[a:b].copy()
        ids = ids_all[a:b]
        bias = radars.azimuth_bias_rad[r]
        if bias:
            for j in range(z.shape[0]):
                z[j, 1] = wrapped(z[j, 1] - bias, np.pi)
        radar = site.radar[r]
        fields = site.fields[r, : site.field_count[r]]
        sensor = RadarView(
            radar, site.noise_tab[r], site.noise_cnt[r], fields, site.pd_tab[r], site.pd_cnt[r]
        )
        # learnt clutter (as of the tracks' last scans) is frozen: neither predicted nor updated
        clutter = learnt_clutter(v.stopped, v.moved, v.time_s, v.born_s, s.clutter_age_s)
        for i in range(n):
            if not clutter[i]:  # its stored views of the radars are out of date
                v.clutter_views[i, :, 0] = 0.0
        predict_tracks(v, clutter, time_s, s)
        view = detections_in_view(z, radar, fields)
        n_out_view = 0
        for j in range(view.size):
            outside[a + j] = not view[j]
            n_out_view += not view[j]
        if n_out_view:
            log[LOG_OUTSIDE_VIEW] += n_out_view
            z, ids = z[view], ids[view]
        used = np.zeros(z.shape[0], np.bool_)
        if n:
            seen, d2, logdet, gated, simple, ti, di, sight = associate_scan(
                v, clutter, r, site, sensor, s, z, ids
            )
            if not simple:
                solved, ti, di = assignment_by_components(d2, s.gate, MAX_CHOICES)
                if not solved:
                    ti, di = _assign(d2, s.gate)
            stats = radars.bias_stats[r]
            used = apply_scan(
                time_s, seen, clutter, d2, logdet, gated, sight, ti, di, z,
                ids, r, v, site, sensor, s, bias, stats,
            )  # fmt: skip
            if stats[BIAS_SAMPLES] >= s.bias_min_samples:
                radars.azimuth_bias_rad[r] = stats[BIAS_SUM] / stats[BIAS_WEIGHT]
        n_used = 0
        for j in range(used.size):
            n_used += used[j]
        log[LOG_UPDATED] += n_used
        if n_used < used.size:  # open tentative tracks from the detections left over
            left = rows_where(used, False)
            corridor, x, p, labels, first = open_tracks(z[left], site, sensor, s)
            near_road = np.empty(corridor.size, np.bool_)  # else beside every road: not opened
            m, off_road = 0, 0  # bodies opened; detections of the bodies beside every road
            for g in range(corridor.size):
                near_road[g] = abs(x[g, 3]) <= s.max_open_offset_m
                m += near_road[g]
            for j in range(left.size):
                off_road += not near_road[labels[j]]
            if m:
                rows_own, t = _room(rows_own, t, n, n + m)
                left_ids = ids[left]
                k = n
                for g in range(corridor.size):
                    if near_road[g]:
                        new_row(
                            t, k, next_id + k - n, time_s, corridor[g], x[g], p[g],
                            s.body_along_std_m, r, left_ids[first[g]],
                        )  # fmt: skip
                        k += 1
                n += m
                next_id += m
                v = _live(t, n)  # the rows grew
            log[LOG_OPENED] += m
            log[LOG_JOINED_NEW] += left.size - m - off_road
            log[LOG_OFF_ROAD] += off_road
        # modes and hazard events
        hazard, on_road = mode_changes(time_s, v, site, s)
        if hazard.any():
            alarm = new_objects(v, n, hazard, s, site)
            for i in np.flatnonzero(alarm):
                events, n_events = _record_event(events, n_events, v, i, site, time_s, 0, np.nan)
        if warning_on(site, time_s):
            cant, lead = stop_line_rows(v, n, time_s, on_road, s, site)
            for i in np.flatnonzero(cant):
                events, n_events = _record_event(events, n_events, v, i, site, time_s, 1, lead[i])
        # split a stopped track over two queued bodies: the part towards the crossing keeps it
        rows, half, body = split_rows(
            v.stopped, v.moved, v.along_m2, v.along_m4, s.split_kurtosis, s.split_min_half_gap_m
        )
        if rows.size:
            rows_own, t = _room(rows_own, t, n, n + rows.size)
            for g in range(rows.size):
                i, j = rows[g], n + g
                towards = 1.0 if site.crossing_u[t.corridor[i]] >= t.x[i, 0] else -1.0
                u = t.x[i, 0]
                spread = min(max(body[g], s.spread_lo_m), s.spread_hi_m)
                _copy_row(t, i, j)
                _place(t, i, u + towards * half[g], spread)
                _place(t, j, u - towards * half[g], spread)
                t.ids[j], t.born_s[j] = next_id + g, time_s
            n += rows.size
            next_id += rows.size
            v = _live(t, n)  # the rows grew
        # delete the expired, the departed and the younger of two tracks on one body
        dead = retired_rows(time_s, v, site, s)
        if dead.any():
            n = _compacted(v, n, dead)  # rows move within the live ones
            v = _live(t, n)
        if record:
            if n_out + n > out_own.track_id.shape[0]:
                out_own = _out_room(out_own, n_out, n)
                out = _borrowed_out(out_own)
            n_out = _write_rows_into(v, time_s, s, site, out, n_out)
    return rows_own, n, next_id, events, n_events, out_own, n_out
