"""Compliance report: plain data first (:func:`build_report`), then one self-contained HTML file.

The HTML has inline CSS and inline SVG figures (matplotlib, fixed hash salt, no dates), no
scripts and no network resources; every user-supplied string is escaped.
"""

from __future__ import annotations

import html
import io
import math
from dataclasses import dataclass, field
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from .. import __version__
from ..models.continuous import ConstantAcceleration
from .compliance import POSITION_LIMIT_M, SPEED_LIMIT_KMH, ComplianceResult
from .radar_sim import simulate_site_case
from .site import Site
from .tracking import track_free_2d, track_on_road
from .traffic import DEFAULT_CASES, VEHICLES


@dataclass(frozen=True)
class SampleTrack:
    """One simulated approach with the free and road-constrained estimates (for figures)."""

    label: str
    times: list[float]
    truth_xy: list[list[float]]
    free_xy: list[list[float]]
    road_xy: list[list[float]]
    free_pos_err: list[float]
    road_pos_err: list[float]
    free_speed_err_kmh: list[float]
    road_speed_err_kmh: list[float]


@dataclass(frozen=True)
class ReportData:
    """Everything the report shows, as plain data (testable without HTML)."""

    title: str
    site: str
    runs: int
    seed: int
    version: str
    rows: list[dict[str, Any]]
    worst: dict[str, dict[str, float]]
    gain_pct: dict[str, dict[str, float]]
    roads: dict[str, list[list[float]]]
    radars: list[dict[str, Any]]
    samples: list[SampleTrack]
    profile: dict[str, list[float]] = field(default_factory=dict)


def sample_tracks(site: Site, seed: int) -> list[SampleTrack]:
    """Simulate one car on the curve and one bus stopping, and track them both ways."""
    out = []
    cases = {c.name: c for c in DEFAULT_CASES}
    for i, (case_name, cls) in enumerate((("curve_60", "car"), ("stop_60", "bus"))):
        case, veh = cases[case_name], VEHICLES[cls]
        radar, road = site.radar_for(case.road), site.roads[case.road]
        runs = simulate_site_case(
            site, case, veh, n_runs=1, rng=np.random.default_rng(np.random.SeedSequence([seed, i]))
        )
        free = track_free_2d(
            runs.times, runs.measurements, runs.detected, radar, scatter_std_m=veh.scatter_std_m
        )
        rd = track_on_road(
            runs.times,
            runs.measurements,
            runs.detected,
            radar,
            road,
            model=ConstantAcceleration(jerk_psd=3.0),
            scatter_std_m=veh.scatter_std_m,
        )

        fp, fs = _errors(free, runs)
        rp, rs = _errors(rd, runs)
        out.append(
            SampleTrack(
                f"{cls}, {case_name}",
                _clean(runs.true_times[0]),
                runs.position[0].tolist(),
                _clean2(free.position[0]),
                _clean2(rd.position[0]),
                fp,
                rp,
                fs,
                rs,
            )
        )
    return out


def _errors(est: Any, runs: Any) -> tuple[list[float], list[float]]:
    pe = np.linalg.norm(est.position[0] - runs.position[0], axis=-1)
    return _clean(pe), _clean(3.6 * (est.speed[0] - runs.speed[0]))


def _clean(a: Any) -> list[float]:
    return [float(v) if np.isfinite(v) else float("nan") for v in np.asarray(a)]


def _clean2(a: Any) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(a)]


def build_report(
    result: ComplianceResult,
    site: Site,
    *,
    samples: list[SampleTrack],
    profile: dict[str, list[float]] | None = None,
) -> ReportData:
    """Collect the report's content as plain data."""
    roads = {
        name: road.lane_point(np.linspace(0, road.length_m, 200)).tolist()
        for name, road in site.roads.items()
    }
    radars = [
        {
            "name": r.name,
            "xy": list(r.position_m),
            "boresight_rad": r.boresight_rad,
            "fov_half_rad": r.fov_half_rad,
            "max_range_m": r.max_range_m,
        }
        for r in site.radars
    ]
    data = result.to_json()
    return ReportData(
        f"Level-crossing compliance report: {site.name}",
        site.name,
        result.runs,
        result.seed,
        __version__,
        data["rows"],
        result.worst,
        result.gain_pct,
        roads,
        radars,
        samples,
        profile or {},
    )


def _svg(fig: Any) -> str:
    buf = io.StringIO()
    with plt.rc_context({"svg.hashsalt": "adaptrack", "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    text = buf.getvalue()
    text = text[text.index("<svg") :]
    if "<metadata>" in text:  # RDF metadata: not needed, and it names external vocabularies
        text = text[: text.index("<metadata>")] + text[text.index("</metadata>") + 11 :]
    return text


def _map_figure(data: ReportData) -> str:
    fig, ax = plt.subplots(figsize=(6, 6))
    for name, pts in data.roads.items():
        p = np.asarray(pts)
        ax.plot(p[:, 0], p[:, 1], color="0.6", lw=3, label=f"lane, road {name}")
    for r in data.radars:
        x, y = r["xy"]
        ax.plot(x, y, "k^", ms=9)
        for sgn in (-1, 1):
            a = r["boresight_rad"] + sgn * r["fov_half_rad"]
            ax.plot([x, x + 60 * math.sin(a)], [y, y + 60 * math.cos(a)], "k:", lw=0.8)
    for s in data.samples:
        t = np.asarray(s.truth_xy)
        ax.plot(t[:, 0], t[:, 1], "g-", lw=1, label=f"truth ({s.label})")
        f = np.asarray(s.free_xy)
        ax.plot(f[:, 0], f[:, 1], "r.", ms=1, label=f"free 2-D EKF ({s.label})")
        d = np.asarray(s.road_xy)
        ax.plot(d[:, 0], d[:, 1], "b-", lw=0.8, label=f"road EKF ({s.label})")
    ax.plot(0, 0, "ks", ms=6, label="crossing centre")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", "datalim")
    ax.legend(fontsize=6, loc="best")
    ax.set_title("site map, radars and sample tracks")
    return _svg(fig)


def _error_figure(data: ReportData) -> str:
    fig, axes = plt.subplots(2, len(data.samples), figsize=(10, 5), squeeze=False)
    for j, s in enumerate(data.samples):
        t = np.asarray(s.times)
        axes[0, j].plot(t, s.free_pos_err, "r-", lw=0.7, label="free 2-D EKF")
        axes[0, j].plot(t, s.road_pos_err, "b-", lw=0.7, label="road EKF (CA)")
        axes[0, j].axhline(POSITION_LIMIT_M, color="k", ls="--", lw=0.8, label="0.7 m")
        axes[0, j].set_ylabel("position error [m]")
        axes[0, j].set_title(s.label)
        axes[1, j].plot(t, s.free_speed_err_kmh, "r-", lw=0.7)
        axes[1, j].plot(t, s.road_speed_err_kmh, "b-", lw=0.7)
        for sgn in (-1, 1):
            axes[1, j].axhline(sgn * SPEED_LIMIT_KMH, color="k", ls="--", lw=0.8)
        axes[1, j].set_ylabel("speed error [km/h]")
        axes[1, j].set_xlabel("time [s]")
        axes[0, j].legend(fontsize=6)
    fig.tight_layout()
    return _svg(fig)


def _rms_figure(data: ReportData) -> str:
    best = min(data.worst, key=lambda k: data.worst[k]["position_rms_m"])
    rows = [r for r in data.rows if r["filter"] == best]
    labels = [f"{r['vehicle_class']} / {r['case']}" for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, max(3, 0.22 * len(rows))))
    y = np.arange(len(rows))
    axes[0].barh(y, [r["position_rms_m"] for r in rows], color="tab:blue")
    axes[0].axvline(POSITION_LIMIT_M, color="k", ls="--")
    axes[0].set_yticks(y, labels, fontsize=6)
    axes[0].set_xlabel("position RMS [m] (limit 0.7)")
    axes[1].barh(
        y,
        [0 if math.isnan(r["speed_rms_kmh"]) else r["speed_rms_kmh"] for r in rows],
        color="tab:orange",
    )
    axes[1].axvline(SPEED_LIMIT_KMH, color="k", ls="--")
    axes[1].set_yticks(y, [""] * len(rows))
    axes[1].set_xlabel("speed RMS [km/h] (limit 2, speeds <= 100 km/h)")
    fig.suptitle(f"RMS vs requirement per class and case: {best}")
    fig.tight_layout()
    return _svg(fig)


def _profile_figure(data: ReportData) -> str:
    fig, ax = plt.subplots(figsize=(6, 3.5))
    lam = np.asarray(data.profile["lambda_per_s2"])
    j = np.asarray(data.profile["criterion"])
    pos = lam > 0
    ax.semilogx(lam[pos], j[pos], "o-", ms=3, label="M1, best accel_psd per lambda")
    if np.any(~pos):  # lambda = 0 is the constant-velocity member: no place on a log axis
        ax.axhline(
            float(j[~pos][0]), color="k", ls="--", lw=0.8, label="lambda = 0 (constant velocity)"
        )
    ax.legend(fontsize=7)
    ax.set_xlabel("lambda [1/s^2]")
    ax.set_ylabel("J (training criterion)")
    ax.set_title("design-time adaptation: J(lambda) of M1")
    fig.tight_layout()
    return _svg(fig)


def _num(v: float, fmt: str) -> str:
    return "" if not math.isfinite(v) else format(v, fmt)


CSS = """body{font-family:sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse;
font-size:12px}td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}th{background:#eee}
td.l{text-align:left}.pass{background:#d9f2d9}.fail{background:#f7d4d4}figure{margin:1em 0}"""


def render_html(data: ReportData) -> str:
    """Render the report as one self-contained HTML document."""
    e = html.escape
    parts = [
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(data.title)}"
        f"</title><style>{CSS}</style></head><body>",
        f"<h1>{e(data.title)}</h1>",
        f"<p>Site <b>{e(data.site)}</b>; {data.runs} Monte-Carlo runs per vehicle class and "
        f"case; seed {data.seed}; adaptrack {e(data.version)}. Requirement: position RMS "
        f"&le; {POSITION_LIMIT_M} m, speed RMS &le; {SPEED_LIMIT_KMH} km/h for speeds up "
        "to 100 km/h (relative speed error &le; 2 % above), in the controlled zone "
        "(0-150 m), from 1 s after track start, while moving.</p>",
        "<h2 id='summary'>Worst case per estimator</h2><table id='worst'><tr>"
        "<th>estimator</th><th>position RMS [m]</th><th>speed RMS [km/h]</th>"
        "<th>all cases pass</th></tr>",
    ]
    for name, w in data.worst.items():
        ok = bool(w["all_pass"])
        parts.append(
            f"<tr class='{'pass' if ok else 'fail'}'><td class='l'>{e(name)}</td>"
            f"<td>{w['position_rms_m']:.3f}</td><td>{w['speed_rms_kmh']:.3f}</td>"
            f"<td>{'yes' if ok else 'NO'}</td></tr>"
        )
    parts.append("</table>")
    if data.gain_pct:
        parts.append(
            "<p>Gain over the road-constrained constant-velocity baseline: "
            + "; ".join(
                f"{e(k)}: position {v['position']:+.1f} %, speed {v['speed']:+.1f} %"
                for k, v in data.gain_pct.items()
            )
            + ".</p>"
        )
    parts.append("<h2>Site</h2><figure id='map'>" + _map_figure(data) + "</figure>")
    if data.samples:
        parts.append(
            "<h2>Errors over time (sample runs)</h2><figure id='errors'>"
            + _error_figure(data)
            + "</figure>"
        )
    parts.append(
        "<h2>RMS against the requirement</h2><figure id='rms'>" + _rms_figure(data) + "</figure>"
    )
    if data.profile:
        parts.append(
            "<h2>Design-time adaptation</h2><figure id='profile'>"
            + _profile_figure(data)
            + "</figure>"
        )
    else:
        parts.append(
            "<h2>Design-time adaptation</h2><p>No tuning result was supplied to this report.</p>"
        )
    parts.append(
        "<h2 id='passfail'>Pass/fail per estimator, class and case</h2><p>PCRLB: the road-aligned "
        "posterior Cramer-Rao bound of a constant-acceleration target (jerk PSD 3 m^2/s^5) "
        "with this radar and scatter; the test trajectories are deterministic, so a filter "
        "can beat it (ratio &lt; 1).</p>"
        "<table id='passfail-table'><tr><th>estimator</th><th>class</th><th>case</th>"
        "<th>position RMS [m]</th><th>speed RMS [km/h]</th><th>rel. speed RMS [%]</th>"
        "<th>epochs</th><th>PCRLB pos. [m]</th><th>ratio</th><th>PCRLB speed [km/h]</th>"
        "<th>ratio</th><th>verdict</th></tr>"
    )
    for r in data.rows:
        cls = "pass" if r["pass"] else "fail"
        bound_p, bound_s = r.get("pcrlb_position_m", math.nan), r.get("pcrlb_speed_kmh", math.nan)
        cells = [
            f"{r['position_rms_m']:.3f}",
            _num(r["speed_rms_kmh"], ".3f"),
            _num(r["speed_rel_rms_pct"], ".2f"),
            str(r["n_epochs"]),
            _num(bound_p, ".3f"),
            _num(r["position_rms_m"] / bound_p, ".2f"),
            _num(bound_s, ".3f"),
            _num(r["speed_rms_kmh"] / bound_s, ".2f"),
        ]
        parts.append(
            f"<tr class='{cls}'><td class='l'>{e(r['filter'])}</td><td class='l'>"
            f"{e(r['vehicle_class'])}</td><td class='l'>{e(r['case'])}</td>"
            + "".join(f"<td>{c}</td>" for c in cells)
            + f"<td>{'pass' if r['pass'] else 'FAIL'}</td></tr>"
        )
    parts.append("</table></body></html>")
    return "".join(parts)


__all__ = ["ReportData", "SampleTrack", "build_report", "render_html", "sample_tracks"]
