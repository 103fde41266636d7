"""The report's mixed-traffic section: the scene tracker on the site's traffic, scored.

:func:`mixed_traffic_study` simulates the site's ``[scene]`` (flows, barrier closures,
clutter, detections without ids) for ``duration_s`` with one vehicle stalled on the crossing,
tracks it with the scene tracker given the crossing's warning intervals, and scores it
(:mod:`adaptrack.crossing.studies.scene_metrics`): GOSPA over time, identities, per-class accuracy
through association with vehicles as the sampling unit of the bounds, the true hazards with
the delay of their "stopped between the barriers" event, false events, and the stop-line
runners with the lead of their "will not stop" event. The result is plain data
(:class:`MixedTraffic`, JSON round trip); :func:`mixed_traffic_html` renders it.
"""

from __future__ import annotations

import html
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import pandas as pd

from ..._typing import FloatArray
from ..scene.tracker import SceneTrackerConfig, track_scene
from ..simulation.object_list import object_list_ids
from ..simulation.scene import Stall, scene_spec, simulate_scene
from ..site.drawing import draw_site, pyplot, svg_of
from ..site.geometry import radial_geometry
from ..site.model import Site
from .compliance import CONFIDENCE, POSITION_LIMIT_M, SPEED_LIMIT_KMH
from .scene_metrics import UNREPORTED, event_outcomes, score_scene, stop_line_outcomes

STALL_AT = 0.58  # the stall starts at this fraction of the study (within a closure on lx_default)
STALL_S = 90.0  # how long the stalled vehicle stands [s]
MAP_STEP_S = 1.0  # the map draws a track's position every this many seconds


@dataclass(frozen=True)
class MixedTraffic:
    """One scored scene, as plain data (units in the names; lists for JSON)."""

    seed: int
    duration_s: float
    stall_road: str
    stall_time_s: float
    road_users: int
    detections: int
    tracker_s: float  # wall-clock time of the scene tracker
    gospa_mean: float
    gospa_localisation: float
    gospa_missed: float
    gospa_false: float
    id_switches: int
    fragmentations: int
    false_tracks: int  # reported tracks in the zone never paired with a road user
    confidence: float
    classes: list[dict[str, Any]]  # per class: RMS, upper bounds, verdict, coverage, ...
    gospa_series: dict[str, list[float]]  # time_s, gospa, localisation, missed, false
    closures: list[list[float]]  # barriers down [s]
    hazards: list[dict[str, Any]]  # object_id, stop_time_s, delay_s (NaN: missed), seen
    false_stop_times_s: list[float]
    stop_line_runs: list[dict[str, float]]  # object_id, cross_time_s, lead_s (NaN: missed)
    false_line_times_s: list[float]
    truth_paths: list[list[list[float]]]  # per road user: [east, north] every MAP_STEP_S
    track_paths: list[list[list[float]]]  # per moving track: [east, north] every MAP_STEP_S
    static_xy: list[list[float]]  # learnt static objects (clutter)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON-able dict (NaN as None)."""
        return dict(_nan_to_none(asdict(self)))

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> MixedTraffic:
        """Inverse of :meth:`to_json`; ValueError names a missing or unknown field."""
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in data]
        unknown = [k for k in data if k not in names]
        if missing or unknown:
            what, bad = ("missing", missing) if missing else ("unknown", unknown)
            more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
            raise ValueError(f"mixed-traffic section: {what} field {bad[0]!r}{more}")
        return cls(**_none_to_nan(data))


def _nan_to_none(x: Any) -> Any:
    if isinstance(x, float) and not np.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _nan_to_none(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_nan_to_none(v) for v in x]
    return x


def _none_to_nan(x: Any) -> Any:
    if x is None:
        return float("nan")
    if isinstance(x, dict):
        return {k: _none_to_nan(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_none_to_nan(v) for v in x]
    return x


def _paths(table: pd.DataFrame, key: str, zone_m: float, distance: str) -> list[list[list[float]]]:
    """Positions per ``key`` within ``zone_m``, the first of every ``MAP_STEP_S`` (0.1 m)."""
    sub = table[np.abs(table[distance].to_numpy()) <= zone_m]
    sub = sub.assign(_bin=np.floor(sub["time_s"].to_numpy() / MAP_STEP_S))
    sub = sub.drop_duplicates([key, "_bin"])
    return [
        np.round(g[["east_m", "north_m"]].to_numpy(), 1).tolist()
        for _, g in sub.groupby(key)
        if len(g) > 1
    ]


def _in_some_view(site: Site, xy: FloatArray) -> list[bool]:
    """Whether each ground point (N, 2) [m] lies in a field of view of one of the radars."""
    seen = np.zeros(len(xy), dtype=bool)
    for radar in site.radars:
        rng_m, az, _ = radial_geometry(xy, np.zeros_like(xy), radar.position_m, radar.height_m)
        seen |= radar.in_view(rng_m, az)
    return seen.tolist()


def mixed_traffic_study(
    site: Site,
    seed: int,
    duration_s: float,
    *,
    config: SceneTrackerConfig | None = None,
    confidence: float = CONFIDENCE,
    on_scan: Callable[[int, int], None] | None = None,
    object_list: bool = False,
) -> MixedTraffic:
    """Simulate, track (with ``config``) and score ``duration_s`` of the site's scene.

    See the module docstring. ``object_list``: the radars label their detections with
    object ids (:func:`.object_list.object_list_ids`: reissued, sometimes swapped) that the
    tracker takes as hints. Raises ValueError when the site has no scene (no flow between
    two roads).
    """
    road = sorted(site.roads)[-1]
    stall = Stall(road, STALL_AT * duration_s, 0.0, STALL_S)
    spec = scene_spec(site, duration_s=duration_s, stalls=(stall,))
    rec = simulate_scene(site, spec, seed)
    detections = (
        rec.detections.assign(object_id=object_list_ids(rec, seed))
        if object_list
        else rec.detections
    )
    start = time.perf_counter()
    tracks, events, _ = track_scene(site, detections, config, on_scan, spec.warnings())
    elapsed = time.perf_counter() - start
    score = score_scene(rec.truth, tracks, site.zone_m, confidence=confidence)
    hazards, false_stops = event_outcomes(rec.truth, events, site.barrier_m)
    runs, false_line = stop_line_outcomes(rec.truth, events)
    series = score.gospa_series
    moving = tracks[~tracks["status"].isin(UNREPORTED)]
    static = tracks[tracks["status"] == "static"].drop_duplicates("track_id", keep="last")
    return MixedTraffic(
        seed,
        duration_s,
        stall.entry,
        stall.time_s,
        int(rec.truth.users.shape[0]),
        len(rec.detections),
        elapsed,
        score.gospa_mean,
        score.gospa_localisation,
        score.gospa_missed,
        score.gospa_false,
        score.id_switches,
        score.fragmentations,
        score.false_tracks,
        confidence,
        score.classes.to_dict("records"),
        {
            k: series[k].astype(float).tolist()
            for k in ("time_s", "gospa", "localisation", "missed", "false")
        },
        rec.truth.closures.tolist(),
        hazards.assign(seen=_in_some_view(site, hazards[["east_m", "north_m"]].to_numpy()))[
            ["object_id", "stop_time_s", "delay_s", "seen"]
        ].to_dict("records"),
        false_stops["time_s"].astype(float).tolist(),
        runs[["object_id", "cross_time_s", "lead_s"]].to_dict("records"),
        false_line["time_s"].astype(float).tolist(),
        _paths(rec.truth.table, "object_id", site.zone_m, "to_crossing_m"),
        _paths(moving, "track_id", site.zone_m, "from_crossing_m"),
        np.round(static[["east_m", "north_m"]].to_numpy(), 1).tolist(),
    )


def _map_figure(
    m: MixedTraffic,
    roads: dict[str, list[list[float]]],
    radars: list[dict[str, Any]],
    zone_m: float,
) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 6))
    draw_site(ax, roads, radars, zone_m)
    for j, p in enumerate(m.truth_paths):
        a = np.asarray(p)
        ax.plot(a[:, 0], a[:, 1], color="0.3", lw=0.4, label="truth" if j == 0 else None)
    colors = [plt.get_cmap("tab10")(k) for k in range(10)]
    for j, p in enumerate(m.track_paths):
        a = np.asarray(p)
        ax.plot(
            a[:, 0],
            a[:, 1],
            ".",
            ms=1.5,
            color=colors[j % 10],
            label="tracks (one colour each)" if j == 0 else None,
        )
    if m.static_xy:
        s = np.asarray(m.static_xy)
        ax.plot(s[:, 0], s[:, 1], "kx", ms=5, label="static objects (learnt clutter)")
    ax.plot(0, 0, "ks", ms=6, label="crossing centre")
    ax.set_xlim(-zone_m, zone_m)
    ax.set_ylim(-zone_m, zone_m)
    ax.set_aspect("equal")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.legend(fontsize=6, loc="upper right")
    ax.set_title(f"mixed traffic: tracks and truth in the controlled zone ({m.duration_s:g} s)")
    return svg_of(fig)


def _shade_closures(ax: Any, m: MixedTraffic) -> None:
    for j, (a, b) in enumerate(m.closures):
        ax.axvspan(a, b, color="0.85", label="barriers down" if j == 0 else None)


def _gospa_figure(m: MixedTraffic) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3))
    s = {k: np.asarray(v) for k, v in m.gospa_series.items()}
    _shade_closures(ax, m)
    ax.plot(s["time_s"], s["gospa"], "k-", lw=0.7, label="GOSPA [m]")
    for part, color in (
        ("localisation", "tab:blue"),
        ("missed", "tab:orange"),
        ("false", "tab:red"),
    ):
        ax.plot(
            s["time_s"], np.sqrt(s[part]), lw=0.6, color=color, label=f"sqrt of the {part} part [m]"
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("[m]")
    ax.set_title(f"GOSPA (c = 5 m, p = 2) over time; mean {m.gospa_mean:.2f} m")
    ax.legend(fontsize=6, ncol=5, loc="lower left", bbox_to_anchor=(0, 1.08))
    fig.tight_layout()
    return svg_of(fig)


def _events_figure(m: MixedTraffic) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 2.6))
    _shade_closures(ax, m)
    lanes = [
        "stop-line runners",
        "'will not stop' events",
        "standstills between barriers",
        "'stopped' events",
    ]
    h_t = np.array([h["stop_time_s"] for h in m.hazards])
    h_d = np.array([h["delay_s"] for h in m.hazards])
    r_t = np.array([r["cross_time_s"] for r in m.stop_line_runs])
    r_l = np.array([r["lead_s"] for r in m.stop_line_runs])
    found = np.isfinite(h_d)
    ax.plot(h_t, np.full(h_t.size, 2), "kv", ms=6, label="true hazard")
    ax.plot(h_t[found] + h_d[found], np.full(found.sum(), 3), "g^", ms=6, label="event (matched)")
    ax.plot(m.false_stop_times_s, [3] * len(m.false_stop_times_s), "rx", ms=7, label="false event")
    ax.plot(h_t[~found], np.full((~found).sum(), 2), "ro", mfc="none", ms=9, label="missed")
    ran = np.isfinite(r_l)
    ax.plot(r_t, np.zeros(r_t.size), "kv", ms=6)
    ax.plot(r_t[ran] - r_l[ran], np.ones(ran.sum()), "g^", ms=6)
    ax.plot(m.false_line_times_s, [1] * len(m.false_line_times_s), "rx", ms=7)
    ax.plot(r_t[~ran], np.zeros((~ran).sum()), "ro", mfc="none", ms=9)
    ax.set_yticks(range(4), lanes, fontsize=7)
    ax.set_ylim(-0.7, 3.7)
    ax.set_xlim(0, m.duration_s)
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=6, ncol=5, loc="upper left", bbox_to_anchor=(0, 1.25))
    fig.tight_layout()
    return svg_of(fig)


def _cell(value: float) -> str:
    """Format a table figure: blank when not computed, "> 100" when a bound says nothing."""
    if not np.isfinite(value):
        return ""
    return "&gt; 100" if value > 100 else f"{value:.3f}"


def _class_table(m: MixedTraffic) -> list[str]:
    e = html.escape
    conf = f"{100 * m.confidence:.0f} %"
    parts = [
        "<table id='mixed-classes'><tr><th>class</th><th>vehicles</th><th>epochs</th>"
        f"<th>coverage [%]</th><th>position RMS [m]</th><th>{conf} bound</th>"
        f"<th>speed RMS [km/h]</th><th>{conf} bound</th><th>verdict</th></tr>"
    ]
    for c in m.classes:
        keys = ("position_rms_m", "position_upper_m", "speed_rms_kmh", "speed_upper_kmh")
        bounds = [_cell(c[k]) for k in keys]
        parts.append(
            f"<tr class='{c['verdict']}'><td class='l'>{e(str(c['class']))}</td>"
            f"<td>{c['vehicles']}</td><td>{c['epochs']}</td><td>{100 * c['coverage']:.1f}</td>"
            + "".join(f"<td>{b}</td>" for b in bounds)
            + f"<td>{c['verdict']}</td></tr>"
        )
    parts.append("</table>")
    return parts


def mixed_traffic_html(
    m: MixedTraffic,
    roads: dict[str, list[list[float]]],
    radars: list[dict[str, Any]],
    zone_m: float,
) -> list[str]:
    """HTML parts of the section (inline SVG figures, escaped strings)."""
    delays = [h["delay_s"] for h in m.hazards]
    found = [d for d in delays if np.isfinite(d)]
    leads = [r["lead_s"] for r in m.stop_line_runs if np.isfinite(r["lead_s"])]
    hours = m.duration_s / 3600.0
    blind = sum(1 for h in m.hazards if not h["seen"])
    hazard_text = (
        f"{len(delays)} true hazards (a road user at a standstill between the barriers), "
        f"{len(found)} raised an event"
        + (f", delays {', '.join(f'{d:.2f}' for d in found)} s" if found else "")
        + (f" ({blind} stood where no radar's field of view reaches)" if blind else "")
        + f"; {len(m.false_stop_times_s)} false 'stopped' events "
        f"({len(m.false_stop_times_s) / hours:.1f} per hour). {len(m.stop_line_runs)} road "
        f"users ran the stop line during a warning, {len(leads)} predicted"
        + (f" with leads {', '.join(f'{x:.2f}' for x in leads)} s" if leads else "")
        + f"; {len(m.false_line_times_s)} false 'will not stop' events."
    )
    return [
        "<h2 id='mixed'>Mixed traffic: many objects from raw detections</h2>",
        f"<p>{m.duration_s:g} s of the site's scene (seed {m.seed}): {m.road_users} road users "
        f"over both directions with barrier closures, clutter and several detections per "
        f"long vehicle, {m.detections} detections without ids; a vehicle on road "
        f"{html.escape(m.stall_road)} stalls on the crossing at {m.stall_time_s:.0f} s for "
        f"{STALL_S:g} s. The scene tracker took {m.tracker_s:.1f} s "
        f"({m.duration_s / m.tracker_s:.0f} times faster than real time). Mean GOSPA "
        f"{m.gospa_mean:.2f} m, {m.id_switches} identity switches, {m.fragmentations} "
        f"fragmentations, {m.false_tracks} false tracks (reported in the zone, never paired "
        f"with a road user; {m.false_tracks / (m.duration_s / 3600.0):.0f} per hour).</p>",
        "<figure id='mixed-map'>" + _map_figure(m, roads, radars, zone_m) + "</figure>",
        "<figure id='mixed-gospa'>" + _gospa_figure(m) + "</figure>",
        f"<h3>Hazard events</h3><p id='mixed-events'>{hazard_text}</p>",
        "<figure id='mixed-timeline'>" + _events_figure(m) + "</figure>",
        "<h3>Accuracy per class through association</h3><p>Each road user in the zone is "
        "paired with a confirmed track by GOSPA's optimal assignment every 0.5 s (every epoch "
        f"in the zone, stopped ones included; coverage: epochs with a track). Limits "
        f"{POSITION_LIMIT_M} m and {SPEED_LIMIT_KMH} km/h; the bounds take the vehicle as the "
        "sampling unit, so a class with few vehicles in one scene stays undecided.</p>",
        *_class_table(m),
    ]


__all__ = ["MixedTraffic", "mixed_traffic_html", "mixed_traffic_study"]
