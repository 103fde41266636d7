"""Commands of the level-crossing application: demo, report, simulate, tune, track."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.console import Console
from rich.table import Table

from .._progress import announce_compilation, progress
from ..crossing.measurements_io import (
    WARNING_COLUMNS,
    detections_frame,
    read_detections,
    read_scene_detections,
    read_warnings,
)
from ..crossing.scene.background import BackgroundMap
from ..crossing.scene.extended_tracker import track_scene_extended
from ..crossing.scene.tracker import load_scene_config, track_scene
from ..crossing.simulation.faces import RADAR_KINDS, FaceRadar, face_returns_of
from ..crossing.simulation.motion import MotionTransform, read_motion, simulate_replay
from ..crossing.simulation.object_list import object_list_ids
from ..crossing.simulation.radar import simulate_site_case
from ..crossing.simulation.scene import SceneRecording, scene_spec, simulate_scene
from ..crossing.site.model import Site, load_site, site_from_mapping
from ..crossing.studies.compliance import (
    POSITION_LIMIT_M,
    SPEED_LIMIT_KMH,
    ComplianceResult,
    confirm_undecided,
    default_trackers,
    evaluate_site,
)
from ..crossing.studies.families import FAMILIES
from ..crossing.studies.mixed_traffic import MixedTraffic, mixed_traffic_study
from ..crossing.studies.report import build_report, render_html, sample_tracks
from ..crossing.studies.scene_metrics import HAZARD_COLUMNS, TRUTH_COLUMNS
from ..crossing.studies.selection import (
    CRITERIA,
    CRITERION_TEXT,
    SiteTuning,
    load_tuning,
    select_estimator,
    site_for,
)
from ..crossing.studies.trackers import RoadTracker, Tracker, track_objects
from ..io.tables import (
    read_table,
    write_table_atomic,
    write_text_atomic,
)
from ..models.continuous import ConstantAcceleration
from .errors import check_outputs as _outputs
from .errors import fail as _fail
from .options import SCHEDULER, WORKERS, number_pair, worker_pool, write_json

CRITERION = typer.Option(
    "tail",
    "--criterion",
    help="Selection criterion: tail (mean ratio of the worst 10 % of class x case pairs), "
    "worst, pooled_position (the seed's J_pos) or pooled_requirement (J_req).",
)


TRAINING_RUNS = typer.Option(3, "--training-runs", min=1, help="Tuning runs per class x case.")


VALIDATION_RUNS = typer.Option(
    20, "--validation-runs", min=2, help="Validation runs per class x case (model choice)."
)


FAMILY_KEYS = typer.Option(
    ",".join(FAMILIES), "--families", help="Comma-separated candidate families."
)


MAX_SCENE_S = 7 * 86400.0  # `simulate --scene --duration`: a week of detections at most


VERDICT_EXIT = {"pass": 0, "fail": 4, "undecided": 5}  # the demo's exit status by verdict


DEMO_COMPILE_TIME = "3 min"  # measured: a fresh clone's demo (4.8 min) less a cached run (1.7)


TRACK_COMPILE_TIME = "1.5 min"  # the scene tracker's compiled loop and kernels (93 s, then 0.3 s)
EXTENDED_COMPILE_TIME = "1 min"  # the extended tracker's compiled loop (69 s, then 0.6 s)


def demo(
    runs: int = typer.Option(
        10, "--runs", min=2, help="Test runs per class and case (the compliance verdict)."
    ),
    seed: int = typer.Option(0, "--seed", min=0, help="Random seed."),
    out: Path = typer.Option(
        Path("out"), "--out", help="Directory for summary.json, tuned.toml and report.html."
    ),
    site: str = typer.Option("lx_default", "--site", help="Built-in site name or a .toml."),
    training_runs: int = TRAINING_RUNS,
    validation_runs: int = VALIDATION_RUNS,
    criterion: str = CRITERION,
    families: str = FAMILY_KEYS,
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    scene_seconds: float = typer.Option(
        600.0,
        "--scene-seconds",
        min=0.0,
        help="Length of the report's mixed-traffic scene [s] (0: no such section).",
    ),
) -> None:
    """Level-crossing demo: adapt the estimator to a site, then prove compliance on new runs.

    Every candidate family is tuned on training runs and scored on validation runs; the best
    is deployed and checked, with the references, on test runs that neither step has seen.
    Then the site's mixed traffic (many objects, raw detections, a vehicle stalled on the
    crossing) is tracked by the scene tracker and scored against its truth.
    """
    _outputs(folder=out)
    st = _load_site(site)
    criterion = _criterion(criterion)
    keys = _families(families)
    announce_compilation(DEMO_COMPILE_TIME)
    console = Console()
    test_seed = int(np.random.SeedSequence([seed, 13]).generate_state(1)[0])
    n_pairs = len(st.pairs())
    with (
        worker_pool(workers, scheduler) as pool,
        progress(console, "demo", total=len(keys) + 2 * n_pairs) as bar,
    ):
        step = bar.advance
        tuning, validation = select_estimator(
            st,
            seed=seed,
            training_runs=training_runs,
            validation_runs=validation_runs,
            criterion=criterion,  # type: ignore[arg-type]
            families=keys,
            pool=pool,
            progress=step,
        )
        winner = tuning.winner
        trackers: dict[str, Tracker] = {winner.label: winner.tracker()}
        baseline = next((c for c in tuning.candidates if c.family == "cv"), winner)
        if baseline is not winner:
            trackers[baseline.label] = baseline.tracker()
        trackers.update({k: v for k, v in default_trackers().items() if not k.startswith("road")})
        test = evaluate_site(
            st, runs, test_seed, trackers=trackers, pool=pool, progress=step,
            baseline=baseline.label,
        )  # fmt: skip
        test = confirm_undecided(
            test, st, {winner.label: trackers[winner.label]}, pool=pool, progress=step
        )
    test = dataclasses.replace(test, seed=seed)
    mixed, mixed_note = _mixed_traffic(st, seed, scene_seconds, console)
    console.print(_candidates_table(tuning))
    console.print(f"deployed: {tuning.reason}")
    console.print(_verdict_table(test, winner.label))
    for name, g in test.gain_pct.items():
        console.print(
            f"{name} vs {baseline.label}: position {g['position']:+.1f} %, speed "
            f"{g['speed']:+.1f} %"
        )
    summary = {
        "site": st.source,
        "seed": seed,
        "deployed": winner.label,
        "selection": tuning.to_json(),
        "validation": validation.to_json(),
        "test": test.to_json(),
        "mixed_traffic": mixed.to_json() if mixed is not None else {"skipped": mixed_note},
    }
    if mixed is not None:
        console.print(_mixed_traffic_table(mixed))
    write_json(out / "summary.json", summary)
    write_text_atomic(out / "tuned.toml", tuning.to_toml())
    report_data = build_report(
        test,
        st,
        samples=sample_tracks(st, seed, winner.tracker()),
        deployed=winner.label,
        tuning=tuning,
        validation=validation,
        mixed_traffic=mixed,
        mixed_traffic_note=mixed_note,
    )
    write_text_atomic(out / "report.html", render_html(report_data))
    console.print(
        f"wrote {out / 'summary.json'}, {out / 'tuned.toml'} and {out / 'report.html'} "
        f"(test Monte Carlo {test.elapsed_s:.1f} s)"
    )
    verdict, line = _site_verdict(st, test, winner.label)
    console.print(line, markup=False, highlight=False)
    raise typer.Exit(VERDICT_EXIT[verdict])


def _site_verdict(st: Site, test: ComplianceResult, deployed: str) -> tuple[str, str]:
    """Return the site's verdict with its deployed estimator, and the sentence saying it."""
    s = test.summary()[deployed]
    n = s["pass"] + s["fail"] + s["undecided"]
    at = f"at {100 * test.confidence:.0f} % confidence"
    if s["verdict"] == "pass":
        return "pass", (
            f"VERDICT: {st.name} complies with {deployed}: all {n} class x case pairs meet "
            f"{POSITION_LIMIT_M:g} m / {SPEED_LIMIT_KMH:g} km/h {at}"
        )
    if s["verdict"] == "fail":
        return "fail", (
            f"VERDICT: {st.name} does NOT comply with {deployed}: {s['fail']} of {n} class x "
            f"case pairs fail {at} (worst {s['worst_case']}); exit status 4"
        )
    return "undecided", (
        f"VERDICT: {st.name} undecided with {deployed}: {s['undecided']} of {n} class x case "
        f"pairs undecided after the confirmation runs, none failing; more --runs decide "
        "them; exit status 5"
    )


def _mixed_traffic(
    st: Site, seed: int, duration_s: float, console: Console
) -> tuple[MixedTraffic | None, str]:
    """Return the demo's scored mixed-traffic scene, or None and why there is none."""
    if duration_s <= 0:
        return None, "not requested (--scene-seconds 0)"
    scene_seed = int(np.random.SeedSequence([seed, 17]).generate_state(1)[0])
    with progress(console, "mixed traffic (scans)") as bar:

        def on_scan(done: int, total: int) -> None:
            if done % 500 == 0 or done == total:
                bar.set(done, total)

        try:
            return mixed_traffic_study(st, scene_seed, duration_s, on_scan=on_scan), ""
        except ValueError as exc:  # a site without a scene (no flow between two roads)
            return None, str(exc)


def _mixed_traffic_table(m: MixedTraffic) -> Table:
    table = Table(
        title=f"mixed traffic, {m.duration_s:g} s: GOSPA {m.gospa_mean:.2f} m, "
        f"{m.id_switches} id switches, hazard delays "
        f"{[round(h['delay_s'], 2) for h in m.hazards]} s, "
        f"{len(m.false_stop_times_s)} false 'stopped' events"
    )
    for col in ("class", "vehicles", "position RMS [m]", "speed RMS [km/h]", "verdict"):
        table.add_column(col)
    for c in m.classes:
        table.add_row(
            str(c["class"]), str(c["vehicles"]), f"{c['position_rms_m']:.3f}",
            f"{c['speed_rms_kmh']:.3f}", str(c["verdict"]),
        )  # fmt: skip
    return table


def _load_site(site: str) -> Site:
    try:
        return load_site(site)
    except ValueError as exc:
        _fail(str(exc))


def _families(text: str) -> tuple[str, ...]:
    keys = tuple(f.strip() for f in text.split(",") if f.strip())
    unknown = [k for k in keys if k not in FAMILIES]
    if unknown or not keys:
        raise typer.BadParameter(f"--families: unknown {unknown}; known: {', '.join(FAMILIES)}")
    return keys


def _criterion(text: str) -> str:
    if text not in CRITERIA:
        raise typer.BadParameter(f"--criterion must be one of {', '.join(CRITERIA)}")
    return text


def _candidates_table(tuning: SiteTuning) -> Table:
    table = Table(
        title=f"{tuning.site}: candidates on {tuning.validation_runs} validation runs per class "
        f"and case (criterion: {CRITERION_TEXT[tuning.criterion]})"
    )
    for col in ("candidate", "parameters", "training", "validation", "worst ratio", "worst case"):
        table.add_column(col, justify="left" if col in ("candidate", "parameters") else "right")
    for c in sorted(tuning.candidates, key=lambda c: c.validation_criterion):
        mark = " *" if c.family == tuning.deployed else ""
        table.add_row(
            c.label + mark,
            ", ".join(f"{k}={v:.3g}" for k, v in c.parameters.items()),
            f"{c.training_criterion:.3f}",
            f"{c.validation_criterion:.3f}",
            f"{c.worst_ratio:.3f}",
            c.worst_case,
        )
    return table


def _verdict_table(test: ComplianceResult, deployed: str) -> Table:
    conf = f"{100 * test.confidence:.0f} %"
    table = Table(
        title=f"{test.site}: verdict on {test.runs} test runs per class and case, seed "
        f"{test.seed} (requirement 0.7 m, 2 km/h; pass when the {conf} upper bounds are within)"
    )
    for col in (
        "estimator",
        "position RMS [m]",
        f"{conf} bound",
        "speed RMS [km/h]",
        f"{conf} bound",
        "pass/fail/undecided",
        "verdict",
    ):
        table.add_column(col, justify="left" if col == "estimator" else "right")
    for name, w in test.summary().items():
        table.add_row(
            name + (" (deployed)" if name == deployed else ""),
            f"{w['position_rms_m']:.3f}",
            f"{w['position_upper_m']:.3f}",
            f"{w['speed_rms_kmh']:.3f}",
            f"{w['speed_upper_kmh']:.3f}",
            f"{w['pass']}/{w['fail']}/{w['undecided']}",
            w["verdict"],
        )
    return table


def report(
    summary: Path = typer.Argument(..., help="summary.json written by 'adaptrack demo'."),
    out: Path = typer.Option(..., "--out", help="Output HTML file."),
) -> None:
    """Render the HTML compliance report of a demo summary (sample tracks re-simulated).

    The summary carries the site it was computed for, so any site works, built-in or a file.
    """
    _outputs(out)
    try:
        data = json.loads(summary.read_text())
        st = site_from_mapping(data["site"], f"{summary}: site")
        test = ComplianceResult.from_json(data["test"])
        tuning = SiteTuning.from_json(data["selection"])
        validation = ComplianceResult.from_json(data["validation"])
        seed = int(data["seed"])
        scene = data.get("mixed_traffic", {"skipped": "the summary has no mixed-traffic scene"})
        mixed = None if "skipped" in scene else MixedTraffic.from_json(scene)
        mixed_note = str(scene.get("skipped", ""))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        _fail(f"{summary}: not a demo summary ({exc})")
    report_data = build_report(
        test,
        st,
        samples=sample_tracks(st, seed, tuning.tracker()),
        deployed=str(data["deployed"]),
        tuning=tuning,
        validation=validation,
        mixed_traffic=mixed,
        mixed_traffic_note=mixed_note,
    )
    write_text_atomic(out, render_html(report_data))
    Console().print(f"wrote {out}")


def simulate(
    site: str = typer.Argument("lx_default", help="Built-in site name or a site .toml."),
    out: Path = typer.Option(..., "--out", help="Detections table (CSV or Parquet)."),
    truth: Path | None = typer.Option(None, "--truth", help="Also write the true kinematics."),
    runs: int = typer.Option(1, "--runs", min=1, help="Vehicles per class and case."),
    seed: int = typer.Option(0, "--seed", min=0, help="Random seed."),
    scene: bool = typer.Option(
        False, "--scene", help="Mixed traffic of the site's [scene]: detections without ids."
    ),
    duration: float | None = typer.Option(
        None,
        "--duration",
        min=1.0,
        max=MAX_SCENE_S,
        help="Scene length [s] (default: the site's; at most a week).",
    ),
    warnings: Path | None = typer.Option(
        None, "--warnings", help="Scene: also write when the lights flash or barriers are down."
    ),
    motion: Path | None = typer.Option(
        None,
        "--motion",
        help="Replay recorded motion (INTERACTION or generic layout) instead of the traffic model.",
    ),
    radar_kind: str | None = typer.Option(
        None,
        "--radar-kind",
        help="Reflections: 'object', 'cluster' or 'cloud' (the face model), or 'symmetric' "
        "(the scene's points about the body centre; the default of --scene). --motion: "
        "default 'cluster'.",
    ),
    origin: str | None = typer.Option(
        None, "--origin", help="--motion: X,Y [m] of the file that is the crossing centre."
    ),
    rotation: float = typer.Option(
        0.0, "--rotation", help="--motion: turn the file's axes this much counter-clockwise [deg]."
    ),
    geodetic_origin: str | None = typer.Option(
        None, "--geodetic-origin", help="--motion: LAT,LON [deg] of the crossing centre."
    ),
    start: float | None = typer.Option(
        None, "--start", help="--motion: replay from this time of the file [s]."
    ),
) -> None:
    """Simulate radar detections of traffic at a site.

    Without ``--scene``: one vehicle at a time per class and case, as a radar object list with
    ``object_id``. With ``--scene``: the site's mixed traffic (flows, closures, clutter), as
    raw detections without identities; ``--truth`` then holds every road user per traffic step.
    With ``--motion``: the road users of a recorded trajectory file, put onto the site by
    ``--origin``/``--rotation`` (or ``--geodetic-origin``), seen by the site's radars through
    the face model; ``--truth`` as for a scene.
    """
    _outputs(out, truth, warnings)
    st = _load_site(site)
    kinds = ("symmetric", *RADAR_KINDS)
    if radar_kind is not None and radar_kind not in kinds:
        _fail(f"--radar-kind must be one of {', '.join(kinds)}; got {radar_kind!r}")
    if radar_kind is not None and not (scene or motion):
        _fail("--radar-kind applies to --scene or --motion")
    if motion is not None:
        if scene:
            _fail("--motion replaces the traffic model of --scene: give one of them")
        kind = radar_kind or "cluster"
        try:
            transform = MotionTransform(
                number_pair(origin, "--origin") if origin else (0.0, 0.0),
                rotation,
                number_pair(geodetic_origin, "--geodetic-origin") if geodetic_origin else None,
            )
            recorded = read_motion(motion, transform)
            rec = simulate_replay(
                st, recorded, seed, None if kind == "symmetric" else FaceRadar.of_kind(kind),
                start_s=start, duration_s=duration,
            )  # fmt: skip
        except ValueError as exc:
            _fail(str(exc))
        _write_recording(rec, out, truth, kind, seed)
        Console().print(
            f"wrote {out} ({len(rec.detections)} detections, {kind}, of "
            f"{len(rec.truth.users)} recorded road users over {rec.spec.duration_s:g} s)"
        )
        return
    if scene:
        try:
            spec = scene_spec(st, **({} if duration is None else {"duration_s": duration}))
        except ValueError as exc:
            _fail(str(exc))
        kind = radar_kind or "symmetric"
        if kind == "symmetric":
            rec = simulate_scene(st, spec, seed)
        else:
            rec = simulate_scene(st, spec, seed, face_returns_of(FaceRadar.of_kind(kind)))
        _write_recording(rec, out, truth, kind, seed)
        if warnings is not None:
            write_table_atomic(pd.DataFrame(spec.warnings(), columns=WARNING_COLUMNS), warnings)
        Console().print(
            f"wrote {out} ({len(rec.detections)} detections of {len(rec.truth.users)} road "
            f"users over {spec.duration_s:g} s)"
        )
        return
    pairs = st.pairs()
    seeds = np.random.SeedSequence(seed).spawn(len(pairs))
    frames, truths = [], []
    next_id, clock = 1, 0.0
    for (case, veh), ss in zip(pairs, seeds, strict=True):
        radar = st.radar_for(case.road)
        sim = simulate_site_case(st, case, veh, n_runs=runs, rng=np.random.default_rng(ss))
        offsets = clock + np.zeros(runs)
        det, tru = detections_frame(sim, radar.name, next_id, offsets)
        det.insert(1, "vehicle_class", veh.name)
        det.insert(2, "case", case.name)
        frames.append(det)
        truths.append(tru)
        next_id += runs
        clock += float(sim.true_times.max()) + 10.0
    write_table_atomic(pd.concat(frames, ignore_index=True), out)
    if truth is not None:
        write_table_atomic(pd.concat(truths, ignore_index=True), truth)
    Console().print(f"wrote {out} ({next_id - 1} objects)")


def _write_recording(
    rec: SceneRecording, out: Path, truth: Path | None, kind: str, seed: int
) -> None:
    """Write detections (an object list with the sensor's ids) and the truth of a scene."""
    det = rec.detections
    if kind == "object":
        det = det.assign(object_id=object_list_ids(rec, seed))
    write_table_atomic(det, out)
    if truth is not None:
        write_table_atomic(rec.truth.table[TRUTH_COLUMNS + HAZARD_COLUMNS], truth)


def tune(
    site: str = typer.Argument("lx_default", help="Built-in site name or a site .toml."),
    out: Path = typer.Option(..., "--out", help="Tuned configuration (TOML)."),
    seed: int = typer.Option(
        0, "--seed", min=0, help="Random seed of the training and validation runs."
    ),
    training_runs: int = TRAINING_RUNS,
    validation_runs: int = VALIDATION_RUNS,
    criterion: str = CRITERION,
    families: str = FAMILY_KEYS,
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
) -> None:
    """Adapt the road estimator to a site: tune every family, choose on validation runs."""
    _outputs(out)
    st = _load_site(site)
    criterion = _criterion(criterion)
    keys = _families(families)
    announce_compilation(DEMO_COMPILE_TIME)
    console = Console()
    with (
        worker_pool(workers, scheduler) as pool,
        progress(console, "tuning", total=len(keys) + len(st.pairs())) as bar,
    ):
        tuning, _ = select_estimator(
            st,
            seed=seed,
            training_runs=training_runs,
            validation_runs=validation_runs,
            criterion=criterion,  # type: ignore[arg-type]
            families=keys,
            pool=pool,
            progress=bar.advance,
        )
    write_text_atomic(out, tuning.to_toml())
    console.print(_candidates_table(tuning))
    console.print(f"deployed: {tuning.reason} Wrote {out}")


def track(
    measurements: Path = typer.Argument(..., help="Detections table (CSV or Parquet)."),
    site: str | None = typer.Option(
        None,
        "--site",
        help="Built-in site name or a .toml (default: the site a tuned --config records).",
    ),
    out: Path = typer.Option(..., "--out", help="Estimates table (CSV or Parquet)."),
    config: Path | None = typer.Option(
        None,
        "--config",
        help="Tuned configuration from 'adaptrack tune' or 'demo' (refused for another site), "
        "or a TOML with a [scene_tracker] table.",
    ),
    events: Path | None = typer.Option(
        None, "--events", help="Hazard events of raw detections (default: next to --out)."
    ),
    warnings: Path | None = typer.Option(
        None,
        "--warnings",
        help="The crossing's warning intervals (start_s, end_s), for the "
        "'will not stop before the stop line' prediction (scene tracker).",
    ),
    ids: str = typer.Option(
        "hint",
        "--ids",
        help="An object list's object_id: 'hint' (the scene tracker, ids as association "
        "hints) or 'truth' (one track per id with the site's road estimator).",
    ),
    tracker: str = typer.Option(
        "corridor",
        "--tracker",
        help="Scene tracker: 'corridor' (along the site's corridors, compiled) or 'extended' "
        "(free 2-D motion, box extents, existence probabilities; compiled).",
    ),
    background: Path | None = typer.Option(
        None,
        "--background",
        help="The empty site's background map of 'adaptrack site background' (extended "
        "tracker): stationary detections on its reflectors are the background's.",
    ),
    trains: Path | None = typer.Option(
        None,
        "--trains",
        help="When the controller has a train due (start_s, end_s; extended tracker): the "
        "train on the rails does not make the crossing 'not clear'.",
    ),
) -> None:
    """Track radar detections at a site; write the estimates.

    The many-object scene tracker (its settings from the ``[scene_tracker]`` table of
    ``--config``, if any) takes raw detections, and an object list's ``object_id`` column as
    association hints, not truth (``--ids hint``): the confirmed tracks go to ``--out`` (status
    tentative: one that has not moved yet on another track's body, a likely duplicate) and
    hazard events to ``--events`` (with ``--warnings``, also the
    predicted "will not stop before the stop line"). With ``--ids truth`` every object id is
    one track of the site's road estimator, the deployed one of ``--config`` (the road EKF with
    constant acceleration without it); the reflection-point scatter follows the
    ``vehicle_class`` column (a car when absent).
    The site is needed: ``--site``, or the one a tuned ``--config`` was tuned for.
    """
    _outputs(out, events)
    try:
        st = site_for(site, config)
    except ValueError as exc:
        _fail(str(exc))
    if ids not in ("hint", "truth"):
        _fail(f"--ids must be 'hint' or 'truth'; got {ids!r}")
    if tracker not in ("corridor", "extended"):
        _fail(f"--tracker must be 'corridor' or 'extended'; got {tracker!r}")
    if tracker == "extended":
        if ids != "hint" or warnings is not None or config is not None:
            _fail("--tracker extended takes raw detections only (no --ids truth, --warnings "
                  "or --config)")  # fmt: skip
        _track_extended_file(measurements, st, out, events, background, trains)
        return
    if background is not None or trains is not None:
        _fail("--background and --trains apply to --tracker extended")
    if ids == "hint":
        _track_scene_file(measurements, st, out, events, warnings, config)
        return
    if "object_id" not in read_table(measurements).columns:
        _fail(f"{measurements}: --ids truth needs an object_id column")
    if warnings is not None:
        _fail("--warnings applies to the scene tracker (--ids hint)")
    try:
        objects = read_detections(measurements, st)
        estimator = (
            load_tuning(config).tracker()
            if config is not None
            else RoadTracker(ConstantAcceleration(jerk_psd=3.0))
        )
    except ValueError as exc:
        _fail(str(exc))
    table = track_objects(objects, st, estimator)
    write_table_atomic(table, out)
    Console().print(f"wrote {out} ({len(objects)} objects)")


def _track_extended_file(
    measurements: Path,
    st: Site,
    out: Path,
    events: Path | None,
    background: Path | None,
    trains: Path | None,
) -> None:
    """Track a detection file with the extended-object tracker; write tracks and events."""
    try:
        det = read_scene_detections(measurements, st)
        bg = BackgroundMap.load(background) if background is not None else None
        intervals = read_warnings(trains) if trains is not None else None
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    announce_compilation(EXTENDED_COMPILE_TIME, "extended_loop.run_scans")
    with progress(Console(), "tracking (scans)") as bar:
        try:
            tracks, events_frame, log = track_scene_extended(
                st, det, on_scan=lambda done, total: bar.set(done, total), background=bg,
                train_intervals=intervals,
            )  # fmt: skip
        except ValueError as exc:
            _fail(f"{measurements}: {exc}")
    write_table_atomic(tracks.astype({"status": str, "class": str}), out)
    ev_path = events or out.with_name(out.stem + ".events.csv")
    write_table_atomic(events_frame, ev_path)
    Console().print(
        f"wrote {out} ({tracks['track_id'].nunique()} tracks) and {ev_path} "
        f"({len(events_frame)} events); detections: "
        f"{log.updated} updated tracks, {log.opened + log.joined_new} opened tracks, "
        f"{log.rejected_outside_view} rejected (outside every field of view), {log.total} of "
        f"{len(det)}"
    )


def _track_scene_file(
    measurements: Path,
    st: Site,
    out: Path,
    events: Path | None,
    warnings: Path | None,
    config: Path | None,
) -> None:
    try:
        det = read_scene_detections(measurements, st)
        intervals = read_warnings(warnings) if warnings is not None else None
        settings = load_scene_config(config) if config is not None else None
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    announce_compilation(TRACK_COMPILE_TIME, "scan_loop.run_scans")
    with progress(Console(), "tracking (scans)") as bar:
        try:
            tracks, events_frame, log = track_scene(
                st,
                det,
                settings,
                on_scan=lambda done, total: bar.set(done, total),
                warnings=intervals,
            )
        except ValueError as exc:
            _fail(f"{measurements}: {exc}")
    write_table_atomic(tracks.astype({"status": str}), out)  # plain strings in files
    ev_path = events or out.with_name(out.stem + ".events.csv")
    write_table_atomic(events_frame, ev_path)
    Console().print(
        f"wrote {out} ({tracks['track_id'].nunique()} tracks) and {ev_path} "
        f"({len(events_frame)} events); detections: {log.updated} updated tracks, "
        f"{log.opened + log.joined_new} opened tracks, {log.off_road} beside every road (no "
        f"track opened), {log.rejected_outside_view} rejected (outside every field of view), "
        f"{log.total} of {len(det)}"
    )
