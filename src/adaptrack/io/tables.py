"""Tables in and out: validation with file, row and column in every error; atomic writes."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .._files import write_atomic
from .._typing import FloatArray


class DataFormatError(ValueError):
    """A file does not have the expected columns, units or values."""


def read_table(path: str | Path) -> pd.DataFrame:
    """Read a CSV or Parquet table (by suffix); errors name the file."""
    p = Path(path)
    if not p.is_file():
        raise DataFormatError(f"{p}: no such file")
    try:
        if p.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(p)
        return pd.read_csv(p)
    except (ValueError, OSError) as exc:
        raise DataFormatError(f"{p}: cannot be read as a table: {exc}") from None


def write_table_atomic(frame: pd.DataFrame, path: str | Path) -> None:
    """Write CSV or Parquet (by suffix) atomically."""
    if Path(path).suffix.lower() in (".parquet", ".pq"):
        write_atomic(path, lambda tmp: frame.to_parquet(tmp, index=False))
    else:
        write_atomic(path, lambda tmp: frame.to_csv(tmp, index=False, float_format="%.10g"))


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write a text file (UTF-8) atomically."""
    write_atomic(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def require_columns(frame: pd.DataFrame, columns: list[str], path: Path) -> None:
    """Raise DataFormatError naming the file and the missing columns."""
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise DataFormatError(f"{path}: missing column(s) {missing}; found {list(frame.columns)}")


def numeric_column(
    frame: pd.DataFrame, column: str, path: Path, *, allow_nan: bool = False
) -> FloatArray:
    """Return a column as float64; errors name file, row (1-based data row) and column."""
    values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=np.float64)
    raw_missing = frame[column].isna().to_numpy()
    bad = np.isnan(values) & ~raw_missing
    if bad.any():
        row = int(np.argmax(bad))
        raise DataFormatError(
            f"{path}: row {row + 1}, column {column!r}: not a number ({frame[column].iloc[row]!r})"
        )
    if not allow_nan and raw_missing.any():
        row = int(np.argmax(raw_missing))
        raise DataFormatError(f"{path}: row {row + 1}, column {column!r}: empty value")
    if np.isinf(values).any():
        row = int(np.argmax(np.isinf(values)))
        raise DataFormatError(f"{path}: row {row + 1}, column {column!r}: infinite value")
    return values


PLAUSIBLE_RANGE_M = 1e7  # no radar reaches further (a bound that keeps the arithmetic finite)
PLAUSIBLE_SPEED_MPS = 1e5  # no target is faster


def check_radar_values(
    path: Path, range_m: FloatArray, range_rate_mps: FloatArray | None = None
) -> None:
    """Raise DataFormatError for implausible radar values, naming the row and column.

    A range must lie in (0, 1e7] m and a range-rate within 1e5 m/s; NaN entries (no radar
    sample on that row) pass.
    """
    bad = (range_m <= 0) | (range_m > PLAUSIBLE_RANGE_M)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise DataFormatError(
            f"{path}: row {row + 1}, column 'range_m': {range_m[row]:g} m is not a radar "
            f"range (expected 0 < range <= {PLAUSIBLE_RANGE_M:g} m)"
        )
    if range_rate_mps is not None:
        fast = np.abs(range_rate_mps) > PLAUSIBLE_SPEED_MPS
        if np.any(fast):
            row = int(np.argmax(fast))
            raise DataFormatError(
                f"{path}: row {row + 1}, column 'range_rate_mps': {range_rate_mps[row]:g} m/s "
                f"is beyond any target (|range-rate| <= {PLAUSIBLE_SPEED_MPS:g} m/s)"
            )


def check_increasing(times: FloatArray, path: Path, column: str = "t_s") -> None:
    """Raise unless times are strictly increasing (names the first offending row)."""
    d = np.diff(times)
    if np.any(d <= 0):
        row = int(np.argmax(d <= 0)) + 2
        what = "duplicate" if d[row - 2] == 0 else "unsorted"
        raise DataFormatError(
            f"{path}: row {row}, column {column!r}: {what} time "
            f"{times[row - 1]} after {times[row - 2]}"
        )


@dataclass(frozen=True, eq=False)
class Flight:
    """A recorded trajectory.

    Times [s], WGS-84 latitude/longitude [rad], altitude [m] and velocity over ground
    (east, north, up) [m/s] (NaN where the source had none).
    """

    name: str
    times: FloatArray
    lat: FloatArray
    lon: FloatArray
    alt: FloatArray
    velocity_enu: FloatArray


def ground_velocity(
    groundspeed_mps: FloatArray, track_rad: FloatArray, vertical_rate_mps: FloatArray | None = None
) -> FloatArray:
    """East, north (and up) velocity [m/s] of a ground speed and a track (clockwise from north)."""
    parts = [groundspeed_mps * np.sin(track_rad), groundspeed_mps * np.cos(track_rad)]
    return np.stack(parts + ([] if vertical_rate_mps is None else [vertical_rate_mps]), axis=-1)


def read_flight_csv(path: str | Path) -> Flight:
    """Read a trajectory in the format of the project's flight data.

    Columns ``t_s, lat_deg, lon_deg, alt_m, groundspeed_mps, track_deg`` and optionally
    ``vertical_rate_mps`` (absent: 0). Degrees are converted to radians here, once.
    """
    p = Path(path)
    frame = read_table(p)
    require_columns(
        frame, ["t_s", "lat_deg", "lon_deg", "alt_m", "groundspeed_mps", "track_deg"], p
    )
    t = numeric_column(frame, "t_s", p)
    check_increasing(t, p)
    lat = numeric_column(frame, "lat_deg", p)
    lon = numeric_column(frame, "lon_deg", p)
    if np.any(np.abs(lat) > 90) or np.any(np.abs(lon) > 360):
        row = int(np.argmax((np.abs(lat) > 90) | (np.abs(lon) > 360)))
        raise DataFormatError(
            f"{p}: row {row + 1}: latitude/longitude out of range (degrees expected)"
        )
    alt = numeric_column(frame, "alt_m", p)
    gs = numeric_column(frame, "groundspeed_mps", p, allow_nan=True)
    trk = np.deg2rad(numeric_column(frame, "track_deg", p, allow_nan=True))
    vr = (
        numeric_column(frame, "vertical_rate_mps", p, allow_nan=True)
        if "vertical_rate_mps" in frame.columns
        else np.zeros_like(gs)
    )
    vel = ground_velocity(gs, trk, vr)
    return Flight(p.stem, t, np.deg2rad(lat), np.deg2rad(lon), alt, vel)


__all__ = [
    "DataFormatError",
    "Flight",
    "check_increasing",
    "ground_velocity",
    "numeric_column",
    "read_flight_csv",
    "read_table",
    "require_columns",
    "write_table_atomic",
]
