"""The body model of a scene track: lane frames, the part of a body a radar sees, its shadow.

Tracks are rows of arrays: state ``x`` (T, 4) = ``[u, du/dt, d2u/dt2, d]`` in corridor
coordinates, covariance ``p`` (T, 4, 4), the corridor index of each row and the learnt body
spread. Corridors are packed as one (5, S) table of centreline samples (``u``, east, north,
heading, curvature) with ``bounds`` (C, 2) the column range of each. The radar row is
``x, y, height, boresight, min range, Doppler gate, folding speed`` as in
:mod:`adaptrack.crossing.estimators.kernels`, whose measurement model
(:func:`~adaptrack.crossing.estimators.kernels.measure`, lane half width 0) and radial-speed
unfolding the scene stages evaluate.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..._borrowed import on_stack
from ...angles import wrapped
from ..estimators.kernels import ROAD, measure_span, road_measure
from ..site.geometry import (
    FIELD_HALF_ANGLE,
    FIELD_MAX_RANGE,
    RADAR_HEIGHT,
    RADAR_MIN_RANGE,
    RADAR_X,
    RADAR_Y,
    centreline_span,
    in_view,
    lane_at,
    off_boresight,
)

N_STATE = 4
BODY_HALF_SPREADS = 2.0  # a body reaches this many spreads either side of its centre
VISIBLE_SAMPLES = 17  # points over a body tested against a field of view
# a road user's width [m] from its length [m]: pedestrian, motorcycle, car, truck, bus (the
# classes of DOMAIN 3 / crossing.traffic), linear between them, the legal 2.55 m beyond
BODY_LENGTHS_M = np.array([0.5, 2.2, 5.0, 7.1, 12.0])
BODY_WIDTHS_M = np.array([0.5, 0.8, 1.8, 2.5, 2.55])


@numba.njit(cache=True, inline="always")
def model_scratch():  # type: ignore[no-untyped-def]
    """Buffers of the measurement model (stack): detection, Jacobian, noise, polar Jacobians."""
    return (
        on_stack(3), on_stack((3, N_STATE)), on_stack((3, 3)), on_stack((3, 2)), on_stack((3, 2))
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def update_scratch(m):  # type: ignore[no-untyped-def]
    """Buffers of an ``m``-dimensional EKF update (``update_into``) and its posterior (stack)."""
    return (
        on_stack((m, N_STATE)), on_stack((m, m)), on_stack((m, m)), on_stack((m, N_STATE)),
        on_stack(m), on_stack((N_STATE, N_STATE)), on_stack((N_STATE, N_STATE)),
        on_stack(N_STATE), on_stack((N_STATE, N_STATE)),
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def lane_frame(roads, bounds, c, u, d):  # type: ignore[no-untyped-def]
    """Corridor ``c`` at ``u``: centreline point, unit tangent, curvature, point at offset ``d``.

    Returns ``(cx, cy, tx, ty, kappa, px, py)``; ``(-ty, tx)`` is the offsets' direction.
    """
    cx, cy, kappa, tx, ty = lane_at(roads, bounds[c, 0], bounds[c, 1], u)
    return cx, cy, tx, ty, kappa, cx - d * ty, cy + d * tx


@numba.njit(cache=True, inline="always")
def store_lane(lanes, i, roads, bounds, corridor, x):  # type: ignore[no-untyped-def]
    """Set row ``i`` of ``lanes`` (T, 5) to track ``i``'s lane frame at its ``u`` (``lane_at``)."""
    c = corridor[i]
    lanes[i, 0], lanes[i, 1], lanes[i, 2], lanes[i, 3], lanes[i, 4] = lane_at(
        roads, bounds[c, 0], bounds[c, 1], x[i, 0]
    )


@numba.njit(cache=True, inline="always")
def ground_point(z_row, radar):  # type: ignore[no-untyped-def]
    """Ground point (x, y) and horizontal range of a detection (range, azimuth, ...)."""
    rho = math.sqrt(max(z_row[0] ** 2 - radar[RADAR_HEIGHT] ** 2, 0.01))
    return radar[RADAR_X] + rho * math.sin(z_row[1]), radar[RADAR_Y] + rho * math.cos(z_row[1]), rho


@numba.njit(cache=True, inline="always")
def _view_uniform(lane, d, half, radar, fields):  # type: ignore[no-untyped-def]
    """Whether the lane points within ``half`` [m] of ``(u, d)`` are all in view (1), all out (-1).

    ``lane``: the lane frame at ``u`` (:func:`..site.geometry.lane_at`). 0 when it cannot
    tell. A sufficient test from the centre point alone: the points lie within ``half`` of it
    (the arc is no shorter than its chord), so their slant ranges differ from its by at most
    ``half`` and their bearings by at most ``asin(half / ground range)``.
    """
    cx, cy, _, tx, ty = lane
    ex = cx - d * ty - radar[RADAR_X]
    ey = cy + d * tx - radar[RADAR_Y]
    ground = math.sqrt(ex * ex + ey * ey)
    if ground <= half:
        return 0
    rng = math.sqrt(ground * ground + radar[RADAR_HEIGHT] * radar[RADAR_HEIGHT])
    if rng + half < radar[RADAR_MIN_RANGE]:
        return -1  # all nearer than the minimum range
    off = off_boresight(math.atan2(ex, ey), radar)
    widen = math.asin(half / ground)
    all_in = rng - half >= radar[RADAR_MIN_RANGE]
    some_field = False
    for f in range(fields.shape[0]):
        if rng + half <= fields[f, FIELD_MAX_RANGE] and off + widen <= fields[f, FIELD_HALF_ANGLE]:
            return 1 if all_in else 0
        some_field |= (
            rng - half <= fields[f, FIELD_MAX_RANGE] and off - widen <= fields[f, FIELD_HALF_ANGLE]
        )
    return 0 if some_field else -1


@numba.njit(cache=True, inline="always")
def visible_part(u, d, spread, lo, hi, roads, radar, fields, lane):  # type: ignore[no-untyped-def]
    """Locate the part of a body inside the radar's field of view.

    The body's centre lies ``u`` [m] along the road in columns ``lo:hi`` of ``roads`` (its
    lane frame there ``lane``: :func:`..site.geometry.lane_at`) and ``d`` [m] across; it spans
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
        ex = cx - d * math.cos(th) - radar[RADAR_X]
        ey = cy + d * math.sin(th) - radar[RADAR_Y]
        rng = math.sqrt(ex * ex + ey * ey + radar[RADAR_HEIGHT] * radar[RADAR_HEIGHT])
        if in_view(rng, off_boresight(math.atan2(ex, ey), radar), fields, radar[RADAR_MIN_RANGE]):
            n_in += 1
            total += a
            first_in |= k == 0
            last_in |= k == VISIBLE_SAMPLES - 1
    if n_in == 0 or n_in == VISIBLE_SAMPLES:
        return 0.0, spread, 0.0, False
    slope = -0.5 if first_in != last_in else (-1.0 if not first_in else 0.0)
    return total / n_in, spread * n_in / VISIBLE_SAMPLES, slope, False


@numba.njit(cache=True, inline="always")
def body_model(  # type: ignore[no-untyped-def]
    i, x, spread, corridor, roads, bounds, radar, noise_tab, noise_cnt, fields, across_std,
    xv, zp, h, rm, jp, jv, visible, lane,
):  # fmt: skip
    """Predicted detection, Jacobian and noise of track ``i`` (body spread along and across).

    A body partly outside the field of view is detected over its visible part only
    (``visible``: :func:`visible_part` of the track): the detection is predicted at that
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


@numba.njit(cache=True, inline="always")
def bodies_overlap(x, spread, a, b):  # type: ignore[no-untyped-def]
    """Whether the bodies of tracks ``a`` and ``b`` (``BODY_HALF_SPREADS`` spreads) overlap."""
    return abs(x[a, 0] - x[b, 0]) < BODY_HALF_SPREADS * (spread[a] + spread[b])


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

    ``lanes`` (T, 5): the tracks' lane frames at their ``u`` (:func:`..site.geometry.lane_at`).
    The half width is twice the body spread along the lane's heading and half the width of a
    road user of that length (:data:`BODY_WIDTHS_M`) across, seen from the radar
    (:func:`nearer_occluders`).
    """
    for i in rows:
        cx, cy, tx, ty = lanes[i, 0], lanes[i, 1], lanes[i, 3], lanes[i, 4]
        px, py = cx - x[i, 3] * ty, cy + x[i, 3] * tx
        ex, ey = px - radar[RADAR_X], py - radar[RADAR_Y]
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
def planar_rows(  # type: ignore[no-untyped-def]
    rows, x, p, corridor, roads, bounds, crossing_u, pos, vel, pos_std, to_cross
):
    """Planar position, velocity, position sigma (trace) and distance to the crossing.

    Of the tracks in ``rows``, written to entry ``k`` for ``rows[k]``.
    """
    for k in range(rows.size):
        i = rows[k]
        d = x[i, 3]
        _, _, tx, ty, kappa, px, py = lane_frame(roads, bounds, corridor[i], x[i, 0], d)
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
