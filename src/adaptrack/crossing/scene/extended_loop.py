"""The extended tracker's scan loop, compiled: many scans per call, equal to the NumPy reference.

:class:`.extended_tracker.ExtendedTracker` is the reference, one scan per call, written for
reading; :func:`run_scans` is the same computation, operation for operation, over a range of
scans in one compiled call (numba), for speed. ``tests/crossing/test_extended_loop.py``
checks that the two give the same tracks, events and detection counts on scenes that take
every branch (births, duplicates, background reflectors, trains, every radar kind).

Layout of the arguments (built by :func:`.extended_tracker.track_scene_extended`):

- ``cfg`` (``N_CFG``,): the settings, in the order of :data:`CFG_FIELDS`;
- ``radars`` per site radar: geometry rows (R, 7) as ``RadarSpec.kernel_row``, fields
  (R, F, 2) with their counts (R,), noise curves (R, 3, 2, K) and counts (R, 3), the default
  P_D curve (R, 1, 2, K) and counts (R, 1), the antenna height (R,);
- ``tracks``: the track arrays in the order of :data:`TRACK_ARRAYS`, with room to spare;
- ``learnt``: per radar the count model (object rate (R, B), clutter mean (R,), P_D hits and
  chances (R, B)) and the clutter map as dense cells (counts and last scans (R, NX, NY), the
  first cell (R, 2), scans seen (R,));
- ``background``: reflector regions per site radar (R, NX, NY; 0: none), the map's origin
  (2,), cell size, static speed, reflector means (K, 2), covariances (K, 2, 2), rates (K,),
  each radar's reflectors (R, K) with counts (R,), and the CUSUM (K,); ``has_background``;
- ``scene``: lane points (L, 2) and directions (L, 2), the crossing area raster (n, n), its
  origin (2,), the train intervals (T, 2), the rails row (centre x, y, direction x, y,
  half width, a train's least speed along them, the tangent of its largest angle to them;
  half width < 0: no rails), the lane points' grid (:func:`lane_grid`);
- ``state`` (int64): tracks held, next id, the crossing's occupant (-1: clear), rows and
  events written, scans done; ``log`` (5,): updated, opened, joined new, outside view,
  background;
- outputs: ``rows_f`` (M, N_ROW_F) and ``rows_i`` (M, 3) (track id, status, moved) of the
  reported tracks after each scan, ``events`` (E, 5) (time, kind 0 not clear / 1 clear,
  track id, east, north).

The call stops early (returning the scan it reached) when the tracks or the outputs could
run out of room in the next scan; the caller grows them and calls again.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ...angles import wrapped
from ...tracking.assignment import cluster_labels
from ..site.geometry import curve_at, in_view, off_boresight

CFG_FIELDS = (
    "accel_psd", "turn_psd", "gate", "shape_model_std_m", "body_doppler_std_mps",
    "birth_density", "clutter_prior_density", "clutter_doppler_span_mps", "clutter_cell_m",
    "clutter_memory_scans", "lifetime_s", "report_existence", "report_speed_std_mps",
    "keep_existence", "drop_existence", "lost_position_std_m", "cluster_gap_m",
    "lane_prior_m", "lane_speed_std_mps", "lane_across_std_mps", "initial_speed_std_mps",
    "initial_turn_std_radps", "prior_length_m", "prior_width_m", "prior_length_std_m",
    "prior_width_std_m", "min_extent_m", "max_extent_m", "extent_learning_rate",
    "count_shape", "count_learning_rate", "body_height_m", "same_body_sigmas",
    "background_alarm_nats", "stopped_speed_mps", "moved_speed_mps", "extent_floor_m",
    "object_reach_m", "coasting_s", "range_bin_m", "radar_share", "pd_prior", "pd_memory",
    "clutter_prior_scans", "area_cell_m",
)  # fmt: skip
N_CFG = len(CFG_FIELDS)
(ACCEL, TURN, GATE, SHAPE, BODY_DOPPLER, BIRTH, CLUTTER_PRIOR, SPAN, CELL, MEMORY, LIFETIME,
 REPORT, REPORT_SPEED, KEEP, DROP, LOST, GAP, LANE_PRIOR, LANE_SPEED, LANE_ACROSS,
 INITIAL_SPEED, INITIAL_TURN, PRIOR_L, PRIOR_W, PRIOR_L_STD, PRIOR_W_STD, MIN_EXTENT,
 MAX_EXTENT, EXTENT_RATE, COUNT_SHAPE, COUNT_RATE, BODY_HEIGHT, SAME_BODY, ALARM, STOPPED,
 MOVED, EXTENT_FLOOR, OBJECT_REACH, COASTING, RANGE_BIN, RADAR_SHARE, PD_PRIOR, PD_MEMORY,
 CLUTTER_PRIOR_SCANS, AREA_CELL) = range(N_CFG)  # fmt: skip
ROW_F_FIELDS = (
    "time_s", "east_m", "north_m", "east_speed_mps", "north_speed_mps", "speed_mps",
    "position_std_m", "speed_std_mps", "existence", "length_m", "width_m", "heading_rad",
    "length_var", "width_var", "top_speed_mps",
)  # fmt: skip
N_ROW_F = len(ROW_F_FIELDS)
TRACK_ARRAYS = (
    "x",
    "p",
    "time_s",
    "existence",
    "heading_rad",
    "extent",
    "extent_var",
    "born_s",
    "last_hit_s",
    "hits",
    "moved",
    "reported",
    "rate",
    "top_speed_mps",
    "track_id",
)  # the order of the ``tracks`` tuple
CONFIRMED, COASTING_STATUS, STOPPED_STATUS = 0, 1, 2  # set by the caller's STATUS_NAMES
SERIES_BELOW = 1e-3  # as models.turn
# state slots
N_TRACKS, NEXT_ID, OCCUPANT, N_ROWS, N_EVENTS, SCANS_DONE = range(6)
# log slots
UPDATED, OPENED, JOINED_NEW, OUTSIDE, BACKGROUND_LOG = range(5)

_njit = numba.njit(cache=True, error_model="numpy")
_inline = numba.njit(cache=True, error_model="numpy", inline="always")


@_inline
def _faces(cx, cy, h, length, width, rx, ry):  # type: ignore[no-untyped-def]
    """One box's face moments as :func:`.box_view.face_moments`: offset x, y, cov 00, 01, 11."""
    half_l, half_w = 0.5 * length, 0.5 * width
    axx, axy = math.cos(h), math.sin(h)
    ayx, ayy = -axy, axx
    tx, ty = rx - cx, ry - cy
    dist = math.sqrt(tx * tx + ty * ty)
    d = max(dist, 1e-9)
    sx, sy = tx / d, ty / d
    mx = my = s00 = s01 = s11 = total = 0.0
    for f in range(4):
        if f == 0:
            nx, ny, reach, half_len, ux, uy = axx, axy, half_l, half_w, ayx, ayy
        elif f == 1:
            nx, ny, reach, half_len, ux, uy = -axx, -axy, half_l, half_w, ayx, ayy
        elif f == 2:
            nx, ny, reach, half_len, ux, uy = ayx, ayy, half_w, half_l, axx, axy
        else:
            nx, ny, reach, half_len, ux, uy = -ayx, -ayy, half_w, half_l, axx, axy
        facing = tx * nx + ty * ny
        w = 2.0 * half_len * (sx * nx + sy * ny) if facing > reach else 0.0
        midx, midy = reach * nx, reach * ny
        sp = half_len * half_len / 3.0
        mx += w * midx
        my += w * midy
        s00 += w * (midx * midx + sp * ux * ux)
        s01 += w * (midx * midy + sp * ux * uy)
        s11 += w * (midy * midy + sp * uy * uy)
        total += w
    if total > 0:
        mx, my = mx / total, my / total
        return mx, my, s00 / total - mx * mx, s01 / total - mx * my, s11 / total - my * my
    a, b = half_l * half_l / 3.0, half_w * half_w / 3.0
    return 0.0, 0.0, a * axx * axx + b * ayx * ayx, a * axx * axy + b * ayx * ayy, (
        a * axy * axy + b * ayy * ayy)  # fmt: skip


@_inline
def _covers(px, py, radar, fields):  # type: ignore[no-untyped-def]
    """Whether a ground point lies in the radar's view (``RadarSpec.covers``)."""
    ex, ey = px - radar[0], py - radar[1]
    rng = math.hypot(math.hypot(ex, ey), radar[2])
    return in_view(rng, off_boresight(math.atan2(ex, ey), radar), fields, radar[4])


@_inline
def _unfold(dv, radar):  # type: ignore[no-untyped-def]
    """Fold a radial-speed residual into +-v_max of a folding radar (else unchanged)."""
    if radar[6] == 0.0:
        return dv
    return wrapped(dv, radar[6])


@_inline
def _bin(ground_m, cfg, n_bins):  # type: ignore[no-untyped-def]
    return min(int(ground_m / cfg[RANGE_BIN]), n_bins - 1)


@_inline
def _count_ratio(n, rate, shape, clutter_mean):  # type: ignore[no-untyped-def]
    """Likelihood ratio object / clutter of ``n`` detections (:func:`existence.count_ratio`)."""
    mu = max(rate, 1e-9)
    k = shape
    log_zero = k * math.log(k / (k + mu))
    log_nb = (math.lgamma(n + k) - math.lgamma(k) - math.lgamma(n + 1.0) + log_zero
              + n * math.log(mu / (k + mu)))  # fmt: skip
    log_object = log_nb - math.log1p(-math.exp(log_zero))
    q = 1.0 - 1.0 / max(clutter_mean, 1.0 + 1e-9)
    log_clutter = math.log1p(-q) + (n - 1.0) * math.log(q)
    return math.exp(min(log_object - log_clutter, 700.0))


@_inline
def _clutter_density(xy0, xy1, r, cfg, clutter):  # type: ignore[no-untyped-def]
    """Return a radar's clutter density at a point [per m^2 per scan] (``ClutterMap.density``)."""
    count, last, first, scans = clutter
    keep = 1.0 - 1.0 / cfg[MEMORY]
    weight = (1.0 - keep ** scans[r]) / (1.0 - keep)
    cell = cfg[CELL]
    area = cell * cell
    i = math.floor(xy0 / cell) - first[r, 0]
    j = math.floor(xy1 / cell) - first[r, 1]
    c = 0.0
    if 0 <= i < count.shape[1] and 0 <= j < count.shape[2]:
        c = count[r, i, j] * keep ** (scans[r] - last[r, i, j])
    return (c + cfg[CLUTTER_PRIOR] * area * cfg[CLUTTER_PRIOR_SCANS]) / (
        (weight + cfg[CLUTTER_PRIOR_SCANS]) * area
    )


@_inline
def _unit(vx, vy):  # type: ignore[no-untyped-def]
    norm = math.hypot(vx, vy)
    if norm > 1e-9:
        return vx / norm, vy / norm
    return 1.0, 0.0


@_njit
def _predict(tracks, n, t_scan, cfg):  # type: ignore[no-untyped-def]
    """Predict every track to the scan time (``ExtendedTracker._predict``)."""
    x, p, time_s, existence, heading = tracks[0], tracks[1], tracks[2], tracks[3], tracks[4]
    f = np.zeros((5, 5))
    fp = np.zeros((5, 5))
    for i in range(n):
        dt = max(t_scan - time_s[i], 0.0)
        vx, vy, w = x[i, 2], x[i, 3], x[i, 4]
        u = w * dt
        s, c = math.sin(u), math.cos(u)
        u2 = u * u
        if abs(u) < SERIES_BELOW:
            a = dt * (1 - u2 / 6 + u2 * u2 / 120)
            b = dt * u * (0.5 - u2 / 24 + u2 * u2 / 720)
            da = dt * dt * u * (-1 / 3 + u2 / 30)
            db = dt * dt * (0.5 - u2 / 8 + u2 * u2 / 144)
        else:
            ww = u / (dt if dt > 0 else 1.0)
            a = s / ww
            b = (1 - c) / ww
            da = (dt * c - a) / ww
            db = (dt * s - b) / ww
        f[:] = 0.0
        for k in range(5):
            f[k, k] = 1.0
        f[0, 2], f[0, 3], f[0, 4] = a, -b, da * vx - db * vy
        f[1, 2], f[1, 3], f[1, 4] = b, a, db * vx + da * vy
        f[2, 2], f[2, 3], f[2, 4] = c, -s, -dt * (s * vx + c * vy)
        f[3, 2], f[3, 3], f[3, 4] = s, c, dt * (c * vx - s * vy)
        x[i, 0] += a * vx - b * vy
        x[i, 1] += b * vx + a * vy
        x[i, 2] = c * vx - s * vy
        x[i, 3] = s * vx + c * vy
        # F P F^T over F's non-zeros: row r of F holds r and 2, 3, 4 (row 4: only 4)
        for r in range(5):
            for k in range(5):
                acc = 0.0 if r >= 2 else p[i, r, k]
                for m in range(2, 5):
                    acc += f[r, m] * p[i, m, k]
                fp[r, k] = acc
        for r in range(5):
            for k in range(5):
                acc = 0.0 if k >= 2 else fp[r, k]
                for m in range(2, 5):
                    acc += fp[r, m] * f[k, m]
                p[i, r, k] = acc
        q = cfg[ACCEL]
        for axis in range(2):
            p[i, axis, axis] += q * dt**3 / 3
            p[i, axis, axis + 2] += q * dt**2 / 2
            p[i, axis + 2, axis] += q * dt**2 / 2
            p[i, axis + 2, axis + 2] += q * dt
        p[i, 4, 4] += cfg[TURN] * dt
        for r in range(5):
            for k in range(r + 1, 5):
                m = 0.5 * (p[i, r, k] + p[i, k, r])
                p[i, r, k] = p[i, k, r] = m
        time_s[i] = t_scan
        existence[i] = existence[i] * math.exp(-dt / cfg[LIFETIME])
        speed = math.hypot(x[i, 2], x[i, 3])
        ux, uy = _unit(x[i, 2], x[i, 3])
        speed_var = ux * (p[i, 2, 2] * ux + p[i, 2, 3] * uy) + uy * (p[i, 3, 2] * ux
                                                                     + p[i, 3, 3] * uy)  # fmt: skip
        if speed > 2.0 * math.sqrt(speed_var) + 0.3:
            heading[i] = math.atan2(x[i, 3], x[i, 2])


@_njit
def _view_share(tracks, n, offset, spread, radar, fields):  # type: ignore[no-untyped-def]
    """Each track's share of five points in view (``ExtendedTracker._view_share``)."""
    x, p = tracks[0], tracks[1]
    share = np.zeros(n)
    for i in range(n):
        cx, cy = x[i, 0] + offset[i, 0], x[i, 1] + offset[i, 1]
        a = p[i, 0, 0] + spread[i, 0]
        b = p[i, 0, 1] + spread[i, 1]
        c = p[i, 1, 1] + spread[i, 2]
        mid, rad = 0.5 * (a + c), math.sqrt(0.25 * (a - c) ** 2 + b * b)
        l1, l2 = mid + rad, mid - rad
        if b != 0.0:
            v1x, v1y = l1 - c, b
        elif a >= c:
            v1x, v1y = 1.0, 0.0
        else:
            v1x, v1y = 0.0, 1.0
        norm = math.hypot(v1x, v1y)
        v1x, v1y = v1x / norm, v1y / norm
        r1, r2 = 2.0 * math.sqrt(max(l1, 0.0)), 2.0 * math.sqrt(max(l2, 0.0))
        hits = 1.0 if _covers(cx, cy, radar, fields) else 0.0
        for sign in (1.0, -1.0):
            if _covers(cx + sign * r1 * v1x, cy + sign * r1 * v1y, radar, fields):
                hits += 1.0
            if _covers(cx - sign * r2 * v1y, cy + sign * r2 * v1x, radar, fields):
                hits += 1.0
        share[i] = hits / 5.0
    return share


@_njit
def _detection_probability(tracks, n, seen, radar, r, pd_tab, pd_n, antenna, cfg, learnt):  # type: ignore[no-untyped-def]
    """Each track's P_D and whether nothing hides it (``_detection_probability``)."""
    x, extent = tracks[0], tracks[5]
    pd_hits, pd_chances = learnt[2], learnt[3]
    n_bins = pd_hits.shape[1]
    ground = np.empty(n)
    az = np.empty(n)
    half = np.empty(n)
    pd = np.zeros(n)
    for i in range(n):
        ex, ey = x[i, 0] - radar[0], x[i, 1] - radar[1]
        ground[i] = math.hypot(ex, ey)
        rng = math.hypot(ground[i], radar[2])
        az[i] = math.atan2(ex, ey)
        declared = curve_at(pd_tab[r], pd_n[r], 0, rng)
        k = _bin(ground[i], cfg, n_bins)
        learnt_pd = (pd_hits[r, k] + cfg[PD_PRIOR] * declared) / (pd_chances[r, k] + cfg[PD_PRIOR])
        pd[i] = learnt_pd if seen[i] else 0.0
        half[i] = math.atan2(0.5 * math.hypot(extent[i, 0], extent[i, 1]), max(ground[i], 1e-6))
    hidden = np.zeros(n)
    for i in range(n):
        if not seen[i]:
            continue
        for j in range(n):
            if not seen[j] or ground[j] >= ground[i] or j == i:
                continue
            diff = az[i] - az[j]
            turn = 2 * math.pi
            lap = half[i] + half[j] - abs(diff - turn * math.floor(diff / turn + 0.5))
            if lap <= 0:
                continue
            share = min(lap / (2 * half[i]), 1.0)
            line = antenna - (antenna - cfg[BODY_HEIGHT]) * ground[i] / max(ground[j], 1e-6)
            depth = min(max(line / cfg[BODY_HEIGHT], 0.0), 1.0)
            hidden[i] = max(hidden[i], share * depth)
    clear = np.empty(n, np.bool_)
    for i in range(n):
        pd[i] = pd[i] * (1.0 - hidden[i])
        clear[i] = hidden[i] == 0.0
    return pd, clear


@_njit
def _learn_extent(tracks, i, g, g_cov, rows, radar, cfg):  # type: ignore[no-untyped-def]
    """Move a box's length and width towards its detections' spread (``_learn_extent``)."""
    x, heading, extent, extent_var = tracks[0], tracks[4], tracks[5], tracks[6]
    h = heading[i]
    ax = (math.cos(h), math.sin(h))
    ay = (-math.sin(h), math.cos(h))
    m = rows.size
    mx = my = 0.0
    for q in rows:
        mx += g[q, 0]
        my += g[q, 1]
    mx, my = mx / m, my / m
    _, _, c00, c01, c11 = _faces(x[i, 0], x[i, 1], h, extent[i, 0], extent[i, 1],
                                 radar[0], radar[1])  # fmt: skip
    rate = cfg[EXTENT_RATE]
    for k in range(2):
        u = ax if k == 0 else ay
        s = s2 = noise = 0.0
        for q in rows:
            v = (g[q, 0] - mx) * u[0] + (g[q, 1] - my) * u[1]
            s += v
            s2 += v * v
            noise += u[0] * (g_cov[q, 0, 0] * u[0] + g_cov[q, 0, 1] * u[1]) + u[1] * (
                g_cov[q, 1, 0] * u[0] + g_cov[q, 1, 1] * u[1])  # fmt: skip
        var = (s2 - s * s / m) / (m - 1)
        observed = max(var - noise / m, 0.0)
        expected = u[0] * (c00 * u[0] + c01 * u[1]) + u[1] * (c01 * u[0] + c11 * u[1])
        size = extent[i, k]
        if expected >= 0.25 * size * size / 12.0:
            square = size * size * (1.0 + rate * (observed / expected - 1.0))
            extent[i, k] = min(max(math.sqrt(max(square, 0.0)), cfg[MIN_EXTENT]),
                               cfg[MAX_EXTENT])  # fmt: skip
            extent_var[i, k] = (1.0 - rate) * extent_var[i, k] + rate * cfg[EXTENT_FLOOR] ** 2


@_inline
def _inverse3(s):  # type: ignore[no-untyped-def]
    """Return the inverse of a 3 x 3 matrix (cofactors) and its determinant."""
    c00 = s[1, 1] * s[2, 2] - s[1, 2] * s[2, 1]
    c01 = s[1, 2] * s[2, 0] - s[1, 0] * s[2, 2]
    c02 = s[1, 0] * s[2, 1] - s[1, 1] * s[2, 0]
    det = s[0, 0] * c00 + s[0, 1] * c01 + s[0, 2] * c02
    out = np.empty((3, 3))
    out[0, 0], out[1, 0], out[2, 0] = c00 / det, c01 / det, c02 / det
    out[0, 1] = (s[0, 2] * s[2, 1] - s[0, 1] * s[2, 2]) / det
    out[1, 1] = (s[0, 0] * s[2, 2] - s[0, 2] * s[2, 0]) / det
    out[2, 1] = (s[0, 1] * s[2, 0] - s[0, 0] * s[2, 1]) / det
    out[0, 2] = (s[0, 1] * s[1, 2] - s[0, 2] * s[1, 1]) / det
    out[1, 2] = (s[0, 2] * s[1, 0] - s[0, 0] * s[1, 2]) / det
    out[2, 2] = (s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]) / det
    return out, det


@_njit
def _update(tracks, i, rows, g, g_cov, a, v_var, vr, offset, spread, radar, r, cfg, clutter):  # type: ignore[no-untyped-def]
    """Update track ``i`` with its detections ``rows``; return their likelihood ratio."""
    x, p = tracks[0], tracks[1]
    moved, reported, top_speed = tracks[10], tracks[11], tracks[13]
    n = rows.size
    h = np.zeros((3, 5))
    h[0, 0] = h[1, 1] = 1.0
    zb = np.zeros(3)
    gc = np.zeros((2, 2))
    vv = 0.0
    arm = 0.0
    for q in rows:
        lx, ly = g[q, 0] - x[i, 0], g[q, 1] - x[i, 1]
        h[2, 2] += a[q, 0]
        h[2, 3] += a[q, 1]
        arm += a[q, 0] * -ly + a[q, 1] * lx
        zb[0] += g[q, 0]
        zb[1] += g[q, 1]
        zb[2] += vr[q]
        gc += g_cov[q]
        vv += v_var[q]
    h[2, 2] /= n
    h[2, 3] /= n
    h[2, 4] = arm / n
    zb /= n
    predicted = np.empty(3)
    predicted[0] = x[i, 0] + offset[i, 0]
    predicted[1] = x[i, 1] + offset[i, 1]
    predicted[2] = h[2, 2] * x[i, 2] + h[2, 3] * x[i, 3] + h[2, 4] * x[i, 4]
    rm = np.zeros((3, 3))
    sm2 = cfg[SHAPE] ** 2
    rm[0, 0] = gc[0, 0] / n**2 + spread[i, 0] / n + sm2
    rm[0, 1] = rm[1, 0] = gc[0, 1] / n**2 + spread[i, 1] / n
    rm[1, 1] = gc[1, 1] / n**2 + spread[i, 2] / n + sm2
    rm[2, 2] = vv / n / n + cfg[BODY_DOPPLER] ** 2
    innov = zb - predicted
    innov[2] = _unfold(innov[2], radar)
    pi = p[i]
    ph = np.empty((5, 3))  # P H^T (H: x, y and the radial-speed row)
    for a_ in range(5):
        ph[a_, 0], ph[a_, 1] = pi[a_, 0], pi[a_, 1]
        ph[a_, 2] = pi[a_, 2] * h[2, 2] + pi[a_, 3] * h[2, 3] + pi[a_, 4] * h[2, 4]
    s = np.empty((3, 3))
    for b_ in range(3):
        s[0, b_], s[1, b_] = ph[0, b_] + rm[0, b_], ph[1, b_] + rm[1, b_]
        s[2, b_] = ph[2, b_] * h[2, 2] + ph[3, b_] * h[2, 3] + ph[4, b_] * h[2, 4] + rm[2, b_]
    s_inv, det_s = _inverse3(s)
    k = ph @ s_inv
    x[i] += k @ innov
    ikh = -(k @ h)
    for a_ in range(5):
        ikh[a_, a_] += 1.0
    post = ikh @ pi @ ikh.T + k @ rm @ k.T
    p[i] = 0.5 * (post + post.T)
    if n >= 3:
        _learn_extent(tracks, i, g, g_cov, rows, radar, cfg)
    speed = math.hypot(x[i, 2], x[i, 3])
    known = p[i, 2, 2] + p[i, 3, 3] < 1.0
    moved[i] = moved[i] or (speed > cfg[MOVED] and known)
    if known and reported[i]:
        top_speed[i] = max(top_speed[i], speed)
    density = _clutter_density(zb[0], zb[1], r, cfg, clutter) / cfg[SPAN]
    d2 = innov @ s_inv @ innov
    g_z = math.exp(-0.5 * d2) / math.sqrt((2 * math.pi) ** 3 * det_s)
    return g_z / density


@_njit
def _nearest_lane(cx, cy, lanes, lane_index):  # type: ignore[no-untyped-def]
    """Return the nearest lane point within one grid cell's reach (-1: none) and its distance.

    ``lane_index``: the lane points bucketed in square cells (``lane_grid``); the cell of
    the point and its eight neighbours hold every lane point within a cell's size of it. Of
    equally near points the first is taken.
    """
    order, start, grid = lane_index
    x0, y0, cell, nx, ny = grid[0], grid[1], grid[2], int(grid[3]), int(grid[4])
    ci, cj = math.floor((cx - x0) / cell), math.floor((cy - y0) / cell)
    best, best_d2 = -1, np.inf
    for i in range(max(ci - 1, 0), min(ci + 2, nx)):
        for j in range(max(cj - 1, 0), min(cj + 2, ny)):
            for q in range(start[i * ny + j], start[i * ny + j + 1]):
                k = order[q]
                d2 = (lanes[k, 0] - cx) ** 2 + (lanes[k, 1] - cy) ** 2
                if d2 < best_d2 or (d2 == best_d2 and k < best):
                    best, best_d2 = k, d2
    return best, math.sqrt(best_d2)


def lane_grid(lanes: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bucket lane points (L, 2) in square cells of ``cell_m`` for :func:`_nearest_lane`.

    Returns the points' order by cell, each cell's first position in it (cells + 1,) and the
    grid (x0, y0, cell, nx, ny).
    """
    if not len(lanes):
        return np.zeros(0, np.int64), np.zeros(2, np.int64), np.array([0.0, 0.0, cell_m, 1, 1])
    lo = lanes.min(axis=0)
    ij = np.floor((lanes - lo) / cell_m).astype(np.int64)
    nx, ny = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
    key = ij[:, 0] * ny + ij[:, 1]
    order = np.argsort(key, kind="stable").astype(np.int64)
    start = np.searchsorted(key[order], np.arange(nx * ny + 1)).astype(np.int64)
    return order, start, np.array([lo[0], lo[1], cell_m, nx, ny], float)


@_njit
def _open(  # type: ignore[no-untyped-def]
    tracks, n, next_id, rows, g, g_cov, a, v_var, vr, t_scan, existence0, radar, cfg, lanes,
    lane_dir, lane_index, train, rails,
):  # fmt: skip
    """Open a track on a group of unexplained detections (``ExtendedTracker._open``)."""
    m = rows.size
    cx = cy = 0.0
    gc = np.zeros((2, 2))
    am = np.zeros(2)
    vrm = vv = 0.0
    for q in rows:
        cx += g[q, 0]
        cy += g[q, 1]
        gc += g_cov[q]
        am += a[q]
        vrm += vr[q]
        vv += v_var[q]
    cx, cy = cx / m, cy / m
    am /= m
    vrm /= m
    vv /= m
    best, best_d = _nearest_lane(cx, cy, lanes, lane_index)
    along = best >= 0 and best_d <= cfg[LANE_PRIOR]
    dx = dy = 0.0
    if along:
        dx, dy = lane_dir[best, 0], lane_dir[best, 1]
    if train and _on_rails(cx, cy, rails):  # a train is due: the rails are a lane too
        noise = vv / m + cfg[BODY_DOPPLER] ** 2
        if not along or _lane_fit(rails[2], rails[3], am, vrm, noise, cfg) > _lane_fit(
            dx, dy, am, vrm, noise, cfg
        ):
            dx, dy, along = rails[2], rails[3], True
    if along:
        heading = math.atan2(dy, dx)
    else:
        heading = math.atan2(radar[1] - cy, radar[0] - cx)
    length, width = cfg[PRIOR_L], cfg[PRIOR_W]
    ox, oy, s00, s01, s11 = _faces(cx, cy, heading, length, width, radar[0], radar[1])
    x = np.zeros(5)
    x[0], x[1] = cx - ox, cy - oy
    p = np.zeros((5, 5))
    sm2 = cfg[SHAPE] ** 2
    p[0, 0] = gc[0, 0] / m**2 + s00 + sm2
    p[0, 1] = p[1, 0] = gc[0, 1] / m**2 + s01
    p[1, 1] = gc[1, 1] / m**2 + s11 + sm2
    if along:
        sa, sc = cfg[LANE_SPEED] ** 2, cfg[LANE_ACROSS] ** 2
        p[2, 2] = sa * dx * dx + sc * (1.0 - dx * dx)
        p[2, 3] = p[3, 2] = sa * dx * dy - sc * dx * dy
        p[3, 3] = sa * dy * dy + sc * (1.0 - dy * dy)
    else:
        p[2, 2] = p[3, 3] = cfg[INITIAL_SPEED] ** 2
    p[4, 4] = cfg[INITIAL_TURN] ** 2
    h = np.zeros(5)
    h[2], h[3] = am[0], am[1]
    ph = p @ h
    s = h @ ph + vv / m + cfg[BODY_DOPPLER] ** 2
    k = ph / s
    x = x + k * (vrm - h @ x)
    p = p - np.outer(k, k) * s
    if math.hypot(x[2], x[3]) > 1.0:
        heading = math.atan2(x[3], x[2])
    (tx, tp, time_s, existence, head, extent, extent_var, born, last_hit, hits, moved,
     reported, rate, top_speed, track_id) = tracks  # fmt: skip
    tx[n] = x
    tp[n] = 0.5 * (p + p.T)
    time_s[n] = t_scan
    existence[n] = existence0
    head[n] = heading
    extent[n, 0], extent[n, 1] = length, width
    extent_var[n, 0], extent_var[n, 1] = cfg[PRIOR_L_STD] ** 2, cfg[PRIOR_W_STD] ** 2
    born[n] = t_scan
    last_hit[n] = t_scan
    hits[n] = 1
    moved[n] = False
    reported[n] = False
    rate[n, :] = np.nan
    top_speed[n] = 0.0
    track_id[n] = next_id


@_njit
def _train_due(trains, t_scan):  # type: ignore[no-untyped-def]
    """Whether a train interval (T, 2) holds ``t_scan``."""
    for k in range(trains.shape[0]):
        if trains[k, 0] <= t_scan < trains[k, 1]:
            return True
    return False


@_njit
def _on_rails(cx, cy, rails):  # type: ignore[no-untyped-def]
    """Whether a point lies in the train's corridor (``CrossingArea.on_rails``; the rails row)."""
    if rails[4] < 0:
        return False
    rx, ry = cx - rails[0], cy - rails[1]
    return abs(-rx * rails[3] + ry * rails[2]) <= rails[4]


@_njit
def _lane_fit(dx, dy, am, vrm, noise, cfg):  # type: ignore[no-untyped-def]
    """Log-likelihood of a new group's mean radial speed under the lane prior along (dx, dy)."""
    sa, sc = cfg[LANE_SPEED] ** 2, cfg[LANE_ACROSS] ** 2
    on = am[0] * dx + am[1] * dy  # the line of sight along the lane
    var = sa * on * on + sc * (am[0] * am[0] + am[1] * am[1] - on * on) + noise
    return -0.5 * (vrm * vrm / var + math.log(var))


@_njit
def _duplicates(tracks, n, cfg):  # type: ignore[no-untyped-def]
    """Tracks whose box overlaps an older track's, moving alike (``_duplicates``)."""
    x, p, heading, extent, born = tracks[0], tracks[1], tracks[4], tracks[5], tracks[7]
    out = np.zeros(n, np.bool_)
    if n < 2:
        return out
    reach = 0.0
    for i in range(n):
        reach = max(reach, extent[i, 0])
    for i in range(n):
        for j in range(i + 1, n):
            if math.hypot(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1]) > reach:
                continue
            older, younger = (i, j) if born[i] <= born[j] else (j, i)
            if out[older] or out[younger]:
                continue
            h = heading[older]
            axx, axy = math.cos(h), math.sin(h)
            dx, dy = x[younger, 0] - x[older, 0], x[younger, 1] - x[older, 1]
            along, across = dx * axx + dy * axy, -dx * axy + dy * axx
            half_o, half_y = 0.5 * extent[older, 0], 0.5 * extent[younger, 0]
            if abs(along) >= half_o + half_y or abs(across) >= 0.5 * (
                    extent[older, 1] + extent[younger, 1]):  # fmt: skip
                continue
            dvx, dvy = x[younger, 2] - x[older, 2], x[younger, 3] - x[older, 3]
            turn = (abs(x[older, 4]) * 2.0 * max(half_o, half_y)) ** 2 + cfg[BODY_DOPPLER] ** 2
            a = p[younger, 2, 2] + p[older, 2, 2] + turn
            b = p[younger, 2, 3] + p[older, 2, 3]
            c = p[younger, 3, 3] + p[older, 3, 3] + turn
            det = a * c - b * b
            if (c * dvx * dvx - 2 * b * dvx * dvy + a * dvy * dvy) / det > cfg[SAME_BODY] ** 2:
                continue
            out[younger] = True
    return out


@_inline
def _move(tracks, src, dst):  # type: ignore[no-untyped-def]
    """Copy track ``src`` over track ``dst``."""
    (x, p, time_s, existence, heading, extent, extent_var, born, last_hit, hits, moved,
     reported, rate, top_speed, track_id) = tracks  # fmt: skip
    x[dst], p[dst], time_s[dst], existence[dst] = x[src], p[src], time_s[src], existence[src]
    heading[dst], extent[dst], extent_var[dst] = heading[src], extent[src], extent_var[src]
    born[dst], last_hit[dst], hits[dst], moved[dst] = (
        born[src],
        last_hit[src],
        hits[src],
        moved[src],
    )
    reported[dst], rate[dst], top_speed[dst] = reported[src], rate[src], top_speed[src]
    track_id[dst] = track_id[src]


@_njit
def _prune(tracks, n, cfg):  # type: ignore[no-untyped-def]
    """Drop tracks gone, lost or duplicating another's body; return the tracks held."""
    x, p, existence, reported = tracks[0], tracks[1], tracks[3], tracks[11]
    for i in range(n):
        speed = math.hypot(x[i, 2], x[i, 3])
        if speed > 1.0:
            ux, uy = _unit(x[i, 2], x[i, 3])
            var = ux * (p[i, 2, 2] * ux + p[i, 2, 3] * uy) + uy * (p[i, 3, 2] * ux
                                                                   + p[i, 3, 3] * uy)  # fmt: skip
        else:
            a, b, c = p[i, 2, 2], p[i, 2, 3], p[i, 3, 3]
            var = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
        if existence[i] >= cfg[REPORT] and var <= cfg[REPORT_SPEED] ** 2:
            reported[i] = True
    dup = _duplicates(tracks, n, cfg)
    kept = 0
    for i in range(n):
        pos_std = math.sqrt(p[i, 0, 0] + p[i, 1, 1])
        if existence[i] >= cfg[DROP] and pos_std <= cfg[LOST] and not dup[i]:
            if kept != i:
                _move(tracks, i, kept)
            kept += 1
    return kept


@_njit
def _touches(cx, cy, h, length, width, inside, origin, cell):  # type: ignore[no-untyped-def]
    """Whether a box's centre or a corner lies in the crossing area (``CrossingArea.touches``)."""
    axx, axy = math.cos(h) * 0.5 * length, math.sin(h) * 0.5 * length
    ayx, ayy = -math.sin(h) * 0.5 * width, math.cos(h) * 0.5 * width
    n = inside.shape[0]
    for k in range(5):
        if k == 0:
            su = sv = 0.0
        else:
            su = 1.0 if k <= 2 else -1.0
            sv = 1.0 if k % 2 == 1 else -1.0
        px = cx + su * axx + sv * ayx
        py = cy + su * axy + sv * ayy
        i = math.floor((px - origin[0]) / cell)
        j = math.floor((py - origin[1]) / cell)
        if 0 <= i < n and 0 <= j < n and inside[i, j]:
            return True
    return False


@_njit
def _clearance(tracks, n, t_scan, cfg, scene, state, events):  # type: ignore[no-untyped-def]
    """Update the crossing's clear / not-clear state (``ClearanceMonitor.update``)."""
    x, existence, heading, extent = tracks[0], tracks[3], tracks[4], tracks[5]
    reported, track_id = tracks[11], tracks[14]
    inside, origin, trains, rails = scene[2], scene[3], scene[4], scene[5]
    train = _train_due(trains, t_scan)
    first = -1
    for i in range(n):
        present = existence[i] >= cfg[REPORT] or (reported[i] and existence[i] >= cfg[KEEP])
        if not present:
            continue
        if not _touches(x[i, 0], x[i, 1], heading[i], extent[i, 0], extent[i, 1], inside,
                        origin, cfg[AREA_CELL]):  # fmt: skip
            continue
        if train and _on_rails(x[i, 0], x[i, 1], rails):  # the train: moving along them
            along = abs(x[i, 2] * rails[2] + x[i, 3] * rails[3])
            across = abs(-x[i, 2] * rails[3] + x[i, 3] * rails[2])
            if along >= rails[5] and across <= along * rails[6]:
                continue
        first = i
        break
    e = state[N_EVENTS]
    if first >= 0 and state[OCCUPANT] < 0:
        state[OCCUPANT] = track_id[first]
        events[e, 0], events[e, 1], events[e, 2] = t_scan, 0.0, track_id[first]
        events[e, 3], events[e, 4] = x[first, 0], x[first, 1]
        state[N_EVENTS] += 1
    elif first < 0 and state[OCCUPANT] >= 0:
        events[e, 0], events[e, 1], events[e, 2] = t_scan, 1.0, state[OCCUPANT]
        events[e, 3] = events[e, 4] = np.nan
        state[N_EVENTS] += 1
        state[OCCUPANT] = -1


@_njit
def _write_rows(tracks, n, t_scan, cfg, state, rows_f, rows_i):  # type: ignore[no-untyped-def]
    """Append the reported tracks after a scan (``ExtendedTracker.columns``)."""
    (x, p, _, existence, heading, extent, extent_var, _, last_hit, _, moved, reported, _,
     top_speed, track_id) = tracks  # fmt: skip
    o = state[N_ROWS]
    for i in range(n):
        if not (reported[i] and existence[i] >= cfg[KEEP]):
            continue
        speed = math.hypot(x[i, 2], x[i, 3])
        ux, uy = _unit(x[i, 2], x[i, 3])
        speed_var = ux * (p[i, 2, 2] * ux + p[i, 2, 3] * uy) + uy * (p[i, 3, 2] * ux
                                                                     + p[i, 3, 3] * uy)  # fmt: skip
        if speed < cfg[STOPPED]:
            status = STOPPED_STATUS
        elif t_scan - last_hit[i] > cfg[COASTING]:
            status = COASTING_STATUS
        else:
            status = CONFIRMED
        row = rows_f[o]
        row[0], row[1], row[2], row[3], row[4] = t_scan, x[i, 0], x[i, 1], x[i, 2], x[i, 3]
        row[5], row[6] = speed, math.sqrt(p[i, 0, 0] + p[i, 1, 1])
        row[7], row[8] = math.sqrt(speed_var), existence[i]
        row[9], row[10], row[11] = extent[i, 0], extent[i, 1], heading[i]
        row[12], row[13], row[14] = extent_var[i, 0], extent_var[i, 1], top_speed[i]
        rows_i[o, 0], rows_i[o, 1], rows_i[o, 2] = track_id[i], status, moved[i]
        o += 1
    state[N_ROWS] = o


@_njit
def _ground_points(z, radar, noise, noise_n):  # type: ignore[no-untyped-def]
    """Ground points, covariances, radial directions and variances (``_ground_points``)."""
    m = z.shape[0]
    g = np.empty((m, 2))
    g_cov = np.empty((m, 2, 2))
    a = np.empty((m, 2))
    v_var = np.empty(m)
    for j in range(m):
        rng, az = z[j, 0], z[j, 1]
        rho = math.sqrt(max(rng * rng - radar[2] ** 2, 0.01))
        s, c = math.sin(az), math.cos(az)
        g[j, 0], g[j, 1] = radar[0] + rho * s, radar[1] + rho * c
        sr = curve_at(noise, noise_n, 0, rng)
        sa = curve_at(noise, noise_n, 1, off_boresight(az, radar))
        sv = curve_at(noise, noise_n, 2, rng)
        drx, dry = rng / rho * s, rng / rho * c
        dax, day = rho * c, -rho * s
        g_cov[j, 0, 0] = sr * sr * drx * drx + sa * sa * dax * dax
        g_cov[j, 0, 1] = g_cov[j, 1, 0] = sr * sr * drx * dry + sa * sa * dax * day
        g_cov[j, 1, 1] = sr * sr * dry * dry + sa * sa * day * day
        a[j, 0], a[j, 1] = rho / rng * s, rho / rng * c
        v_var[j] = sv * sv
    return g, g_cov, a, v_var


@_njit
def _background_explains(r, g, vr, owner, cost, radar, cfg, learnt, bg):  # type: ignore[no-untyped-def]
    """Stationary detections a reflector explains (``_background_explains``)."""
    regions, origin, cell, span, mean, cov, rate, seen_by, n_seen, cusum = bg
    m = g.shape[0]
    reflector = np.full(m, -1, np.int64)
    own = np.zeros(m)
    for j in range(m):
        i = math.floor((g[j, 0] - origin[0]) / cell)
        k = math.floor((g[j, 1] - origin[1]) / cell)
        if 0 <= i < regions.shape[1] and 0 <= k < regions.shape[2]:
            reflector[j] = regions[r, i, k] - 1
        q = reflector[j]
        if q >= 0:
            ex, ey = g[j, 0] - mean[q, 0], g[j, 1] - mean[q, 1]
            a, b, c = cov[q, 0, 0], cov[q, 0, 1], cov[q, 1, 1]
            det = a * c - b * b
            d2 = (c * ex * ex - 2 * b * ex * ey + a * ey * ey) / det
            own[j] = rate[q] * math.exp(-0.5 * d2) / (2 * math.pi * math.sqrt(det))
    object_rate = learnt[0]
    n_bins = object_rate.shape[1]
    for s in range(n_seen[r]):
        k = seen_by[r, s]
        ground = math.hypot(mean[k, 0] - radar[0], mean[k, 1] - radar[1])
        mk = max(object_rate[r, _bin(ground, cfg, n_bins)], 0.5)
        beside = mk / (math.pi * cfg[OBJECT_REACH] ** 2)
        llr = 0.0
        for j in range(m):
            if abs(vr[j]) <= span and reflector[j] == k:
                llr += math.log1p(beside / max(own[j], 1e-300))
        cusum[k] = min(max(cusum[k] + llr - mk, 0.0), 2.0 * cfg[ALARM])
    out = np.zeros(m, np.bool_)
    for j in range(m):
        if not (abs(vr[j]) <= span and reflector[j] >= 0):
            continue
        if cusum[reflector[j]] >= cfg[ALARM]:
            continue
        track = 0.0
        if owner[j] >= 0:
            track = math.exp(-0.5 * cost[owner[j], j]) / (2 * math.pi) ** 1.5
        out[j] = own[j] / (2.0 * span) > track
    return out


@_njit
def _scan(  # type: ignore[no-untyped-def]
    tracks, state, log, r, t_scan, z_all, radars, learnt, clutter, bg, has_bg, scene, cfg
):  # fmt: skip
    """One scan of radar ``r`` (``ExtendedTracker.step`` after its checks)."""
    geometry, fields_all, n_fields, noise_all, noise_n_all, pd_tab, pd_n, antenna_all = radars
    radar = geometry[r]
    fields = fields_all[r, : n_fields[r]]
    n = state[N_TRACKS]
    _predict(tracks, n, t_scan, cfg)
    m_all = z_all.shape[0]
    keep = np.zeros(m_all, np.bool_)
    for j in range(m_all):
        keep[j] = in_view(z_all[j, 0], off_boresight(z_all[j, 1], radar), fields, radar[4])
    log[OUTSIDE] += m_all - keep.sum()
    z = z_all[keep]
    m = z.shape[0]
    g, g_cov, a, v_var = _ground_points(z, radar, noise_all[r], noise_n_all[r])
    x, p, existence, extent, heading = tracks[0], tracks[1], tracks[3], tracks[5], tracks[4]
    last_hit, hits, reported, rate = tracks[8], tracks[9], tracks[11], tracks[12]
    offset = np.empty((n, 2))
    spread = np.empty((n, 3))
    for i in range(n):
        ox, oy, s00, s01, s11 = _faces(x[i, 0], x[i, 1], heading[i], extent[i, 0],
                                       extent[i, 1], radar[0], radar[1])  # fmt: skip
        offset[i, 0], offset[i, 1] = ox, oy
        spread[i, 0], spread[i, 1], spread[i, 2] = s00, s01, s11
    share = _view_share(tracks, n, offset, spread, radar, fields)
    seen = share > 0
    owner = np.full(m, -1, np.int64)
    cost = np.full((n, m), np.inf)
    sm2 = cfg[SHAPE] ** 2
    bd2 = cfg[BODY_DOPPLER] ** 2
    for i in range(n):
        if not seen[i]:
            continue
        for j in range(m):
            ex = g[j, 0] - (x[i, 0] + offset[i, 0])
            ey = g[j, 1] - (x[i, 1] + offset[i, 1])
            s_a = p[i, 0, 0] + spread[i, 0] + g_cov[j, 0, 0] + sm2
            s_b = p[i, 0, 1] + spread[i, 1] + g_cov[j, 0, 1]
            s_c = p[i, 1, 1] + spread[i, 2] + g_cov[j, 1, 1] + sm2
            det = s_a * s_c - s_b * s_b
            d2 = (s_c * ex * ex - 2 * s_b * ex * ey + s_a * ey * ey) / det
            lx, ly = g[j, 0] - x[i, 0], g[j, 1] - x[i, 1]
            predicted = a[j, 0] * (x[i, 2] + x[i, 4] * -ly) + a[j, 1] * (x[i, 3] + x[i, 4] * lx)
            dv = _unfold(z[j, 2] - predicted, radar)
            sv = (a[j, 0] * (p[i, 2, 2] * a[j, 0] + p[i, 2, 3] * a[j, 1])
                  + a[j, 1] * (p[i, 3, 2] * a[j, 0] + p[i, 3, 3] * a[j, 1])
                  + v_var[j] + bd2)  # fmt: skip
            chi = d2 + dv * dv / sv
            if chi <= cfg[GATE]:
                cost[i, j] = chi + math.log(det * sv)
    for j in range(m):
        best, best_c = -1, np.inf
        for i in range(n):
            if cost[i, j] < best_c:
                best, best_c = i, cost[i, j]
        owner[j] = best
    if has_bg and m:
        explained = _background_explains(r, g, z[:, 2], owner, cost, radar, cfg, learnt, bg)
        for j in range(m):
            if explained[j]:
                owner[j] = -2
    pd, clear = _detection_probability(tracks, n, seen, radar, r, pd_tab, pd_n,
                                       antenna_all[r], cfg, learnt)  # fmt: skip
    learns = np.empty(n, np.bool_)
    for i in range(n):
        pd[i] *= share[i]
        learns[i] = existence[i] >= cfg[REPORT] and reported[i] and share[i] >= 1.0 and clear[i]
    object_rate, clutter_mean, pd_hits, pd_chances = learnt
    n_bins = object_rate.shape[1]
    hit = np.zeros(n, np.bool_)
    for i in range(n):
        rows = np.flatnonzero(owner == i)
        if rows.size == 0:
            continue
        ratio = _update(tracks, i, rows, g, g_cov, a, v_var, z[:, 2], offset, spread, radar, r,
                        cfg, clutter)  # fmt: skip
        n_mine = rows.size
        ground = math.hypot(x[i, 0] - radar[0], x[i, 1] - radar[1])
        b = _bin(ground, cfg, n_bins)
        own_rate = rate[i, r]
        mean_rate = object_rate[r, b] if np.isnan(own_rate) else own_rate
        ratio *= _count_ratio(float(n_mine), mean_rate, cfg[COUNT_SHAPE], clutter_mean[r])
        if np.isnan(own_rate):
            rate[i, r] = n_mine
        else:
            rate[i, r] = own_rate + cfg[COUNT_RATE] * (n_mine - own_rate)
        if reported[i]:
            object_rate[r, b] += cfg[COUNT_RATE] * cfg[RADAR_SHARE] * (n_mine - object_rate[r, b])
        e = existence[i]
        gain = 1.0 - pd[i] + pd[i] * ratio
        existence[i] = e / (e + (1.0 - e) / gain)
        last_hit[i] = t_scan
        hits[i] += 1
        hit[i] = True
    for j in range(m):
        if owner[j] >= 0:
            log[UPDATED] += 1
        elif owner[j] == -2:
            log[BACKGROUND_LOG] += 1
    forget = 1.0 - 1.0 / cfg[PD_MEMORY]
    for i in range(n):
        if learns[i]:
            b = _bin(math.hypot(x[i, 0] - radar[0], x[i, 1] - radar[1]), cfg, n_bins)
            pd_hits[r, b] = forget * pd_hits[r, b] + (1.0 if hit[i] else 0.0)
            pd_chances[r, b] = forget * pd_chances[r, b] + 1.0
        if seen[i] and not hit[i]:
            e = existence[i]
            existence[i] = e * (1.0 - pd[i]) / (1.0 - e * pd[i])
    _births(tracks, state, log, r, t_scan, owner, g, g_cov, a, v_var, z[:, 2], radar, learnt,
            clutter, scene, cfg)  # fmt: skip
    state[N_TRACKS] = _prune(tracks, state[N_TRACKS], cfg)


@_njit
def _births(  # type: ignore[no-untyped-def]
    tracks, state, log, r, t_scan, owner, g, g_cov, a, v_var, vr, radar, learnt, clutter, scene, cfg
):  # fmt: skip
    """Open a track on each group of unexplained detections (``ExtendedTracker._births``)."""
    left = np.flatnonzero(owner == -1)
    object_rate, clutter_mean = learnt[0], learnt[1]
    n_bins = object_rate.shape[1]
    count, last, first, scans = clutter
    if left.size:
        labels, n_groups = cluster_labels(g[left, 0].copy(), g[left, 1].copy(), cfg[GAP])
    else:
        labels, n_groups = np.zeros(0, np.int64), 0
    centres = np.zeros((n_groups, 2))
    sizes = np.zeros(n_groups)
    for q in range(left.size):
        centres[labels[q]] += g[left[q]]
        sizes[labels[q]] += 1.0
    density = np.empty(n_groups)
    for k in range(n_groups):
        centres[k] /= sizes[k]
        density[k] = _clutter_density(centres[k, 0], centres[k, 1], r, cfg, clutter) / cfg[SPAN]
    birth = cfg[BIRTH] / cfg[SPAN]
    train = _train_due(scene[4], t_scan)
    for k in range(n_groups):
        rows = left[labels == k]
        r0 = birth / (birth + density[k])
        ground = math.hypot(centres[k, 0] - radar[0], centres[k, 1] - radar[1])
        mean_rate = object_rate[r, _bin(ground, cfg, n_bins)]
        odds = r0 / (1.0 - r0) * _count_ratio(float(rows.size), mean_rate, cfg[COUNT_SHAPE],
                                              clutter_mean[r])  # fmt: skip
        _open(tracks, state[N_TRACKS], state[NEXT_ID], rows, g, g_cov, a, v_var, vr, t_scan,
              odds / (1.0 + odds), radar, cfg, scene[0], scene[1], scene[6], train,
              scene[5])  # fmt: skip
        state[N_TRACKS] += 1
        state[NEXT_ID] += 1
        step = cfg[COUNT_RATE] * cfg[RADAR_SHARE] * (rows.size - clutter_mean[r])
        clutter_mean[r] = max(clutter_mean[r] + step, 1.01)
        log[OPENED] += 1
        log[JOINED_NEW] += rows.size - 1
    scans[r] += 1
    keep = 1.0 - 1.0 / cfg[MEMORY]
    for k in range(n_groups):
        i = math.floor(centres[k, 0] / cfg[CELL]) - first[r, 0]
        j = math.floor(centres[k, 1] / cfg[CELL]) - first[r, 1]
        if 0 <= i < count.shape[1] and 0 <= j < count.shape[2]:
            count[r, i, j] = count[r, i, j] * keep ** (scans[r] - last[r, i, j]) + 1.0
            last[r, i, j] = scans[r]


@_njit
def run_scans(  # type: ignore[no-untyped-def]
    k0, k1, scan_radar, scan_time, starts, z, tracks, state, log, radars, learnt, clutter, bg,
    has_bg, scene, cfg, rows_f, rows_i, events,
):  # fmt: skip
    """Process scans ``k0:k1``; return the next scan (``k1``, or earlier when out of room)."""
    capacity = tracks[0].shape[0]
    for k in range(k0, k1):
        a, b = starts[k], starts[k + 1]
        n = state[N_TRACKS]
        if (n + (b - a) > capacity or state[N_ROWS] + n + (b - a) > rows_f.shape[0]
                or state[N_EVENTS] + 1 > events.shape[0]):  # fmt: skip
            return k
        r = scan_radar[k]
        t_scan = scan_time[k]
        _scan(tracks, state, log, r, t_scan, z[a:b], radars, learnt, clutter, bg, has_bg,
              scene, cfg)  # fmt: skip
        _write_rows(tracks, state[N_TRACKS], t_scan, cfg, state, rows_f, rows_i)
        _clearance(tracks, state[N_TRACKS], t_scan, cfg, scene, state, events)
        state[SCANS_DONE] = k + 1
    return k1


__all__ = ["CFG_FIELDS", "N_ROW_F", "ROW_F_FIELDS", "TRACK_ARRAYS", "lane_grid", "run_scans"]
