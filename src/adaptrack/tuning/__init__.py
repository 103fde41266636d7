"""Design-time adaptation (spec B.7); truth-free ML tuning, also causal; clock calibration."""

from .calibration import fit_clock_offset, fit_radar_bias
from .causal import OnlineFit, refit_online
from .em import EMFit, em_fit
from .likelihood import LikelihoodFit, fit_by_likelihood
from .optimize import (
    TrackingData,
    TuningResult,
    rms_criterion,
    tune_constant_acceleration,
    tune_constant_velocity,
    tune_inverse_dynamics,
    tune_shaping_filter,
    tune_singer,
)

__all__ = [
    "EMFit",
    "LikelihoodFit",
    "OnlineFit",
    "TrackingData",
    "TuningResult",
    "em_fit",
    "fit_by_likelihood",
    "fit_clock_offset",
    "fit_radar_bias",
    "refit_online",
    "rms_criterion",
    "tune_constant_acceleration",
    "tune_constant_velocity",
    "tune_inverse_dynamics",
    "tune_shaping_filter",
    "tune_singer",
]
