"""Recorded position logs (GNSS, local positions): read them, and write estimates as tables.

A log has ``time_s`` (or ``t_s``) and one layout's columns; GNSS fixes are converted to a local
east-north-up frame at the log's first fix, and estimates are converted back to latitude,
longitude and altitude. Fitting and filtering a log: :mod:`adaptrack.tuning.log_fit`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from .._typing import FloatArray
from ..coords.geodetic import ecef_to_enu, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef
from .radar_plots import RADAR_LAYOUTS, RadarLog
from .tables import (
    DataFormatError,
    check_increasing,
    ground_velocity,
    numeric_column,
    read_table,
    require_columns,
)

Measurement = Literal["gnss", "position"]
MEASUREMENTS: tuple[str, ...] = ("gnss", "position")
ALL_MEASUREMENTS: tuple[str, ...] = MEASUREMENTS + RADAR_LAYOUTS  # what `adaptrack fit` reads
_COLUMNS = {  # measured columns of each layout (the last is optional: a planar log)
    "gnss": ("lat_deg", "lon_deg", "alt_m"),
    "position": ("east_m", "north_m", "up_m"),
}


@dataclass(frozen=True)
class PositionLog:
    """One recording's positions in a local frame.

    ``times`` (T,) [s]; ``enu`` (T, k) east, north (and up) [m]; ``origin`` the geodetic
    origin of the frame (latitude, longitude [rad], height [m]) for a GNSS log, else None;
    ``unused`` the file's columns that are not read; ``velocity`` the log's velocity reports
    in the same frame, if it has them.
    """

    times: FloatArray
    enu: FloatArray
    origin: tuple[float, float, float] | None
    unused: tuple[str, ...]
    velocity: FloatArray | None = None  # (T, k) the log's own velocity reports [m/s] (NaN: none)

    @property
    def n_axes(self) -> int:
        """Measured axes: 2 (planar) or 3."""
        return int(self.enu.shape[1])


def read_position_log(path: str | Path, measurement: Measurement) -> PositionLog:
    """Read a position log: ``time_s`` (or ``t_s``) and the layout's columns.

    ``gnss``: ``lat_deg, lon_deg`` and optionally ``alt_m`` (WGS-84), converted to east-north-up
    at the first fix; ``position``: ``east_m, north_m`` and optionally ``up_m``. Times must
    increase; values must be finite (errors name the row and column). Velocity reports are
    read where present (empty cells: none that epoch): ``velocity_east_mps,
    velocity_north_mps[, velocity_up_mps]``, or ``groundspeed_mps, track_deg[,
    vertical_rate_mps]`` (the project's flight files).
    """
    if measurement not in MEASUREMENTS:
        raise ValueError(f"measurement must be one of {MEASUREMENTS}; got {measurement!r}")
    p = Path(path)
    frame = read_table(p)
    time_col = "time_s" if "time_s" in frame.columns or "t_s" not in frame.columns else "t_s"
    wanted = _COLUMNS[measurement]
    require_columns(frame, [time_col, *wanted[:2]], p)
    cols = [c for c in wanted if c in frame.columns]
    t = numeric_column(frame, time_col, p)
    check_increasing(t, p, time_col)
    if t.size < 2:
        raise DataFormatError(f"{p}: a position log needs at least 2 fixes; got {t.size}")
    values = np.stack([numeric_column(frame, c, p) for c in cols], axis=-1)
    velocity, vel_cols = _velocity_reports(frame, p, values.shape[1])
    unused = tuple(str(c) for c in frame.columns if c not in (time_col, *cols, *vel_cols))
    if measurement == "position":
        return PositionLog(t, values, None, unused, velocity)
    lat, lon = np.deg2rad(values[:, 0]), np.deg2rad(values[:, 1])
    if np.any(np.abs(values[:, 0]) > 90) or np.any(np.abs(values[:, 1]) > 360):
        row = int(np.argmax((np.abs(values[:, 0]) > 90) | (np.abs(values[:, 1]) > 360)))
        raise DataFormatError(f"{p}: row {row + 1}: latitude/longitude out of range (degrees)")
    alt = values[:, 2] if values.shape[1] == 3 else np.zeros(t.size)
    origin = (float(lat[0]), float(lon[0]), float(alt[0]))
    enu = ecef_to_enu(geodetic_to_ecef(lat, lon, alt), *origin)
    return PositionLog(t, enu[:, : values.shape[1]], origin, unused, velocity)


def _velocity_reports(
    frame: pd.DataFrame, path: Path, k: int
) -> tuple[FloatArray | None, tuple[str, ...]]:
    """Return the log's velocity reports (T, k) [m/s], east-north(-up), and their columns."""
    names = ("velocity_east_mps", "velocity_north_mps", "velocity_up_mps")[:k]
    if all(c in frame.columns for c in names):
        cols = [numeric_column(frame, c, path, allow_nan=True) for c in names]
        return np.stack(cols, axis=-1), names
    if {"groundspeed_mps", "track_deg"} <= set(frame.columns):
        speed = numeric_column(frame, "groundspeed_mps", path, allow_nan=True)
        track = np.deg2rad(numeric_column(frame, "track_deg", path, allow_nan=True))
        used: tuple[str, ...] = ("groundspeed_mps", "track_deg")
        up = None
        if k == 3:
            has_up = "vertical_rate_mps" in frame.columns
            up = (
                numeric_column(frame, "vertical_rate_mps", path, allow_nan=True)
                if has_up
                else np.full(speed.size, np.nan)
            )
            used += ("vertical_rate_mps",) if has_up else ()
        return ground_velocity(speed, track, up), used
    return None, ()


def estimates_table(
    log: PositionLog | RadarLog,
    mean: FloatArray,
    cov: FloatArray,
    offset_s: float = 0.0,
    turn_rate: bool = False,
    probabilities: dict[str, FloatArray] | None = None,
) -> pd.DataFrame:
    """Estimates as a table: position, velocity, their sigmas, the position covariance.

    ``time_s, east_m, north_m(, up_m), velocity_east_mps, ...``, ``*_std_*``, ``cov_e_n`` (and
    ``cov_e_u``, ``cov_n_u``); ``turn_rate_radps`` and its sigma if ``turn_rate`` (the
    coordinated turn's last state, counter-clockwise positive); ``probability_<model>``
    for each of an IMM's ``probabilities`` (name: (T,)); with a clock offset [s]
    (fixes stamped that late), ``corrected_time_s``: when each fix was made; for a GNSS log
    also ``lat_deg, lon_deg, alt_m``.
    """
    k = log.n_axes
    names = ("east", "north", "up")[:k]
    cols: dict[str, FloatArray] = {"time_s": log.times}
    for a, name in enumerate(names):
        cols[f"{name}_m"] = mean[:, a]
    for a, name in enumerate(names):
        cols[f"velocity_{name}_mps"] = mean[:, k + a]
    for a, name in enumerate(names):
        cols[f"{name}_std_m"] = np.sqrt(cov[:, a, a])
    for a, name in enumerate(names):
        cols[f"velocity_{name}_std_mps"] = np.sqrt(cov[:, k + a, k + a])
    for a in range(k):
        for b in range(a + 1, k):
            cols[f"cov_{names[a][0]}_{names[b][0]}"] = cov[:, a, b]
    if turn_rate:
        cols["turn_rate_radps"], cols["turn_rate_std_radps"] = mean[:, -1], np.sqrt(cov[:, -1, -1])
    for name, p in (probabilities or {}).items():
        cols[f"probability_{name}"] = p
    if offset_s:
        cols["corrected_time_s"] = log.times - offset_s
    if log.origin is not None:
        enu = np.zeros((log.times.size, 3))
        enu[:, :k] = mean[:, :k]
        lat, lon, alt = ecef_to_geodetic(enu_to_ecef(enu, *log.origin))
        cols["lat_deg"], cols["lon_deg"] = np.rad2deg(lat), np.rad2deg(lon)
        if k == 3:
            cols["alt_m"] = alt
    return pd.DataFrame(cols)


__all__ = [
    "ALL_MEASUREMENTS",
    "MEASUREMENTS",
    "Measurement",
    "PositionLog",
    "estimates_table",
    "read_position_log",
]
