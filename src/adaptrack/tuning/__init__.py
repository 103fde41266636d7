"""Design-time adaptation of motion-model parameters (spec B.7)."""

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
    "TrackingData",
    "TuningResult",
    "rms_criterion",
    "tune_constant_acceleration",
    "tune_constant_velocity",
    "tune_inverse_dynamics",
    "tune_shaping_filter",
    "tune_singer",
]
