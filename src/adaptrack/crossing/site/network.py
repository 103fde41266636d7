"""The road network: where roads meet, the route of a flow, and roads that overlap.

Roads meet where one starts: at another road's start (the crossing centre, or a junction
elsewhere) or on another road's centreline (a side street joining a main road), within
``MEET_TOLERANCE_M``. The network is a graph whose nodes are the road ends and the meeting
points, whose edges run along the roads (their length) and join the coinciding nodes of
different roads (length 0); a flow's route is the shortest path from the far end of its entry
road to the far end of its exit road (``scipy.sparse.csgraph.dijkstra``), as legs ``(road,
s_from, s_to)``: driven towards the road's start when ``s_from > s_to``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import dijkstra

from .road import Road

MEET_TOLERANCE_M = 1.0  # a road's start this near another road meets it
JUNCTION_CLEAR_M = 20.0  # overlaps are looked for this far from every meeting point
OVERLAP_STEP_M = 1.0


@dataclass(frozen=True)
class Leg:
    """A stretch of one road on a route, from ``s_from`` to ``s_to`` [m]."""

    road: str
    s_from: float
    s_to: float

    @property
    def inbound(self) -> bool:
        """Whether the leg is driven towards the road's start (the crossing end)."""
        return self.s_from > self.s_to


def _centreline_distance(road: Road, point: np.ndarray) -> tuple[float, float]:
    """Distance [m] of a point from a road's sampled centreline, and the ``s`` there."""
    d = np.hypot(road.xy[:, 0] - point[0], road.xy[:, 1] - point[1])
    i = int(np.argmin(d))
    return float(d[i]), float(road.s[i])


def meeting_points(roads: dict[str, Road]) -> list[tuple[str, float, str, float]]:
    """Where roads meet: ``(road_a, s_a, road_b, s_b)``, ``road_b`` starting there."""
    out = []
    names = list(roads)
    for b in names:
        start = roads[b].xy[0]
        for a in names:
            if a == b:
                continue
            if np.hypot(*(roads[a].xy[0] - start)) <= MEET_TOLERANCE_M:
                if names.index(a) < names.index(b):
                    out.append((a, 0.0, b, 0.0))
                continue
            dist, s_a = _centreline_distance(roads[a], start)
            if dist <= MEET_TOLERANCE_M and s_a > 0.0:
                out.append((a, s_a, b, 0.0))
    return out


def route(roads: dict[str, Road], entry: str, exit_: str) -> list[Leg] | None:
    """Find the legs from the far end of ``entry`` to the far end of ``exit_`` (None: no path)."""
    if entry == exit_:
        return None
    nodes: dict[tuple[str, float], int] = {}

    def node(name: str, s: float) -> int:
        return nodes.setdefault((name, round(s, 6)), len(nodes))

    for name, road in roads.items():
        node(name, 0.0)
        node(name, road.length_m)
    joins = []
    for a, s_a, b, s_b in meeting_points(roads):
        joins.append((node(a, s_a), node(b, s_b)))
    rows, cols, weights = [], [], []
    for name in roads:
        on_road = sorted((s, i) for (r, s), i in nodes.items() if r == name)
        for (s0, i0), (s1, i1) in itertools.pairwise(on_road):
            rows += [i0, i1]
            cols += [i1, i0]
            weights += [s1 - s0, s1 - s0]
    for i, j in joins:
        rows += [i, j]
        cols += [j, i]
        weights += [1e-9, 1e-9]  # a join costs nothing (a zero would be no edge)
    graph = coo_array((weights, (rows, cols)), shape=(len(nodes), len(nodes))).tocsr()
    start, goal = (
        nodes[(entry, round(roads[entry].length_m, 6))],
        nodes[(exit_, round(roads[exit_].length_m, 6))],
    )
    dist, pred = dijkstra(graph, indices=start, return_predecessors=True)
    if not np.isfinite(dist[goal]):
        return None
    path = [goal]
    while path[-1] != start:
        path.append(int(pred[path[-1]]))
    key = {i: k for k, i in nodes.items()}
    stops = [key[i] for i in reversed(path)]
    legs: list[Leg] = []
    for (r0, s0), (r1, s1) in itertools.pairwise(stops):
        if r0 != r1:
            continue  # a join between roads
        if legs and legs[-1].road == r0:
            legs[-1] = Leg(r0, legs[-1].s_from, s1)
        else:
            legs.append(Leg(r0, s0, s1))
    return legs


def overlaps(roads: dict[str, Road]) -> list[tuple[str, str, float, float]]:
    """Stretches where two roads lie on each other away from where they meet.

    ``(road_a, road_b, s_from, s_to)`` along ``road_a``: its centreline within a lane width of
    ``road_b``'s, ``JUNCTION_CLEAR_M`` or more from every meeting point (a road drawn twice,
    or two roads that should meet but do not).
    """
    meets = meeting_points(roads)
    points = [roads[a].centreline(s_a)[0] for a, s_a, _, _ in meets]
    points += [road.xy[0] for road in roads.values()]
    anchors = np.array(points).reshape(-1, 2)
    out = []
    names = list(roads)
    for i, a in enumerate(names):
        s = np.arange(0.0, roads[a].length_m, OVERLAP_STEP_M)
        p = roads[a].centreline(s)[0]
        clear = np.min(np.hypot(*(p[:, None, :] - anchors[None, :, :]).transpose(2, 0, 1)), 1)
        for b in names[i + 1 :]:
            near = np.array([_centreline_distance(roads[b], q)[0] for q in p])
            lane = 0.5 * (roads[a].lane_width_m + roads[b].lane_width_m)
            hit = (near < lane) & (clear >= JUNCTION_CLEAR_M)
            if hit.sum() >= 3:
                out.append((a, b, float(s[hit][0]), float(s[hit][-1])))
    return out


__all__ = ["MEET_TOLERANCE_M", "Leg", "meeting_points", "overlaps", "route"]
