"""Reading radar and velocity measurement tables for navigation smoothing.

One row per node, ``time_s`` plus one complete group:

* radar: ``range_m``, ``azimuth_deg`` or ``azimuth_rad`` (clockwise from north),
  ``elevation_deg`` or ``elevation_rad``;
* velocity (a second source): ``velocity_east_mps``, ``velocity_north_mps``,
  ``velocity_up_mps`` in the radar's ENU frame.

A radar that measures range-rate (``range_rate_mps``, optionally ``range_accel_mps2``) is
read as a radar record (:func:`read_radar_record`): its samples become triple nodes (spec
D.2), not converted positions. Degrees are converted once, here. Times must be strictly
increasing within each group.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .._typing import FloatArray
from ..coords.radar import polar_to_enu, polar_to_enu_cov
from .radar_plots import angle_column, read_radar_log
from .tables import (
    DataFormatError,
    check_increasing,
    check_radar_values,
    numeric_column,
    read_table,
    require_columns,
)

VELOCITY_COLUMNS = ["velocity_east_mps", "velocity_north_mps", "velocity_up_mps"]
RATE_COLUMNS = ["range_rate_mps", "range_accel_mps2"]
KNOWN_COLUMNS = {
    "time_s", "range_m", "azimuth_deg", "azimuth_rad", "elevation_deg", "elevation_rad",
    *VELOCITY_COLUMNS, *RATE_COLUMNS,
}  # fmt: skip


@dataclass(frozen=True, eq=False)
class NavigationNodes:
    """Position nodes (radar, converted to ENU) and velocity nodes of a second source.

    Attributes
    ----------
    radar_times : ndarray, shape (K,)
    radar_position, radar_cov : ndarray, shapes (K, 3), (K, 3, 3)
        ENU positions [m] and their covariance.
    velocity_times : ndarray, shape (J,)
    velocity, velocity_cov : ndarray, shapes (J, 3), (J, 3, 3)
        ENU velocities [m/s] and their covariance.
    """

    radar_times: FloatArray
    radar_position: FloatArray
    radar_cov: FloatArray
    velocity_times: FloatArray
    velocity: FloatArray
    velocity_cov: FloatArray


def read_navigation_measurements(
    path: str | Path,
    *,
    range_std_m: float,
    azimuth_std_rad: float,
    elevation_std_rad: float,
    velocity_std_mps: float,
    frame: pd.DataFrame | None = None,
) -> NavigationNodes:
    """Read a measurement table into ENU position and velocity nodes with covariances.

    ``frame``: the table already read from ``path`` (it is not read again).
    """
    p = Path(path)
    frame = read_table(p) if frame is None else frame
    _check_columns(frame, p)
    if any(c in frame.columns for c in RATE_COLUMNS):
        raise DataFormatError(
            f"{p}: a radar with range-rate is read as a record (read_radar_record: triple "
            "nodes), not as converted position nodes"
        )
    t = numeric_column(frame, "time_s", p)
    has_radar = "range_m" in frame.columns
    has_vel = all(c in frame.columns for c in VELOCITY_COLUMNS)
    if not has_radar:
        raise DataFormatError(f"{p}: missing column 'range_m' (radar nodes are required)")
    rng_m = numeric_column(frame, "range_m", p, allow_nan=True)
    az = angle_column(frame, "azimuth", p, allow_nan=True)[0]
    el = angle_column(frame, "elevation", p, allow_nan=True)[0]
    radar_group = np.stack([rng_m, az, el], -1)
    vel = (
        np.stack([numeric_column(frame, c, p, allow_nan=True) for c in VELOCITY_COLUMNS], -1)
        if has_vel
        else np.full((t.size, 3), np.nan)
    )
    r_full = np.all(np.isfinite(radar_group), -1)
    v_full = np.all(np.isfinite(vel), -1)
    partial = (np.any(np.isfinite(radar_group), -1) & ~r_full) | (
        np.any(np.isfinite(vel), -1) & ~v_full
    )
    neither = ~r_full & ~v_full
    both = r_full & v_full
    for bad, what in (
        (partial, "an incomplete radar or velocity group"),
        (neither, "no complete radar or velocity group"),
        (both, "both a radar and a velocity group (one node per row)"),
    ):
        if bad.any():
            raise DataFormatError(f"{p}: row {int(np.argmax(bad)) + 1}: {what}")
    check_radar_values(p, np.where(r_full, rng_m, 1.0))
    check_increasing(t[r_full], p, "time_s (radar rows)")
    check_increasing(t[v_full], p, "time_s (velocity rows)")
    if r_full.sum() < 3:
        raise DataFormatError(f"{p}: at least 3 radar rows are needed; got {int(r_full.sum())}")
    polar = radar_group[r_full]
    cov = polar_to_enu_cov(
        polar, np.diag([range_std_m**2, azimuth_std_rad**2, elevation_std_rad**2])
    )
    nv = int(v_full.sum())
    return NavigationNodes(
        t[r_full],
        polar_to_enu(polar),
        cov,
        t[v_full],
        vel[v_full],
        np.broadcast_to(velocity_std_mps**2 * np.eye(3), (nv, 3, 3)),
    )


def _check_columns(frame: pd.DataFrame, p: Path) -> None:
    """Name the columns no smoother reads (never ignored silently) and require ``time_s``."""
    if "time_s" not in frame.columns:
        raise DataFormatError(f"{p}: missing column 'time_s'; found {list(frame.columns)}")
    unknown = [str(c) for c in frame.columns if c not in KNOWN_COLUMNS]
    if unknown:
        raise DataFormatError(
            f"{p}: unknown column(s) {unknown}: the smoother would not use them (it reads "
            f"{sorted(KNOWN_COLUMNS)}); drop or rename them"
        )


def read_radar_record(path: str | Path, frame: pd.DataFrame | None = None) -> RadarRecord:
    """Read one target's radar samples with range-rate: every row a complete radar sample.

    ``time_s, range_m, azimuth_*, elevation_*, range_rate_mps[, range_accel_mps2]``, read by
    :func:`~adaptrack.io.radar_plots.read_radar_log`; any other column is refused, velocity
    rows of a second source too (not combined with triple nodes). ``frame``: the table
    already read from ``path``.
    """
    p = Path(path)
    frame = read_table(p) if frame is None else frame
    _check_columns(frame, p)
    require_columns(frame, ["range_m", "range_rate_mps"], p)
    if any(c in frame.columns for c in VELOCITY_COLUMNS):
        raise DataFormatError(
            f"{p}: velocity rows of a second source are not combined with a radar's triple "
            "nodes; smooth them in a file without range_rate_mps"
        )
    log = read_radar_log(p, "radar3d", frame)
    return RadarRecord(log.times, log.plots[:, :3], log.plots[:, 3], log.range_accel)


@dataclass(frozen=True)
class RadarRecord:
    """One target's radar samples.

    Times [s], (range [m], azimuth, elevation [rad]) (n, 3), range-rate [m/s] and, if
    measured, range acceleration [m/s^2].
    """

    times: np.ndarray
    polar: np.ndarray
    range_rate: np.ndarray
    range_accel: np.ndarray | None


__all__ = ["NavigationNodes", "RadarRecord", "read_navigation_measurements", "read_radar_record"]
