"""Interactive figures of the HTML report (plotly): the site map and the errors over time.

Each figure is a ``<div>`` with its plotting call; :func:`plotly_script` is the library
itself, inlined once per page, so that the report works offline (no network resource).
Element ids are fixed, so the same data gives the same HTML.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import plotly.graph_objects as go
from plotly.offline import get_plotlyjs

CONFIG = {"scrollZoom": True, "displaylogo": False, "responsive": True}
FOV_ARC_POINTS = 40  # points on the far edge of a field of view


def plotly_script() -> str:
    """Return the plotting library as one inline ``<script>`` (about 5 MB; offline)."""
    return "<script>" + get_plotlyjs() + "</script>"


def _div(fig: go.Figure, div_id: str, height_px: int) -> str:
    fig.update_layout(
        height=height_px, template="plotly_white", margin={"l": 50, "r": 20, "t": 40, "b": 40},
        legend={"font": {"size": 10}},
    )  # fmt: skip
    return str(fig.to_html(full_html=False, include_plotlyjs=False, div_id=div_id, config=CONFIG))


def _wedge(xy: list[float], boresight: float, half: float, reach: float) -> tuple[list, list]:
    """Outline of a field of view (a circular sector) [m]."""
    a = boresight + np.linspace(-half, half, FOV_ARC_POINTS)
    x = [xy[0], *(xy[0] + reach * np.sin(a)), xy[0]]
    y = [xy[1], *(xy[1] + reach * np.cos(a)), xy[1]]
    return x, y


def site_map_div(
    roads: dict[str, list[list[float]]],
    radars: list[dict[str, Any]],
    blind: dict[str, list[list[float]]],
    marks: dict[str, list[list[list[float]]]],
    tracks: list[tuple[str, list[list[float]], str]],
    reach_m: float,
) -> str:
    """Pan/zoom map: lanes, stop lines, barriers, zone ends, radars, fields, blind zones, tracks.

    ``marks``: label -> segments ``[[x0, y0], [x1, y1]]`` (stop line, barrier, zone end);
    ``tracks``: (label, polyline [m], colour) drawn over the site.
    """
    fig = go.Figure()
    for k, r in enumerate(radars):
        for j, (max_range, half) in enumerate(r["fields"]):
            x, y = _wedge(r["xy"], r["boresight_rad"], half, min(max_range, reach_m))
            fig.add_trace(go.Scatter(
                x=x, y=y, mode="lines", fill="toself", fillcolor="rgba(70,130,180,0.08)",
                line={"color": "rgba(70,130,180,0.5)", "width": 1, "dash": "dot"},
                name="field of view", legendgroup="fov", showlegend=k == 0 and j == 0,
                hoverinfo="name",
            ))  # fmt: skip
    for name, pts in roads.items():
        p = np.asarray(pts)
        fig.add_trace(go.Scatter(
            x=p[:, 0], y=p[:, 1], mode="lines", line={"color": "grey", "width": 4},
            name=f"lane, road {name}",
        ))  # fmt: skip
    colours = {"stop line": "blue", "barrier": "red", "end of the controlled zone": "green"}
    for label, segments in marks.items():
        xs: list[float | None] = []
        ys: list[float | None] = []
        for (x0, y0), (x1, y1) in segments:
            xs += [x0, x1, None]
            ys += [y0, y1, None]
        fig.add_trace(go.Scatter(
            x=xs, y=ys, mode="lines", name=label,
            line={"color": colours.get(label, "black"), "width": 3},
        ))  # fmt: skip
    for j, (label, pts) in enumerate(blind.items()):
        p = np.asarray(pts)
        fig.add_trace(go.Scatter(
            x=p[:, 0], y=p[:, 1], mode="lines", line={"color": "rgba(255,0,0,0.6)", "width": 8},
            name="blind zone", legendgroup="blind", showlegend=j == 0, hovertext=label,
        ))  # fmt: skip
    for label, pts, colour in tracks:
        p = np.asarray(pts, dtype=float).reshape(-1, 2)
        fig.add_trace(go.Scatter(
            x=p[:, 0], y=p[:, 1], mode="lines", line={"color": colour, "width": 1.5}, name=label,
        ))  # fmt: skip
    fig.add_trace(go.Scatter(
        x=[r["xy"][0] for r in radars], y=[r["xy"][1] for r in radars], mode="markers+text",
        marker={"symbol": "triangle-up", "size": 12, "color": "black"},
        text=[r["name"] for r in radars], textposition="top right", name="radars",
    ))  # fmt: skip
    fig.add_trace(go.Scatter(
        x=[0.0], y=[0.0], mode="markers", marker={"symbol": "square", "color": "black"},
        name="crossing centre",
    ))  # fmt: skip
    fig.update_xaxes(title_text="east [m]")
    fig.update_yaxes(title_text="north [m]", scaleanchor="x", scaleratio=1)
    fig.update_layout(title="Site map (drag to pan, scroll to zoom, click legend to hide)")
    return _div(fig, "map-plot", 700)


def error_plot_div(samples: list[Any], limits: tuple[float, float]) -> str:
    """Position and speed error over time of the sample runs (free 2-D EKF and deployed)."""
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.08)
    palette = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
    for k, s in enumerate(samples):
        colour = palette[k % len(palette)]
        t = s.times
        series = (
            (s.free_pos_err, s.road_pos_err, "m"),
            (s.free_speed_err_kmh, s.road_speed_err_kmh, "km/h"),
        )
        for row, (free, road, unit) in enumerate(series, start=1):
            fig.add_trace(go.Scatter(
                x=t, y=_nan_to_none(road), mode="lines", line={"color": colour, "width": 1.5},
                name=f"deployed ({s.label})", legendgroup=f"d{k}", showlegend=row == 1,
                hovertemplate=f"%{{y:.3f}} {unit}",
            ), row=row, col=1)  # fmt: skip
            fig.add_trace(go.Scatter(
                x=t, y=_nan_to_none(free), mode="lines",
                line={"color": colour, "width": 0.8, "dash": "dot"},
                name=f"free 2-D EKF ({s.label})", legendgroup=f"f{k}", showlegend=row == 1,
                hovertemplate=f"%{{y:.3f}} {unit}",
            ), row=row, col=1)  # fmt: skip
    for row, limit in enumerate(limits, start=1):
        fig.add_hline(y=limit, line={"color": "red", "dash": "dash", "width": 1}, row=row, col=1)
    fig.add_hline(y=-limits[1], line={"color": "red", "dash": "dash", "width": 1}, row=2, col=1)
    fig.update_yaxes(title_text="position error [m]", row=1, col=1)
    fig.update_yaxes(title_text="speed error [km/h]", row=2, col=1)
    fig.update_xaxes(title_text="time [s]", row=2, col=1)
    fig.update_layout(title="Errors over time of the sample runs (dashed: the requirement)")
    return _div(fig, "errors-plot", 600)


def _nan_to_none(values: list[float]) -> list[float | None]:
    return [None if not math.isfinite(v) else v for v in values]


__all__ = ["error_plot_div", "plotly_script", "site_map_div"]
