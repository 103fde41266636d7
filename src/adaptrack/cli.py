"""Command-line interface (typer + rich). It parses, calls the library and writes files."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from .analysis.singer_study import run_singer_study

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


__all__ = ["app"]
