"""A recorded radar plot list: read it and filter it with an EKF for a truth-free fit.

Layouts: ``radar2d`` (``time_s, range_m, azimuth_deg[, range_rate_mps]``, a planar radar)
and ``radar3d`` (``elevation_deg`` as well). One target's plots, in the radar's own frame:
east-north(-up) about the antenna, azimuth clockwise from north. The fit's parameters are the
motion PSD and one noise variance per measured component, in SI units (``r_range`` [m^2],
``r_azimuth`` and ``r_elevation`` [rad^2], ``r_range_rate`` [m^2/s^2]).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from .._typing import FloatArray
from ..coords.radar import polar_to_enu
from ..filters.ekf import ekf_filter
from ..io.tables import (
    DataFormatError,
    check_increasing,
    check_radar_values,
    numeric_column,
    read_table,
    require_columns,
)
from ..models.continuous import MotionModel
from ..models.measurement import RadarMeasurement
from ..models.turn import NonlinearMotionModel
from ..types import FilterResult, GaussianState

RadarLayout = Literal["radar2d", "radar3d"]
RADAR_LAYOUTS: tuple[str, ...] = ("radar2d", "radar3d")
_COLUMNS = {  # file column, component, scale to SI
    "range": ("range_m", 1.0),
    "azimuth": ("azimuth_deg", np.pi / 180.0),
    "elevation": ("elevation_deg", np.pi / 180.0),
    "range_rate": ("range_rate_mps", 1.0),
}
START_VARIANCE = {  # starting values of the noise variances for the fit
    "range": 10.0**2,
    "azimuth": 1e-3**2,
    "elevation": 1e-3**2,
    "range_rate": 0.5**2,
}
VELOCITY_PRIOR_STD_MPS = 100.0  # unknown at the first plot
TURN_PRIOR_STD = 0.3  # turn rate at the first plot or fix [rad/s]: unknown (17 deg/s)


@dataclass(frozen=True)
class RadarLog:
    """One target's radar plots.

    ``times`` (T,) [s], ``plots`` (T, m) in SI units, the ``components`` measured, and the
    file's ``unused`` columns. ``origin`` is None (the radar's own frame, no geodetic position).
    """

    times: FloatArray
    plots: FloatArray
    components: tuple[str, ...]
    unused: tuple[str, ...]
    origin: None = None

    @property
    def n_axes(self) -> int:
        """2 for a planar radar, 3 with elevation."""
        return 3 if "elevation" in self.components else 2


def read_radar_log(path: str | Path, layout: RadarLayout) -> RadarLog:
    """Read a radar plot list (``time_s`` or ``t_s``; angles in degrees in the file).

    Values must be finite and times increasing (errors name the row and column);
    ``range_rate_mps`` is used when the file has it.
    """
    if layout not in RADAR_LAYOUTS:
        raise ValueError(f"layout must be one of {RADAR_LAYOUTS}; got {layout!r}")
    p = Path(path)
    frame = read_table(p)
    time_col = "time_s" if "time_s" in frame.columns or "t_s" not in frame.columns else "t_s"
    comps = ["range", "azimuth"] + (["elevation"] if layout == "radar3d" else [])
    require_columns(frame, [time_col] + [_COLUMNS[c][0] for c in comps], p)
    if _COLUMNS["range_rate"][0] in frame.columns:
        comps.append("range_rate")
    t = numeric_column(frame, time_col, p)
    check_increasing(t, p, time_col)
    plots = np.stack(
        [numeric_column(frame, _COLUMNS[c][0], p) * _COLUMNS[c][1] for c in comps], axis=-1
    )
    check_radar_values(p, plots[:, 0], plots[:, -1] if "range_rate" in comps else None)
    if t.size < 2:
        raise DataFormatError(f"{p}: a radar log needs at least 2 plots; got {t.size}")
    used = {time_col, *(_COLUMNS[c][0] for c in comps)}
    unused = tuple(str(c) for c in frame.columns if c not in used)
    return RadarLog(t, plots, tuple(comps), unused)


def radar_parameters(log: RadarLog) -> dict[str, float]:
    """Return starting values of the noise variances to fit, named ``r_<component>``."""
    return {f"r_{c}": START_VARIANCE[c] for c in log.components}


def run_radar(
    log: RadarLog, motion: MotionModel | NonlinearMotionModel, values: dict[str, float]
) -> FilterResult:
    """EKF of ``log`` with the given noise variances; prior at the first plot."""
    k = log.n_axes
    radar = RadarMeasurement(
        noise_cov=np.array([values[f"r_{c}"] for c in log.components]),
        components=log.components,
        n_axes=k,
    )  # fmt: skip
    first = log.plots[0]
    polar = np.array([first[0], first[1], first[2] if k == 3 else 0.0])
    n = motion.state_dim
    mean = np.zeros(n)
    mean[:k] = polar_to_enu(polar)[:k]
    cross = first[0] ** 2 * values["r_azimuth"]  # variance across the line of sight [m^2]
    var = np.full(n, VELOCITY_PRIOR_STD_MPS**2)
    var[:k] = values["r_range"] + cross
    if isinstance(motion, NonlinearMotionModel):
        var[-1] = TURN_PRIOR_STD**2
    prior = GaussianState(mean, np.diag(var), np.asarray(log.times[0]))
    return ekf_filter(log.times, log.plots, motion, radar, prior)


__all__ = ["RADAR_LAYOUTS", "RadarLog", "radar_parameters", "read_radar_log", "run_radar"]
