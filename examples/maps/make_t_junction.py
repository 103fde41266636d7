"""Write ``t_junction.osm``: a small hand-made Lanelet2 map (OSM XML) of a crossing road.

A main road runs east-west along y = 0 (one lane each way, 3.5 m wide) from x = -100 m to
x = 100 m; a level crossing is meant at x = -40 m (stop lines at x = -55 m and -25 m); a side
road leaves it northwards at x = 30 m (centreline x = 30 m, to y = 100 m; stop line at
y = 10 m) with four turning lanelets. Coordinates are metres of the map's local frame, written
as latitude/longitude through Lanelet2's ``UtmProjector`` about the origin (0, 0), the
INTERACTION data set's convention. Run ``python examples/maps/make_t_junction.py`` (needs
``lanelet2``) to rebuild the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lanelet2.core import BasicPoint3d
from lanelet2.io import Origin
from lanelet2.projection import UtmProjector

HALF = 1.75  # half a lane [m]
R = 6.25  # turning radius of the right turns' lane centres [m]


def _arc(centre, a0, a1):
    """Lane centre along a circle of radius R from angle a0 to a1 [rad, ccw from east]."""
    return lambda t: np.stack(
        [centre[0] + R * np.cos(a0 + t * (a1 - a0)), centre[1] + R * np.sin(a0 + t * (a1 - a0))], -1
    )


def _bezier(p0, c0, c1, p1):
    p0, c0, c1, p1 = (np.asarray(v, dtype=float) for v in (p0, c0, c1, p1))
    return lambda t: (
        (1 - t[:, None]) ** 3 * p0
        + 3 * (1 - t[:, None]) ** 2 * t[:, None] * c0
        + 3 * (1 - t[:, None]) * t[:, None] ** 2 * c1
        + t[:, None] ** 3 * p1
    )


def _straight(p, q):
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    return lambda t: p + t[:, None] * (q - p)


def lanes():
    """Lane centres as curves t in [0, 1] -> (east, north) [m], in driving direction."""
    x = (-100.0, 22.0, 38.0, 100.0)
    out = {}
    for i in range(3):  # eastbound (y = -1.75), westbound (y = +1.75), in three pieces
        out[f"eb{i}"] = _straight((x[i], -HALF), (x[i + 1], -HALF))
        out[f"wb{i}"] = _straight((x[3 - i], HALF), (x[2 - i], HALF))
    out["nb"] = _straight((30.0 + HALF, 8.0), (30.0 + HALF, 100.0))  # the side road, away
    out["sb"] = _straight((30.0 - HALF, 100.0), (30.0 - HALF, 8.0))  # towards the main road
    out["wb_to_nb"] = _arc((38.0, 8.0), -0.5 * np.pi, -np.pi)  # right turns
    out["sb_to_wb"] = _arc((22.0, 8.0), 0.0, -0.5 * np.pi)
    out["eb_to_nb"] = _bezier((22.0, -HALF), (28.0, -HALF), (31.75, 2.0), (31.75, 8.0))  # left
    out["sb_to_eb"] = _bezier((28.25, 8.0), (28.25, 2.0), (32.0, -HALF), (38.0, -HALF))
    return out


def _bounds(curve, n=25):
    """Left and right boundaries (n, 2) of a lane, HALF from its centre (exact tangents)."""
    t = np.linspace(0.0, 1.0, n)
    h = 1e-6
    d = curve(np.clip(t + h, 0, 1)) - curve(np.clip(t - h, 0, 1))
    d /= np.hypot(d[:, 0], d[:, 1])[:, None]
    left = np.stack([-d[:, 1], d[:, 0]], -1)
    centre = curve(t)
    return centre + HALF * left, centre - HALF * left


STOP_LINES = (
    ((-55.0, -3.5), (-55.0, 0.0)),
    ((-25.0, 0.0), (-25.0, 3.5)),
    ((30.0, 10.0), (26.5, 10.0)),
)


def osm_text() -> str:
    """The map as OSM XML (shared end points of boundaries are shared nodes)."""
    proj = UtmProjector(Origin(0.0, 0.0))
    nodes: dict[tuple[float, float], int] = {}
    ways: list[tuple[int, list[int], dict[str, str]]] = []
    relations = []

    def node(p) -> int:
        key = (round(float(p[0]), 3), round(float(p[1]), 3))
        return nodes.setdefault(key, len(nodes) + 1)

    def way(points, tags) -> int:
        wid = 1000 + len(ways)
        ways.append((wid, [node(p) for p in points], tags))
        return wid

    for k, curve in enumerate(lanes().values()):
        left, right = _bounds(curve)
        lw = way(left, {"type": "line_thin", "subtype": "dashed"})
        rw = way(right, {"type": "line_thin", "subtype": "solid"})
        relations.append((2000 + k, lw, rw))
    for line in STOP_LINES:
        way(np.array(line), {"type": "stop_line"})
    rows = ["<?xml version='1.0' encoding='UTF-8'?>", "<osm version='0.6' generator='adaptrack'>"]
    for (x, y), nid in nodes.items():
        g = proj.reverse(BasicPoint3d(x, y, 0.0))
        attrs = f"id='{nid}' visible='true' version='1' lat='{g.lat:.11f}' lon='{g.lon:.11f}'"
        rows.append(f"  <node {attrs} />")
    for wid, refs, tags in ways:
        rows.append(f"  <way id='{wid}' visible='true' version='1'>")
        rows += [f"    <nd ref='{r}' />" for r in refs]
        rows += [f"    <tag k='{k}' v='{v}' />" for k, v in tags.items()]
        rows.append("  </way>")
    for rid, lw, rw in relations:
        rows.append(f"  <relation id='{rid}' visible='true' version='1'>")
        rows.append(f"    <member type='way' ref='{lw}' role='left' />")
        rows.append(f"    <member type='way' ref='{rw}' role='right' />")
        for k, v in (
            ("type", "lanelet"),
            ("subtype", "road"),
            ("location", "urban"),
            ("one_way", "yes"),
        ):
            rows.append(f"    <tag k='{k}' v='{v}' />")
        rows.append("  </relation>")
    rows.append("</osm>")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    Path(__file__).with_name("t_junction.osm").write_text(osm_text(), encoding="utf-8")
