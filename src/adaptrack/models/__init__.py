"""Continuous-time motion models and their discretisation.

Models: :class:`ConstantVelocity`, :class:`ConstantAcceleration`, :class:`Singer` (seed 000),
:class:`InverseDynamics` (M1) and :class:`ShapingFilter` (M2) of seed 001, and a generic
:class:`LinearSDE`. Measurement models for the EKF and UKF: :class:`RadarMeasurement`,
:class:`GeodeticMeasurement`, :class:`PositionMeasurement`, :class:`FunctionMeasurement`.
A nonlinear motion model for them: :class:`CoordinatedTurn` (a :class:`NonlinearMotionModel`).
State order: all positions, then velocities, then higher states.
"""

from .adaptive import InverseDynamics, ShapingFilter, singer_accel_std
from .continuous import (
    ConstantAcceleration,
    ConstantVelocity,
    LinearSDE,
    MotionModel,
    Singer,
    drift_matrix,
    filterpy_order,
    measurement_matrix,
    noise_input_matrix,
    noise_psd,
    seed000_permutation,
)
from .discretize import Discretization, control_offset, discretize, discretize_with_input
from .measurement import (
    FunctionMeasurement,
    GeodeticMeasurement,
    MeasurementModel,
    PositionMeasurement,
    RadarMeasurement,
)
from .turn import CoordinatedTurn, NonlinearMotionModel

__all__ = [
    "ConstantAcceleration",
    "ConstantVelocity",
    "CoordinatedTurn",
    "Discretization",
    "FunctionMeasurement",
    "GeodeticMeasurement",
    "InverseDynamics",
    "LinearSDE",
    "MeasurementModel",
    "MotionModel",
    "NonlinearMotionModel",
    "PositionMeasurement",
    "RadarMeasurement",
    "ShapingFilter",
    "Singer",
    "control_offset",
    "discretize",
    "discretize_with_input",
    "drift_matrix",
    "filterpy_order",
    "measurement_matrix",
    "noise_input_matrix",
    "noise_psd",
    "seed000_permutation",
    "singer_accel_std",
]
