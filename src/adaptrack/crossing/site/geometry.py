"""Ground geometry of a site, in one place: sensor curves, fields of view, lanes, the radar.

Angles wrap with :mod:`adaptrack.angles`. The compiled (numba) forms serve the simulation's
detection kernel, the road estimators and the scene tracker; the NumPy forms serve the Python
paths. A radar row is :data:`RADAR_FIELDS` (the estimators' and the scene tracker's layout); a
packed road table (5, S) holds sampled ``s``, x, y, heading and curvature rows of one or more
roads side by side. Azimuth is clockwise from north (+y).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..._typing import ArrayLike, FloatArray
from ...angles import wrapped

RADAR_FIELDS = ("x", "y", "height", "boresight", "min_range", "doppler_gate", "fold")
"""A radar's row in compiled code: east, north, height [m], boresight [rad], minimum slant
range [m], Doppler gate [m/s] and folding speed [m/s] (0: none); indices ``RADAR_*``."""
RADAR_X, RADAR_Y, RADAR_HEIGHT, RADAR_BORESIGHT, RADAR_MIN_RANGE = range(5)
RADAR_DOPPLER_GATE, RADAR_FOLD = 5, 6
FIELD_MAX_RANGE, FIELD_HALF_ANGLE = 0, 1  # columns of a field-of-view table (F, 2)


def polar(
    position: ArrayLike, radar_xy: ArrayLike, height_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Slant range [m], azimuth [rad] and offset (..., 2) [m] of ground points from a radar."""
    rel = np.asarray(position, dtype=float) - np.asarray(radar_xy, dtype=float)
    rng = np.hypot(np.hypot(rel[..., 0], rel[..., 1]), height_m)
    return rng, np.arctan2(rel[..., 0], rel[..., 1]), rel


def radial_geometry(
    pos: FloatArray, vel: FloatArray, radar_xy: ArrayLike, height_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Slant range [m], azimuth [rad] and radial speed [m/s] (...,) of moving ground points."""
    rng_m, az, rel = polar(pos, radar_xy, height_m)
    vr = np.einsum("...i,...i->...", rel, vel) / rng_m
    return rng_m, az, vr


def polar_jacobian(
    pos: FloatArray, vel: FloatArray, radar_xy: ArrayLike, height_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted (r, az, vr) (..., 3) and its Jacobians w.r.t. position and velocity (..., 3, 2).

    The NumPy form of :func:`polar_into` (the same operations).
    """
    rel = pos - np.asarray(radar_xy)
    h2 = rel[..., 0] ** 2 + rel[..., 1] ** 2
    r = np.sqrt(h2 + height_m**2)
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


@numba.njit(cache=True, inline="always")
def curve_at(table, counts, row, x):  # type: ignore[no-untyped-def]
    """Value of curve ``row`` of a packed table (``curve_tables``) at ``x``, as ``np.interp``."""
    n = counts[row]
    if x <= table[row, 0, 0] or n == 1:
        return table[row, 1, 0]
    if x >= table[row, 0, n - 1]:
        return table[row, 1, n - 1]
    j = 0
    while table[row, 0, j + 1] < x:
        j += 1
    x0, x1, y0, y1 = table[row, 0, j], table[row, 0, j + 1], table[row, 1, j], table[row, 1, j + 1]
    slope = (y1 - y0) / (x1 - x0)
    return slope * (x - x0) + y0


@numba.njit(cache=True, inline="always")
def in_view(rng_m, off_axis, fields, min_range):  # type: ignore[no-untyped-def]
    """Whether a slant range and absolute off-boresight angle lie in a field of view."""
    if rng_m < min_range:
        return False
    for f in range(fields.shape[0]):
        if rng_m <= fields[f, FIELD_MAX_RANGE] and off_axis <= fields[f, FIELD_HALF_ANGLE]:
            return True
    return False


@numba.njit(cache=True, inline="always")
def polar_into(px, py, vx, vy, radar, zp, jp, jv):  # type: ignore[no-untyped-def]
    """Predicted (r, az, vr) and its Jacobians (3, 2) w.r.t. position and velocity."""
    ex, ey = px - radar[RADAR_X], py - radar[RADAR_Y]
    h2 = ex * ex + ey * ey
    r = math.sqrt(h2 + radar[RADAR_HEIGHT] * radar[RADAR_HEIGHT])
    rv = ex * vx + ey * vy
    zp[0], zp[1], zp[2] = r, math.atan2(ex, ey), rv / r
    jp[0, 0], jp[0, 1] = ex / r, ey / r
    jp[1, 0], jp[1, 1] = ey / h2, -ex / h2
    jp[2, 0] = vx / r - rv / r**3 * ex
    jp[2, 1] = vy / r - rv / r**3 * ey
    jv[0, 0] = jv[0, 1] = jv[1, 0] = jv[1, 1] = 0.0
    jv[2, 0], jv[2, 1] = ex / r, ey / r


@numba.njit(cache=True, inline="always")
def off_boresight(az, radar):  # type: ignore[no-untyped-def]
    """Angle of azimuth ``az`` off the radar's boresight ``radar[3]``, in ``[0, pi]`` [rad]."""
    return abs(wrapped(az - radar[RADAR_BORESIGHT], math.pi))


@numba.njit(cache=True, inline="always")
def centreline_span(roads, lo, hi, s):  # type: ignore[no-untyped-def]
    """Centreline x, y, heading and curvature at ``s`` of the road in columns ``lo:hi``.

    ``roads`` (5, S): sampled ``s``, x, y, heading and curvature rows of one or more roads
    side by side; ``s`` is clipped to the road, as np.interp. Indexes in place: a view of
    the road's columns per call would cost its reference counting in the scan loop.
    """
    last = hi - lo - 1
    q = min(max(s, 0.0), roads[0, lo + last])
    # last j with s_j <= q (as np.interp); the samples are nearly uniform: guess, then walk
    j = min(int(q * (last / roads[0, lo + last])), last - 1)
    while j < last - 1 and roads[0, lo + j + 1] <= q:
        j += 1
    while j > 0 and roads[0, lo + j] > q:
        j -= 1
    a, b = lo + j, lo + j + 1
    u = q - roads[0, a]
    ds = roads[0, b] - roads[0, a]
    cx = (roads[1, b] - roads[1, a]) / ds * u + roads[1, a]
    cy = (roads[2, b] - roads[2, a]) / ds * u + roads[2, a]
    th = (roads[3, b] - roads[3, a]) / ds * u + roads[3, a]
    kappa = (roads[4, b] - roads[4, a]) / ds * u + roads[4, a]
    return cx, cy, th, kappa


@numba.njit(cache=True, inline="always")
def centreline(road, s):  # type: ignore[no-untyped-def]
    """Centreline x, y, heading and curvature at ``s`` of ``road`` (5, S) (clipped to it)."""
    return centreline_span(road, 0, road.shape[1], s)


@numba.njit(cache=True, inline="always")
def lane_at(roads, lo, hi, s):  # type: ignore[no-untyped-def]
    """Return the lane frame at ``s`` of the road in columns ``lo:hi`` of ``roads``.

    ``(cx, cy, kappa, tx, ty)``: centreline point, curvature and unit tangent (the sine and
    cosine of the heading) of :func:`centreline_span`.
    """
    cx, cy, th, kappa = centreline_span(roads, lo, hi, s)
    return cx, cy, kappa, math.sin(th), math.cos(th)
