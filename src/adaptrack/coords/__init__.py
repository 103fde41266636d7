"""Coordinate frames: WGS-84 geodetic, ECEF, local ENU and radar polar, with Jacobians."""

from .geodetic import (
    ecef_to_enu,
    ecef_to_geodetic,
    enu_to_ecef,
    enu_to_ecef_rotation,
    geodetic_to_ecef,
    rotate_cov,
)
from .radar import (
    enu_to_polar,
    enu_to_polar_rates,
    polar_kinematics_cov_to_ecef,
    polar_kinematics_jacobian,
    polar_kinematics_to_enu,
    polar_to_enu,
    polar_to_enu_cov,
)

__all__ = [
    "ecef_to_enu",
    "ecef_to_geodetic",
    "enu_to_ecef",
    "enu_to_ecef_rotation",
    "enu_to_polar",
    "enu_to_polar_rates",
    "geodetic_to_ecef",
    "polar_kinematics_cov_to_ecef",
    "polar_kinematics_jacobian",
    "polar_kinematics_to_enu",
    "polar_to_enu",
    "polar_to_enu_cov",
    "rotate_cov",
]
