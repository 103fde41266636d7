"""The ``adaptrack score`` command: a scene's tracks against its truth.

GOSPA with its parts, identity switches and fragmentations, and each class's accuracy through
association with its verdict against the crossing's limits
(:func:`adaptrack.crossing.studies.scene_metrics.score_scene`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.console import Console
from rich.table import Table

from ..crossing.site.model import load_site
from ..crossing.studies.scene_metrics import (
    HAZARD_COLUMNS,
    TRACK_COLUMNS,
    TRUTH_COLUMNS,
    USER_COVERAGE,
    SceneScore,
    event_outcomes,
    score_scene,
)
from ..io.tables import numeric_column, read_table, require_columns, write_text_atomic
from .errors import check_outputs, fail


def _table(path: Path, columns: list[str], numeric: list[str]) -> pd.DataFrame:
    """Read ``path`` with ``columns``; the ``numeric`` ones finite (errors name row and column)."""
    frame = read_table(path)
    require_columns(frame, columns, path)
    for col in numeric:
        frame[col] = numeric_column(frame, col, path)  # NaN, inf, text: an error
    return frame


def _truth(path: Path) -> pd.DataFrame:
    """Read the truth table, its ``in_zone`` column as booleans."""
    frame = _table(path, TRUTH_COLUMNS, ["object_id", "time_s", "east_m", "north_m", "speed_mps"])
    zone = frame["in_zone"].astype(str).str.lower()
    bad = np.flatnonzero(~zone.isin(["true", "false", "1", "0"]).to_numpy())
    if bad.size:
        raise ValueError(
            f"{path}: row {bad[0] + 1}, column 'in_zone': {frame['in_zone'].iloc[bad[0]]!r} is "
            "not true or false"
        )
    return frame.assign(
        in_zone=zone.isin(["true", "1"]).to_numpy(),
        vehicle_class=frame["vehicle_class"].astype(str),
    )


def _summary(score: SceneScore) -> dict[str, object]:
    """Return the scores as plain values (JSON)."""
    classes = score.classes.replace({math.nan: None}).to_dict(orient="records")
    return {
        "gospa_mean_m": score.gospa_mean, "gospa_localisation_m2": score.gospa_localisation,
        "gospa_missed_m2": score.gospa_missed, "gospa_false_m2": score.gospa_false,
        "id_switches": score.id_switches, "fragmentations": score.fragmentations,
        "epochs": score.n_epochs, "hours": score.hours, "false_tracks": score.false_tracks,
        "confirm_delays_s": [float(d) for d in score.confirm_delays_s],
        "never_confirmed": score.never_confirmed, "classes": classes,
        "users_meeting": score.users_meeting(), "users": len(score.users),
    }  # fmt: skip


def score(
    tracks: Path = typer.Argument(..., help="Tracks of `adaptrack track` (CSV or Parquet)."),
    truth: Path = typer.Option(
        ..., "--truth", help="Truth of `adaptrack simulate --scene --truth` (or its columns)."
    ),
    site: str = typer.Option(..., "--site", help="Built-in site name or a .toml (its zone)."),
    cutoff: float = typer.Option(5.0, "--cutoff", help="GOSPA cut-off c [m] (p = 2)."),
    events: Path | None = typer.Option(
        None,
        "--events",
        help="Hazard events of `adaptrack track` (its .events.csv): matched with the road users "
        "that truly stood between the barriers (the truth's to_crossing_m needed).",
    ),
    json_path: Path | None = typer.Option(None, "--json", help="Also write the scores as JSON."),
) -> None:
    """Score a scene's tracks against its truth: GOSPA, identities, accuracy per class.

    Every half second the road users in the controlled zone are paired with the moving or
    stopped confirmed tracks in the zone by GOSPA's assignment; each class's position and
    speed RMS over its users' epochs (stopped ones included), with 95 % upper bounds and the
    verdict against 0.7 m and 2 km/h. A reported track in the zone never paired is false; a
    road user's time to confirm runs from its first epoch in the zone to its first paired
    one. With ``--events``, each road user that stood still
    between the barriers for 0.5 s takes the first "stopped between the barriers" event
    within 5 m of it, from 2 s before its stop to 30 s after (its delay; none: missed); the
    events left over are false.
    """
    check_outputs(json_path)
    if not (math.isfinite(cutoff) and cutoff > 0):
        fail(f"--cutoff must be a positive number of metres; got {cutoff}")
    try:
        st = load_site(site)
        truth_table = _truth(truth)
        track_table = _table(tracks, TRACK_COLUMNS, TRACK_COLUMNS[:-1])
        event_table = None
        if events is not None:
            require_columns(truth_table, HAZARD_COLUMNS, truth)
            truth_table[HAZARD_COLUMNS[0]] = numeric_column(truth_table, HAZARD_COLUMNS[0], truth)
            event_table = _table(events, ["time_s", "event", "east_m", "north_m"],
                                 ["time_s", "east_m", "north_m"])  # fmt: skip
    except ValueError as exc:
        fail(str(exc))
    result = score_scene(truth_table, track_table, st.zone_m, c=cutoff)
    summary = _summary(result)
    console = Console()
    console.print(
        f"GOSPA (c = {cutoff:g} m, p = 2) over {result.n_epochs} epochs: mean "
        f"{result.gospa_mean:.2f} m; its square's parts, mean: localisation "
        f"{result.gospa_localisation:.2f} m^2, missed {result.gospa_missed:.2f} m^2, false "
        f"{result.gospa_false:.2f} m^2; identity switches {result.id_switches}, "
        f"fragmentations {result.fragmentations}"
    )
    rate = f" ({result.false_tracks / result.hours:.1f} per hour)" if result.hours > 0 else ""
    delays = result.confirm_delays_s
    confirm = (
        f"median {np.median(delays):.2f} s, 90 % {np.quantile(delays, 0.9):.2f} s, max "
        f"{delays.max():.2f} s over {delays.size} road users"
        if delays.size
        else "no road user"
    )
    console.print(
        f"false tracks: {result.false_tracks}{rate}; time to confirm: {confirm}, "
        f"{result.never_confirmed} never confirmed"
    )
    console.print(
        f"road users within 0.7 m / 2 km/h RMS at >= {USER_COVERAGE:.0%} coverage: "
        f"{result.users_meeting()} of {len(result.users)}"
    )
    table = Table(title="accuracy per class through association (95 % upper bounds)")
    for col in ("class", "users", "epochs", "coverage", "position RMS [m]", "speed RMS [km/h]",
                "verdict"):  # fmt: skip
        table.add_column(col, justify="left" if col in ("class", "verdict") else "right")
    for row in result.classes.itertuples():
        table.add_row(
            str(row[1]), str(row.vehicles), str(row.epochs), f"{row.coverage:.0%}",
            f"{row.position_rms_m:.2f} ({row.position_upper_m:.2f})",
            f"{row.speed_rms_kmh:.2f} ({row.speed_upper_kmh:.2f})", str(row.verdict),
        )  # fmt: skip
    console.print(table)
    if event_table is not None:
        hazards, false_events = event_outcomes(truth_table, event_table, st.barrier_m)
        delays = hazards["delay_s"].to_numpy()
        found = delays[np.isfinite(delays)]
        summary["stopped_between_barriers"] = {
            "true_stops": len(hazards), "detected": int(found.size),
            "delays_s": [float(d) for d in delays if np.isfinite(d)],
            "missed": int(len(hazards) - found.size), "false_events": len(false_events),
        }  # fmt: skip
        late = f", delays {found.min():.2f}-{found.max():.2f} s" if found.size else ""
        console.print(
            f"stopped between the barriers: {len(hazards)} road users truly stood there, "
            f"{found.size} detected{late}, {len(hazards) - found.size} missed; "
            f"{len(false_events)} false events"
        )
    if json_path is not None:
        write_text_atomic(json_path, json.dumps(summary, indent=2) + "\n")
        console.print(f"wrote {json_path}")
