"""Mixed-traffic scene at a crossing: many road users, barrier closures and raw radar detections.

Road users arrive on each flow (entry road -> exit road) as a Poisson stream with the scene's
class mix and drive along their corridor (:mod:`adaptrack.crossing.site.corridor`) with the
Intelligent Driver Model: they keep their desired speed, follow the vehicle ahead, and queue
at the stop line while the barriers are closed (from ``WARNING_S`` before closure, if they can
stop at ``STOP_DECEL_MPS2``; those that cannot drive on). A road user follows the nearest one
ahead in its corridor and direction whose body its own would touch beside it (lateral extents
overlapping): the vehicles of a lane follow one another; a motorcycle along the centre line,
a cyclist on the lane's edge and a pedestrian on the footway pass a car queue where there is
room (they are overtaken, and motorcycles overtake), and queue behind a vehicle they cannot
pass (a bus or truck leaves no room in the lane; a car that keeps to that side neither). A
stall makes one vehicle stop between the barriers for minutes; the vehicles behind it
queue.

Each radar scan reports **detections without identities**: each road user in view gives a
class-dependent number of detections (several over a long body), each detected with the
radar's ``P_D(class, range)``, reflected from a point spread over the body (along
``N(0, (L/4)^2)`` clipped to the body, across uniform), with the radar's noise curves; users in
the radar shadow of a nearer truck or bus are lost (``OCCLUDED_P``); each detection has a
multipath ghost further out with the scene's probability; Poisson false alarms fall uniformly
over the fields of view with random radial speed; static clutter points (barrier arms, poles)
return zero Doppler on every scan with ``STATIC_P_D``. The reference point of a road user is
the centre of its body.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import pandas as pd

from ..._typing import FloatArray
from ...angles import wrap, wrapped
from ..site.corridor import Corridor
from ..site.geometry import radial_geometry
from ..site.model import Site
from ..site.road import polyline_road
from ..site.sensor import RadarSpec
from ..site.traffic import KMH, WALKERS_AND_RIDERS, VehicleClass

DESIRED_SPEED_KMH = {  # mean and standard deviation of the desired speed per class
    "car": (60.0, 12.0),
    "motorcycle": (65.0, 15.0),
    "truck": (50.0, 8.0),
    "bus": (50.0, 8.0),
    "pedestrian": (5.0, 1.0),
    "cyclist": (18.0, 4.0),
}  # another class: 0.8 of its top speed up to 60 km/h, sigma 20 % of that
LONG_M = 7.0  # a body this long gives 2-4 detections per scan (4 m: 1-2; shorter: 1)
LARGE_WIDTH_M = 2.4  # a body this wide (truck, bus, tractor) casts a radar shadow


def road_users(site: Site) -> dict[str, VehicleClass]:
    """Classes of a site's scene: its vehicle classes, pedestrians and cyclists."""
    return {**site.classes, **WALKERS_AND_RIDERS}


def desired_speed_kmh(user: VehicleClass) -> tuple[float, float]:
    """Mean and standard deviation of a class's desired speed [km/h]."""
    if user.name in DESIRED_SPEED_KMH:
        return DESIRED_SPEED_KMH[user.name]
    mean = min(60.0, 0.8 * user.max_speed_kmh)
    return mean, 0.2 * mean


def detections_per_scan(length_m: FloatArray) -> np.ndarray:
    """Fewest and most detections of a body per scan (N, 2), by its length [m]."""
    length_m = np.asarray(length_m, dtype=float)
    lo = np.where(length_m >= LONG_M, 2, 1)
    hi = np.where(length_m >= LONG_M, 4, np.where(length_m >= 4.0, 2, 1))
    return np.stack([lo, hi], -1)


OCCLUDED_P = 0.85  # probability that a detection in a radar shadow is lost
STATIC_P_D = 0.9
WARNING_S = 8.0  # lights flash this long before the barriers close
STOP_DECEL_MPS2 = 4.0  # a vehicle stops for the barriers if it can at this deceleration
IDM_GAP_M, IDM_HEADWAY_S, IDM_COMFORT_DECEL = 2.0, 1.2, 2.0
FALSE_ALARM_SPEED_MPS = 20.0  # false alarms' radial speeds are uniform within +-this
STEP_S = 0.05  # integration step of the traffic [s]
STOPPED_MPS = 0.3  # a road user slower than this is stopped (stall events are timed by it)


@dataclass(frozen=True)
class Flow:
    """Poisson arrivals on the corridor from road ``entry`` to road ``exit`` [vehicles/h]."""

    entry: str
    exit: str
    vehicles_per_h: float


@dataclass(frozen=True)
class Stall:
    """The first vehicle from ``entry`` after ``time_s`` stops ``at_m`` before the crossing."""

    entry: str
    time_s: float
    at_m: float = 0.0
    duration_s: float = 180.0
    vehicle_class: str = "car"


@dataclass(frozen=True)
class Parked:
    """A road user standing at ``position_m`` from ``from_s`` to ``until_s`` (None: the end).

    ``heading_deg`` clockwise from north; size the class's unless given [m].
    """

    position_m: tuple[float, float]
    heading_deg: float = 0.0
    vehicle_class: str = "car"
    length_m: float | None = None
    width_m: float | None = None
    from_s: float = 0.0
    until_s: float | None = None


SCRIPT_STEP_M = 1.0  # a scripted path is sampled this finely ...
SCRIPT_ROUNDING_M = 0.1  # ... and smoothed this much: its corners are rounded


@dataclass(frozen=True)
class Scripted:
    """A road user driven along ``path_m`` [m] by ``speed_profile`` from ``start_s`` [s].

    ``speed_profile``: ``(time_s, speed_mps)`` knots from 0, linear between them; the user
    travels the path from its first point, facing backwards while the speed is negative
    (reversing); it leaves after the last knot or at the end of the path. Size the class's
    unless given [m].
    """

    path_m: tuple[tuple[float, float], ...]
    speed_profile: tuple[tuple[float, float], ...]
    start_s: float = 0.0
    vehicle_class: str = "car"
    length_m: float | None = None
    width_m: float | None = None


@dataclass(frozen=True)
class Trains:
    """A train passes between the barriers in the middle of every closure.

    The trains alternate direction and track; each is a box ``length_m`` x ``width_m`` x
    ``height_m`` at ``speed_kmh``, simulated while within ``run_m`` of the crossing centre.
    """

    length_m: float = 150.0
    width_m: float = 3.2
    height_m: float = 4.2
    speed_kmh: float = 80.0
    run_m: float = 300.0


@dataclass(frozen=True)
class SceneSpec:
    """What the scene simulates (the ``[scene]`` table of a site file; defaults below)."""

    duration_s: float = 3600.0
    flows: tuple[Flow, ...] = ()
    mix: dict[str, float] = field(default_factory=dict)
    closure_every_s: float = 600.0
    closure_s: float = 120.0
    first_closure_s: float = 300.0
    false_alarms_per_scan: float = 0.5
    static_clutter_m: tuple[tuple[float, float], ...] = ()
    multipath_probability: float = 0.01
    multipath_extra_m: float = 8.0
    occlusion: bool = True
    stationary_detections: bool = True
    stalls: tuple[Stall, ...] = ()
    parked: tuple[Parked, ...] = ()
    scripted: tuple[Scripted, ...] = ()
    trains: Trains | None = None

    def closures(self) -> FloatArray:
        """Barrier closures (K, 2): closing and opening times [s]."""
        if self.closure_s <= 0:
            return np.zeros((0, 2))
        start = np.arange(self.first_closure_s, self.duration_s, self.closure_every_s)
        return np.stack([start, start + self.closure_s], -1)

    def warnings(self) -> FloatArray:
        """Return the warning intervals (K, 2) [s]: lights flashing, then barriers down.

        From ``WARNING_S`` before each closure until the barriers open (what the crossing
        controller tells a tracker).
        """
        closures = self.closures()
        return np.stack([closures[:, 0] - WARNING_S, closures[:, 1]], -1)


def scene_spec(site: Site, **changes: Any) -> SceneSpec:
    """Return the site's scene (its ``[scene]`` table) with ``changes``.

    Without flows, every corridor carries 300 vehicles/h each way (600/h in all on a two-road
    site); without a mix, the site's traffic mix plus 2 % pedestrians and 2 % cyclists.
    """
    data = dict(site.source.get("scene", {}))
    if "flows" in data:
        flows = tuple(Flow(**f) for f in data.pop("flows"))
    else:
        flows = tuple(
            flow
            for c in site.corridors
            if c.second in site.roads
            for flow in (Flow(c.first, c.second, 300.0), Flow(c.second, c.first, 300.0))
        )
    mix = data.pop("mix", None)
    if mix is None:
        mix = {k: 0.96 * v for k, v in site.traffic_mix.items()}
        mix.update(pedestrian=0.02, cyclist=0.02)
    stalls = tuple(Stall(**s) for s in data.pop("stalls", []))
    parked = tuple(
        Parked(**{**p, "position_m": tuple(p["position_m"])}) for p in data.pop("parked", [])
    )
    scripted = tuple(
        Scripted(
            **{**p, "path_m": tuple(tuple(q) for q in p["path_m"]),
               "speed_profile": tuple((t, v * KMH) for t, v in p["speed_profile"])}
        )
        for p in data.pop("scripted", [])
    )  # fmt: skip
    trains = Trains(**data.pop("trains")) if "trains" in data else None
    clutter = tuple(tuple(p) for p in data.pop("static_clutter_m", []))
    spec = SceneSpec(
        flows=flows,
        mix=mix,
        stalls=stalls,
        parked=parked,
        scripted=scripted,
        trains=trains,
        static_clutter_m=clutter,
        **data,
    )
    spec = SceneSpec(**{**spec.__dict__, **changes})
    _check_spec(spec, site)
    return spec


def _check_spec(spec: SceneSpec, site: Site) -> None:
    if not any(f.vehicles_per_h > 0 for f in spec.flows):
        raise ValueError(
            f"scene of site {site.name!r}: no traffic flow; flows run between two roads that "
            "continue each other through the crossing (set [scene] flows; a site with one "
            "road, or roads that all turn at the crossing, has none)"
        )
    for f in spec.flows:
        for road in (f.entry, f.exit):
            if road not in site.roads:
                raise ValueError(f"scene flow {f.entry}->{f.exit}: unknown road {road!r}")
    users = road_users(site)
    for name in spec.mix:
        if name not in users:
            raise ValueError(f"scene mix: unknown class {name!r}; known: {', '.join(users)}")
    total = sum(spec.mix.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"scene mix: shares must sum to 1; they sum to {total:g}")
    for st in spec.stalls:
        if not any(f.entry == st.entry for f in spec.flows):
            raise ValueError(f"scene stall: no flow enters on road {st.entry!r}")
    added = [("parked", i, p.vehicle_class) for i, p in enumerate(spec.parked)]
    added += [("scripted", i, p.vehicle_class) for i, p in enumerate(spec.scripted)]
    for key, i, name in added:
        if name not in users:
            raise ValueError(f"scene {key}[{i}]: unknown class {name!r}; known: {', '.join(users)}")
    if spec.trains is not None and site.rails is None:
        raise ValueError("scene trains: the site has no [rails] for them to run on")


@dataclass(frozen=True, eq=False)
class SceneTruth:
    """Trajectories of every road user, one row per user and traffic step."""

    table: pd.DataFrame  # object_id, vehicle_class, time_s, east_m, north_m, speed_mps, ...
    users: pd.DataFrame  # object_id, vehicle_class, corridor, direction, arrival_s, ...
    closures: FloatArray
    stall_stops: pd.DataFrame  # object_id, stop_time_s (the stall's standstill between barriers)
    stop_line_runs: pd.DataFrame  # object_id, cross_time_s: front over the stop line in a warning


@dataclass(frozen=True, eq=False)
class SceneRecording:
    """A simulated scene: truth and the detections of every radar (time order)."""

    truth: SceneTruth
    detections: pd.DataFrame  # radar, time_s, range_m, azimuth_rad, radial_speed_mps
    sources: np.ndarray  # per detection: object id, or -1 false alarm, -2 static, -3 ghost
    spec: SceneSpec


def _corridor_of(corridors: list[Corridor], entry: str, exit_: str) -> tuple[Corridor, int]:
    for c in corridors:
        if (c.first, c.second) == (entry, exit_):
            return c, 1
        if (c.second, c.first) == (entry, exit_):
            return c, -1
    raise ValueError(f"no corridor joins roads {entry!r} and {exit_!r}")


def _arrivals(spec: SceneSpec, rng: np.random.Generator) -> pd.DataFrame:
    rows = []
    names = list(spec.mix)
    shares = np.array([spec.mix[n] for n in names])
    for i, f in enumerate(spec.flows):
        if f.vehicles_per_h <= 0:
            continue
        n = rng.poisson(f.vehicles_per_h * spec.duration_s / 3600.0)
        t = np.sort(rng.uniform(0.0, spec.duration_s, n))
        cls = rng.choice(len(names), n, p=shares / shares.sum())
        rows.append(pd.DataFrame({"flow": i, "arrival_s": t, "cls": [names[c] for c in cls]}))
    out = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()
    return out.sort_values("arrival_s", kind="stable").reset_index(drop=True)


def _idm_accel(
    v: FloatArray, v0: FloatArray, a_max: FloatArray, gap: FloatArray, dv: FloatArray
) -> FloatArray:
    """Intelligent Driver Model acceleration; ``gap`` to the obstacle, ``dv`` closing speed."""
    star = IDM_GAP_M + np.maximum(
        v * IDM_HEADWAY_S + v * dv / (2.0 * np.sqrt(a_max * IDM_COMFORT_DECEL)), 0.0
    )
    free = 1.0 - (v / np.maximum(v0, 0.1)) ** 4
    return a_max * (free - (star / np.maximum(gap, 0.1)) ** 2)


def simulate_traffic(site: Site, spec: SceneSpec, rng: np.random.Generator) -> SceneTruth:
    """Move every road user of the scene along its corridor (module docstring)."""
    corridors = site.corridors
    arrivals = _arrivals(spec, rng)
    n = len(arrivals)
    flow_cor = [_corridor_of(corridors, f.entry, f.exit) for f in spec.flows]
    cor_index = {id(c): i for i, c in enumerate(corridors)}
    flow_idx = arrivals["flow"].to_numpy() if n else np.zeros(0, int)
    classes = arrivals["cls"].to_numpy() if n else np.zeros(0, str)
    for stall in spec.stalls:  # the stalled vehicle is of the stall's class
        cand = np.flatnonzero(
            (arrivals["arrival_s"].to_numpy() >= stall.time_s)
            & np.array([spec.flows[f].entry == stall.entry for f in flow_idx], dtype=bool)
        )
        if cand.size:
            classes[cand[0]] = stall.vehicle_class
    known = road_users(site)
    users = [known[c] for c in classes]
    mean_sd = np.array([desired_speed_kmh(u) for u in users]).reshape(-1, 2)
    v0 = np.clip(rng.normal(mean_sd[:, 0], mean_sd[:, 1]), 3.0, None) * KMH
    v0 = np.minimum(v0, np.array([u.max_speed_kmh for u in users]) * KMH)
    length_m = np.array([u.length_m for u in users])
    a_max = np.array([u.accel_mps2 for u in users])
    direction = np.array([flow_cor[f][1] for f in flow_idx], dtype=float)
    corridor = np.array([cor_index[id(flow_cor[f][0])] for f in flow_idx], dtype=int)
    crossing_u = np.array([corridors[c].crossing_u for c in corridor])
    path_len = np.array([corridors[c].path.length_m for c in corridor])
    half_lane = 0.5 * next(iter(site.roads.values())).lane_width_m
    width = np.array([u.width_m for u in users])
    wander = np.clip(
        rng.normal(0.0, site.lateral_offset_std_m, n),
        -(half_lane - width / 2),
        half_lane - width / 2,
    )
    # pedestrians on a footway, cyclists on the lane's edge, motorcycles along the centre line
    # (past a queue's cars: width / 2 + 0.9 m + wander away from a car's centre)
    lateral = half_lane + np.where(
        classes == "pedestrian",
        half_lane + 1.5,
        np.where(
            classes == "cyclist", half_lane, np.where(classes == "motorcycle", 0.2 - half_lane, 0.0)
        ),
    )
    lateral = np.where(
        np.isin(classes, ["pedestrian", "cyclist", "motorcycle"]), lateral, lateral + wander
    )
    lanes = np.array([corridors[c].lanes[0 if d > 0 else 1] for c, d in
                      zip(corridor, direction, strict=True)], dtype=int)  # fmt: skip
    if n and lanes.max() > 1:  # several lanes: each user keeps one, drawn evenly
        lane = rng.integers(0, np.maximum(lanes, 1))
        lane = np.where(np.isin(classes, ["pedestrian", "cyclist"]), lanes - 1, lane)  # kerb
        lateral = lateral + lane * 2 * half_lane
    d_side = -direction * lateral  # corridor offset (right of decreasing u)
    # along-corridor distance travelled by the front from the corridor's start of this direction
    x = length_m.copy()  # the whole body is on the corridor when a user appears
    v = v0.copy()
    x_cross = np.where(direction > 0, crossing_u, path_len - crossing_u)
    total = path_len
    arrival = arrivals["arrival_s"].to_numpy() if n else np.zeros(0)
    stall_of = np.full(n, -1)
    for k, stall in enumerate(spec.stalls):
        cand = np.flatnonzero(
            (arrival >= stall.time_s)
            & np.array([spec.flows[f].entry == stall.entry for f in flow_idx], dtype=bool)
        )
        if cand.size:
            stall_of[cand[0]] = k
    stall_at = np.array(
        [
            x_cross[i] - spec.stalls[stall_of[i]].at_m if stall_of[i] >= 0 else np.inf
            for i in range(n)
        ]
    )
    stall_until = np.full(n, np.inf)
    stall_stop_time = np.full(n, np.nan)
    line_run_time = np.full(n, np.nan)
    entry_road = [spec.flows[f].entry for f in flow_idx]
    stop_line = x_cross - np.array([site.stop_line_of(r) for r in entry_road])
    closures = spec.closures()
    steps = math.ceil(spec.duration_s / STEP_S) + 1
    active = np.zeros(n, dtype=bool)
    done = np.zeros(n, dtype=bool)
    next_arrival = 0
    out_t, out_i, out_x, out_v = [], [], [], []
    group = [
        np.flatnonzero((corridor == c) & (direction == dr))
        for c in range(len(corridors))
        for dr in (1.0, -1.0)
    ]
    for step in range(steps):
        t = step * STEP_S
        while next_arrival < n and arrival[next_arrival] <= t:
            active[next_arrival] = True
            next_arrival += 1
        warn = (
            np.any((t >= closures[:, 0] - WARNING_S) & (t < closures[:, 1]))
            if closures.size
            else False
        )
        idx = np.flatnonzero(active & ~done)
        if idx.size == 0:
            continue
        gap = np.full(idx.size, np.inf)
        dv = np.zeros(idx.size)
        for members in group:
            mem = members[active[members] & ~done[members]]
            if mem.size < 2:
                continue
            # who follows whom: the nearest user ahead whose body its own would touch beside it
            xm, dm, wm = x[mem], d_side[mem], width[mem]
            touch = np.abs(dm[:, None] - dm[None, :]) < 0.5 * (wm[:, None] + wm[None, :])
            rear_gap = np.where(
                touch & (xm[None, :] > xm[:, None]), (xm - length_m[mem])[None, :] - xm[:, None],
                np.inf,
            )  # fmt: skip
            lead = np.argmin(rear_gap, axis=1)
            has = np.isfinite(rear_gap[np.arange(mem.size), lead])
            j = np.searchsorted(idx, mem[has])  # idx: the active users, ascending
            gap[j] = rear_gap[has, lead[has]]
            dv[j] = v[mem[has]] - v[mem[lead[has]]]
        xa, va = x[idx], v[idx]
        # the stop line while the lights flash, for those who can still stop there
        if warn:
            to_line = stop_line[idx] - xa
            can = (to_line > 0) & (va**2 <= 2 * STOP_DECEL_MPS2 * np.maximum(to_line, 1e-6))
            closer = can & (to_line < gap)
            gap = np.where(closer, to_line, gap)
            dv = np.where(closer, va, dv)
        # a stall: its vehicle stops at its point and waits
        stalling = stall_of[idx] >= 0
        if stalling.any():
            to_stall = stall_at[idx] - xa
            waiting = stalling & (t < stall_until[idx])
            use = waiting & (to_stall + IDM_GAP_M < gap)
            gap = np.where(use, to_stall + IDM_GAP_M, gap)
            dv = np.where(use, va, dv)
        acc = _idm_accel(va, v0[idx], a_max[idx], gap, dv)
        acc = np.maximum(acc, -9.0)
        vn = np.maximum(va + acc * STEP_S, 0.0)
        x[idx] = xa + 0.5 * (va + vn) * STEP_S
        v[idx] = vn
        if warn:  # fronts over the stop line while the lights flash or the barriers are down
            over = (xa < stop_line[idx]) & (x[idx] >= stop_line[idx])
            line_run_time[idx[over]] = np.fmin(line_run_time[idx[over]], t + STEP_S)
        if stalling.any():
            for j in np.flatnonzero(stalling).tolist():
                i = int(idx[j])
                if (
                    np.isnan(stall_stop_time[i])
                    and vn[j] < STOPPED_MPS
                    and abs(stall_at[i] - x[i]) < 3.0
                ):
                    stall_stop_time[i] = t + STEP_S
                    stall_until[i] = t + STEP_S + spec.stalls[stall_of[i]].duration_s
        out_t.append(np.full(idx.size, t + STEP_S))
        out_i.append(idx)
        out_x.append(x[idx].copy())
        out_v.append(v[idx].copy())
        done |= active & (x >= total)
    t_all = np.concatenate(out_t) if out_t else np.zeros(0)
    i_all = np.concatenate(out_i) if out_i else np.zeros(0, int)
    x_all = np.concatenate(out_x) if out_x else np.zeros(0)
    v_all = np.concatenate(out_v) if out_v else np.zeros(0)
    keep = x_all < total[i_all]
    t_all, i_all, x_all, v_all = t_all[keep], i_all[keep], x_all[keep], v_all[keep]
    # body centre in corridor coordinates
    centre = x_all - 0.5 * length_m[i_all]
    u = np.where(direction[i_all] > 0, centre, path_len[i_all] - centre)
    east = np.empty(u.size)
    north = np.empty(u.size)
    speed = np.empty(u.size)
    heading = np.empty(u.size)
    for c, cor in enumerate(corridors):
        sel = corridor[i_all] == c
        if not sel.any():
            continue
        p, tangent, _, kappa = cor.path.lane_geometry(u[sel], d_side[i_all[sel]])
        east[sel], north[sel] = p[:, 0], p[:, 1]
        speed[sel] = v_all[sel] * (1.0 + kappa * d_side[i_all[sel]])
        th = np.arctan2(tangent[:, 0], tangent[:, 1])
        heading[sel] = np.where(direction[i_all[sel]] > 0, th, th + np.pi)
    to_cross = x_cross[i_all] - centre
    table = pd.DataFrame(
        {
            "object_id": i_all,
            "vehicle_class": classes[i_all],
            "time_s": t_all,
            "east_m": east,
            "north_m": north,
            "speed_mps": speed,
            "heading_rad": heading,
            "to_crossing_m": to_cross,
            "in_zone": np.abs(to_cross) <= site.zone_m,
        }
    ).sort_values(["time_s", "object_id"], kind="stable", ignore_index=True)
    users_t = pd.DataFrame(
        {
            "object_id": np.arange(n),
            "vehicle_class": classes,
            "corridor": corridor,
            "direction": direction.astype(int),
            "arrival_s": arrival,
            "lateral_m": d_side,
            "length_m": length_m,
            "width_m": width,
        }
    )
    stalled = np.flatnonzero(~np.isnan(stall_stop_time))
    stops = pd.DataFrame({"object_id": stalled, "stop_time_s": stall_stop_time[stalled]})
    ran = np.flatnonzero(~np.isnan(line_run_time))
    runs = pd.DataFrame({"object_id": ran, "cross_time_s": line_run_time[ran]})
    if spec.parked or spec.scripted or spec.trains is not None:
        table, users_t = _added_users(site, spec, table, users_t)
    return SceneTruth(table, users_t, closures, stops, runs)


def _added_users(
    site: Site, spec: SceneSpec, table: pd.DataFrame, users: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Add the parked and scripted road users and the closures' trains to the truth (ids after).

    With scripted users every row carries its velocity (``east_speed_mps``,
    ``north_speed_mps``: a reversing body moves against its heading).
    """
    known = road_users(site)
    steps = np.arange(math.ceil(spec.duration_s / STEP_S) + 1) * STEP_S
    rows, extra = [], []
    next_id = len(users)
    for p in spec.parked:
        cls = known[p.vehicle_class]
        t = steps[(steps >= p.from_s) & (steps <= (p.until_s or spec.duration_s))]
        dist = math.hypot(*p.position_m)
        rows.append(pd.DataFrame({
            "object_id": next_id, "vehicle_class": p.vehicle_class, "time_s": t,
            "east_m": p.position_m[0], "north_m": p.position_m[1], "speed_mps": 0.0,
            "heading_rad": math.radians(p.heading_deg) % (2 * math.pi), "to_crossing_m": dist,
            "in_zone": dist <= site.zone_m,
        }))  # fmt: skip
        extra.append((next_id, p.vehicle_class, p.length_m or cls.length_m,
                      p.width_m or cls.width_m, np.nan, p.from_s))  # fmt: skip
        next_id += 1
    for sc in spec.scripted:
        cls = known[sc.vehicle_class]
        rows.append(_scripted_rows(sc, next_id, steps, site.zone_m))
        extra.append((next_id, sc.vehicle_class, sc.length_m or cls.length_m,
                      sc.width_m or cls.width_m, np.nan, sc.start_s))  # fmt: skip
        next_id += 1
    tr = spec.trains
    if tr is not None and site.rails is not None:
        rails, v = site.rails, tr.speed_kmh * KMH
        span = 2 * tr.run_m + tr.length_m  # the front's run [m]
        for k, (c0, c1) in enumerate(spec.closures()):
            sign = 1.0 if k % 2 == 0 else -1.0
            start = 0.5 * (c0 + c1) - 0.5 * span / v
            t = steps[(steps >= start) & (steps <= start + span / v)]
            centre_along = sign * (-tr.run_m - 0.5 * tr.length_m + v * (t - start))
            pos = rails.track_point(k % rails.tracks, centre_along)
            heading = rails.axis_rad + (0.0 if sign > 0 else math.pi)
            rows.append(pd.DataFrame({
                "object_id": next_id, "vehicle_class": "train", "time_s": t,
                "east_m": pos[:, 0], "north_m": pos[:, 1], "speed_mps": v,
                "heading_rad": heading % (2 * math.pi), "to_crossing_m": -sign * centre_along,
                "in_zone": False,
            }))  # fmt: skip
            extra.append((next_id, "train", tr.length_m, tr.width_m, tr.height_m, start))
            next_id += 1
    if not rows:
        return table, users
    table = pd.concat([table, *rows], ignore_index=True)
    if "east_speed_mps" in table.columns:
        hd, speed = table["heading_rad"].to_numpy(), table["speed_mps"].to_numpy()
        for col, part in (("east_speed_mps", np.sin(hd)), ("north_speed_mps", np.cos(hd))):
            table[col] = table[col].fillna(pd.Series(speed * part, index=table.index))
    table = table.sort_values(["time_s", "object_id"], kind="stable", ignore_index=True)
    added = pd.DataFrame(extra, columns=["object_id", "vehicle_class", "length_m", "width_m",
                                         "height_m", "arrival_s"])  # fmt: skip
    added = added.assign(corridor=-1, direction=0, lateral_m=0.0)
    return table, pd.concat([users.assign(height_m=np.nan), added], ignore_index=True)


def _scripted_rows(sc: Scripted, object_id: int, steps: FloatArray, zone_m: float) -> pd.DataFrame:
    """Truth rows of a scripted road user on the traffic model's steps (see ``Scripted``).

    The path is the polyline of ``path_m`` with its corners rounded (a smoothing spline
    through points every metre of it); the user travels it at the profile's speed, facing
    backwards while the speed is negative.
    """
    pts = np.asarray(sc.path_m, dtype=float)
    dense = [pts[:1]]
    for p, q in itertools.pairwise(pts):
        n = max(2, math.ceil(math.hypot(*(q - p)) / SCRIPT_STEP_M) + 1)
        dense.append(p + np.linspace(0.0, 1.0, n)[1:, None] * (q - p))
    path = polyline_road("scripted", np.concatenate(dense), 1.0, survey_std_m=SCRIPT_ROUNDING_M)
    knots_t = np.array([k[0] for k in sc.speed_profile])
    knots_v = np.array([k[1] for k in sc.speed_profile])
    t = steps[(steps >= sc.start_s) & (steps <= sc.start_s + knots_t[-1])]
    v = np.interp(t - sc.start_s, knots_t, knots_v)
    # distance travelled: the exact integral of |speed| (piecewise linear, split at zeros)
    grid = np.union1d(knots_t, t - sc.start_s)
    cross = [a[0] + (b[0] - a[0]) * a[1] / (a[1] - b[1])
             for a, b in itertools.pairwise(sc.speed_profile)
             if a[1] * b[1] < 0]  # fmt: skip
    grid = np.union1d(grid, cross)
    vg = np.abs(np.interp(grid, knots_t, knots_v))
    along = np.concatenate([[0.0], np.cumsum(0.5 * (vg[1:] + vg[:-1]) * np.diff(grid))])
    s = np.interp(t - sc.start_s, grid, along)
    keep = s <= path.length_m  # it leaves at the end of the path
    t, v, s = t[keep], v[keep], s[keep]
    xy, heading = path.centreline(s)
    vel = np.abs(v)[:, None] * np.stack([np.sin(heading), np.cos(heading)], -1)
    heading = np.where(v < 0.0, heading + math.pi, heading)
    dist = np.hypot(xy[:, 0], xy[:, 1])
    closing = -(xy * vel).sum(axis=1)  # a standing user keeps the sign it had (or gets)
    sign = pd.Series(np.where(np.abs(closing) > 1e-9, np.sign(closing), np.nan)).ffill().bfill()
    return pd.DataFrame({
        "object_id": object_id, "vehicle_class": sc.vehicle_class, "time_s": t,
        "east_m": xy[:, 0], "north_m": xy[:, 1], "speed_mps": np.abs(v),
        "heading_rad": np.mod(heading, 2 * math.pi),
        "to_crossing_m": sign.fillna(1.0).to_numpy() * dist, "in_zone": dist <= zone_m,
        "east_speed_mps": vel[:, 0], "north_speed_mps": vel[:, 1],
    })  # fmt: skip


@numba.njit(cache=True)
def _occluded(scan_start, rng_m, az, half_angle, large, draw, p_loss):  # type: ignore[no-untyped-def]
    """Per object-scan row (sorted by scan): whether a nearer large body shadows it."""
    n_scans = scan_start.size - 1
    out = np.zeros(rng_m.size, dtype=np.bool_)
    for k in range(n_scans):
        a, b = scan_start[k], scan_start[k + 1]
        for i in range(a, b):
            for j in range(a, b):
                if j == i or not large[j] or rng_m[j] >= rng_m[i]:
                    continue
                d = az[i] - az[j]
                d = wrapped(d, math.pi)
                if abs(d) < half_angle[j] and draw[i] < p_loss:
                    out[i] = True
                    break
    return out


def _radar_scans(radar: RadarSpec, duration_s: float, phase_s: float) -> FloatArray:
    return np.arange(phase_s, duration_s, radar.period_s)


@dataclass(frozen=True, eq=False)
class ScanStates:
    """Every road user at every scan of one radar, one row per user and scan.

    ``scan_of`` indexes ``scans``; ``centre`` (N, 2) [m], ``forward`` (N, 2) unit heading,
    ``velocity`` (N, 2) [m/s]; ``length``, ``width``, ``height`` (N,) [m] (NaN height: the
    class's); ``object_id`` and ``vehicle_class`` per row.
    """

    scans: FloatArray
    scan_of: np.ndarray
    object_id: np.ndarray
    vehicle_class: np.ndarray
    centre: FloatArray
    forward: FloatArray
    velocity: FloatArray
    length: FloatArray
    width: FloatArray
    height: FloatArray
    offset_s: FloatArray  # scan time minus the truth sample's


@dataclass(frozen=True, eq=False)
class BodyReturns:
    """Reflections of road users in one radar's scans, before measurement noise.

    Slant range [m], azimuth [rad], radial speed [m/s] and scan index per return, the road
    user's id as its source; ``elevation_rad`` (or None) for a radar that measures it;
    ``doppler_step_mps`` (or None) quantises the measured radial speeds.
    """

    scan_of: np.ndarray
    range_m: FloatArray
    azimuth_rad: FloatArray
    radial_speed_mps: FloatArray
    source: np.ndarray
    elevation_rad: FloatArray | None = None
    doppler_step_mps: float | None = None


def scan_states(truth: SceneTruth, scans: FloatArray) -> ScanStates:
    """Road users at the scan times: the nearest traffic step's state moved on to the scan."""
    tab = truth.table
    users = truth.users.set_index("object_id")
    k = np.rint(tab["time_s"].to_numpy() / STEP_S).astype(np.int64)
    scan_k = np.rint(scans / STEP_S).astype(np.int64)
    at = np.isin(k, scan_k)
    rows = tab[at]
    scan_of = np.searchsorted(scan_k, k[at])
    obj = rows["object_id"].to_numpy()
    hd = rows["heading_rad"].to_numpy()
    fwd = np.stack([np.sin(hd), np.cos(hd)], -1)
    vel = rows["speed_mps"].to_numpy()[:, None] * fwd
    if "east_speed_mps" in rows.columns:  # recorded or scripted motion: its velocity
        given = rows[["east_speed_mps", "north_speed_mps"]].to_numpy(dtype=float)
        vel = np.where(np.isnan(given), vel, given)
    ahead_s = scans[scan_of] - k[at] * STEP_S
    height = (
        users.loc[obj, "height_m"].to_numpy(dtype=float)
        if "height_m" in users.columns
        else np.full(obj.size, np.nan)
    )
    return ScanStates(
        scans, scan_of, obj, rows["vehicle_class"].to_numpy(),
        rows[["east_m", "north_m"]].to_numpy() + ahead_s[:, None] * vel, fwd, vel,
        users.loc[obj, "length_m"].to_numpy(), users.loc[obj, "width_m"].to_numpy(), height,
        ahead_s,
    )  # fmt: skip


def symmetric_returns(
    radar: RadarSpec, spec: SceneSpec, st: ScanStates, rng: np.random.Generator
) -> BodyReturns:
    """Draw the scene's own reflections: points spread symmetrically about the body centre.

    Per user and scan, a length-dependent count of points along ``N(0, (L/4)^2)`` (clipped to
    the body) and uniform across it; a nearer truck or bus shadows with ``OCCLUDED_P``.
    """
    obj, cls, length, width = st.object_id, st.vehicle_class, st.length, st.width
    fwd, vel, centre, scan_of, scans = st.forward, st.velocity, st.centre, st.scan_of, st.scans
    rel = centre - np.asarray(radar.position_m)
    rng_c, az_c, _ = radial_geometry(centre, vel, radar.position_m, radar.height_m)
    near = radar.in_view(rng_c, az_c) | (rng_c < radar.max_range_m + 20.0)
    occluded = np.zeros(obj.size, dtype=bool)
    if spec.occlusion and obj.size:
        order = np.argsort(scan_of, kind="stable")
        starts = np.searchsorted(scan_of[order], np.arange(scans.size + 1))
        # apparent half-width of the body across the line of sight
        los = rel / np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1e-9)[:, None]
        across = (
            np.abs(los[:, 0] * fwd[:, 1] - los[:, 1] * fwd[:, 0]) * length
            + np.abs(los[:, 0] * fwd[:, 0] + los[:, 1] * fwd[:, 1]) * width
        )
        half = np.arctan2(0.5 * across, rng_c)
        large = width >= LARGE_WIDTH_M
        occ = _occluded(
            starts.astype(np.int64), rng_c[order], az_c[order], half[order], large[order],
            rng.uniform(size=obj.size), OCCLUDED_P,
        )  # fmt: skip
        occluded[order] = occ
    lo_hi = detections_per_scan(length)
    count = rng.integers(lo_hi[:, 0], lo_hi[:, 1] + 1)
    count = np.where(near & ~occluded, count, 0)
    rep = np.repeat(np.arange(obj.size), count)
    along = np.clip(rng.normal(0.0, 0.25 * length[rep]), -0.5 * length[rep], 0.5 * length[rep])
    side = rng.uniform(-0.5, 0.5, rep.size) * width[rep]
    right = np.stack([fwd[rep, 1], -fwd[rep, 0]], -1)
    point = centre[rep] + along[:, None] * fwd[rep] + side[:, None] * right
    prng, paz, pvr = radial_geometry(point, vel[rep], radar.position_m, radar.height_m)
    pd_ = np.empty(rep.size)
    for c in np.unique(cls[rep]) if rep.size else []:
        m = cls[rep] == c
        pd_[m] = radar.detection_curve(str(c))(prng[m])
    seen = radar.in_view(prng, paz) & (rng.uniform(size=rep.size) < pd_)
    if not spec.stationary_detections:
        seen &= np.abs(pvr) >= radar.min_radial_speed_mps
    rep = rep[seen]
    return BodyReturns(scan_of[rep], prng[seen], paz[seen], pvr[seen], obj[rep])


Returns = Callable[[RadarSpec, SceneSpec, ScanStates, np.random.Generator], BodyReturns]


def detect(
    site: Site,
    spec: SceneSpec,
    truth: SceneTruth,
    rng: np.random.Generator,
    returns: Returns = symmetric_returns,
) -> tuple[pd.DataFrame, np.ndarray]:
    """Return the detections of every radar over the scene, and their sources.

    ``returns`` models the road users' reflections (default: :func:`symmetric_returns`; the
    face model is :func:`adaptrack.crossing.simulation.faces.face_returns`); multipath ghosts,
    false alarms, static clutter and the measurement noise are the scene's.
    """
    frames, sources = [], []
    duration = spec.duration_s
    for r_i, radar in enumerate(site.radars):
        scans = _radar_scans(radar, duration, rng.uniform(0.0, radar.period_s))
        body = returns(radar, spec, scan_states(truth, scans), rng)
        prng, paz, pvr, src = body.range_m, body.azimuth_rad, body.radial_speed_mps, body.source
        t_det = scans[body.scan_of]
        # multipath ghosts: the same direction and Doppler, further out
        ghost = rng.uniform(size=src.size) < spec.multipath_probability
        g_rng = prng[ghost] + spec.multipath_extra_m * rng.uniform(0.5, 1.5, ghost.sum())
        # false alarms over the fields of view
        n_fa = rng.poisson(spec.false_alarms_per_scan, scans.size)
        fa_scan = np.repeat(np.arange(scans.size), n_fa)
        fa_rng = radar.max_range_m * np.sqrt(rng.uniform(0.01, 1.0, fa_scan.size))
        half_fov = max(f.half_angle_rad for f in radar.fields)
        fa_az = radar.boresight_rad + rng.uniform(-half_fov, half_fov, fa_scan.size)
        fa_ok = radar.in_view(fa_rng, fa_az)
        fa_scan, fa_rng, fa_az = fa_scan[fa_ok], fa_rng[fa_ok], fa_az[fa_ok]
        fa_vr = rng.uniform(-FALSE_ALARM_SPEED_MPS, FALSE_ALARM_SPEED_MPS, fa_scan.size)
        # static clutter
        st_pts = np.asarray(spec.static_clutter_m, dtype=float).reshape(-1, 2)
        st_rng, st_az, _ = radial_geometry(
            st_pts, np.zeros_like(st_pts), radar.position_m, radar.height_m
        )
        vis = radar.in_view(st_rng, st_az) if st_pts.size else np.zeros(0, bool)
        st_rng, st_az = st_rng[vis], st_az[vis]
        if not spec.stationary_detections:
            st_rng, st_az = st_rng[:0], st_az[:0]
        st_hit = rng.uniform(size=(scans.size, st_rng.size)) < STATIC_P_D
        st_scan, st_which = np.nonzero(st_hit)
        all_rng = np.concatenate([prng, g_rng, fa_rng, st_rng[st_which]])
        all_az = np.concatenate([paz, paz[ghost], fa_az, st_az[st_which]])
        all_vr = np.concatenate([pvr, pvr[ghost], fa_vr, np.zeros(st_which.size)])
        all_t = np.concatenate([t_det, t_det[ghost], scans[fa_scan], scans[st_scan]])
        all_src = np.concatenate(
            [src, np.full(ghost.sum(), -3), np.full(fa_scan.size, -1), np.full(st_which.size, -2)]
        )
        sd_r, sd_a, sd_v = radar.noise_std(all_rng, all_az)
        z_r = all_rng + sd_r * rng.standard_normal(all_rng.size)
        z_a = all_az + radar.azimuth_bias_rad + sd_a * rng.standard_normal(all_rng.size)
        z_v: FloatArray = all_vr + sd_v * rng.standard_normal(all_rng.size)
        if body.doppler_step_mps:
            z_v = body.doppler_step_mps * np.round(z_v / body.doppler_step_mps)
        if radar.max_unambiguous_speed_mps:
            h = radar.max_unambiguous_speed_mps
            z_v = wrap(z_v, h)
        jitter = rng.uniform(-radar.time_jitter_s, radar.time_jitter_s, scans.size)
        scan_idx = np.searchsorted(scans, all_t)
        frame = pd.DataFrame(
            {
                "radar": radar.name,
                "time_s": all_t + jitter[np.minimum(scan_idx, scans.size - 1)] + radar.latency_s,
                "range_m": np.maximum(z_r, radar.min_range_m),
                "azimuth_rad": wrap(z_a),
                "radial_speed_mps": z_v,
                "_scan": r_i * 10_000_000 + scan_idx,
            }
        )
        if body.elevation_rad is not None:  # clutter and false alarms: on the ground
            ground = -np.arcsin(np.minimum(radar.height_m / np.maximum(all_rng, 1e-9), 1.0))
            frame["elevation_rad"] = np.concatenate(
                [body.elevation_rad, body.elevation_rad[ghost], ground[src.size + ghost.sum() :]]
            )
        frames.append(frame)
        sources.append(all_src)
    det = pd.concat(frames, ignore_index=True)
    src = np.concatenate(sources)
    order = np.lexsort(
        (det["range_m"].to_numpy(), det["_scan"].to_numpy(), det["time_s"].to_numpy())
    )
    det = det.iloc[order].drop(columns="_scan").reset_index(drop=True)
    return det, src[order]


def simulate_scene(
    site: Site, spec: SceneSpec, seed: int, returns: Returns = symmetric_returns
) -> SceneRecording:
    """Traffic and detections of one scene (``seed`` makes it reproducible).

    ``returns``: the reflection model (:func:`detect`).
    """
    rng = np.random.default_rng(seed)
    truth = simulate_traffic(site, spec, rng)
    det, src = detect(site, spec, truth, rng, returns)
    return SceneRecording(truth, det, src, spec)


__all__ = [
    "WALKERS_AND_RIDERS",
    "BodyReturns",
    "Flow",
    "ScanStates",
    "SceneRecording",
    "SceneSpec",
    "SceneTruth",
    "Stall",
    "desired_speed_kmh",
    "detect",
    "detections_per_scan",
    "road_users",
    "scan_states",
    "scene_spec",
    "simulate_scene",
    "simulate_traffic",
    "symmetric_returns",
]
