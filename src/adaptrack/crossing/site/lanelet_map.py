"""Read a Lanelet2 map (OSM XML) into plain arrays: lanes with their topology, stop lines.

A Lanelet2 map (the format of the INTERACTION data set and of Autoware) holds lanelets: a
left and a right boundary polyline and the driving direction between them; stop lines are
line strings of type ``stop_line``. :func:`read_lanelet_map` parses the file with the
``lanelet2`` library (``pip install 'adaptrack[maps]'``), projects it onto a local metric frame
(Lanelet2's ``UtmProjector`` about ``origin_latlon``; the INTERACTION maps use the origin
(0, 0), which gives their track files' x/y) and finds each lanelet's successors in its
routing graph (vehicles, no lane changes).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..._typing import FloatArray


@dataclass(frozen=True, eq=False)
class Lane:
    """One lanelet: its centre (K, 2) in driving order [m], mean width [m], successor ids."""

    id: int
    centre: FloatArray
    width_m: float
    successors: tuple[int, ...]


@dataclass(frozen=True, eq=False)
class LaneletMap:
    """The lanes and stop lines (each (2+, 2) [m]) of a map, in its local metric frame."""

    lanes: dict[int, Lane]
    stop_lines: tuple[FloatArray, ...]
    origin_latlon: tuple[float, float]

    @cached_property
    def _predecessors(self) -> dict[int, list[int]]:
        out: dict[int, list[int]] = {k: [] for k in self.lanes}
        for k, lane in self.lanes.items():
            for n in lane.successors:
                out[n].append(k)
        return out

    def predecessors(self, lane_id: int) -> list[int]:
        """Ids of the lanes that lead into ``lane_id``."""
        return self._predecessors[lane_id]


def _lanelet2():  # type: ignore[no-untyped-def]
    try:
        import lanelet2
        from lanelet2 import projection
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ValueError(
            "reading a Lanelet2 map needs the lanelet2 package: pip install 'adaptrack[maps]'"
        ) from exc
    return lanelet2, projection


def _polyline(line) -> FloatArray:  # type: ignore[no-untyped-def]
    return np.array([[p.x, p.y] for p in line], dtype=float)


def _mean_width(left: FloatArray, right: FloatArray) -> float:
    """Mean distance from the left boundary's points to the right boundary polyline [m]."""
    a, b = right[:-1], right[1:]
    d = b - a
    t = np.clip(
        np.einsum("kij,ij->ki", left[:, None, :] - a[None], d) / np.maximum((d * d).sum(1), 1e-12),
        0.0,
        1.0,
    )
    nearest = a[None] + t[..., None] * d[None]
    return float(np.hypot(*(left[:, None, :] - nearest).transpose(2, 0, 1)).min(1).mean())


def read_lanelet_map(path: Path, origin_latlon: tuple[float, float] = (0.0, 0.0)) -> LaneletMap:
    """Read the lanelets and stop lines of a Lanelet2 OSM file (see the module docstring).

    Raises ``ValueError`` naming the file when it cannot be read or holds no lanelet.
    """
    lanelet2, projection = _lanelet2()
    if not Path(path).is_file():
        raise ValueError(f"{path}: no such map file")
    projector = projection.UtmProjector(lanelet2.io.Origin(*origin_latlon))
    try:
        lmap, errors = lanelet2.io.loadRobust(str(path), projector)
    except RuntimeError as exc:
        raise ValueError(f"{path}: not a Lanelet2 map ({exc})") from exc
    if len(lmap.laneletLayer) == 0:
        detail = f" ({errors[0]})" if errors else ""
        raise ValueError(f"{path}: the map holds no lanelet{detail}")
    rules = lanelet2.traffic_rules.create(
        lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
    )
    graph = lanelet2.routing.RoutingGraph(lmap, rules)
    lanes = {}
    for ll in lmap.laneletLayer:
        left, right = _polyline(ll.leftBound), _polyline(ll.rightBound)
        lanes[int(ll.id)] = Lane(
            int(ll.id),
            _polyline(ll.centerline),
            _mean_width(left, right),
            tuple(int(n.id) for n in graph.following(ll, False)),
        )
    stops = tuple(
        _polyline(ls)
        for ls in lmap.lineStringLayer
        if "type" in ls.attributes and ls.attributes["type"] == "stop_line"
    )
    return LaneletMap(lanes, stops, origin_latlon)


def project_latlon(latlon: tuple[float, float], origin_latlon: tuple[float, float]) -> FloatArray:
    """Map-frame x, y [m] of a point ``(lat_deg, lon_deg)`` (the map's ``UtmProjector``)."""
    lanelet2, projection = _lanelet2()
    projector = projection.UtmProjector(lanelet2.io.Origin(*origin_latlon))
    p = projector.forward(lanelet2.core.GPSPoint(*latlon))
    return np.array([p.x, p.y])


__all__ = ["Lane", "LaneletMap", "project_latlon", "read_lanelet_map"]
