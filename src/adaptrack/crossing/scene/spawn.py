"""Spawn stage of a scan: tracks opened from detections left over, and split tracks."""

from __future__ import annotations

import math

import numba
import numpy as np

from ...tracking.assignment import cluster_labels
from ..site.geometry import RADAR_FOLD, RADAR_HEIGHT, RADAR_X, RADAR_Y, curve_at
from .body import N_STATE, ground_point, lane_frame

NEAREST_BLOCK = 32  # centreline samples searched as a block once it may hold the nearest
NEAREST_GROUP = 32  # blocks tested as a group first


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
def open_tracks(z, site, view, cfg):  # type: ignore[no-untyped-def]
    """First states of the tentative tracks opened by left-over detections ``z`` (n, 3).

    Detections within ``radius`` [m] of each other on the ground are one body
    (:func:`cluster_labels`); each body's track starts at the corridor point nearest to its
    detections' mean (:func:`nearest_sample`), with the speed along the corridor that its first
    detection's radial speed gives where the line of sight is not across the lane (and the
    radar does not fold), else 0 with variance ``initial_speed_var``; the position along has
    variance ``1 + along_var``. Returns ``(corridor, x, p, labels, first)``: one row per body,
    each detection's body, and each body's first detection.
    Bundles: ``site`` (the site, :class:`~.bundles.SiteTables`), ``view`` (the scan's radar,
    :class:`~.bundles.RadarView`), ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting
    named here is the field of ``cfg``.
    """
    radar, noise_tab, noise_cnt = view.radar, view.noise_tab, view.noise_cnt
    roads, bounds = site.roads, site.bounds
    radius, initial_speed_var = cfg.cluster_radius_m, cfg.initial_speed_var
    along_var = cfg.body_along_std_m**2
    n = z.shape[0]
    gx, gy = np.zeros(n), np.zeros(n)
    for j in range(n):
        gx[j], gy[j], _ = ground_point(z[j], radar)
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
        _, _, tx, ty, _, px, py = lane_frame(roads, bounds, c, u, d)
        ex, ey = px - radar[RADAR_X], py - radar[RADAR_Y]
        cos = (ex * tx + ey * ty) / math.sqrt(
            ex * ex + ey * ey + radar[RADAR_HEIGHT] * radar[RADAR_HEIGHT]
        )
        j = first[g]
        corridor[g] = c
        x[g, 0], x[g, 3] = u, d
        if abs(cos) > 0.3 and radar[RADAR_FOLD] == 0.0:
            x[g, 1] = z[j, 2] / cos
            p[g, 1, 1] = (curve_at(noise_tab, noise_cnt, 2, z[j, 0]) / abs(cos)) ** 2 + 1.0
        else:
            p[g, 1, 1] = initial_speed_var
        p[g, 0, 0] = 1.0 + along_var
        p[g, 2, 2] = 9.0
        p[g, 3, 3] = 1.0
    return corridor, x, p, labels, first


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
