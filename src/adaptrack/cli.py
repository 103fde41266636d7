"""Command-line interface (typer + rich). It parses, calls the library and writes files."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from .analysis.evaluation import Evaluation, evaluate_scenario
from .analysis.flights import FlightRow, evaluate_flight, smooth_kalman, smooth_lsq
from .coords.geodetic import enu_to_ecef, enu_to_ecef_rotation
from .crossing.compliance import ComplianceResult, ComplianceRow, evaluate_site
from .crossing.measurements_io import detections_frame, read_detections
from .crossing.radar_sim import simulate_site_case
from .crossing.report import build_report, render_html, sample_tracks
from .crossing.site import load_site
from .crossing.tracking import track_on_road
from .crossing.traffic import DEFAULT_CASES, VEHICLES, applicable
from .crossing.tuning import load_tuning, tune_road_model, tune_road_shaping
from .io.navigation import read_navigation_measurements
from .io.tables import DataFormatError, read_flight_csv, write_table_atomic
from .models.continuous import ConstantAcceleration, Singer
from .parallel import TaskPool, task_pool
from .simulation.scenario import load_scenario

DEMO_LAMBDAS = (1e-3, 3e-2, 1.0)  # coarse M1 profile of the demo (lambda = 0 is always in)

WORKERS = typer.Option(
    None,
    "--workers",
    min=1,
    help="Local worker processes (a Dask LocalCluster; default one per CPU core, 1: in-process).",
)
SCHEDULER = typer.Option(
    None, "--scheduler", help="Address of an existing Dask scheduler, e.g. tcp://host:8786."
)

app = typer.Typer(
    help="adaptrack: adaptive motion estimation.", no_args_is_help=True, add_completion=False
)
_err = Console(stderr=True)


@app.callback()
def _main() -> None:
    """Adaptive motion estimation from noisy measurements."""


@app.command()
def demo(
    runs: int = typer.Option(10, "--runs", min=1, help="Monte-Carlo runs per class and case."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    out: Path = typer.Option(
        Path("out"), "--out", help="Directory for summary.json and report.html."
    ),
    site: str = typer.Option("lx_default", "--site", help="Built-in site name or a .toml."),
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
) -> None:
    """Level-crossing compliance demo: simulate a site, track, check the requirements."""
    try:
        st = load_site(site)
    except ValueError as exc:
        _fail(str(exc))
    console = Console()
    n_pairs = sum(1 for v in VEHICLES.values() for c in DEFAULT_CASES if applicable(c, v))
    train_seed, eval_seed = (
        int(x.generate_state(1)[0]) for x in np.random.SeedSequence(seed).spawn(2)
    )
    with _pool(workers, scheduler) as pool, Progress(console=console, transient=True) as progress:
        task = progress.add_task("tuning", total=n_pairs + len(DEMO_LAMBDAS) + 1)

        def step(msg: str) -> None:
            progress.update(task, advance=1, description=msg)

        tuning = tune_road_model(
            st, n_runs=3, seed=train_seed, pool=pool, lambdas=DEMO_LAMBDAS, progress=step
        )
        result = evaluate_site(
            st,
            runs,
            eval_seed,
            pool=pool,
            progress=step,
            tuned_m1=(tuning.lambda_per_s2, tuning.accel_psd),
        )
    result = dataclasses.replace(result, seed=seed)
    table = Table(
        title=f"{st.name}: worst case over classes and cases, {runs} runs, seed {seed}"
        f" (requirement 0.7 m, 2 km/h)"
    )
    for col in ("estimator", "position RMS [m]", "speed RMS [km/h]", "all pass"):
        table.add_column(col, justify="left" if col == "estimator" else "right")
    for name, w in result.worst.items():
        table.add_row(
            name,
            f"{w['position_rms_m']:.3f}",
            f"{w['speed_rms_kmh']:.3f}",
            "yes" if w["all_pass"] else "NO",
        )
    console.print(table)
    for name, g in result.gain_pct.items():
        console.print(
            f"{name} vs road EKF (CV): position {g['position']:+.1f} %, speed {g['speed']:+.1f} %"
        )
    summary = {**result.to_json(), "tuning": dataclasses.asdict(tuning)}
    _write_json(out / "summary.json", summary)
    _write_text(out / "tuned.toml", tuning.to_toml())
    _write_text(
        out / "report.html",
        render_html(
            build_report(result, st, samples=sample_tracks(st, seed), profile=tuning.profile)
        ),
    )
    console.print(
        f"wrote {out / 'summary.json'} and {out / 'report.html'} "
        f"(Monte Carlo {result.elapsed_s:.1f} s)"
    )


@app.command()
def report(
    summary: Path = typer.Argument(..., help="summary.json written by 'adaptrack demo'."),
    out: Path = typer.Option(..., "--out", help="Output HTML file."),
) -> None:
    """Render the HTML compliance report of a demo summary (sample tracks re-simulated)."""
    try:
        data = json.loads(summary.read_text())
        st = load_site(data["site"])
        result = ComplianceResult(
            data["site"],
            int(data["runs"]),
            int(data["seed"]),
            [
                ComplianceRow(
                    r["filter"],
                    r["vehicle_class"],
                    r["case"],
                    r["position_rms_m"],
                    r["speed_rms_kmh"],
                    r["speed_rel_rms_pct"],
                    r["pass"],
                    r["n_epochs"],
                    r.get("pcrlb_position_m", math.nan),
                    r.get("pcrlb_speed_kmh", math.nan),
                )
                for r in data["rows"]
            ],
            float(data["elapsed_s"]),
            data["worst_case"],
            data["gain_over_cv_pct"],
        )
    except (OSError, ValueError, KeyError, TypeError) as exc:
        _fail(f"{summary}: not a demo summary ({exc})")
    _write_text(out, render_html(build_report(result, st, samples=sample_tracks(st, result.seed))))
    Console().print(f"wrote {out}")


@app.command()
def simulate(
    site: str = typer.Argument("lx_default", help="Built-in site name or a site .toml."),
    out: Path = typer.Option(..., "--out", help="Detections table (CSV or Parquet)."),
    truth: Path | None = typer.Option(None, "--truth", help="Also write the true kinematics."),
    runs: int = typer.Option(1, "--runs", min=1, help="Vehicles per class and case."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
) -> None:
    """Simulate radar detections of traffic at a site, as a radar object list."""
    try:
        st = load_site(site)
    except ValueError as exc:
        _fail(str(exc))
    pairs = [(c, v) for v in VEHICLES.values() for c in DEFAULT_CASES if applicable(c, v)]
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


@app.command()
def tune(
    site: str = typer.Argument("lx_default", help="Built-in site name or a site .toml."),
    out: Path = typer.Option(..., "--out", help="Tuned configuration (TOML)."),
    runs: int = typer.Option(3, "--runs", min=1, help="Training runs per approach."),
    seed: int = typer.Option(0, "--seed", help="Random seed of the training runs."),
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    model: str = typer.Option("m1", "--model", help="m1, or m2 (also tunes M2; slower)."),
) -> None:
    """Tune the road-constrained model (M1: lambda, accel_psd) to a site's training runs."""
    if model not in ("m1", "m2"):
        raise typer.BadParameter("--model must be 'm1' or 'm2'")
    try:
        st = load_site(site)
    except ValueError as exc:
        _fail(str(exc))
    with _pool(workers, scheduler) as pool, Progress(transient=True) as progress:
        task = progress.add_task("tuning", total=7)
        tuning = tune_road_model(
            st,
            n_runs=runs,
            seed=seed,
            pool=pool,
            progress=lambda m: progress.update(task, advance=1, description=m),
        )
    if model == "m2":
        tuning = tune_road_shaping(st, tuning, n_runs=runs, seed=seed)
        Console().print(f"M2: {tuning.shaping}")
    _write_text(out, tuning.to_toml())
    Console().print(
        f"lambda = {tuning.lambda_per_s2:g} 1/s^2, accel_psd = "
        f"{tuning.accel_psd:.4g} m^2/s^3, J_req = {tuning.criterion:.4f} "
        f"(CV baseline {tuning.baseline_criterion:.4f}); wrote {out}"
    )


@app.command()
def track(
    measurements: Path = typer.Argument(..., help="Detections table (CSV or Parquet)."),
    site: str = typer.Option("lx_default", "--site", help="Built-in site name or a .toml."),
    out: Path = typer.Option(..., "--out", help="Estimates table (CSV or Parquet)."),
    config: Path | None = typer.Option(
        None, "--config", help="Tuned configuration from 'adaptrack tune' or 'demo'."
    ),
) -> None:
    """Track every radar object with the road-constrained EKF; write per-object estimates.

    The reflection-point scatter follows the ``vehicle_class`` column (a car when absent).
    """
    try:
        st = load_site(site)
        objects = read_detections(measurements, st)
        model = (
            load_tuning(config).model()
            if config is not None
            else ConstantAcceleration(jerk_psd=3.0)
        )
    except ValueError as exc:
        _fail(str(exc))
    road_of_radar = {v: k for k, v in st.settings.get("radar_of_road", {}).items()}
    frames = []
    for obj in objects:
        road_name = road_of_radar.get(obj.radar, next(iter(st.roads)))
        radar = next(r for r in st.radars if r.name == obj.radar)
        est = track_on_road(
            obj.times[None],
            obj.measurements[None],
            np.ones((1, obj.times.size), dtype=bool),
            radar,
            st.roads[road_name],
            model=model,
            scatter_std_m=VEHICLES[obj.vehicle_class or "car"].scatter_std_m,
        )
        frames.append(
            pd.DataFrame(
                {
                    "object_id": obj.object_id,
                    "time_s": obj.times,
                    "east_m": est.position[0, :, 0],
                    "north_m": est.position[0, :, 1],
                    "speed_mps": est.speed[0],
                    "speed_kmh": 3.6 * est.speed[0],
                    "position_std_m": np.sqrt(np.trace(est.position_cov[0], axis1=-2, axis2=-1)),
                }
            )
        )
    write_table_atomic(pd.concat(frames, ignore_index=True), out)
    Console().print(f"wrote {out} ({len(objects)} objects)")


@contextmanager
def _pool(workers: int | None, scheduler: str | None) -> Iterator[TaskPool]:
    """Task pool of the --workers/--scheduler options (errors reported, not raised)."""
    if scheduler is not None and workers is not None:
        raise typer.BadParameter("give --workers or --scheduler, not both")
    n = workers if workers is not None else (1 if scheduler else os.cpu_count() or 1)
    stack = ExitStack()
    try:
        pool = stack.enter_context(task_pool(n, scheduler))
    except OSError as exc:
        _fail(f"cannot start the task pool ({exc})")
    with stack:
        yield pool


def _fail(message: str) -> None:
    _err.print(f"error: {message}", markup=False, highlight=False)
    raise typer.Exit(code=1)


def _write_text(path: Path, text: str) -> None:
    """Write text atomically (temporary file, then rename): nothing half-written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def _write_json(path: Path, payload: object) -> None:
    """Write JSON atomically."""
    _write_text(path, json.dumps(payload, indent=2))


@app.command()
def evaluate(
    scenario: str = typer.Argument(
        ..., help="Built-in scenario name, a scenario .toml, or 'flights' followed by files."
    ),
    files: list[Path] = typer.Argument(None, help="Flight CSV files (with 'flights')."),
    runs: int = typer.Option(100, "--runs", min=1, help="Evaluation runs."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    train_runs: int = typer.Option(50, "--train-runs", min=1, help="Tuning runs."),
    profile_points: int = typer.Option(
        41, "--profile-points", min=3, help="Grid points of the M1 profile J(lambda)."
    ),
    json_path: Path | None = typer.Option(None, "--json", help="Write the table as JSON."),
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
) -> None:
    """Compare the CV-KF, the seed-002 adaptive filters, IMM and tuned M1/M2 on a scenario.

    ``adaptrack evaluate flights FILE...`` instead compares navigation smoothers (triple-node
    and position-only LSQ, Kalman filter, RTS smoother) on recorded flights used as truth.
    """
    if scenario == "flights":
        _evaluate_flights(files or [], seed, json_path)
        return
    try:
        sc = load_scenario(scenario)
    except ValueError as exc:
        _fail(str(exc))
    console = Console()
    with _pool(workers, scheduler) as pool, Progress(console=console, transient=True) as progress:
        task = progress.add_task("evaluating", total=None)

        def step(msg: str) -> None:
            progress.update(task, description=msg)

        result = evaluate_scenario(
            sc,
            runs,
            seed,
            train_runs=train_runs,
            profile_points=profile_points,
            pool=pool,
            progress=step,
        )
    console.print(_evaluation_table(result, sc.settings.get("published_table1")))
    if json_path is not None:
        _write_json(json_path, result.to_json())
        console.print(f"wrote {json_path}")


def _evaluate_flights(files: list[Path], seed: int, json_path: Path | None) -> None:
    if not files:
        _fail("'evaluate flights' needs at least one flight CSV file")
    rows: list[FlightRow] = []
    console = Console()
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("flights", total=len(files))
        for path in files:
            try:
                flight = read_flight_csv(path)
                rows += evaluate_flight(flight, seed=seed)
            except ValueError as exc:
                _fail(str(exc))
            progress.update(task, advance=1)
    table = Table(title=f"navigation smoothing on recorded flights (seed {seed})")
    for col in (
        "flight",
        "scan [s]",
        "method",
        "position RMSE [m]",
        "velocity RMSE [m/s]",
        "scored scans",
    ):
        table.add_column(col, justify="left" if col in ("flight", "method") else "right")
    for r in rows:
        table.add_row(
            r.flight,
            f"{r.scan_s:g}",
            r.method,
            f"{r.position_rmse_m:.2f}",
            f"{r.velocity_rmse_mps:.2f}",
            str(r.n_scored),
        )
    console.print(table)
    if json_path is not None:
        _write_json(json_path, {"seed": seed, "rows": [dataclasses.asdict(r) for r in rows]})
        console.print(f"wrote {json_path}")


def _parse_site(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise typer.BadParameter("--site must be LAT,LON,ALT (degrees, degrees, metres)") from None
    if not (abs(lat) <= 90 and abs(lon) <= 360 and math.isfinite(alt)):
        raise typer.BadParameter(f"--site {text}: latitude/longitude out of range")
    return math.radians(lat), math.radians(lon), alt


@app.command()
def smooth(
    measurements: Path = typer.Argument(..., help="CSV/Parquet of radar and velocity nodes."),
    site: str = typer.Option(..., "--site", help="Radar site LAT,LON,ALT (deg, deg, m)."),
    method: str = typer.Option("lsq", "--method", help="lsq or rts."),
    degree: int = typer.Option(2, "--degree", min=0, help="Polynomial degree (lsq)."),
    window: float = typer.Option(20.0, "--window", help="Sliding window [s] (lsq)."),
    range_std_m: float = typer.Option(30.0, "--range-std-m"),
    azimuth_std_deg: float = typer.Option(0.08, "--azimuth-std-deg"),
    elevation_std_deg: float = typer.Option(0.1, "--elevation-std-deg"),
    velocity_std_mps: float = typer.Option(1.0, "--velocity-std-mps"),
    out: Path = typer.Option(..., "--out", help="Output CSV or Parquet."),
) -> None:
    """Smooth radar (and velocity) measurements; write ENU and ECEF estimates with covariance."""
    lat, lon, alt = _parse_site(site)
    if method not in ("lsq", "rts"):
        raise typer.BadParameter("--method must be 'lsq' or 'rts'")
    try:
        nodes = read_navigation_measurements(
            measurements,
            range_std_m=range_std_m,
            azimuth_std_rad=math.radians(azimuth_std_deg),
            elevation_std_rad=math.radians(elevation_std_deg),
            velocity_std_mps=velocity_std_mps,
        )
        if method == "lsq":
            est = smooth_lsq(nodes, use_velocity=True, degree=degree, window_s=window)
        else:
            est = smooth_kalman(nodes, Singer(time_constant_s=20.0, accel_std_mps2=2.0, n_axes=3))
    except (DataFormatError, ValueError) as exc:
        _fail(str(exc))
    write_table_atomic(_estimates_frame(est.time, est.mean, est.cov, (lat, lon, alt)), out)
    Console().print(f"wrote {out} ({est.time.size} epochs)")


def _estimates_frame(
    t: np.ndarray, mean: np.ndarray, cov: np.ndarray, site: tuple[float, float, float]
) -> pd.DataFrame:
    """ENU and ECEF position/velocity with standard deviations and the ENU covariance."""
    rot = enu_to_ecef_rotation(site[0], site[1])
    big = np.kron(np.eye(2), rot)
    cov6 = cov[:, :6, :6]
    ecef_cov = big @ cov6 @ big.T
    cols: dict[str, np.ndarray] = {"time_s": t}
    enu = [
        "east_m",
        "north_m",
        "up_m",
        "velocity_east_mps",
        "velocity_north_mps",
        "velocity_up_mps",
    ]
    ecef = ["ecef_x_m", "ecef_y_m", "ecef_z_m", "ecef_vx_mps", "ecef_vy_mps", "ecef_vz_mps"]
    ok = np.all(np.isfinite(mean[:, :6]), axis=-1)  # NaN rows: windows with too few nodes
    ecef_vals = np.full((t.size, 6), np.nan)
    ecef_vals[ok] = np.concatenate([enu_to_ecef(mean[ok, :3], *site), mean[ok, 3:6] @ rot.T], -1)
    for i, name in enumerate(enu):
        cols[name] = mean[:, i]
    for i, name in enumerate(ecef):
        cols[name] = ecef_vals[:, i]
    for i, name in enumerate(enu):
        cols[
            name.replace("_m", "_std_m", 1)
            if name.endswith("_m")
            else name.replace("_mps", "_std_mps")
        ] = np.sqrt(cov6[:, i, i])
    for i, name in enumerate(ecef):
        cols[
            name.replace("_m", "_std_m", 1)
            if name.endswith("_m")
            else name.replace("_mps", "_std_mps")
        ] = np.sqrt(ecef_cov[:, i, i])
    short = ["e", "n", "u", "ve", "vn", "vu"]
    for i in range(6):
        for j in range(i + 1, 6):
            cols[f"cov_{short[i]}_{short[j]}"] = cov6[:, i, j]
    return pd.DataFrame(cols)


def _evaluation_table(result: Evaluation, published: dict[str, list[float]] | None) -> Table:
    intervals = list(result.rows[0].rmse_m)
    table = Table(
        title=f"{result.scenario}: position RMSE [m] per interval [s], "
        f"{result.runs} runs, seed {result.seed}"
    )
    table.add_column("filter")
    for name in intervals:
        table.add_column(name, justify="right")
    table.add_column(f"ANEES ({result.anees_dof} dof)", justify="right")
    table.add_column("note / compares with")
    if published:
        for key, label in (
            ("adaptive", "Table 1, adaptive (published)"),
            ("kalman", "Table 1, Kalman filter (published)"),
        ):
            table.add_row(
                label, *(f"{v:.2f}" for v in published[key]), "", "seed 002's published figures"
            )
    compares = {
        "CV-KF (DWNA": "Table 1 'Kalman filter' row",
        "adaptive KF, published": "Table 1 'adaptive' row (the published algorithm)",
    }
    for row in result.rows:
        hint = next((v for k, v in compares.items() if row.filter.startswith(k)), "")
        note = "; ".join(x for x in (row.note, hint if published else "") if x)
        table.add_row(
            row.filter, *(f"{row.rmse_m[k]:.4g}" for k in intervals), f"{row.anees:.2f}", note
        )
    return table


__all__ = ["app"]
