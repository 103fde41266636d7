"""Site authoring: a commented template of the site file, and a check that draws a site.

``adaptrack site new`` writes :func:`site_template`; ``adaptrack site check`` loads a file
(the strict schema names every unknown or misspelt key, with the nearest valid one), then
summarises its coverage (:func:`coverage_table`) and draws its map (:func:`site_map_svg`:
roads, stop lines, barriers, controlled zone, radars with their fields of view, blind zones,
static clutter) and its coverage (:func:`coverage_svg`: which radar sees which stretch of
each lane).
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import pandas as pd

from ..._typing import FloatArray
from .drawing import (
    blind_polylines,
    draw_blind,
    draw_marks,
    draw_network,
    draw_site,
    network_layers,
    pyplot,
    site_layers,
    site_marks,
    svg_of,
)
from .model import COVERAGE_STEP_M, Site

TEMPLATE = "template.toml"


def site_template() -> str:
    """Text of the commented site template (every key, optional ones at their default)."""
    return (resources.files("adaptrack.crossing.site") / TEMPLATE).read_text(encoding="utf-8")


def _stations(site: Site) -> FloatArray:
    """Distances from the crossing centre along a road where coverage is sampled [m]."""
    return np.arange(0.0, site.zone_m + site.run_in_m + 1e-9, COVERAGE_STEP_M)


def coverage_table(site: Site) -> pd.DataFrame:
    """Share of each road's controlled zone that each radar sees (lane centre, 0.5 m steps).

    Columns ``road, radar, tracks_road`` (the radar that tracks the road: detections of
    several radars are not fused) and ``zone_seen`` (0-1).
    """
    s = np.arange(0.0, site.zone_m + 1e-9, COVERAGE_STEP_M)
    rows = [
        {
            "road": name,
            "radar": radar.name,
            "tracks_road": site.radar_of_road[name] == radar.name,
            "zone_seen": float(radar.covers(road.lane_point(s)).mean()),
        }
        for name, road in site.roads.items()
        for radar in site.radars
    ]
    return pd.DataFrame(rows)


def site_map_svg(site: Site, centre_m: float = 40.0) -> str:
    """Map of the site as inline SVG: the whole site, and its centre within ``centre_m``.

    It shows every lane, the driven paths (turns included), the rails, stop lines,
    barriers, the ends of the controlled zone, the radars with their fields of view, blind
    zones and the scene's static clutter.
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(14, 7))
    roads, radars = site_layers(site)
    reach = site.zone_m + site.run_in_m
    clutter = np.asarray(site.source.get("scene", {}).get("static_clutter_m", []), float)
    for ax, half in zip(axes, (None, centre_m), strict=True):
        draw_network(ax, network_layers(site))
        draw_site(ax, roads, radars, reach)
        draw_blind(ax, blind_polylines(site))
        draw_marks(ax, site_marks(site))
        for name in site.roads:
            end = site.roads[name].lane_point(np.array([reach if half is None else half]))[0]
            ax.annotate(f"road {name}", end, fontsize=8)
        for r in radars:
            ax.annotate(r["name"], r["xy"], fontsize=8, xytext=(4, 4), textcoords="offset points")
        if clutter.size:
            ax.plot(clutter[:, 0], clutter[:, 1], "mx", label="static clutter")
        ax.plot(0, 0, "ks", ms=6, label="crossing centre")
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.set_aspect("equal", "datalim" if half is None else "box")
        if half is not None:
            ax.set_xlim(-half, half)
            ax.set_ylim(-half, half)
            ax.set_title(f"within {half:g} m of the crossing centre")
        else:
            ax.set_title(f"{site.name}: roads, radars' fields of view, blind zones")
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    return svg_of(fig)


def coverage_svg(site: Site) -> str:
    """Which radar sees each road's lane centre, against the distance from the centre."""
    plt = pyplot()
    s = _stations(site)
    fig, axes = plt.subplots(len(site.roads), 1, figsize=(8, 1.2 + 0.8 * len(site.radars) *
                             len(site.roads)), squeeze=False)  # fmt: skip
    for ax, (name, road) in zip(axes[:, 0], site.roads.items(), strict=True):
        points = road.lane_point(s)
        for k, radar in enumerate(site.radars):
            seen = radar.covers(points)
            tracking = site.radar_of_road[name] == radar.name
            ax.fill_between(s, k - 0.35, k + 0.35, where=seen, step="mid",
                            color="tab:blue" if tracking else "0.7")  # fmt: skip
        ax.axvspan(0.0, site.zone_m, color="tab:green", alpha=0.08)
        ax.set_yticks(range(len(site.radars)), [r.name for r in site.radars])
        ax.set_xlim(0.0, s[-1])
        ax.set_title(f"road {name} (blue: its tracking radar; shaded: controlled zone)",
                     fontsize=9)  # fmt: skip
    axes[-1, 0].set_xlabel("distance from the crossing centre along the road [m]")
    fig.tight_layout()
    return svg_of(fig)


__all__ = ["coverage_svg", "coverage_table", "site_map_svg", "site_template"]
