"""Level-crossing site: approach roads, barrier, stop line and radars (TOML).

Frame: local ENU with the origin at the crossing centre. Radar azimuths are clockwise from
north; angles in the file are degrees (``_deg`` keys), converted here once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._toml import builtin_names, load_named_toml
from .road import Road, RoadElement, build_road


@dataclass(frozen=True)
class RadarSpec:
    """A traffic radar reporting (range, azimuth, radial speed) detections."""

    name: str
    position_m: tuple[float, float]
    height_m: float
    boresight_rad: float
    fov_half_rad: float
    max_range_m: float
    min_range_m: float
    period_s: float
    range_std_m: float
    azimuth_std_rad: float
    radial_speed_std_mps: float
    min_radial_speed_mps: float
    azimuth_bias_rad: float = 0.0
    time_jitter_s: float = 0.0
    max_unambiguous_speed_mps: float | None = None


@dataclass(frozen=True, eq=False)
class Site:
    """A crossing site: roads by name, radars, and the barrier / stop-line distances [m]."""

    name: str
    roads: dict[str, Road]
    radars: tuple[RadarSpec, ...]
    barrier_m: float
    stop_line_m: float
    zone_m: float
    run_in_m: float
    settings: dict[str, Any]

    def radar_for(self, road: str) -> RadarSpec:
        """Return the radar assigned to a road (settings ``radar_of_road``, else the first)."""
        wanted = self.settings.get("radar_of_road", {}).get(road)
        for r in self.radars:
            if r.name == wanted:
                return r
        return self.radars[0]


def builtin_sites() -> list[str]:
    """Names of the sites shipped with adaptrack."""
    return builtin_names("adaptrack.crossing", "sites")


def load_site(name_or_path: str | Path) -> Site:
    """Load a built-in site by name, or a site TOML file."""
    return site_from_mapping(*load_named_toml(name_or_path, "adaptrack.crossing", "sites", "site"))


def _get(data: dict[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise ValueError(f"{where}: missing key {key!r}")
    return data[key]


def site_from_mapping(data: dict[str, Any], where: str) -> Site:
    """Build and check a Site: roads must start at the crossing; radars must see a road."""
    lane = float(data.get("lane_width_m", 3.5))
    roads = {}
    for i, rd in enumerate(_get(data, "roads", where)):
        w = f"{where}: roads[{i}]"
        start = tuple(float(v) for v in rd.get("start_m", (0.0, 0.0)))
        if math.hypot(*start) > 1.0:
            raise ValueError(
                f"{w}: the road does not reach the crossing (it starts at {start}, "
                "more than 1 m from the crossing centre)"
            )
        elems = []
        for j, e in enumerate(_get(rd, "elements", w)):
            e = dict(e)
            if "angle_deg" in e:  # arc length from radius and angle
                e["length_m"] = float(e["radius_m"]) * math.radians(float(e.pop("angle_deg")))
            try:
                elems.append(RoadElement(**e))
            except TypeError as exc:
                raise ValueError(f"{w}: elements[{j}]: {exc}") from None
        name = str(_get(rd, "name", w))
        roads[name] = build_road(
            name, math.radians(float(_get(rd, "heading_deg", w))), lane, tuple(elems)
        )
    radars = []
    for i, r in enumerate(_get(data, "radars", where)):
        w = f"{where}: radars[{i}]"
        try:
            spec = RadarSpec(
                name=str(r.get("name", f"radar{i}")),
                position_m=(float(_get(r, "position_m", w)[0]), float(r["position_m"][1])),
                height_m=float(r.get("height_m", 6.0)),
                boresight_rad=math.radians(float(_get(r, "boresight_deg", w))),
                fov_half_rad=math.radians(float(r.get("fov_half_deg", 50.0))),
                max_range_m=float(r.get("max_range_m", 250.0)),
                min_range_m=float(r.get("min_range_m", 0.5)),
                period_s=float(r.get("period_s", 0.05)),
                range_std_m=float(r.get("range_std_m", 0.25)),
                azimuth_std_rad=math.radians(float(r.get("azimuth_std_deg", 0.3))),
                radial_speed_std_mps=float(r.get("radial_speed_std_mps", 0.10)),
                min_radial_speed_mps=float(r.get("min_radial_speed_mps", 0.1)),
                azimuth_bias_rad=math.radians(float(r.get("azimuth_bias_deg", 0.0))),
                time_jitter_s=float(r.get("time_jitter_s", 0.0)),
                max_unambiguous_speed_mps=(
                    None
                    if r.get("max_unambiguous_speed_mps") is None
                    else float(r["max_unambiguous_speed_mps"])
                ),
            )
        except (TypeError, IndexError) as exc:
            raise ValueError(f"{w}: {exc}") from None
        radars.append(spec)
    if not radars:
        raise ValueError(f"{where}: needs at least one radar")
    site = Site(
        str(data.get("name", Path(where).stem)),
        roads,
        tuple(radars),
        float(data.get("barrier_m", 10.0)),
        float(data.get("stop_line_m", 15.0)),
        float(data.get("zone_m", 150.0)),
        float(data.get("run_in_m", 50.0)),
        dict(data.get("settings", {})),
    )
    for r in site.radars:
        if not any(_sees(r, road) for road in roads.values()):
            raise ValueError(
                f"{where}: radar {r.name!r} has no road in view (field of view "
                f"+-{math.degrees(r.fov_half_rad):.0f} deg, range "
                f"{r.max_range_m:.0f} m)"
            )
    return site


def _sees(radar: RadarSpec, road: Road) -> bool:
    pts = road.lane_point(np.linspace(0, road.length_m, 200)) - np.asarray(radar.position_m)
    rng_m = np.hypot(pts[:, 0], pts[:, 1])
    az = np.arctan2(pts[:, 0], pts[:, 1]) - radar.boresight_rad
    az = (az + np.pi) % (2 * np.pi) - np.pi
    return bool(
        np.any(
            (np.abs(az) <= radar.fov_half_rad)
            & (rng_m <= radar.max_range_m)
            & (rng_m >= radar.min_range_m)
        )
    )


__all__ = ["RadarSpec", "Site", "builtin_sites", "load_site", "site_from_mapping"]
