"""Commands of the estimation studies: evaluate (scenarios, flights) and smooth (navigation)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.console import Console
from rich.table import Table

from .._progress import progress
from ..analysis.evaluation import Evaluation, evaluate_scenario
from ..analysis.flights import (
    FlightRow,
    RadarSigmas,
    evaluate_flight,
    smooth_kalman,
    smooth_lsq,
    smooth_record_kalman,
    smooth_record_lsq,
)
from ..coords.geodetic import enu_to_ecef, enu_to_ecef_rotation
from ..io.navigation import read_navigation_measurements, read_radar_record
from ..io.tables import (
    DataFormatError,
    read_flight_csv,
    read_table,
    write_table_atomic,
)
from ..models.continuous import Singer
from ..simulation.scenario import load_scenario
from .errors import check_outputs as _outputs
from .errors import fail as _fail
from .options import SCHEDULER, WORKERS, worker_pool, write_json

SMOOTH_SINGER = Singer(time_constant_s=20.0, accel_std_mps2=2.0, n_axes=3)  # `smooth --method rts`


def evaluate(
    scenario: str = typer.Argument(
        ..., help="Built-in scenario name, a scenario .toml, or 'flights' followed by files."
    ),
    files: list[Path] = typer.Argument(None, help="Flight CSV files (with 'flights')."),
    runs: int = typer.Option(100, "--runs", min=1, help="Evaluation runs."),
    seed: int = typer.Option(0, "--seed", min=0, help="Random seed."),
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
    _outputs(json_path)
    if scenario == "flights":
        _evaluate_flights(files or [], seed, json_path)
        return
    try:
        sc = load_scenario(scenario)
    except ValueError as exc:
        _fail(str(exc))
    console = Console()
    with worker_pool(workers, scheduler) as pool, progress(console, "evaluating") as bar:
        result = evaluate_scenario(
            sc,
            runs,
            seed,
            train_runs=train_runs,
            profile_points=profile_points,
            pool=pool,
            progress=bar.describe,
        )
    console.print(_evaluation_table(result, sc.settings.get("published_table1")))
    if json_path is not None:
        write_json(json_path, result.to_json())
        console.print(f"wrote {json_path}")


def _evaluate_flights(files: list[Path], seed: int, json_path: Path | None) -> None:
    if not files:
        _fail("'evaluate flights' needs at least one flight CSV file")
    rows: list[FlightRow] = []
    console = Console()
    with progress(console, "flights", total=len(files)) as bar:
        for path in files:
            try:
                flight = read_flight_csv(path)
                rows += evaluate_flight(flight, seed=seed)
            except ValueError as exc:
                _fail(str(exc))
            bar.advance(path.name)
    for name in dict.fromkeys(r.flight for r in rows):  # one table a flight, in file order
        table = Table(title=f"{name}: navigation smoothing (seed {seed})")
        columns = ("scan [s]", "method", "position RMSE [m]", "velocity RMSE [m/s]",
                   "scored / scans", "radars")  # fmt: skip
        for col in columns:
            table.add_column(col, justify="left" if col == "method" else "right")
        for r in rows:
            if r.flight == name:
                table.add_row(
                    f"{r.scan_s:g}", r.method, f"{r.position_rmse_m:.2f}",
                    f"{r.velocity_rmse_mps:.2f}", f"{r.n_scored} / {r.n_scans}", str(r.n_radars),
                )  # fmt: skip
        console.print(table)
    if json_path is not None:
        write_json(json_path, {"seed": seed, "rows": [dataclasses.asdict(r) for r in rows]})
        console.print(f"wrote {json_path}")


def _parse_site(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise typer.BadParameter("--site must be LAT,LON,ALT (degrees, degrees, metres)") from None
    if not (abs(lat) <= 90 and abs(lon) <= 360 and math.isfinite(alt)):
        raise typer.BadParameter(f"--site {text}: latitude/longitude out of range")
    return math.radians(lat), math.radians(lon), alt


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
    range_rate_std_mps: float = typer.Option(0.5, "--range-rate-std-mps"),
    range_accel_std_mps2: float = typer.Option(1.0, "--range-accel-std-mps2"),
    out: Path = typer.Option(..., "--out", help="Output CSV or Parquet."),
) -> None:
    """Smooth radar (and velocity) measurements; write ENU and ECEF estimates with covariance.

    A file with range_rate_mps (and optionally range_accel_mps2) is one radar's record: lsq
    fits its triple nodes (position, velocity and acceleration of each sample, the angle rates
    from sliding fits, spec D.2) with the honest sandwich covariance; rts runs an EKF over
    range, azimuth, elevation and range-rate, then the RTS smoother.
    """
    _outputs(out)
    lat, lon, alt = _parse_site(site)
    if method not in ("lsq", "rts"):
        raise typer.BadParameter("--method must be 'lsq' or 'rts'")
    sigmas = RadarSigmas(
        range_std_m, math.radians(azimuth_std_deg), math.radians(elevation_std_deg),
        range_rate_std_mps, range_accel_std_mps2,
    )  # fmt: skip
    try:
        frame = read_table(measurements)
        if "range_rate_mps" in frame.columns:
            record = read_radar_record(measurements, frame)
            est = (
                smooth_record_lsq(record, sigmas, degree=degree, window_s=window)
                if method == "lsq"
                else smooth_record_kalman(record, sigmas, SMOOTH_SINGER)
            )
            write_table_atomic(_estimates_frame(est.time, est.mean, est.cov, (lat, lon, alt)), out)
            Console().print(f"wrote {out} ({est.time.size} epochs, range-rate used)")
            return
        nodes = read_navigation_measurements(
            measurements,
            range_std_m=range_std_m,
            azimuth_std_rad=math.radians(azimuth_std_deg),
            elevation_std_rad=math.radians(elevation_std_deg),
            velocity_std_mps=velocity_std_mps,
            frame=frame,
        )
        if method == "lsq":
            est = smooth_lsq(nodes, use_velocity=True, degree=degree, window_s=window)
        else:
            est = smooth_kalman(nodes, SMOOTH_SINGER)
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
