"""Command-line interface (typer + rich). It parses, calls the library and writes files."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from .analysis.evaluation import Evaluation, evaluate_scenario
from .analysis.singer_study import run_singer_study
from .simulation.scenario import load_scenario

app = typer.Typer(
    help="adaptrack: adaptive motion estimation.", no_args_is_help=True, add_completion=False
)
_err = Console(stderr=True)


@app.callback()
def _main() -> None:
    """Adaptive motion estimation from noisy measurements."""


@app.command()
def demo(
    runs: int = typer.Option(200, "--runs", min=1, help="Monte-Carlo runs."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    out: Path | None = typer.Option(None, "--out", help="Directory for summary.json."),
) -> None:
    """Simulate a manoeuvring target and compare filters and smoothers (Monte Carlo)."""
    console = Console()
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("filtering", total=3)

        def step(name: str) -> None:
            progress.update(task, advance=1, description=f"filtering: {name}")

        result = run_singer_study(n_runs=runs, seed=seed, progress=step)
    table = Table(title=f"2-D Singer target, {runs} runs x {result.n_steps} steps, seed {seed}")
    for col in (
        "filter",
        "pos RMSE [m]",
        "vel RMSE [m/s]",
        "RTS pos [m]",
        "RTS vel [m/s]",
        "ANEES (pos+vel)",
    ):
        table.add_column(col, justify="right" if col != "filter" else "left")
    for row in result.rows:
        table.add_row(
            row.filter,
            f"{row.position_rmse_m:.3f}",
            f"{row.velocity_rmse_mps:.3f}",
            f"{row.smoothed_position_rmse_m:.3f}",
            f"{row.smoothed_velocity_rmse_mps:.3f}",
            f"{row.anees:.2f}",
        )
    console.print(table)
    lo, hi = result.anees_band
    console.print(f"95 % ANEES band of a consistent filter: [{lo:.3f}, {hi:.3f}]")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        path = out / "summary.json"
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(dataclasses.asdict(result), indent=2))
        tmp.replace(path)
        console.print(f"wrote {path}")


def _fail(message: str) -> None:
    _err.print(f"error: {message}", markup=False, highlight=False)
    raise typer.Exit(code=1)


def _write_json(path: Path, payload: object) -> None:
    """Write JSON atomically (temporary file, then rename): nothing half-written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(payload, indent=2))
    tmp.replace(path)


@app.command()
def evaluate(
    scenario: str = typer.Argument(..., help="Built-in scenario name or a scenario .toml."),
    runs: int = typer.Option(100, "--runs", min=1, help="Evaluation runs."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    train_runs: int = typer.Option(50, "--train-runs", min=1, help="Tuning runs."),
    profile_points: int = typer.Option(
        41, "--profile-points", min=3, help="Grid points of the M1 profile J(lambda)."
    ),
    json_path: Path | None = typer.Option(None, "--json", help="Write the table as JSON."),
) -> None:
    """Compare the CV-KF, the seed-002 adaptive filters, IMM and tuned M1/M2 on a scenario."""
    try:
        sc = load_scenario(scenario)
    except ValueError as exc:
        _fail(str(exc))
    console = Console()
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("evaluating", total=None)

        def step(msg: str) -> None:
            progress.update(task, description=msg)

        result = evaluate_scenario(
            sc, runs, seed, train_runs=train_runs, profile_points=profile_points, progress=step
        )
    console.print(_evaluation_table(result, sc.settings.get("published_table1")))
    if json_path is not None:
        _write_json(json_path, result.to_json())
        console.print(f"wrote {json_path}")


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
            row.filter, *(f"{row.rmse_m[k]:.2f}" for k in intervals), f"{row.anees:.2f}", note
        )
    return table


__all__ = ["app"]
