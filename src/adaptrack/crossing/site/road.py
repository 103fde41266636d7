"""Road centrelines made of straights, clothoids and circular arcs, or surveyed polylines.

A road starts at its crossing end (the crossing centre, the origin of the local ENU frame,
unless it starts at a junction elsewhere) and leaves it with azimuth ``heading`` (clockwise
from north). ``s`` is the distance along the centreline from that end [m]. Curvature is
positive for a turn to the right (heading increasing). Approaching traffic drives towards the
crossing end (``s`` decreasing) in the ``lanes_in`` lanes on its right-hand side, the first
centred ``lane_width / 2`` from the centreline, the next ``lane_width`` further; traffic
leaving drives in the ``lanes_out`` lanes on the other side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from ..._typing import ArrayLike, FloatArray
from ..._validation import as_float_array

STEP_M = 0.05  # sampling of the centreline; linear interpolation error < kappa * STEP^2 / 8


@dataclass(frozen=True)
class RoadElement:
    """One piece of a road centreline.

    ``kind``: "straight", "clothoid" (curvature ramps linearly to ``end_curvature_per_m``) or
    "arc" (constant curvature ``1 / radius``, ``turn`` "left" or "right").
    """

    kind: str
    length_m: float
    end_curvature_per_m: float = 0.0
    radius_m: float = 0.0
    turn: str = "right"


@dataclass(frozen=True, eq=False)
class Road:
    """A sampled road centreline (see module docstring)."""

    name: str
    heading_rad: float
    lane_width_m: float
    elements: tuple[RoadElement, ...]
    s: FloatArray
    xy: FloatArray
    heading: FloatArray
    curvature: FloatArray
    lanes_in: int = 1
    lanes_out: int = 1

    @property
    def length_m(self) -> float:
        """Length of the centreline [m]."""
        return float(self.s[-1])

    def centreline(self, s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Centreline point (..., 2) and heading (...) at along-road positions ``s`` [m]."""
        q = np.clip(as_float_array(s, "s"), 0.0, self.length_m)
        x = np.interp(q, self.s, self.xy[:, 0])
        y = np.interp(q, self.s, self.xy[:, 1])
        return np.stack([x, y], -1), np.interp(q, self.s, self.heading)

    def lane_geometry(
        self, s: ArrayLike, offset_m: ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Lane point (..., 2), outward tangent (..., 2), right normal (..., 2), curvature.

        The right normal is the right of the inbound direction; derivatives:
        ``dp/ds = t (1 + kappa (w/2 + d))``, ``dp/dd = right``, ``dt/ds = -kappa right``.
        """
        q = np.clip(as_float_array(s, "s"), 0.0, self.length_m)
        x = np.interp(q, self.s, self.xy[:, 0])
        y = np.interp(q, self.s, self.xy[:, 1])
        th = np.interp(q, self.s, self.heading)
        kappa = np.interp(q, self.s, self.curvature)
        sin, cos = np.sin(th), np.cos(th)
        tangent = np.stack([sin, cos], -1)
        right = np.stack([-cos, sin], -1)
        off = 0.5 * self.lane_width_m + np.asarray(offset_m, dtype=float)
        return np.stack([x, y], -1) + off[..., None] * right, tangent, right, kappa

    def lane_point(self, s: ArrayLike, offset_m: ArrayLike = 0.0) -> FloatArray:
        """Point (..., 2) of the approach lane at ``s``, ``offset_m`` to the right of its centre."""
        p, th = self.centreline(s)
        right = np.stack([-np.cos(th), np.sin(th)], -1)  # right of the inbound direction
        off = np.asarray(offset_m, dtype=float)[..., None]
        return p + (0.5 * self.lane_width_m + off) * right

    def lane_speed_factor(self, s: ArrayLike, offset_m: ArrayLike = 0.0) -> FloatArray:
        """Speed of the lane point per unit centreline speed, ``1 + kappa (w/2 + d)`` (...,).

        A point ``w/2 + d`` to the right of the inbound direction moves this much faster than
        the centreline (slower on the inside of a curve).
        """
        q = np.clip(as_float_array(s, "s"), 0.0, self.length_m)
        kappa = np.interp(q, self.s, self.curvature)
        return 1.0 + kappa * (0.5 * self.lane_width_m + np.asarray(offset_m, dtype=float))

    def centreline_at(self, lane_distance_m: ArrayLike, offset_m: ArrayLike = 0.0) -> FloatArray:
        """Centreline ``s`` where the lane at ``offset_m`` has run ``lane_distance_m`` from s = 0.

        The lane's own arc length is ``s + (w/2 + d) (theta(s) - theta(0))``; shapes broadcast
        to (N, T) with one offset per row (N,) or (N, 1), or (T,) with a scalar offset.
        Beyond the ends of the road the distance carries on one to one.
        """
        sigma = as_float_array(lane_distance_m, "lane_distance_m")
        off = np.asarray(offset_m, dtype=float)
        if off.ndim == 0:
            lane = self.s + (0.5 * self.lane_width_m + off) * (self.heading - self.heading[0])
            beyond = np.minimum(sigma, 0.0) + np.maximum(sigma - lane[-1], 0.0)
            return np.interp(sigma, lane, self.s) + beyond  # past the ends: as a straight
        off = off.reshape(-1)
        sig = np.broadcast_to(sigma, (off.size,) + sigma.shape[-1:])
        return np.stack([self.centreline_at(row, o) for row, o in zip(sig, off, strict=True)])

    def inbound_direction(self, s: ArrayLike) -> FloatArray:
        """Return the unit vector (..., 2) of travel towards the crossing at ``s``."""
        _, th = self.centreline(s)
        return -np.stack([np.sin(th), np.cos(th)], -1)

    @cached_property
    def _lane_index(self) -> cKDTree:
        """Nearest-neighbour index of the sampled lane centre (built on first projection)."""
        return cKDTree(self.lane_point(self.s))

    def project(self, xy: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Along-road position ``s`` and signed offset from the lane centre (to the right).

        ``s`` is the nearest lane sample's (every ``STEP_M``).
        """
        p = as_float_array(xy, "xy", min_ndim=1)
        _, i = self._lane_index.query(p)
        lane = self._lane_index.data
        s = self.s[i]
        right = np.stack([-np.cos(self.heading[i]), np.sin(self.heading[i])], -1)
        return s, np.einsum("...i,...i->...", p - lane[i], right)


def build_road(
    name: str,
    heading_rad: float,
    lane_width_m: float,
    elements: tuple[RoadElement, ...],
    start_m: tuple[float, float] = (0.0, 0.0),
    lanes: tuple[int, int] = (1, 1),
) -> Road:
    """Integrate the curvature of the elements into a sampled centreline from ``start_m``.

    ``lanes``: the lanes towards the crossing end and away from it.
    """
    if not elements:
        raise ValueError(f"road {name!r}: needs at least one element")
    kappa_parts = []
    k0 = 0.0
    for i, e in enumerate(elements):
        if not e.length_m > 0:
            raise ValueError(f"road {name!r}, element {i}: length_m must be > 0")
        n = max(1, round(e.length_m / STEP_M))
        frac = (np.arange(n) + 0.5) / n
        if e.kind == "straight":
            k = np.zeros(n)
            k0 = 0.0
        elif e.kind == "clothoid":
            k = k0 + (e.end_curvature_per_m - k0) * frac
            k0 = e.end_curvature_per_m
        elif e.kind == "arc":
            if not e.radius_m > 0 or e.turn not in ("left", "right"):
                raise ValueError(
                    f"road {name!r}, element {i}: an arc needs radius_m > 0 and "
                    "turn 'left' or 'right'"
                )
            k0 = (1.0 if e.turn == "right" else -1.0) / e.radius_m
            k = np.full(n, k0)
        else:
            raise ValueError(
                f"road {name!r}, element {i}: kind must be 'straight', "
                f"'clothoid' or 'arc'; got {e.kind!r}"
            )
        kappa_parts.append((k, e.length_m / n))
    ds = np.concatenate([np.full(k.size, h) for k, h in kappa_parts])
    kappa = np.concatenate([k for k, _ in kappa_parts])
    theta = heading_rad + np.concatenate([[0.0], np.cumsum(kappa * ds)])
    mid = 0.5 * (theta[1:] + theta[:-1])
    # exact chord of a circular step of length ds and turning angle kappa ds
    chord = ds * np.where(np.abs(kappa * ds) > 1e-12, np.sinc(kappa * ds / (2 * math.pi)), 1.0)
    steps = np.stack([chord * np.sin(mid), chord * np.cos(mid)], -1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(steps, axis=0)]) + np.asarray(start_m)
    s = np.concatenate([[0.0], np.cumsum(ds)])
    curv = np.concatenate([kappa[:1], kappa])
    return Road(name, heading_rad, lane_width_m, elements, s, xy, theta, curv, *lanes)


SURVEY_STD_M = 0.05  # survey points are smoothed to this residual by default (RMS) [m]


def polyline_road(
    name: str,
    points_m: ArrayLike,
    lane_width_m: float,
    extend_m: float = 0.0,
    lanes: tuple[int, int] = (1, 1),
    survey_std_m: float = SURVEY_STD_M,
) -> Road:
    """Build a road through surveyed centreline points, the first at its crossing end.

    A parametric cubic smoothing spline (FITPACK ``splprep``) with an RMS residual of
    ``survey_std_m`` per point (0: through the points), sampled every ``STEP_M`` of arc
    length; heading and curvature come from its derivatives. ``extend_m`` continues it
    straight beyond the last point.
    """
    from scipy.interpolate import splev, splprep  # here: scipy.interpolate takes 0.4 s

    p = as_float_array(points_m, "points_m")
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 2:
        raise ValueError(f"road {name!r}: points_m needs two or more [east, north] points")
    chord = np.hypot(*np.diff(p, axis=0).T)
    if (chord < 1e-3).any():
        k = int(np.argmax(chord < 1e-3))
        raise ValueError(f"road {name!r}: points_m[{k}] and [{k + 1}] coincide")
    degree = min(3, len(p) - 1)
    tck, _ = splprep(p.T, s=len(p) * survey_std_m**2, k=degree)
    fine = np.linspace(0.0, 1.0, max(200, int(20 * chord.sum() / STEP_M) // 10))
    x, y = splev(fine, tck)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    s = np.arange(0.0, along[-1], STEP_M)
    if along[-1] - s[-1] > 1e-6:
        s = np.append(s, along[-1])  # the last surveyed point ends the road
    u = np.interp(s, along, fine)
    x, y = splev(u, tck)
    dx, dy = splev(u, tck, der=1)
    ddx, ddy = splev(u, tck, der=2) if degree >= 2 else (np.zeros_like(u), np.zeros_like(u))
    heading = np.unwrap(np.arctan2(dx, dy))
    speed = np.hypot(dx, dy)
    curvature = (dy * ddx - dx * ddy) / np.maximum(speed, 1e-12) ** 3  # right turns positive
    xy = np.stack([x, y], -1)
    if extend_m > 0:
        ext = np.arange(STEP_M, extend_m + 1e-9, STEP_M)
        tangent = np.array([math.sin(heading[-1]), math.cos(heading[-1])])
        xy = np.concatenate([xy, xy[-1] + ext[:, None] * tangent])
        s = np.concatenate([s, s[-1] + ext])
        heading = np.concatenate([heading, np.full(ext.size, heading[-1])])
        curvature = np.concatenate([curvature, np.zeros(ext.size)])
    return Road(name, float(heading[0]), lane_width_m, (), s, xy, heading, curvature, *lanes)


__all__ = ["Road", "RoadElement", "build_road", "polyline_road"]
