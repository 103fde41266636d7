"""Radar object-list tables: write simulated detections, read and validate recorded ones.

Columns (one row per detection): ``object_id``, ``radar``, ``time_s``, ``range_m``,
``azimuth_rad`` (or ``azimuth_deg``, converted once here), ``radial_speed_mps``; optionally
``vehicle_class`` (motorcycle, car, truck, bus), as radar object lists report it. Times must be
strictly increasing per object; radars must exist in the site.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .._typing import FloatArray
from ..io.tables import DataFormatError, numeric_column, read_table, require_columns
from .simulation.radar import CrossingRuns
from .site.model import Site

COLUMNS = ["object_id", "radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps"]


def detections_frame(
    runs: CrossingRuns, radar: str, first_object_id: int, time_offset_s: FloatArray
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return detections and truth of simulated runs as tables (one object per run)."""
    rows, truth = [], []
    for i in range(runs.times.shape[0]):
        det = runs.detected[i]
        oid = first_object_id + i
        t = runs.times[i] + time_offset_s[i]
        rows.append(
            pd.DataFrame(
                {
                    "object_id": oid,
                    "radar": radar,
                    "time_s": t[det],
                    "range_m": runs.measurements[i, det, 0],
                    "azimuth_rad": runs.measurements[i, det, 1],
                    "radial_speed_mps": runs.measurements[i, det, 2],
                }
            )
        )
        truth.append(
            pd.DataFrame(
                {
                    "object_id": oid,
                    "time_s": runs.true_times[i] + time_offset_s[i],
                    "east_m": runs.position[i, :, 0],
                    "north_m": runs.position[i, :, 1],
                    "speed_mps": runs.speed[i],
                    "along_road_m": runs.along_road_m[i],
                }
            )
        )
    return pd.concat(rows, ignore_index=True), pd.concat(truth, ignore_index=True)


@dataclass(frozen=True, eq=False)
class ObjectDetections:
    """Detections of one radar object: times (T,), measurements (T, 3) and its radar.

    ``times`` are when the detections were made: the timestamps less the radar's declared
    latency.
    """

    object_id: int
    radar: str
    times: FloatArray
    measurements: FloatArray
    vehicle_class: str | None = None


SCENE_COLUMNS = ["radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps"]


def _polar_columns(
    frame: pd.DataFrame, p: Path, site: Site, extra: tuple[str, ...] = ()
) -> tuple[np.ndarray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return the validated radar names, times, ranges, azimuths [rad] and radial speeds of a table.

    ``extra`` columns are required as well. Errors name file, row and column.
    """
    az_col = "azimuth_rad" if "azimuth_rad" in frame.columns else "azimuth_deg"
    if "azimuth_rad" in frame.columns and "azimuth_deg" in frame.columns:
        raise DataFormatError(f"{p}: both 'azimuth_rad' and 'azimuth_deg' (mixed units)")
    require_columns(frame, [*extra, "radar", "time_s", "range_m", az_col, "radial_speed_mps"], p)
    if frame.empty:
        raise DataFormatError(f"{p}: no detections (the table has a header but no rows)")
    t = numeric_column(frame, "time_s", p)
    r = numeric_column(frame, "range_m", p)
    az = numeric_column(frame, az_col, p)
    vr = numeric_column(frame, "radial_speed_mps", p)
    if az_col == "azimuth_deg":
        az = np.deg2rad(az)
    elif np.any(np.abs(az) > 2 * np.pi):
        row = int(np.argmax(np.abs(az) > 2 * np.pi))
        raise DataFormatError(
            f"{p}: row {row + 1}, column 'azimuth_rad': {az[row]} is out of "
            "range for radians; degrees given? (use an azimuth_deg column)"
        )
    if np.any(r <= 0):
        row = int(np.argmax(r <= 0))
        raise DataFormatError(f"{p}: row {row + 1}, column 'range_m': must be > 0")
    radars = {x.name for x in site.radars}
    names = frame["radar"].astype(str).to_numpy()
    unknown = ~np.isin(names, list(radars))
    if unknown.any():
        row = int(np.argmax(unknown))
        raise DataFormatError(
            f"{p}: row {row + 1}, column 'radar': unknown radar "
            f"{names[row]!r}; the site has {sorted(radars)}"
        )
    return names, t, r, az, vr


def _object_ids(frame: pd.DataFrame, p: Path, minimum: int | None = None) -> np.ndarray:
    """Return the ``object_id`` column as int64: integers (at least ``minimum``), row named."""
    oid = numeric_column(frame, "object_id", p)
    bad = (oid != np.round(oid)) | (oid < (-np.inf if minimum is None else minimum))
    if bad.any():
        row = int(np.argmax(bad))
        least = "" if minimum is None else f" >= {minimum}"
        raise DataFormatError(
            f"{p}: row {row + 1}, column 'object_id': {oid[row]} is not an integer{least}"
        )
    return oid.astype(np.int64)


def read_scene_detections(path: str | Path, site: Site) -> pd.DataFrame:
    """Read and validate detections for the scene tracker.

    Columns ``SCENE_COLUMNS`` (``azimuth_deg`` accepted), and ``object_id`` for a radar object
    list: the sensor's ids (integers, -1: none), kept as association hints. Errors name file,
    row and column. Rows come back sorted by time, stably.
    """
    p = Path(path)
    frame = read_table(p)
    names, t, r, az, vr = _polar_columns(frame, p, site)
    out = pd.DataFrame(
        {"radar": names, "time_s": t, "range_m": r, "azimuth_rad": az, "radial_speed_mps": vr}
    )
    if "object_id" in frame.columns:
        out["object_id"] = _object_ids(frame, p, minimum=-1)
    return out.sort_values("time_s", kind="stable", ignore_index=True)


WARNING_COLUMNS = ["start_s", "end_s"]


def read_warnings(path: str | Path) -> FloatArray:
    """Read the crossing's warning intervals (K, 2) [s]: lights flashing or barriers down.

    Columns ``start_s``, ``end_s`` (finite, start before end); errors name file, row and column.
    """
    p = Path(path)
    frame = read_table(p)
    require_columns(frame, WARNING_COLUMNS, p)
    start, end = (numeric_column(frame, c, p) for c in WARNING_COLUMNS)
    bad = ~(start < end)
    if bad.any():
        row = int(np.argmax(bad))
        raise DataFormatError(f"{p}: row {row + 1}: start_s must be before end_s")
    return np.stack([start, end], -1)


def read_detections(path: str | Path, site: Site) -> list[ObjectDetections]:
    """Read and validate a detection table; errors name file, row and column."""
    p = Path(path)
    frame = read_table(p)
    names, t, r, az, vr = _polar_columns(frame, p, site, ("object_id",))
    oid = _object_ids(frame, p)
    out = []
    for obj in np.unique(oid):
        sel = np.flatnonzero(oid == obj)
        ts = t[sel]
        bad = np.diff(ts) <= 0
        if bad.any():
            row = int(sel[np.argmax(bad) + 1])
            raise DataFormatError(
                f"{p}: row {row + 1}, column 'time_s': times of object "
                f"{int(obj)} are not strictly increasing"
            )
        if len(set(names[sel])) != 1:
            raise DataFormatError(
                f"{p}: object {int(obj)} is reported by several radars; "
                "one radar per object is supported"
            )
        cls = None
        if "vehicle_class" in frame.columns:
            cls = str(frame["vehicle_class"].iloc[sel[0]])
            if cls not in site.classes:
                raise DataFormatError(
                    f"{p}: row {sel[0] + 1}, column 'vehicle_class': unknown "
                    f"class {cls!r}; expected one of {sorted(site.classes)}"
                )
        made = site.radar(str(names[sel[0]])).measured_at(ts)
        z = np.stack([r[sel], az[sel], vr[sel]], -1)
        out.append(ObjectDetections(int(obj), str(names[sel[0]]), made, z, cls))
    return out


__all__ = [
    "COLUMNS",
    "SCENE_COLUMNS",
    "ObjectDetections",
    "detections_frame",
    "read_detections",
    "read_scene_detections",
]
