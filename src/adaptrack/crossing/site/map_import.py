"""A site file from a lane map: the roads, lanes, stop lines and turns around a crossing.

:func:`site_from_map` turns the lanes of a :class:`~.lanelet_map.LaneletMap` into the mapping
of a site file (``adaptrack site import`` writes it as TOML):

- **Arms.** A lane that starts or ends on the map's outline (within ``EDGE_M`` of its convex
  hull, at least ``MIN_LANE_WIDTH_M`` wide) is a mouth; mouths within ``ARM_JOIN_M`` of each
  other form one arm: its lanes in (towards the map's inside) and out.
- **Roads.** From the arm's innermost lane in, the lane is followed through its successors
  while it runs within ``ARM_TURN_DEG`` of the arm's direction (the straightest successor
  first). An arm whose lane passes within ``junction_radius_m`` of the crossing point is a
  road starting at the crossing centre; any other starts on the nearest road already built
  (a junction). The road's centreline is the lane's centre moved half a lane to its left
  (its points, smoothed as a survey, run outward from the crossing end), continued straight
  to the controlled zone and the run-in.
- **Stop lines.** The map's stop line across a crossing road's lanes in, nearest the centre.
- **Turns.** The map's lanes that lead from one crossing road's lanes in to another's lanes
  out become the connection's path; every pair of roads joined by lanes is a flow.
- **Radars.** One per road, 12 m behind its crossing end on the kerb side of its lanes in,
  looking along it, with typical 77 GHz noise curves (edit them to the installed radars).

Coordinates in the site are the map's minus the crossing point: recorded motion in the map's
frame replays with ``adaptrack simulate --motion ... --origin X,Y`` (the crossing point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import tomlkit
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial import ConvexHull

from ..._typing import FloatArray
from .corridor import left_of
from .lanelet_map import LaneletMap
from .road import Road, polyline_road

EDGE_M = 5.0  # a lane end this near the map's outline is a mouth
MIN_LANE_WIDTH_M = 2.0  # narrower lanelets are painted islands or kerb strips, not lanes
ARM_JOIN_M = 10.0  # mouths this near each other belong to one arm
ARM_TURN_DEG = 35.0  # a successor heading this far off the arm's direction turns off it
SURVEY_STEP_M = 2.0  # centreline points kept every this far
RADAR_BACK_M = 12.0  # a radar stands this far behind the crossing centre
RADAR_KERB_M = 2.0  # and this far beyond its road's outermost lane in
MAX_ROUTE_LANES = 12  # lanelets on a path from one road to another at most
DEFAULT_RADAR = {
    "height_m": 6.0,
    "period_s": 0.05,
    "fov_half_deg": 60.0,
    "range_std_m": [[0.0, 0.15], [250.0, 0.4]],
    "azimuth_std_deg": [[0.0, 0.1], [9.0, 0.3], [60.0, 1.2]],
    "radial_speed_std_mps": 0.1,
}


@dataclass(frozen=True)
class _Arm:
    """Lanes in and out at one mouth of the map, and the lanes followed from them."""

    lanes_in: tuple[int, ...]
    lanes_out: tuple[int, ...]
    spine: tuple[int, ...]  # from the innermost lane in, inwards
    exit_chain: tuple[int, ...]  # to the innermost lane out, outwards
    direction: FloatArray  # unit vector of travel inwards


def _unit(v: FloatArray) -> FloatArray:
    return v / max(float(np.hypot(*v)), 1e-12)


def _end_direction(c: FloatArray, end: bool) -> FloatArray:
    """Return the unit tangent of a centre polyline at its end (``end``) or its start."""
    return _unit(c[-1] - c[-2]) if end else _unit(c[1] - c[0])


def _mouths(lmap: LaneletMap) -> list[tuple[int, bool, FloatArray]]:
    """Lane ends on the map's outline: ``(lane id, inbound, point)``."""
    pts = np.concatenate([lane.centre for lane in lmap.lanes.values()])
    hull = ConvexHull(pts)
    eq = hull.equations  # a x + b y + c <= 0 inside

    def on_edge(p: FloatArray) -> bool:
        return bool(np.max(eq[:, :2] @ p + eq[:, 2]) > -EDGE_M)

    mouths = []
    for k, lane in lmap.lanes.items():
        if lane.width_m < MIN_LANE_WIDTH_M or len(lane.centre) < 2:
            continue
        if not lmap.predecessors(k) and on_edge(lane.centre[0]):
            mouths.append((k, True, lane.centre[0]))
        if not lane.successors and on_edge(lane.centre[-1]):
            mouths.append((k, False, lane.centre[-1]))
    return mouths


def _follow(lmap: LaneletMap, first: int, direction: FloatArray, forward: bool) -> tuple[int, ...]:
    """Lanes from ``first`` through successors (or predecessors) that keep ``direction``."""
    chain = [first]
    while True:
        here = lmap.lanes[chain[-1]].centre
        nxt = lmap.lanes[chain[-1]].successors if forward else tuple(lmap.predecessors(chain[-1]))
        best, best_turn = None, math.radians(ARM_TURN_DEG)
        for k in nxt:
            if k in chain:
                continue
            c = lmap.lanes[k].centre
            far_end = _end_direction(c, forward)
            turn = math.acos(float(np.clip(far_end @ direction, -1.0, 1.0)))
            if (
                turn <= best_turn
                and np.hypot(*(c[0 if forward else -1] - here[-1 if forward else 0])) < 1.0
            ):
                best, best_turn = k, turn
        if best is None:
            return tuple(chain)
        chain.append(best)


def _arms(lmap: LaneletMap) -> list[_Arm]:
    mouths = _mouths(lmap)
    if not mouths:
        raise ValueError("the map has no lane that starts or ends on its outline (no arm)")
    points = np.array([m[2] for m in mouths])
    groups = (
        fcluster(linkage(points, "single"), ARM_JOIN_M, "distance")
        if len(points) > 1
        else np.array([1])
    )
    arms = []
    for g in np.unique(groups):
        members = [m for m, gi in zip(mouths, groups, strict=True) if gi == g]
        ins = [m for m in members if m[1]]
        outs = [m for m in members if not m[1]]
        if not ins:
            continue  # a mouth with lanes out only: traffic leaves there but never enters
        out_centre = np.mean([m[2] for m in outs], 0) if outs else None
        inner = min(
            ins, key=lambda m: 0.0 if out_centre is None else np.hypot(*(m[2] - out_centre))
        )
        direction = _end_direction(lmap.lanes[inner[0]].centre, False)
        spine = _follow(lmap, inner[0], direction, True)
        chain: tuple[int, ...] = ()
        if outs:
            in_centre = np.mean([m[2] for m in ins], 0)
            inner_out = min(outs, key=lambda m: np.hypot(*(m[2] - in_centre)))
            back = _end_direction(lmap.lanes[inner_out[0]].centre, True)
            chain = _follow(lmap, inner_out[0], back, False)[::-1]
        arms.append(
            _Arm(
                tuple(sorted(m[0] for m in ins)),
                tuple(sorted(m[0] for m in outs)),
                spine,
                chain,
                direction,
            )
        )
    return arms


def _centre_points(lmap: LaneletMap, lanes: tuple[int, ...]) -> FloatArray:
    """Join the centres of consecutive lanes into one polyline, repeated joints dropped."""
    pts = [lmap.lanes[lanes[0]].centre]
    for k in lanes[1:]:
        c = lmap.lanes[k].centre
        pts.append(c[1:] if np.hypot(*(c[0] - pts[-1][-1])) < 1e-6 else c)
    return np.concatenate(pts)


def _forward_only(points: FloatArray, min_step_m: float = 1.0) -> FloatArray:
    """Drop the points of a polyline that step back or sideways (joints of lanelets)."""
    kept = [points[0]]
    heading = None
    for p in points[1:]:
        step = p - kept[-1]
        length = float(np.hypot(*step))
        if length < min_step_m or (heading is not None and step @ heading < 0.5 * length):
            continue
        heading = step / length
        kept.append(p)
    return np.array(kept)


def _thin(points: FloatArray, step_m: float) -> FloatArray:
    """Keep the points of a polyline at least ``step_m`` apart, its first and last always."""
    kept = [0]
    for k in range(1, len(points) - 1):
        if np.hypot(*(points[k] - points[kept[-1]])) >= step_m:
            kept.append(k)
    if np.hypot(*(points[-1] - points[kept[-1]])) < 0.5 * step_m and len(kept) > 1:
        kept.pop()
    return points[[*kept, len(points) - 1]]


def _rounded(points: FloatArray) -> list:
    """Coordinates to the centimetre, as lists (no negative zero)."""
    return (np.round(points, 2) + 0.0).tolist()


def _heading_deg(v: FloatArray) -> float:
    return math.degrees(math.atan2(v[0], v[1])) % 360.0


def _lane_path(lmap: LaneletMap, sources: set[int], targets: set[int]) -> list[int] | None:
    """Shortest run of lanes from a lane in ``sources`` to one in ``targets`` (both ends kept)."""
    frontier = [[k] for k in sources]
    seen = set(sources)
    for _ in range(MAX_ROUTE_LANES):
        nxt = []
        for path in frontier:
            if path[-1] in targets:
                return path
            for k in lmap.lanes[path[-1]].successors:
                if k not in seen:
                    seen.add(k)
                    nxt.append([*path, k])
        frontier = nxt
    return None


def site_from_map(
    lmap: LaneletMap,
    crossing_xy: tuple[float, float],
    name: str,
    junction_radius_m: float = 15.0,
    zone_m: float = 150.0,
    run_in_m: float = 50.0,
    rails_deg: float | None = None,
    vehicles_per_h: float = 30.0,
) -> dict:
    """Build the mapping of a site file for the crossing at ``crossing_xy`` (map frame) [m].

    See the module docstring; raises ``ValueError`` when the map has no arm or none near the
    crossing point.
    """
    c = np.asarray(crossing_xy, dtype=float)
    arms = _arms(lmap)
    widths = [lmap.lanes[k].width_m for a in arms for k in a.spine]
    lane_w = round(float(np.median(widths)) * 20) / 20
    length = zone_m + run_in_m
    built: dict[str, Road] = {}
    roads, names, at_centre = [], {}, []
    spines = []
    for arm in arms:
        lane = _forward_only(_centre_points(lmap, arm.spine))
        centre = _forward_only(left_of(lane, 0.5 * lane_w)) - c
        spines.append(centre)
    order = np.argsort([np.hypot(*s.T).min() for s in spines])
    used_names: set[str] = set()
    for i in order:
        arm, centre = arms[i], spines[i]
        dist = np.hypot(*centre.T)
        nearest = int(np.argmin(dist))
        crossing_road = dist[nearest] <= junction_radius_m
        if crossing_road:
            outward = centre[: nearest + 1][::-1]
            outward = outward[np.hypot(*outward.T) > lane_w]
            start = np.zeros(2)
        elif built:
            outward = centre[::-1]
            start = min(
                (r.xy[int(np.argmin(np.hypot(*(r.xy - outward[0]).T)))] for r in built.values()),
                key=lambda p: float(np.hypot(*(p - outward[0]))),
            )
        else:
            raise ValueError(
                f"no lane of the map passes within {junction_radius_m:g} m of the crossing point "
                f"{tuple(crossing_xy)}: give the point on a road (map frame, metres), or a "
                "larger --junction-radius"
            )
        points = _thin(np.concatenate([[start], outward]), SURVEY_STEP_M)
        base = _compass(_heading_deg(-arm.direction))
        road_name = base
        for k in range(2, len(arms) + 2):
            if road_name not in used_names:
                break
            road_name = f"{base}{k}"
        used_names.add(road_name)
        names[i] = road_name
        lanes = (len(arm.lanes_in), len(arm.lanes_out))
        surveyed = polyline_road(road_name, points, lane_w, 0.0, lanes).length_m
        extend = float(math.ceil(max(length - surveyed, 0.0))) + 1.0
        built[road_name] = polyline_road(road_name, points, lane_w, extend, lanes)
        entry: dict = {
            "name": road_name,
            "points_m": _rounded(points),
            "extend_m": extend,
            "lanes_in": lanes[0],
            "lanes_out": lanes[1],
        }
        if crossing_road:
            at_centre.append(i)
            stop = _stop_line(lmap, built[road_name], c, lane_w)
            if stop is not None:
                entry["stop_line_m"] = stop
        roads.append(entry)
    connections, flows = [], []
    lane_sets = {i: (set(arms[i].spine), set(arms[i].exit_chain)) for i in names}
    for i in names:
        for j in names:
            if i == j or not lane_sets[j][1]:
                continue
            path = _lane_path(lmap, lane_sets[i][0], lane_sets[j][1])
            if path is None:
                continue
            flows.append({"entry": names[i], "exit": names[j], "vehicles_per_h": vehicles_per_h})
            between = [k for k in path if k not in lane_sets[i][0] and k not in lane_sets[j][1]]
            if between and i in at_centre and j in at_centre:
                pts = _thin(_centre_points(lmap, tuple(between)) - c, 1.0)
                if len(pts) >= 2:
                    connections.append(
                        {"entry": names[i], "exit": names[j], "points_m": _rounded(pts)}
                    )
    radars = [_radar(name, road, lane_w, length) for name, road in built.items()]
    site: dict = {
        "name": name,
        "description": (
            f"Imported from a lane map; its point ({c[0]:.2f}, {c[1]:.2f}) [m] is the crossing "
            "centre. Radars, noise and flows are typical values: edit them."
        ),
        "lane_width_m": lane_w,
        "zone_m": zone_m,
        "run_in_m": run_in_m,
    }
    if rails_deg is not None:
        site["rails"] = {"axis_deg": rails_deg}
    site["roads"] = roads
    if connections:
        site["connections"] = connections
    site["radars"] = radars
    if flows:
        site["scene"] = {"duration_s": 900.0, "flows": flows}
    return site


def _compass(heading_deg: float) -> str:
    return ("north", "east", "south", "west")[int(((heading_deg + 45.0) % 360.0) // 90.0)]


def _stop_line(lmap: LaneletMap, road: Road, c: FloatArray, lane_w: float) -> float | None:
    """Distance from the crossing end of the map's stop line across ``road``'s lanes in [m]."""
    best = None
    for line in lmap.stop_lines:
        mid = line.mean(0) - c
        s, d = road.project(mid)
        if abs(float(d)) <= (road.lanes_in + 0.5) * lane_w and 0.0 < float(s) < 100.0:
            best = float(s) if best is None else min(best, float(s))
    return None if best is None else round(best, 2)


def _radar(road_name: str, road: Road, lane_w: float, length_m: float) -> dict:
    ahead = road.centreline(np.array([0.0, min(30.0, road.length_m)]))[0]
    out = _unit(ahead[1] - ahead[0])
    left = np.array([-out[1], out[0]])
    pos = road.xy[0] - RADAR_BACK_M * out + (road.lanes_in * lane_w + RADAR_KERB_M) * left
    aim = road.lane_point(np.array([min(60.0, road.length_m)]))[0] - pos
    return {
        "name": f"radar_{road_name}",
        "position_m": _rounded(pos),
        "boresight_deg": round(_heading_deg(aim), 1),
        "max_range_m": float(math.ceil(length_m + 2 * RADAR_BACK_M)),
        **DEFAULT_RADAR,
    }


def site_toml(site: dict, header: str) -> str:
    """Write the site mapping as TOML text, after ``header`` (each line made a comment)."""
    lines = "".join(f"# {line}\n".replace("# \n", "#\n") for line in header.splitlines())
    return lines + "\n" + tomlkit.dumps(site)


__all__ = ["site_from_map", "site_toml"]
