"""Compliance report: plain data first (:func:`build_report`), then one self-contained HTML file.

The answer leads: a verdict banner (does the site comply, with which deployed estimator, at
what confidence) and the class x case matrix of the deployed estimator coloured by its margin
to the requirement with the Monte-Carlo interval. Then the verdict table of every estimator on
the test runs (RMS with one-sided confidence bounds), the design-time selection (every
candidate on the validation runs, its ratio to the road-aligned PCRLB, and why the winner
won), the interactive site map (pan/zoom: roads, stop lines, barriers, zone ends, radars with
fields of view, blind zones, sample tracks), interactive error plots, the M1 profile
J(lambda), the mixed-traffic scene (:mod:`adaptrack.crossing.studies.mixed_traffic`) and the
pass/fail table.

The HTML is one file: inline CSS, inline SVG figures (matplotlib, fixed hash salt, no dates)
and the interactive ones with the plotting library's JavaScript inlined
(:mod:`adaptrack.crossing.site.interactive`); it loads no network resource. Every
user-supplied string is escaped.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ... import __version__
from ..estimators.road_filters import track_free_2d
from ..simulation.radar import simulate_site_case
from ..site.drawing import blind_polylines, pyplot, site_layers, site_marks, svg_of
from ..site.interactive import error_plot_div, plotly_script, site_map_div
from ..site.model import Site
from .compliance import (
    CONFIRMATION_FACTOR,
    POSITION_LIMIT_M,
    RANDOM_RUNS_FACTOR,
    SPEED_LIMIT_KMH,
    WARM_UP_S,
    ComplianceResult,
    requirement_ratio,
)
from .mixed_traffic import MixedTraffic, mixed_traffic_html
from .selection import CRITERION_TEXT, SiteTuning
from .trackers import PlanarTracker, Tracker


@dataclass(frozen=True)
class SampleTrack:
    """One simulated approach with the free 2-D and the deployed estimates (for figures)."""

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
    description: str
    version: str
    seed: int
    runs: int
    confidence: float
    zone_m: float
    rows: list[dict[str, Any]]
    summary: dict[str, dict[str, Any]]
    gain_pct: dict[str, dict[str, float]]
    roads: dict[str, list[list[float]]]
    radars: list[dict[str, Any]]
    blind: dict[str, list[list[float]]]
    skipped: list[list[str]]
    samples: list[SampleTrack]
    deployed: str = ""
    selection: dict[str, Any] = field(default_factory=dict)
    candidates: list[dict[str, Any]] = field(default_factory=list)
    profile: dict[str, list[float]] = field(default_factory=dict)
    mixed_traffic: MixedTraffic | None = None
    mixed_traffic_note: str = ""  # why there is no mixed-traffic section
    marks: dict[str, list[list[list[float]]]] = field(default_factory=dict)  # stop lines, ...


def _sample_pairs(site: Site) -> list[tuple[Any, Any]]:
    """Pick a pass near 60 km/h on the most curved road and the longest class stopping."""
    pairs = site.pairs()
    curvy = max(site.roads, key=lambda r: float(abs(site.roads[r].curvature).max()))
    passes = [p for p in pairs if p[0].kind == "pass" and p[0].road == curvy]
    stops = [p for p in pairs if p[0].kind in ("stop", "emergency")]
    first = min(passes or pairs, key=lambda p: abs(p[0].speed_kmh - 60.0))
    second = max(stops, key=lambda p: p[1].length_m) if stops else pairs[-1]
    return [first, second]


def sample_tracks(site: Site, seed: int, deployed: Tracker) -> list[SampleTrack]:
    """Simulate two approaches and track them with the free 2-D EKF and ``deployed``."""
    out = []
    for i, (case, veh) in enumerate(_sample_pairs(site)):
        runs = simulate_site_case(
            site, case, veh, n_runs=1, rng=np.random.default_rng(np.random.SeedSequence([seed, i]))
        )
        free = PlanarTracker(track_free_2d)(runs, site, case, veh)
        rd = deployed(runs, site, case, veh)
        fp, fs = _errors(free, runs)
        rp, rs = _errors(rd, runs)
        out.append(
            SampleTrack(
                f"{veh.name}, {case.name}",
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


def _bound_ratios(rows: list[dict[str, Any]], name: str) -> tuple[float, float]:
    """Pooled RMS of an estimator over its pairs divided by the pooled PCRLB (pos, speed)."""
    mine = [r for r in rows if r["filter"] == name]

    def pooled(key: str, count: str) -> float:
        vals = [(r[key], r[count]) for r in mine if math.isfinite(r[key]) and r[count] > 0]
        n = sum(c for _, c in vals)
        return math.sqrt(sum(v * v * c for v, c in vals) / n) if n else math.nan

    with np.errstate(invalid="ignore"):
        return (
            pooled("position_rms_m", "n_epochs") / pooled("pcrlb_position_m", "n_epochs"),
            pooled("speed_rms_kmh", "n_speed_epochs") / pooled("pcrlb_speed_kmh", "n_speed_epochs"),
        )


def build_report(
    test: ComplianceResult,
    site: Site,
    *,
    samples: list[SampleTrack],
    deployed: str = "",
    tuning: SiteTuning | None = None,
    validation: ComplianceResult | None = None,
    mixed_traffic: MixedTraffic | None = None,
    mixed_traffic_note: str = "",
) -> ReportData:
    """Collect the report's content as plain data.

    ``test``: the compliance Monte Carlo (``deployed`` names its deployed estimator);
    ``tuning`` and ``validation``: the design-time selection and its validation runs;
    ``mixed_traffic``: the scored scene (or ``mixed_traffic_note``: why there is none).
    """
    roads, radars = site_layers(site)
    blind = blind_polylines(site)
    candidates = []
    selection: dict[str, Any] = {}
    if tuning is not None and validation is not None:
        vrows = validation.to_json()["rows"]
        vsum = validation.summary()
        for c in tuning.candidates:
            pos_ratio, spd_ratio = _bound_ratios(vrows, c.label)
            candidates.append(
                {
                    "family": c.family,
                    "label": c.label,
                    "parameters": c.parameters,
                    "training_criterion": c.training_criterion,
                    "validation_criterion": c.validation_criterion,
                    "worst_ratio": c.worst_ratio,
                    "worst_case": c.worst_case,
                    "position_rms_m": vsum[c.label]["position_rms_m"],
                    "speed_rms_kmh": vsum[c.label]["speed_rms_kmh"],
                    "pcrlb_position_ratio": pos_ratio,
                    "pcrlb_speed_ratio": spd_ratio,
                    "meets": c.meets_requirement,
                    "deployed": c.family == tuning.deployed,
                }
            )
        selection = {
            "criterion": CRITERION_TEXT[tuning.criterion],
            "reason": tuning.reason,
            "training_runs": tuning.training_runs,
            "validation_runs": tuning.validation_runs,
        }
    data = test.to_json()
    return ReportData(
        f"Level-crossing compliance report: {site.name}",
        site.name,
        site.description,
        __version__,
        test.seed,
        test.runs,
        test.confidence,
        site.zone_m,
        data["rows"],
        data["summary"],
        test.gain_pct,
        roads,
        radars,
        blind,
        [list(x) for x in site.skipped_pairs()],
        samples,
        deployed,
        selection,
        candidates,
        dict(tuning.m1_profile) if tuning is not None else {},
        mixed_traffic,
        mixed_traffic_note,
        site_marks(site),
    )


def _map_div(data: ReportData) -> str:
    reach = max(float(np.hypot(*np.asarray(p).T).max()) for p in data.roads.values())
    tracks = []
    for s in data.samples:
        tracks += [
            (f"truth ({s.label})", s.truth_xy, "green"),
            (f"free 2-D EKF ({s.label})", s.free_xy, "salmon"),
            (f"deployed ({s.label})", s.road_xy, "blue"),
        ]
    return site_map_div(data.roads, data.radars, data.blind, data.marks, tracks, reach)


def _rms_figure(data: ReportData, name: str) -> str:
    plt = pyplot()
    rows = [r for r in data.rows if r["filter"] == name]
    labels = [f"{r['vehicle_class']} / {r['case']}" for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, max(3, 0.2 * len(rows))))
    y = np.arange(len(rows))
    for ax, key, limit, color, label in (
        (axes[0], "position", POSITION_LIMIT_M, "tab:blue", "position RMS [m] (limit 0.7)"),
        (axes[1], "speed", SPEED_LIMIT_KMH, "tab:orange", "speed RMS [km/h] (limit 2)"),
    ):
        unit = "m" if key == "position" else "kmh"
        rms = np.array([r[f"{key}_rms_{unit}"] for r in rows], dtype=float)
        upper = np.array([r[f"{key}_upper_{unit}"] for r in rows], dtype=float)
        ax.barh(y, np.nan_to_num(rms), color=color)
        ax.errorbar(
            np.nan_to_num(rms), y, xerr=[np.zeros(y.size), np.nan_to_num(upper - rms)],
            fmt="none", ecolor="k", lw=0.7, capsize=1.5,
        )  # fmt: skip
        ax.axvline(limit, color="k", ls="--")
        ax.set_xlabel(label)
        ax.set_yticks(y, labels if key == "position" else [""] * len(rows), fontsize=6)
    fig.suptitle(
        f"{name}: RMS per class and case with the {100 * data.confidence:.0f} % upper bound"
    )
    fig.tight_layout()
    return svg_of(fig)


def _profile_figure(data: ReportData) -> str:
    plt = pyplot()
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
    return svg_of(fig)


def _num(v: float, fmt: str) -> str:
    return "" if not math.isfinite(v) else format(v, fmt)


CSS = """body{font-family:sans-serif;margin:2em;max-width:1150px}table{border-collapse:collapse;
font-size:12px}td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}th{background:#eee}
td.l{text-align:left}.pass{background:#d9f2d9}.fail{background:#f7d4d4}
.undecided{background:#fbeec2}.win{font-weight:bold}figure{margin:1em 0}
.banner{color:#fff;padding:14px 18px;border-radius:6px;margin:1em 0;font-size:15px}
.banner .big{font-size:26px;font-weight:bold}td.m{text-align:center;min-width:70px}
td.na{color:#999;text-align:center}"""


BANNER = {
    "pass": ("#1e7b34", "COMPLIES"),
    "fail": ("#a61b1b", "DOES NOT COMPLY"),
    "undecided": ("#9a6b00", "UNDECIDED"),
}


def _banner(data: ReportData) -> str:
    """Say the answer first: does the site comply, with which estimator, how sure."""
    e = html.escape
    name = data.deployed or next(iter(data.summary), "")
    w = data.summary.get(name)
    if w is None:
        return "<div id='banner' class='banner'>No estimator was evaluated.</div>"
    colour, said = BANNER[w["verdict"]]
    n = w["pass"] + w["fail"] + w["undecided"]
    conf = f"{100 * data.confidence:.0f} %"
    detail = (
        f"all {n} class x case pairs meet {POSITION_LIMIT_M} m / {SPEED_LIMIT_KMH} km/h at "
        f"{conf} confidence"
        if w["verdict"] == "pass"
        else f"{w['pass']} of {n} class x case pairs pass, {w['fail']} fail, "
        f"{w['undecided']} undecided at {conf} confidence"
    )
    return (
        f"<div id='banner' class='banner' style='background:{colour}'><div class='big'>"
        f"{e(data.site)}: {said}</div><div>with {e(name)}{' (deployed)' if data.deployed else ''}"
        f": {detail}. Worst position RMS {w['position_rms_m']:.2f} m (bound "
        f"{w['position_upper_m']:.2f} m), worst speed RMS {_num(w['speed_rms_kmh'], '.2f')} "
        f"km/h (bound {_num(w['speed_upper_kmh'], '.2f')} km/h); {data.runs} test runs per "
        "pair that neither tuning nor selection has seen.</div></div>"
    )


def _margin_colour(verdict: str, upper_ratio: float) -> str:
    """Cell colour: green, paler as the margin to the requirement shrinks; amber; red."""
    if verdict == "fail":
        return "#f2b8b8"
    if verdict == "undecided":
        return "#fbe3a6"
    margin = min(max(1.0 - upper_ratio, 0.0), 1.0)  # 0: at the limit, 1: perfect
    light = 88 - 38 * margin  # lightness [%]
    return f"hsl(130, 55%, {light:.0f}%)"


def _matrix(data: ReportData) -> list[str]:
    """Case x class matrix of the deployed estimator: RMS / limit with its interval."""
    e = html.escape
    name = data.deployed or next(iter(data.summary), "")
    mine = [r for r in data.rows if r["filter"] == name]
    if not mine:
        return []
    classes = list(dict.fromkeys(r["vehicle_class"] for r in mine))
    cases = list(dict.fromkeys(r["case"] for r in mine))
    cell = {(r["vehicle_class"], r["case"]): r for r in mine}
    conf = f"{100 * data.confidence:.0f} %"
    parts = [
        f"<h2 id='matrix'>Class x case: {e(name)}</h2><p>Each cell: the worse of position "
        f"RMS / {POSITION_LIMIT_M} m and speed RMS / {SPEED_LIMIT_KMH} km/h (1 is the "
        f"requirement), with its {conf} Monte-Carlo interval; green is darker the larger the "
        "margin to the requirement at the upper bound, amber undecided, red failed. Hover a "
        "cell for the figures.</p><table id='matrix-table'><tr><th>case \\ class</th>"
        + "".join(f"<th>{e(v)}</th>" for v in classes)
        + "</tr>"
    ]
    for c in cases:
        parts.append(f"<tr><th class='l'>{e(c)}</th>")
        for v in classes:
            r = cell.get((v, c))
            if r is None:
                parts.append("<td class='na' title='the class cannot drive this case'>-</td>")
                continue
            ratio = requirement_ratio(r["position_rms_m"], r["speed_rms_kmh"],
                                      r["speed_rel_rms_pct"])  # fmt: skip
            lo = requirement_ratio(r["position_lower_m"], r["speed_lower_kmh"],
                                   r["speed_rel_lower_pct"])  # fmt: skip
            hi = requirement_ratio(r["position_upper_m"], r["speed_upper_kmh"],
                                   r["speed_rel_upper_pct"])  # fmt: skip
            tip = (
                f"position RMS {r['position_rms_m']:.3f} m ({conf}: "
                f"{_num(r['position_lower_m'], '.3f')}-{_num(r['position_upper_m'], '.3f')}); "
                f"speed RMS {_num(r['speed_rms_kmh'], '.3f')} km/h ({conf}: "
                f"{_num(r['speed_lower_kmh'], '.3f')}-{_num(r['speed_upper_kmh'], '.3f')}); "
                f"{r['n_runs']} runs; {r['verdict']}"
            )
            parts.append(
                f"<td class='m' style='background:{_margin_colour(r['verdict'], hi)}' "
                f"title='{e(tip)}'><b>{_num(ratio, '.2f')}</b> "
                f"<small>({_num(lo, '.2f')}-{_num(hi, '.2f')})</small></td>"
            )
        parts.append("</tr>")
    parts.append("</table>")
    return parts


def _verdict_table(data: ReportData) -> list[str]:
    e = html.escape
    conf = f"{100 * data.confidence:.0f} %"
    parts = [
        f"<h2 id='verdict'>Verdict on the test runs</h2><p>{data.runs} runs per class and "
        f"case ({RANDOM_RUNS_FACTOR} times as many for random approaches) that neither tuning "
        f"nor selection has seen. A row passes when the {conf} upper bounds of its RMS are "
        "within the limits, fails when a lower bound is beyond them, and is undecided "
        "otherwise; an undecided row of the deployed estimator is decided by a confirmation "
        f"Monte Carlo with {CONFIRMATION_FACTOR} times the runs on fresh seeds (marked "
        "'confirmed' in the table).</p><table id='worst'><tr><th>estimator</th>"
        f"<th>worst position RMS [m]</th><th>({conf} bound)</th><th>worst speed RMS [km/h]</th>"
        f"<th>({conf} bound)</th><th>criterion</th><th>worst case</th><th>pass / fail / "
        "undecided</th><th>verdict</th></tr>"
    ]
    for name, w in data.summary.items():
        label = e(name) + (" (deployed)" if name == data.deployed else "")
        parts.append(
            f"<tr class='{w['verdict']}'><td class='l'>{label}</td>"
            f"<td>{w['position_rms_m']:.3f}</td><td>{w['position_upper_m']:.3f}</td>"
            f"<td>{_num(w['speed_rms_kmh'], '.3f')}</td><td>{_num(w['speed_upper_kmh'], '.3f')}"
            f"</td><td>{w['criterion']:.3f}</td><td class='l'>{e(w['worst_case'])}</td>"
            f"<td>{w['pass']} / {w['fail']} / {w['undecided']}</td><td>{w['verdict']}</td></tr>"
        )
    parts.append("</table>")
    if data.gain_pct:
        parts.append(
            "<p>Pooled gain over the rectilinear (CV) road model: "
            + "; ".join(
                f"{e(k)}: position {v['position']:+.1f} %, speed {v['speed']:+.1f} %"
                for k, v in data.gain_pct.items()
            )
            + " (seed 001 claims +3 % / +9 %).</p>"
        )
    return parts


def _selection_table(data: ReportData) -> list[str]:
    e = html.escape
    sel = data.selection
    parts = [
        "<h2 id='selection'>Design-time selection</h2>",
        f"<p>Every candidate was tuned on {sel['training_runs']} training runs and scored on "
        f"{sel['validation_runs']} validation runs per class and case. Criterion: "
        f"{e(sel['criterion'])}; a ratio is an RMS divided by its limit (0.7 m, 2 km/h, 2 % "
        f"above 100 km/h). <b>{e(sel['reason'])}</b></p>",
        "<table id='candidates'><tr><th>candidate</th><th>parameters</th>"
        "<th>training criterion</th><th>validation criterion</th><th>worst ratio</th>"
        "<th>worst case</th><th>worst position RMS [m]</th><th>worst speed RMS [km/h]</th>"
        "<th>RMS / PCRLB position</th><th>RMS / PCRLB speed</th><th>meets</th></tr>",
    ]
    for c in data.candidates:
        params = ", ".join(f"{e(k)} = {v:.4g}" for k, v in c["parameters"].items())
        cls = ("win " if c["deployed"] else "") + ("pass" if c["meets"] else "fail")
        parts.append(
            f"<tr class='{cls}'><td class='l'>{e(c['label'])}"
            f"{' (deployed)' if c['deployed'] else ''}</td><td class='l'>{params}</td>"
            f"<td>{_num(c['training_criterion'], '.3f')}</td>"
            f"<td>{_num(c['validation_criterion'], '.3f')}</td>"
            f"<td>{_num(c['worst_ratio'], '.3f')}</td><td class='l'>{e(c['worst_case'])}</td>"
            f"<td>{_num(c['position_rms_m'], '.3f')}</td><td>{_num(c['speed_rms_kmh'], '.3f')}"
            f"</td><td>{_num(c['pcrlb_position_ratio'], '.2f')}</td>"
            f"<td>{_num(c['pcrlb_speed_ratio'], '.2f')}</td>"
            f"<td>{'yes' if c['meets'] else 'NO'}</td></tr>"
        )
    parts.append(
        "</table><p>RMS / PCRLB: pooled RMS over every class and case divided by the pooled "
        "road-aligned posterior Cramer-Rao bound of a constant-acceleration target (jerk PSD "
        "3 m^2/s^5) with this radar and scatter, on the same validation runs. The test "
        "trajectories are deterministic, so a filter can beat it (ratio &lt; 1).</p>"
    )
    return parts


def render_html(data: ReportData) -> str:
    """Render the report as one self-contained HTML document."""
    e = html.escape
    parts = [
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(data.title)}"
        f"</title><style>{CSS}</style>{plotly_script()}</head><body>",
        f"<h1>{e(data.title)}</h1>",
        _banner(data),
        f"<p>{e(data.description)}</p>" if data.description else "",
        f"<p>Site <b>{e(data.site)}</b>; seed {data.seed}; adaptrack {e(data.version)}. "
        f"Requirement (seed 001, table 1.1): position RMS &le; {POSITION_LIMIT_M} m, speed RMS "
        f"&le; {SPEED_LIMIT_KMH} km/h for speeds up to 100 km/h (relative speed error &le; 2 % "
        f"above). Scoring: every epoch with the vehicle's front in the controlled zone (0-"
        f"{data.zone_m:g} m from the crossing centre), stopped ones included, from "
        f"{WARM_UP_S:g} s after the track starts; zone epochs without an estimate are counted "
        "as untracked.</p>",
        *_matrix(data),
        *_verdict_table(data),
    ]
    if data.candidates:
        parts += _selection_table(data)
    parts.append("<h2>Site</h2><figure id='map'>" + _map_div(data) + "</figure>")
    parts.append(
        "<p id='blind'>Blind zones (parts of a controlled zone its road's radar does not see): "
        + (", ".join(e(k) for k in data.blind) if data.blind else "none")
        + ".</p>"
    )
    if data.skipped:
        parts.append(
            "<p>Not evaluated (the class cannot drive the case): "
            + "; ".join(f"{e(v)} / {e(c)}: {e(why)}" for c, v, why in data.skipped)
            + ".</p>"
        )
    if data.samples:
        parts.append(
            "<h2>Errors over time (sample runs)</h2><figure id='errors'>"
            + error_plot_div(data.samples, (POSITION_LIMIT_M, SPEED_LIMIT_KMH))
            + "</figure>"
        )
    if data.deployed:
        parts.append(
            "<h2>RMS against the requirement</h2><figure id='rms'>"
            + _rms_figure(data, data.deployed)
            + "</figure>"
        )
    if data.profile:
        parts.append(
            "<h2>Design-time adaptation of M1</h2><figure id='profile'>"
            + _profile_figure(data)
            + "</figure>"
        )
    if data.mixed_traffic is not None:
        parts += mixed_traffic_html(data.mixed_traffic, data.roads, data.radars, data.zone_m)
    elif data.mixed_traffic_note:
        parts.append(
            "<h2 id='mixed'>Mixed traffic</h2><p>No mixed-traffic section: "
            f"{e(data.mixed_traffic_note)}</p>"
        )
    conf = f"{100 * data.confidence:.0f} %"
    parts.append(
        "<h2 id='passfail'>Pass/fail per estimator, class and case</h2>"
        "<table id='passfail-table'><tr><th>estimator</th><th>class</th><th>case</th>"
        f"<th>position RMS [m]</th><th>{conf} bound</th><th>speed RMS [km/h]</th>"
        f"<th>{conf} bound</th><th>rel. speed RMS [%]</th><th>epochs</th>"
        "<th>untracked [%]</th><th>PCRLB pos. [m]</th><th>ratio</th><th>PCRLB speed [km/h]</th>"
        "<th>ratio</th><th>verdict</th></tr>"
    )
    for r in data.rows:
        bound_p, bound_s = r["pcrlb_position_m"], r["pcrlb_speed_kmh"]
        cells = [
            f"{r['position_rms_m']:.3f}",
            _num(r["position_upper_m"], ".3f"),
            _num(r["speed_rms_kmh"], ".3f"),
            _num(r["speed_upper_kmh"], ".3f"),
            _num(r["speed_rel_rms_pct"], ".2f"),
            str(r["n_epochs"]),
            _num(r["untracked_pct"], ".1f"),
            _num(bound_p, ".3f"),
            _num(r["position_rms_m"] / bound_p, ".2f"),
            _num(bound_s, ".3f"),
            _num(r["speed_rms_kmh"] / bound_s, ".2f"),
        ]
        parts.append(
            f"<tr class='{r['verdict']}'><td class='l'>{e(r['filter'])}</td><td class='l'>"
            f"{e(r['vehicle_class'])}</td><td class='l'>{e(r['case'])}</td>"
            + "".join(f"<td>{c}</td>" for c in cells)
            + f"<td>{r['verdict']}{' (confirmed)' if r['confirmation'] else ''}</td></tr>"
        )
    parts.append("</table></body></html>")
    return "".join(parts)


__all__ = ["ReportData", "SampleTrack", "build_report", "render_html", "sample_tracks"]
