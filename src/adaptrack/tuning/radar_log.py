"""A recorded radar plot list filtered with an EKF for a truth-free fit.

The plots are read by :func:`adaptrack.io.radar_plots.read_radar_log` (layouts ``radar2d``
and ``radar3d``). The fit's parameters are the motion PSD and one noise variance per measured
component, in SI units (``r_range`` [m^2], ``r_azimuth`` and ``r_elevation`` [rad^2],
``r_range_rate`` [m^2/s^2]).
"""

from __future__ import annotations

import numpy as np

from ..coords.radar import polar_to_enu
from ..io.radar_plots import RadarLog
from ..models.continuous import MotionModel
from ..models.measurement import RadarMeasurement
from ..models.turn import NonlinearMotionModel
from ..types import GaussianState

START_VARIANCE = {  # starting values of the noise variances for the fit
    "range": 10.0**2,
    "azimuth": 1e-3**2,
    "elevation": 1e-3**2,
    "range_rate": 0.5**2,
}
VELOCITY_PRIOR_STD_MPS = 100.0  # unknown at the first plot
TURN_PRIOR_STD = 0.3  # turn rate at the first plot or fix [rad/s]: unknown (17 deg/s)


def radar_parameters(log: RadarLog) -> dict[str, float]:
    """Return starting values of the noise variances to fit, named ``r_<component>``."""
    return {f"r_{c}": START_VARIANCE[c] for c in log.components}


def radar_inputs(
    log: RadarLog, motion: MotionModel | NonlinearMotionModel, values: dict[str, float]
) -> tuple[RadarMeasurement, GaussianState]:
    """Return the EKF's measurement model (these noise variances) and prior at the first plot."""
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
    return radar, GaussianState(mean, np.diag(var), np.asarray(log.times[0]))


__all__ = ["radar_inputs", "radar_parameters"]
