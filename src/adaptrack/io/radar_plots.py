"""A radar plot list: one target's plots in the radar's own frame, read and checked.

Columns: ``time_s`` (or ``t_s``), ``range_m``, ``azimuth_deg`` or ``azimuth_rad`` (clockwise
from north), for a 3-D radar ``elevation_deg`` or ``elevation_rad``, optionally
``range_rate_mps`` (positive receding) and, with it, ``range_accel_mps2``. Degrees are
converted once, here. Every value must be finite and plausible (errors name the file, row and
column); times strictly increasing. ``adaptrack fit``/``filter`` and ``adaptrack smooth`` read
plots with it; what a caller does with the other columns (note them, refuse them) is its
policy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from .._typing import FloatArray
from .tables import (
    DataFormatError,
    check_increasing,
    check_radar_values,
    numeric_column,
    read_table,
    require_columns,
)

RadarLayout = Literal["radar2d", "radar3d"]
RADAR_LAYOUTS: tuple[str, ...] = ("radar2d", "radar3d")
ANGLE_LIMITS = {"azimuth": 2 * np.pi, "elevation": np.pi / 2}  # |value| in radians at most


@dataclass(frozen=True)
class RadarLog:
    """One target's radar plots.

    ``times`` (T,) [s], ``plots`` (T, m) in SI units (range [m], angles [rad], range-rate
    [m/s]) of the ``components`` measured, ``range_accel`` (T,) [m/s^2] if the file has it,
    and the file's ``unused`` columns. ``origin`` is None (the radar's own frame, no geodetic
    position).
    """

    times: FloatArray
    plots: FloatArray
    components: tuple[str, ...]
    unused: tuple[str, ...]
    range_accel: FloatArray | None = None
    origin: None = None

    @property
    def n_axes(self) -> int:
        """2 for a planar radar, 3 with elevation."""
        return 3 if "elevation" in self.components else 2


def angle_column(
    frame: pd.DataFrame, name: str, path: Path, *, allow_nan: bool = False
) -> tuple[FloatArray, str]:
    """Return ``<name>_deg`` or ``<name>_rad`` in radians, and the column read.

    Both columns (mixed units), neither, or radians beyond :data:`ANGLE_LIMITS` (degrees
    given?) are errors naming the file (and row); empty cells only with ``allow_nan``.
    """
    deg, rad = f"{name}_deg", f"{name}_rad"
    if deg in frame.columns and rad in frame.columns:
        raise DataFormatError(f"{path}: both {deg!r} and {rad!r} given (mixed units); keep one")
    if rad in frame.columns:
        v = numeric_column(frame, rad, path, allow_nan=allow_nan)
        bad = np.abs(v) > ANGLE_LIMITS[name]
        if np.any(bad):
            row = int(np.argmax(bad))
            raise DataFormatError(
                f"{path}: row {row + 1}, column {rad!r}: {v[row]} is out of range for radians "
                f"(|value| <= {ANGLE_LIMITS[name]:.4g}); degrees given?"
            )
        return v, rad
    if deg in frame.columns:
        return np.deg2rad(numeric_column(frame, deg, path, allow_nan=allow_nan)), deg
    raise DataFormatError(f"{path}: missing column {deg!r} or {rad!r}")


def read_radar_log(
    path: str | Path, layout: RadarLayout, frame: pd.DataFrame | None = None
) -> RadarLog:
    """Read a radar plot list (``frame``: the table already read from ``path``)."""
    if layout not in RADAR_LAYOUTS:
        raise ValueError(f"layout must be one of {RADAR_LAYOUTS}; got {layout!r}")
    p = Path(path)
    frame = read_table(p) if frame is None else frame
    time_col = "time_s" if "time_s" in frame.columns or "t_s" not in frame.columns else "t_s"
    require_columns(frame, [time_col, "range_m"], p)
    t = numeric_column(frame, time_col, p)
    check_increasing(t, p, time_col)
    comps, values, used = ["range"], [numeric_column(frame, "range_m", p)], [time_col, "range_m"]
    for name in ("azimuth", "elevation")[: 1 + (layout == "radar3d")]:
        v, column = angle_column(frame, name, p)
        comps, values, used = [*comps, name], [*values, v], [*used, column]
    rate = accel = None
    if "range_rate_mps" in frame.columns:
        rate = numeric_column(frame, "range_rate_mps", p)
        comps, values, used = [*comps, "range_rate"], [*values, rate], [*used, "range_rate_mps"]
        if "range_accel_mps2" in frame.columns:
            accel = numeric_column(frame, "range_accel_mps2", p)
            used.append("range_accel_mps2")
    check_radar_values(p, values[0], rate)
    if t.size < 2:
        raise DataFormatError(f"{p}: a radar plot list needs at least 2 plots; got {t.size}")
    unused = tuple(str(c) for c in frame.columns if c not in used)
    return RadarLog(t, np.stack(values, axis=-1), tuple(comps), unused, accel)


__all__ = ["RADAR_LAYOUTS", "RadarLayout", "RadarLog", "angle_column", "read_radar_log"]
