"""The ``adaptrack fit`` and ``adaptrack filter`` commands: a recorded log, no truth."""

from __future__ import annotations

import math
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from .._progress import announce_compilation, progress
from .._toml import load_toml
from ..analysis.consistency import innovation_consistency
from ..filters.imm import IMMResult
from ..io.position_log import ALL_MEASUREMENTS, PositionLog, estimates_table, read_position_log
from ..io.radar_plots import RADAR_LAYOUTS, RadarLog, read_radar_log
from ..io.tables import DataFormatError, write_table_atomic, write_text_atomic
from ..tuning.likelihood import LikelihoodFit
from ..tuning.log_fit import MODELS, MotionFit, compiled_kernel, fit_from_toml, fit_motion, fit_toml
from .errors import check_outputs, err_console, fail


def _read(path: Path, measurement: str) -> PositionLog | RadarLog:
    """Read the log (errors as one line); say which of its columns are not used."""
    if measurement not in ALL_MEASUREMENTS:
        raise typer.BadParameter(f"--measurement must be one of {', '.join(ALL_MEASUREMENTS)}")
    try:
        log: PositionLog | RadarLog = (
            read_radar_log(path, measurement)  # type: ignore[arg-type]
            if measurement in RADAR_LAYOUTS
            else read_position_log(path, measurement)  # type: ignore[arg-type]
        )
    except (DataFormatError, ValueError, OSError) as exc:
        fail(str(exc))
    if log.unused:
        err_console.print(f"note: {path}: columns not used: {', '.join(log.unused)}", markup=False)
    return log


# a first fit compiles its kernel; measured on an empty cache (then warm) on 2 cores:
COMPILE_TIMES = {
    "_imm_kernel.imm_kernel": "2 min",  # the car's CV + CT fit 108 s (then 7 s)
    "_ekf_kernel.ekf_kernel": "1 min",  # a 600-fix CT fit 44 s (then 3 s)
}
UNDETERMINED_SPAN = 100.0  # a 95 % interval wider than this factor: the data say little


def _fit_notes(fit: LikelihoodFit) -> list[str]:
    """Return notes on the intervals: a rough likelihood, or parameters the log hardly fixes."""
    if fit.rough:
        return [
            f"the likelihood is rough in {', '.join(fit.rough)} (its curvature differs "
            "between steps of 1 % and 0.5 %): the filter's estimates jump with small changes "
            "of the parameters, so the model may not suit the log; no standard error for "
            "them, and the others', where shown, hold them at their values"
        ]
    notes = []
    for name in fit.names:
        lo, hi = fit.interval(name)
        if name in fit.signed:
            continue
        if math.isnan(lo) or math.isnan(hi):
            why = "the log gives no interval for it: the likelihood is not curved down there"
        elif hi > UNDETERMINED_SPAN * lo:
            span = hi / lo if lo > 0 else math.inf
            why = f"the log hardly constrains it: its 95 % interval spans a factor of {span:.2g}"
        else:
            continue
        notes.append(
            f"{name} = {fit.value(name):.4g}: {why} (flat, or the value at a limit such as 0); "
            "a simpler model may explain the log as well"
        )
    return notes


def fit(
    log_file: Path = typer.Argument(..., help="CSV/Parquet position log."),
    measurement: str = typer.Option(
        ...,
        "--measurement",
        help="gnss (time_s, lat_deg, lon_deg[, alt_m]), position "
        "(time_s, east_m, north_m[, up_m]), radar2d (time_s, range_m, azimuth_deg"
        "[, range_rate_mps]) or radar3d (with elevation_deg); t_s is taken for time_s.",
    ),
    model: str = typer.Option(
        "cv",
        "--model",
        help="cv (white acceleration), ca (jerk), ct (coordinated turn: constant speed, "
        "a wandering turn rate; EKF), or an IMM of CV and a manoeuvre model switching at a "
        "fitted rate: cv+ca, cv+ct.",
    ),
    clock_offset: bool = typer.Option(
        False,
        "--clock-offset",
        help="Also fit how late the fixes are stamped against the "
        "log's velocity reports (velocity_*_mps or groundspeed_mps, track_deg columns).",
    ),
    out: Path = typer.Option(..., "--out", help="Output TOML (input of `adaptrack filter`)."),
) -> None:
    """Fit motion PSD and noise variances to a log by maximum likelihood (no truth needed).

    A radar plot list is one target's plots in the radar's frame (EKF; estimates in metres
    east and north of the antenna).
    """
    check_outputs(out)
    if model not in MODELS:
        raise typer.BadParameter(f"--model must be one of {', '.join(MODELS)}")
    log = _read(log_file, measurement)
    kernel = compiled_kernel(log, model)
    if kernel is not None:
        announce_compilation(COMPILE_TIMES[kernel], kernel, "filters")
    try:
        with progress(Console(), f"{model.upper()} fit (likelihood evaluations)") as bar:
            result = fit_motion(log, model, clock_offset, bar.advance)  # type: ignore[arg-type]
    except ValueError as exc:
        fail(str(exc))
    write_text_atomic(out, fit_toml(result, measurement, str(log_file)))
    table = Table(title=f"{log_file.name}: {model.upper()} fit on {log.times.size} fixes")
    for col in ("parameter", "value", "95 % interval"):
        table.add_column(col)
    for name in result.fit.names:
        lo, hi = result.fit.interval(name)
        table.add_row(name, f"{result.fit.value(name):.4g}", f"{lo:.4g} to {hi:.4g}")
    if result.clock is not None:
        lo, hi = result.clock.interval("offset_s")
        table.add_row("clock offset_s", f"{result.offset_s:+.4f}", f"{lo:+.4f} to {hi:+.4f}")
    Console().print(table)
    if not result.fit.converged:
        err_console.print(f"warning: the optimiser did not converge: {result.fit.message}")
    for note in _fit_notes(result.fit):
        err_console.print(f"note: {note}")
    Console().print(f"wrote {out}")


def filter_log(
    log_file: Path = typer.Argument(..., help="CSV/Parquet position log (the fit's layout)."),
    config: Path = typer.Option(..., "--config", help="TOML written by `adaptrack fit`."),
    smooth: bool = typer.Option(False, "--smooth", help="RTS smoothing (not causal)."),
    refit: bool = typer.Option(
        False,
        "--refit-online",
        help="Refit the parameters from the log's own earlier fixes as the filter goes "
        "(maximum likelihood, starting at the config's; causal; not with --smooth).",
    ),
    out: Path = typer.Option(..., "--out", help="Output CSV or Parquet."),
) -> None:
    """Filter (or smooth) a log with a fit: estimates with sigmas and covariance at each fix."""
    check_outputs(out)
    if refit and smooth:
        raise typer.BadParameter("--refit-online filters causally; it does not take --smooth")
    try:
        result: MotionFit
        result, measurement = fit_from_toml(load_toml(config), str(config))
    except (ValueError, OSError) as exc:
        fail(str(exc))
    log = _read(log_file, measurement)
    if refit:
        _filter_refitting(log_file, log, result, out)
        return
    try:
        run = result.run(log)
        check = None if isinstance(run, IMMResult) else innovation_consistency(run)
        est, mode_probs = result.estimate(run, smooth)
    except ValueError as exc:
        fail(f"{log_file}: {exc}")
    probabilities = None
    if mode_probs is not None:  # an IMM's, one column a model
        probabilities = dict(zip(result.model.split("+"), mode_probs.T, strict=True))
    table = estimates_table(
        log, est.mean, est.cov, result.offset_s, result.model == "ct", probabilities
    )
    write_table_atomic(table, out)
    if check is None:
        Console().print("innovations: not checked (an IMM's differ from model to model)")
    else:
        lo, hi = check.mean_nis_band
        Console().print(
            f"innovations: mean NIS {check.mean_nis:.2f} (95 % band {lo:.2f}-{hi:.2f} for "
            f"{check.dof:.0f} dof), lag-1 correlation {check.lag1:+.2f} (band "
            f"+-{check.lag1_limit:.2f}): {check.verdict}"
        )
    Console().print(
        f"wrote {out} ({log.times.size} epochs, {'smoothed' if smooth else 'filtered'})"
    )


def _filter_refitting(
    log_file: Path, log: PositionLog | RadarLog, result: MotionFit, out: Path
) -> None:
    """``filter --refit-online``: causal estimates, the parameters refitted as it goes."""
    try:
        mean, cov, online = result.filter_online(log)
    except ValueError as exc:
        fail(f"{log_file}: {exc}")
    table = estimates_table(log, mean, cov, result.offset_s, result.model == "ct", None)
    write_table_atomic(table, out)
    if online.fits:
        last = ", ".join(f"{k} {v:.4g}" for k, v in online.params[-1].items())
        Console().print(
            f"refitted {len(online.fits)} times, the last on the fixes up to "
            f"{online.fit_times[-1]:.1f} s: {last}"
        )
    else:
        Console().print("not refitted: too few fixes (20 per parameter before the first refit)")
    Console().print(f"wrote {out} ({log.times.size} epochs, filtered, refitted online)")
