"""Figure helpers of the HTML reports: deterministic inline SVG and the site's map layers."""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from .model import Site, blind_zones


def pyplot() -> Any:
    """Return ``matplotlib.pyplot`` on the file-only Agg backend (imported on first use: 0.7 s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def svg_of(fig: Any) -> str:
    """Return ``fig`` as inline SVG (fixed hash salt, no dates, no metadata); close it."""
    buf = io.StringIO()
    plt = pyplot()
    with plt.rc_context({"svg.hashsalt": "adaptrack", "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    text = buf.getvalue()
    text = text[text.index("<svg") :]
    if "<metadata>" in text:  # RDF metadata: not needed, and it names external vocabularies
        text = text[: text.index("<metadata>")] + text[text.index("</metadata>") + 11 :]
    return text


def site_layers(site: Site) -> tuple[dict[str, list[list[float]]], list[dict[str, Any]]]:
    """Return the site's lane polylines (200 points per road) and radars as plain data [m, rad]."""
    roads = {
        name: road.lane_point(np.linspace(0, road.length_m, 200)).tolist()
        for name, road in site.roads.items()
    }
    radars = [
        {
            "name": r.name,
            "xy": list(r.position_m),
            "boresight_rad": r.boresight_rad,
            "fields": [[f.max_range_m, f.half_angle_rad] for f in r.fields],
        }
        for r in site.radars
    ]
    return roads, radars


def draw_site(
    ax: Any, roads: dict[str, list[list[float]]], radars: list[dict[str, Any]], reach_m: float
) -> None:
    """Draw the lanes (grey), the radars (triangles) and their fields of view up to ``reach_m``.

    ``roads``: lane polylines [m]; ``radars``: ``name``, ``xy`` [m], ``boresight_rad`` and
    ``fields`` ([max range m, half angle rad] each).
    """
    for name, pts in roads.items():
        p = np.asarray(pts)
        ax.plot(p[:, 0], p[:, 1], color="0.6", lw=3, label=f"lane, road {name}")
    for r in radars:
        x, y = r["xy"]
        ax.plot(x, y, "k^", ms=9)
        for max_range, half in r["fields"]:
            length = min(max_range, reach_m)
            for sgn in (-1, 1):
                a = r["boresight_rad"] + sgn * half
                ax.plot([x, x + length * math.sin(a)], [y, y + length * math.cos(a)], "k:", lw=0.8)


def blind_polylines(site: Site) -> dict[str, list[list[float]]]:
    """Lane polylines of the site's blind zones, keyed ``"road: from-to m"`` [m]."""
    return {
        f"{name}: {a:.1f}-{b:.1f} m": site.roads[name].lane_point(np.linspace(a, b, 20)).tolist()
        for name, parts in blind_zones(site).items()
        for a, b in parts
    }


def draw_blind(ax: Any, blind: dict[str, list[list[float]]]) -> None:
    """Draw blind zones (:func:`blind_polylines`) in red over the lanes."""
    for j, pts in enumerate(blind.values()):
        p = np.asarray(pts)
        label = "blind zone (its radar does not see it)" if j == 0 else None
        ax.plot(p[:, 0], p[:, 1], color="red", lw=5, alpha=0.6, label=label)


MARK_LABELS = ("stop line", "barrier", "end of the controlled zone")


def site_marks(site: Site) -> dict[str, list[list[list[float]]]]:
    """Cross-sections of every road's carriageway: stop line, barrier, end of the zone.

    Label -> segments ``[[x0, y0], [x1, y1]]`` [m] across both lanes. A road that starts at
    a junction away from the crossing centre has its stop line and barrier on the road that
    leads on to the crossing: only its zone end is drawn.
    """
    out: dict[str, list[list[list[float]]]] = {label: [] for label in MARK_LABELS}
    for name, road in site.roads.items():
        at = (site.stop_line_of(name), site.barrier_of(name), site.zone_m)
        at_centre = float(np.hypot(*road.xy[0])) < 1.0
        w = road.lane_width_m
        spans = ((0.0, road.lanes_in * w), (-road.lanes_out * w, road.lanes_in * w),
                 (-road.lanes_out * w, road.lanes_in * w))  # fmt: skip  # stop line: inbound
        for label, at_m, (lo, hi) in zip(MARK_LABELS, at, spans, strict=True):
            if not at_centre and label != MARK_LABELS[-1]:
                continue
            centre, th = road.centreline(np.array([at_m]))
            across = np.array([-math.cos(th[0]), math.sin(th[0])])  # right of inbound
            ends = centre[0] + np.outer([lo - 0.2 * w, hi + 0.2 * w], across)
            out[label].append(ends.tolist())
    return out


def network_layers(site: Site) -> dict[str, list[list[list[float]]]]:
    """Every lane of every road, every corridor's driven lanes, and the rails, as polylines.

    ``lanes``: each lane's centre (towards and away from the crossing end); ``paths``: the
    lanes of the corridors, turning paths included, in both directions; ``rails``: both rails
    of every track [m].
    """
    lanes = []
    for road in site.roads.values():
        s = np.linspace(0.0, road.length_m, 200)
        w = road.lane_width_m
        offsets = [k * w for k in range(road.lanes_in)]
        offsets += [-(k + 1) * w for k in range(road.lanes_out)]
        lanes += [road.lane_point(s, d).tolist() for d in offsets]
    paths = []
    for c in site.corridors:
        u = np.linspace(0.0, c.path.length_m, 400)
        w = next(iter(site.roads.values())).lane_width_m
        paths += [c.path.lane_point(u, d).tolist() for d in (-0.5 * w, 0.5 * w)]
    rails = []
    if site.rails is not None:
        rails = [seg.tolist() for seg in site.rails.rail_lines(site.zone_m + site.run_in_m)]
    return {"lanes": lanes, "paths": paths, "rails": rails}


def draw_network(ax: Any, layers: dict[str, list[list[list[float]]]]) -> None:
    """Draw :func:`network_layers`: lanes (grey), corridor paths (thin blue), rails (black)."""
    styles = {"lanes": ("0.75", 2.0, "-"), "paths": ("tab:blue", 0.6, "--"),
              "rails": ("k", 1.2, "-")}  # fmt: skip
    names = {"lanes": "every lane", "paths": "driven paths (turns included)", "rails": "rails"}
    for key, lines in layers.items():
        colour, width, style = styles[key]
        for k, pts in enumerate(lines):
            p = np.asarray(pts)
            ax.plot(p[:, 0], p[:, 1], color=colour, lw=width, ls=style,
                    label=names[key] if k == 0 else None)  # fmt: skip


def draw_marks(ax: Any, marks: dict[str, list[list[list[float]]]]) -> None:
    """Draw :func:`site_marks` (blue stop lines, red barriers, dashed green zone ends)."""
    styles = {"stop line": "b-", "barrier": "r-", "end of the controlled zone": "g--"}
    for label, segments in marks.items():
        for k, seg in enumerate(segments):
            p = np.asarray(seg)
            ax.plot(p[:, 0], p[:, 1], styles[label], lw=2, label=label if k == 0 else None)
