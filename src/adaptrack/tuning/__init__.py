"""Design-time adaptation of motion-model parameters (spec B.7); truth-free ML tuning."""

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
    "LikelihoodFit",
    "TrackingData",
    "TuningResult",
    "fit_by_likelihood",
    "rms_criterion",
    "tune_constant_acceleration",
    "tune_constant_velocity",
    "tune_inverse_dynamics",
    "tune_shaping_filter",
    "tune_singer",
]
