"""Corridors: the path through the crossing formed by two roads.

A corridor joins the centreline of one road (driven towards the crossing) to the centreline of
another (driven away from it). Its coordinate ``u`` runs from the far end of the first road
through the crossing centre (``u = crossing_u``) to the far end of the second. It is a
:class:`~adaptrack.crossing.site.road.Road` with lane width 0, so its ``lane_point(u, d)`` is the
point ``d`` to the right of the direction of *decreasing* ``u``: traffic from the first road
drives at ``d = -w/2`` (on its right), traffic from the second at ``d = +w/2``. The scene
simulator moves road users along corridors and the scene tracker estimates in corridor
coordinates, both through this geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .road import STEP_M, Road, RoadElement, build_road

MAX_JOIN_DEG = 20.0  # two roads join into a corridor if they leave the crossing this straight


@dataclass(frozen=True, eq=False)
class Corridor:
    """A path ``first -> second`` through the crossing; ``path`` holds its geometry."""

    first: str
    second: str
    path: Road
    crossing_u: float


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
    return Corridor(first.name, second.name, path, float(u[s_in.size]))


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


def site_corridors(roads: dict[str, Road], length_m: float) -> list[Corridor]:
    """One corridor per pair of roads that continue each other; a lone road alone.

    A road without a partner forms a corridor with a straight stub beyond the crossing.
    """
    names = list(roads)
    used: set[str] = set()
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if a in used or b in used:
                continue
            try:
                out.append(build_corridor(roads[a], roads[b], length_m))
            except ValueError:
                continue
            used.update((a, b))
    for name in names:
        if name not in used:
            road = roads[name]
            stub = build_road(
                f"{name}-stub", road.heading_rad + math.pi, road.lane_width_m,
                (RoadElement("straight", 30.0),),
            )  # fmt: skip
            out.append(build_corridor(road, stub, length_m))
    return out


__all__ = ["Corridor", "build_corridor", "nearest_corridor", "site_corridors"]
