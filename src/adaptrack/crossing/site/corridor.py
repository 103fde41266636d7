"""Corridors: the path through the crossing formed by two roads, or a flow's route.

A corridor joins the centreline of one road (driven towards the crossing) to the centreline of
another (driven away from it), directly where two roads leave one point in line, else along
the flow's route (:mod:`adaptrack.crossing.site.network`) with a turning path of
``TURN_RADIUS_M`` between its roads (a cubic Hermite curve from where one road is left to where
the next is joined) or through a connection's surveyed lane points. Its coordinate ``u``
runs from the far end of the first road through the crossing centre (``u = crossing_u``) to
the far end of the second. It is a :class:`~adaptrack.crossing.site.road.Road` with lane
width 0, so its ``lane_point(u, d)`` is the point ``d`` to the right of the direction of
*decreasing* ``u``: traffic from the first road drives at ``d = -w/2`` (on its right),
traffic from the second at ``d = +w/2``. The scene simulator moves road users along
corridors and the scene tracker estimates in corridor coordinates, both through this
geometry.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from .network import Leg, route
from .road import STEP_M, Road, RoadElement, build_road

MAX_JOIN_DEG = 20.0  # two roads join into a corridor if they leave the crossing this straight
TURN_RADIUS_M = 10.0  # centreline radius of a turning path between two roads
HERMITE_SAMPLES = 400
MIN_JOIN_M = 3.0  # a join between two roads is smoothed over at least this much of each


@dataclass(frozen=True, eq=False)
class Corridor:
    """A path ``first -> second`` through the crossing; ``path`` holds its geometry.

    ``lanes``: the lanes in the direction of increasing ``u`` (from ``first``) and of
    decreasing ``u`` (from ``second``), the fewest of the roads it runs on.
    """

    first: str
    second: str
    path: Road
    crossing_u: float
    lanes: tuple[int, int] = (1, 1)


def build_corridor(first: Road, second: Road, length_m: float) -> Corridor:
    """Join ``first`` (driven inbound) and ``second`` (outbound), ``length_m`` of each."""
    turn = abs(math.remainder(second.heading_rad - first.heading_rad - math.pi, 2 * math.pi))
    if math.degrees(turn) > MAX_JOIN_DEG:
        raise ValueError(
            f"roads {first.name!r} and {second.name!r} do not continue each other through the "
            f"crossing ({math.degrees(turn):.0f} deg turn; a corridor needs <= {MAX_JOIN_DEG:g})"
        )
    s_in = np.arange(min(length_m, first.length_m), 0.0, -STEP_M)
    s_out = np.arange(0.0, min(length_m, second.length_m) + 1e-9, STEP_M)
    xy = np.concatenate([first.centreline(s_in)[0], second.centreline(s_out)[0]])
    steps = np.diff(xy, axis=0)
    u = np.concatenate([[0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))])
    heading = np.unwrap(np.arctan2(steps[:, 0], steps[:, 1]))
    heading = np.concatenate([heading[:1], 0.5 * (heading[1:] + heading[:-1]), heading[-1:]])
    curvature = np.gradient(heading, u)
    path = Road(
        f"{first.name}-{second.name}", float(heading[0]), 0.0, (), u, xy, heading, curvature
    )
    lanes = (min(first.lanes_in, second.lanes_out), min(second.lanes_in, first.lanes_out))
    return Corridor(first.name, second.name, path, float(u[s_in.size]), lanes)


def _hermite(p0, t0, p1, t1) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Points of the cubic Hermite curve p0 -> p1 with unit tangents t0, t1, every STEP_M."""
    scale = float(np.hypot(*(p1 - p0)))
    h = np.linspace(0.0, 1.0, HERMITE_SAMPLES)[:, None]
    curve = (
        (2 * h**3 - 3 * h**2 + 1) * p0 + (h**3 - 2 * h**2 + h) * scale * t0
        + (-2 * h**3 + 3 * h**2) * p1 + (h**3 - h**2) * scale * t1
    )  # fmt: skip
    return _resampled(curve)


def _resampled(curve: np.ndarray) -> np.ndarray:
    """Resample a dense curve (K, 2) every STEP_M of its length, its end left out."""
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(curve, axis=0).T))])
    s = np.arange(0.0, along[-1], STEP_M)
    return np.stack([np.interp(s, along, curve[:, k]) for k in range(2)], -1)


def _travel(road: Road, s: float, inbound: bool) -> np.ndarray:
    """Return the unit direction of travel on a road at ``s`` (towards its start when inbound)."""
    _, th = road.centreline(s)
    t = np.array([np.sin(th), np.cos(th)])
    return -t if inbound else t


def route_corridor(
    roads: dict[str, Road],
    legs: list[Leg],
    length_m: float,
    via: dict[tuple[str, str], np.ndarray] | None = None,
    crossing_xy: tuple[float, float] = (0.0, 0.0),
) -> Corridor:
    """Build the corridor along a route's legs, ``length_m`` of its first and last road at most.

    Between two legs a turning path replaces ``TURN_RADIUS_M tan(turn / 2)`` of each (at least
    ``MIN_JOIN_M``, at most 0.45 of the leg), or the lane points ``via[(road_a, road_b)]``
    (K, 2) are followed (the
    path runs half a lane to their left). ``crossing_u`` is where the path passes nearest to
    ``crossing_xy``.
    """
    via = via or {}
    legs = list(legs)
    first, last = legs[0], legs[-1]
    legs[0] = Leg(first.road, min(first.s_from, length_m), first.s_to)
    legs[-1] = Leg(last.road, last.s_from, min(last.s_to, length_m))
    cut_in = [0.0] * len(legs)  # cut off the start and the end of each leg
    cut_out = [0.0] * len(legs)
    joins: list[np.ndarray | None] = [None] * (len(legs) - 1)
    for k in range(len(legs) - 1):
        a, b = legs[k], legs[k + 1]
        ra, rb = roads[a.road], roads[b.road]
        lane_pts = via.get((a.road, b.road))
        if lane_pts is not None:
            _, s_a = _nearest(ra, lane_pts[0])
            _, s_b = _nearest(rb, lane_pts[-1])
            cut_out[k] = min(abs(a.s_to - s_a), 0.9 * abs(a.s_to - a.s_from))
            cut_in[k + 1] = min(abs(b.s_from - s_b), 0.9 * abs(b.s_to - b.s_from))
            joins[k] = left_of(lane_pts, 0.5 * ra.lane_width_m)
            continue
        ta, tb = _travel(ra, a.s_to, a.inbound), _travel(rb, b.s_from, b.inbound)
        turn = float(np.arccos(np.clip(ta @ tb, -1.0, 1.0)))
        cut = max(TURN_RADIUS_M * np.tan(0.5 * min(turn, np.radians(150.0))), MIN_JOIN_M)
        cut_out[k] = min(cut, 0.45 * abs(a.s_to - a.s_from))
        cut_in[k + 1] = min(cut, 0.45 * abs(b.s_to - b.s_from))
    pieces = []
    for k, leg in enumerate(legs):
        road = roads[leg.road]
        sign = -1.0 if leg.inbound else 1.0
        s0 = leg.s_from + sign * cut_in[k]
        s1 = leg.s_to - sign * cut_out[k]
        s = np.arange(s0, s1, sign * STEP_M)
        if k == len(legs) - 1:
            s = np.append(s, s1)
        pieces.append(road.centreline(s)[0])
        if k < len(legs) - 1:
            nxt = legs[k + 1]
            rb = roads[nxt.road]
            p0 = road.centreline(s1)[0]
            sb = nxt.s_from + (-1.0 if nxt.inbound else 1.0) * cut_in[k + 1]
            p1 = rb.centreline(sb)[0]
            if joins[k] is not None:
                pts = np.concatenate([[p0], joins[k], [p1]])
                pieces.append(_resampled(_dense_polyline(pts)))
            elif np.hypot(*(p1 - p0)) > 1e-6:
                pieces.append(_hermite(p0, _travel(road, s1, leg.inbound), p1,
                                       _travel(rb, sb, nxt.inbound)))  # fmt: skip
    xy = np.concatenate(pieces)
    keep = np.concatenate([[True], np.hypot(*np.diff(xy, axis=0).T) > 1e-9])
    xy = xy[keep]
    steps = np.diff(xy, axis=0)
    u = np.concatenate([[0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))])
    heading = np.unwrap(np.arctan2(steps[:, 0], steps[:, 1]))
    heading = np.concatenate([heading[:1], 0.5 * (heading[1:] + heading[:-1]), heading[-1:]])
    curvature = np.gradient(heading, u)
    name = f"{first.road}-{last.road}"
    path = Road(name, float(heading[0]), 0.0, (), u, xy, heading, curvature)
    centre = np.hypot(xy[:, 0] - crossing_xy[0], xy[:, 1] - crossing_xy[1])
    fwd = min(roads[g.road].lanes_in if g.inbound else roads[g.road].lanes_out for g in legs)
    back = min(roads[g.road].lanes_out if g.inbound else roads[g.road].lanes_in for g in legs)
    return Corridor(first.road, last.road, path, float(u[int(np.argmin(centre))]), (fwd, back))


def _nearest(road: Road, point: np.ndarray) -> tuple[float, float]:
    d = np.hypot(road.xy[:, 0] - point[0], road.xy[:, 1] - point[1])
    i = int(np.argmin(d))
    return float(d[i]), float(road.s[i])


def left_of(points: np.ndarray, offset_m: float) -> np.ndarray:
    """Points (K, 2) moved ``offset_m`` to the left of their direction of travel."""
    d = np.gradient(points, axis=0)
    d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    return points + offset_m * np.stack([-d[:, 1], d[:, 0]], -1)


def _dense_polyline(points: np.ndarray) -> np.ndarray:
    """Sample a polyline (K, 2) densely (every tenth of STEP_M) along its straight pieces."""
    out = [points[:1]]
    for p, q in itertools.pairwise(points):
        n = max(2, int(np.hypot(*(q - p)) / (0.1 * STEP_M)))
        out.append(p + np.linspace(0.0, 1.0, n)[1:, None] * (q - p))
    return np.concatenate(out)


def nearest_corridor(corridors: list[Corridor], xy: np.ndarray) -> tuple[np.ndarray, ...]:
    """Index of the corridor nearest to each point (N, 2), and ``u``, ``d`` on it."""
    best = np.full(len(xy), np.inf)
    index = np.zeros(len(xy), dtype=int)
    u0, d0 = np.zeros(len(xy)), np.zeros(len(xy))
    for c, cor in enumerate(corridors):
        u, d = cor.path.project(xy)
        nearer = np.abs(d) < best
        best = np.where(nearer, np.abs(d), best)
        index[nearer], u0[nearer], d0[nearer] = c, u[nearer], d[nearer]
    return index, u0, d0


def site_corridors(
    roads: dict[str, Road],
    length_m: float,
    routes: tuple[tuple[str, str], ...] = (),
    via: dict[tuple[str, str], np.ndarray] | None = None,
) -> list[Corridor]:
    """Build the site's corridors: roads in line from one point, lone roads, then routes.

    One corridor per pair of roads that continue each other from one point, then one per
    route ``(entry, exit)`` that no pair serves. A road without a partner or a route forms a
    corridor with a straight stub beyond the crossing. A route with no path raises
    ``ValueError`` naming it.
    """
    names = list(roads)
    used: set[str] = set()
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if a in used or b in used:
                continue
            if np.hypot(*(roads[a].xy[0] - roads[b].xy[0])) > 1e-6:
                continue  # they do not leave one point
            try:
                out.append(build_corridor(roads[a], roads[b], length_m))
            except ValueError:
                continue
            used.update((a, b))
    routed = {r for pair in routes for r in pair}
    for name in names:
        if name not in used and name not in routed:
            road = roads[name]
            stub = build_road(
                f"{name}-stub", road.heading_rad + math.pi, road.lane_width_m,
                (RoadElement("straight", 30.0),), start_m=tuple(road.xy[0]),
            )  # fmt: skip
            out.append(build_corridor(road, stub, length_m))
    for entry, exit_ in dict.fromkeys(routes):
        if any({c.first, c.second} == {entry, exit_} for c in out):
            continue
        legs = route(roads, entry, exit_)
        if legs is None:
            raise ValueError(
                f"no path joins roads {entry!r} and {exit_!r}: roads meet where one starts at "
                "another's start or on its centreline"
            )
        out.append(route_corridor(roads, legs, length_m, via))
    return out


__all__ = ["Corridor", "build_corridor", "left_of", "nearest_corridor", "site_corridors"]
