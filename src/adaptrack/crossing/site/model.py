"""Level-crossing site: approach roads, radars, road users and the cases to check (TOML).

Frame: local ENU with the origin at the crossing centre. Radar azimuths are clockwise from
north; angles in the file are degrees (``_deg`` keys), converted here once. The file format is
:mod:`adaptrack.crossing.site.schema` (strict: unknown keys are errors); this module builds
the frozen site objects every consumer reads (simulator, trackers, bound, report) and checks
the cross-references: a road's radar, a case's road and classes, the classes of the traffic mix
and of the detection probabilities must exist; roads must be long enough for the controlled
zone and the run-in; every radar must see a road and every road must be seen.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..._toml import builtin_names, load_named_toml
from .corridor import Corridor, site_corridors
from .network import MEET_TOLERANCE_M, route
from .rails import Rails
from .road import Road, RoadElement, build_road, polyline_road
from .schema import RadarFile, SiteFile, validate_site_mapping
from .sensor import Curve, FieldOfView, RadarSpec
from .traffic import (
    VEHICLES,
    WALKERS_AND_RIDERS,
    Case,
    VehicleClass,
    default_cases,
    inapplicable_reason,
)

COVERAGE_STEP_M = 0.5  # sampling of a road's zone when choosing its radar and finding blind parts


@dataclass(frozen=True, eq=False)
class Site:
    """A crossing site (see the module docstring).

    ``radar_of_road`` names the radar that tracks each road; ``classes`` are the road-user
    classes present (the traffic mix's, or every known class) with their ``traffic_mix``
    shares; ``cases`` the approach scripts; ``source`` the validated file content (plain
    data: a summary carries it, so that a report can rebuild the site).
    """

    name: str
    description: str
    roads: dict[str, Road]
    radars: tuple[RadarSpec, ...]
    radar_of_road: dict[str, str]
    classes: dict[str, VehicleClass]
    traffic_mix: dict[str, float]
    cases: tuple[Case, ...]
    barrier_m: float
    stop_line_m: float
    zone_m: float
    run_in_m: float
    lateral_offset_std_m: float
    source: dict[str, Any]
    stop_lines: dict[str, float] = field(default_factory=dict)
    barriers: dict[str, float] = field(default_factory=dict)
    rails: Rails | None = None
    connections: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)

    @cached_property
    def corridors(self) -> list[Corridor]:
        """The paths road users drive: roads in line, then every flow's and connection's route.

        See :func:`~adaptrack.crossing.site.corridor.site_corridors`.
        """
        return site_corridors(
            self.roads, self.zone_m + self.run_in_m, self.routes, self.connections
        )

    @property
    def routes(self) -> tuple[tuple[str, str], ...]:
        """(entry, exit) of every scene flow and connection, in file order."""
        flows = self.source.get("scene", {}).get("flows", [])
        pairs = [(f["entry"], f["exit"]) for f in flows] + list(self.connections)
        pairs += [(c["entry"], c["exit"]) for c in self.source.get("connections", [])]
        return tuple(dict.fromkeys(pairs))

    def stop_line_of(self, road: str) -> float:
        """Return where traffic towards the crossing on ``road`` stops [m from its crossing end]."""
        return self.stop_lines.get(road, self.stop_line_m)

    def barrier_of(self, road: str) -> float:
        """Return the barrier on ``road`` [m from its crossing end]."""
        return self.barriers.get(road, self.barrier_m)

    @property
    def fingerprint(self) -> str:
        """Digest of the site's definition: changes with any value of its file (16 hex)."""
        text = json.dumps(self.source, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def radar_for(self, road: str) -> RadarSpec:
        """Return the radar that tracks a road."""
        wanted = self.radar_of_road[road]
        return next(r for r in self.radars if r.name == wanted)

    def radar(self, name: str) -> RadarSpec:
        """Return a radar by name."""
        for r in self.radars:
            if r.name == name:
                return r
        raise ValueError(f"unknown radar {name!r}; the site has {[r.name for r in self.radars]}")

    def road_of_radar(self, radar: str) -> str:
        """Return the road a radar tracks (the first, if it tracks several)."""
        for road, name in self.radar_of_road.items():
            if name == radar:
                return road
        raise ValueError(f"radar {radar!r} tracks no road of site {self.name!r}")

    def pairs(self) -> list[tuple[Case, VehicleClass]]:
        """Every (case, class) that the class can drive, in a fixed order."""
        return [
            (c, v)
            for v in self.classes.values()
            for c in self.cases
            if inapplicable_reason(c, v) is None
        ]

    def skipped_pairs(self) -> list[tuple[str, str, str]]:
        """(case, class, reason) of the combinations a class cannot drive."""
        out = []
        for v in self.classes.values():
            for c in self.cases:
                reason = inapplicable_reason(c, v)
                if reason is not None:
                    out.append((c.name, v.name, reason))
        return out


def builtin_sites() -> list[str]:
    """Names of the sites shipped with adaptrack."""
    return builtin_names("adaptrack.crossing.site", "sites")


def load_site(name_or_path: str | Path) -> Site:
    """Load a built-in site by name, or a site TOML file."""
    return site_from_mapping(
        *load_named_toml(name_or_path, "adaptrack.crossing.site", "sites", "site")
    )


def site_from_mapping(data: dict[str, Any], where: str) -> Site:
    """Validate a site mapping (a parsed file, or a summary's copy) and build the site."""
    spec = validate_site_mapping(data, where)
    roads = _roads(spec, where)
    radars = tuple(_radar(r) for r in spec.radars)
    _unique([r.name for r in spec.radars], "radars", where)
    classes = _classes(spec, where)
    mix = dict(spec.traffic.mix) if spec.traffic is not None else None
    if mix is not None:
        for name in mix:
            if name not in classes:
                raise ValueError(
                    f"{where}: traffic.mix: unknown class {name!r}; classes are "
                    f"{', '.join(classes)}"
                )
        classes = {k: classes[k] for k in mix}
    else:
        mix = {k: 1.0 / len(classes) for k in classes}
    seen_classes = {**classes, **WALKERS_AND_RIDERS}
    for i, r in enumerate(spec.radars):
        for cls in r.detection_probability:
            if cls != "default" and cls not in seen_classes:
                raise ValueError(
                    f"{where}: radars[{i}].detection_probability: unknown class {cls!r}; "
                    f"classes are {', '.join(seen_classes)} (or 'default')"
                )
    cases = _cases(spec, roads, classes, where)
    stop_line = spec.stop_line_m
    for name, road in roads.items():
        needed = spec.zone_m + spec.run_in_m
        if road.length_m < needed - 1e-9:
            raise ValueError(
                f"{where}: road {name!r} is {road.length_m:.1f} m long; the controlled zone "
                f"and run-in need {needed:.1f} m"
            )
    radar_of_road = _assign_radars(spec, roads, radars, where)
    track = spec.zone_m + spec.run_in_m
    for radar in radars:
        if not any(_coverage(radar, road, track).any() for road in roads.values()):
            view = ", ".join(
                f"+-{math.degrees(f.half_angle_rad):.0f} deg to {f.max_range_m:.0f} m"
                for f in radar.fields
            )
            raise ValueError(f"{where}: radar {radar.name!r} has no road in view (fields: {view})")
    rails = None
    if spec.rails is not None:
        rf = spec.rails
        rails = Rails(math.radians(rf.axis_deg), (rf.centre_m[0], rf.centre_m[1]), rf.tracks,
                      rf.track_spacing_m, rf.gauge_m)  # fmt: skip
    connections = {}
    for i, c in enumerate(spec.connections):
        for key in ("entry", "exit"):
            if getattr(c, key) not in roads:
                raise ValueError(
                    f"{where}: connections[{i}].{key}: unknown road {getattr(c, key)!r}; roads "
                    f"are {', '.join(roads)}"
                )
        if c.points_m is not None:
            connections[(c.entry, c.exit)] = np.asarray(c.points_m, dtype=float)
    site = Site(
        spec.name or Path(where).stem,
        spec.description,
        roads,
        radars,
        radar_of_road,
        classes,
        mix,
        cases,
        spec.barrier_m,
        stop_line,
        spec.zone_m,
        spec.run_in_m,
        spec.lateral_offset_std_m,
        _source(spec),
        {r.name: r.stop_line_m for r in spec.roads if r.stop_line_m is not None},
        {r.name: r.barrier_m for r in spec.roads if r.barrier_m is not None},
        rails,
        connections,
    )
    _check_routes(site, spec, where)
    return site


ADDED_DEFAULTS: dict[
    str, dict[str, Any]
] = {  # keys added after sites were first tuned: left out at their defaults,
    "roads": {"extend_m": 0.0, "survey_std_m": 0.05, "lanes_in": 1, "lanes_out": 1},
    "scene": {"parked": [], "scripted": []},
    "": {"connections": []},
}  # so that the fingerprint of a site that does not use them stays what it was


def _source(spec: SiteFile) -> dict[str, Any]:
    """Return the validated file as plain data, without the added keys at their defaults."""
    data = spec.model_dump(mode="json", exclude_none=True)
    tables = [data, *data.get("roads", [])] + ([data["scene"]] if "scene" in data else [])
    for table in tables:
        key = "" if table is data else ("scene" if table is data.get("scene") else "roads")
        for name, default in ADDED_DEFAULTS[key].items():
            if table.get(name, None) == default:
                del table[name]
    return data


def _check_routes(site: Site, spec: SiteFile, where: str) -> None:
    """Every flow and connection has a path; its roads exist (named in the error)."""
    flows = spec.scene.flows if spec.scene is not None and spec.scene.flows else []
    for i, f in enumerate(flows):
        for key in ("entry", "exit"):
            if getattr(f, key) not in site.roads:
                raise ValueError(
                    f"{where}: scene.flows[{i}].{key}: unknown road {getattr(f, key)!r}; roads "
                    f"are {', '.join(site.roads)}"
                )
        if f.entry == f.exit:
            raise ValueError(f"{where}: scene.flows[{i}]: entry and exit are one road")
    paths = [(f"scene.flows[{i}]", f.entry, f.exit) for i, f in enumerate(flows)]
    paths += [(f"connections[{i}]", c.entry, c.exit) for i, c in enumerate(spec.connections)]
    for place, entry, exit_ in paths:
        if route(site.roads, entry, exit_) is None:
            raise ValueError(
                f"{where}: {place} {entry}->{exit_}: no path joins the roads (roads meet where "
                f"one starts at another's start or on its centreline, within "
                f"{MEET_TOLERANCE_M:g} m)"
            )
    try:
        _ = site.corridors
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _unique(names: list[str], what: str, where: str) -> None:
    seen = set()
    for n in names:
        if n in seen:
            raise ValueError(f"{where}: {what}: the name {n!r} is used twice")
        seen.add(n)


def _roads(spec: SiteFile, where: str) -> dict[str, Road]:
    _unique([r.name for r in spec.roads], "roads", where)
    roads = {}
    for i, rd in enumerate(spec.roads):
        lanes = (rd.lanes_in, rd.lanes_out)
        if rd.points_m is not None:
            try:
                roads[rd.name] = polyline_road(rd.name, rd.points_m, spec.lane_width_m,
                                               rd.extend_m, lanes, rd.survey_std_m)  # fmt: skip
            except ValueError as exc:
                raise ValueError(f"{where}: roads[{i}]: {exc}") from None
            continue
        assert rd.elements is not None and rd.heading_deg is not None  # the schema's rule
        elems = tuple(
            RoadElement(
                e.kind,
                e.radius_m * math.radians(e.angle_deg)
                if e.angle_deg is not None and e.radius_m is not None
                else float(e.length_m or 0.0),
                end_curvature_per_m=e.end_curvature_per_m or 0.0,
                radius_m=e.radius_m or 0.0,
                turn=e.turn or "right",
            )
            for e in rd.elements
        )
        start = (0.0, 0.0) if rd.start_m is None else (rd.start_m[0], rd.start_m[1])
        roads[rd.name] = build_road(rd.name, math.radians(rd.heading_deg), spec.lane_width_m,
                                    elems, start, lanes)  # fmt: skip
    return roads


def _radar(r: RadarFile) -> RadarSpec:
    given = (  # the schema allows fields, or the one-field shortcut keys
        [(f.max_range_m, f.fov_half_deg) for f in r.fields]
        if r.fields is not None
        else [(r.max_range_m, r.fov_half_deg)]
    )
    fields = tuple(FieldOfView(float(m or 0.0), math.radians(float(h or 0.0))) for m, h in given)
    deg = math.pi / 180
    return RadarSpec(
        name=r.name,
        position_m=(float(r.position_m[0]), float(r.position_m[1])),
        height_m=r.height_m,
        boresight_rad=math.radians(r.boresight_deg),
        fields=fields,
        min_range_m=r.min_range_m,
        period_s=r.period_s,
        range_std_m=Curve(r.range_std_m),
        azimuth_std_rad=Curve(r.azimuth_std_deg).scaled(argument=deg, value=deg),
        radial_speed_std_mps=Curve(r.radial_speed_std_mps),
        min_radial_speed_mps=r.min_radial_speed_mps,
        detection_probability={k: Curve(v) for k, v in r.detection_probability.items()},
        azimuth_bias_rad=math.radians(r.azimuth_bias_deg),
        time_jitter_s=r.time_jitter_s,
        max_unambiguous_speed_mps=r.max_unambiguous_speed_mps,
        latency_s=r.latency_s,
    )


def _classes(spec: SiteFile, where: str) -> dict[str, VehicleClass]:
    classes = dict(VEHICLES)
    for name, c in spec.classes.items():
        given = {k: v for k, v in c.model_dump().items() if v is not None}
        if name in classes:
            classes[name] = dataclasses.replace(
                classes[name],
                **given,
                **(
                    {}
                    if "scatter_std_m" in given or "length_m" not in given
                    else {"scatter_std_m": 0.15 * given["length_m"]}
                ),
            )
            continue
        needed = [
            f.name
            for f in dataclasses.fields(VehicleClass)
            if f.name not in ("name", "scatter_std_m")
        ]
        missing = [k for k in needed if k not in given]
        if missing:
            raise ValueError(f"{where}: classes.{name}: a new class needs {', '.join(missing)}")
        classes[name] = VehicleClass(name=name, **given)
    return classes


def _cases(
    spec: SiteFile, roads: dict[str, Road], classes: dict[str, VehicleClass], where: str
) -> tuple[Case, ...]:
    if spec.cases is None:
        return default_cases(list(roads))
    _unique([c.name for c in spec.cases], "cases", where)
    out = []
    for i, c in enumerate(spec.cases):
        w = f"{where}: cases[{i}]"
        if c.road not in roads:
            raise ValueError(f"{w}.road: unknown road {c.road!r}; roads are {', '.join(roads)}")
        for cls in c.classes or ():
            if cls not in classes:
                raise ValueError(
                    f"{w}.classes: unknown class {cls!r}; classes are {', '.join(classes)}"
                )
        profile = c.speed_profile or ()
        case = Case(
            c.name,
            c.kind,
            c.speed_kmh if c.speed_kmh is not None else profile[0][1],
            c.road,
            dwell_s=c.dwell_s or 0.0,
            decel_mps2=c.decel_mps2,
            jerk_mps3=c.jerk_mps3,
            stop_at_m=c.stop_at_m,
            profile=profile,
            classes=tuple(c.classes) if c.classes is not None else None,
            **{
                k: v
                for k, v in (
                    ("time_constant_s", c.time_constant_s),
                    ("accel_std_mps2", c.accel_std_mps2),
                )
                if v is not None
            },
        )
        stop_at = spec.stop_line_m if c.stop_at_m is None else c.stop_at_m
        if c.kind in ("stop", "emergency") and stop_at >= spec.zone_m + spec.run_in_m:
            raise ValueError(f"{w}.stop_at_m: {stop_at:g} m is beyond the track start")
        if not any(inapplicable_reason(case, v) is None for v in classes.values()):
            reasons = "; ".join(
                f"{v.name}: {inapplicable_reason(case, v)}" for v in classes.values()
            )
            raise ValueError(f"{w}: no class of the site can drive it ({reasons})")
        out.append(case)
    return tuple(out)


def _coverage(radar: RadarSpec, road: Road, length_m: float) -> np.ndarray:
    """Whether the lane centre is seen by ``radar`` every ``COVERAGE_STEP_M`` up to a length."""
    s = np.arange(0.0, length_m + 1e-9, COVERAGE_STEP_M)
    return radar.covers(road.lane_point(s))


def _assign_radars(
    spec: SiteFile, roads: dict[str, Road], radars: tuple[RadarSpec, ...], where: str
) -> dict[str, str]:
    """Map each road to the file's ``radar``, or to the radar that sees most of its zone."""
    names = [r.name for r in radars]
    out = {}
    for rd in spec.roads:
        if rd.radar is not None:
            if rd.radar not in names:
                raise ValueError(
                    f"{where}: road {rd.name!r}: unknown radar {rd.radar!r}; radars are "
                    f"{', '.join(names)}"
                )
            radar = radars[names.index(rd.radar)]
            if not _coverage(radar, roads[rd.name], spec.zone_m).any():
                raise ValueError(
                    f"{where}: road {rd.name!r}: its radar {rd.radar!r} sees no part of its "
                    "controlled zone"
                )
            out[rd.name] = rd.radar
            continue
        seen = [float(_coverage(r, roads[rd.name], spec.zone_m).mean()) for r in radars]
        if max(seen) == 0.0:
            raise ValueError(f"{where}: road {rd.name!r}: no radar sees its controlled zone")
        out[rd.name] = names[int(np.argmax(seen))]
    return out


def blind_zones(site: Site) -> dict[str, list[tuple[float, float]]]:
    """Parts of each road's controlled zone its radar does not see: (from, to) along-road [m].

    A road is tracked with the radar of ``site.radar_of_road`` only (detections of several
    radars are not fused), so that radar's fields of view and range gates decide. The lane
    centre is sampled every ``COVERAGE_STEP_M``; the Doppler gate is not geometry and is not
    counted.
    """
    out = {}
    s = np.arange(0.0, site.zone_m + 1e-9, COVERAGE_STEP_M)
    for name, road in site.roads.items():
        seen = site.radar_for(name).covers(road.lane_point(s))
        edges = np.diff(np.concatenate([[0], (~seen).astype(int), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        out[name] = [(float(s[a]), float(s[b])) for a, b in zip(starts, stops, strict=True)]
    return out


__all__ = ["Site", "blind_zones", "builtin_sites", "load_site", "site_from_mapping"]
