"""Candidate families of road-constrained estimators and their tunable parameters.

Every family is the road-constrained EKF (:func:`~.tracking.track_on_road`) with one along-road
motion model, or the IMM of two of them (:func:`~.tracking.track_on_road_imm`):

=========  ============================================  ======================================
key        model                                         parameters (searched in log space)
=========  ============================================  ======================================
``cv``     constant velocity (the rectilinear baseline)  ``accel_psd`` [m^2/s^3]
``ca``     constant acceleration                         ``jerk_psd`` [m^2/s^5]
``singer`` Singer acceleration (spec A)                  ``time_constant_s``, ``accel_std_mps2``
``m1``     M1 inverse dynamics (spec B.3)                ``lambda_per_s2`` (profile, 0 = CV),
                                                         ``accel_psd``
``m2``     M2 shaping filter (spec B.4)                  ``lambda_per_s2``, ``alpha_per_s``,
                                                         ``shaping_std``
``imm``    IMM of CV and CA                              ``accel_psd``, ``jerk_psd``,
                                                         ``sojourn_s`` (both modes)
=========  ============================================  ======================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..._backend import Backend
from ...models.adaptive import InverseDynamics, ShapingFilter, singer_accel_std
from ...models.continuous import ConstantAcceleration, ConstantVelocity, MotionModel, Singer
from .trackers import IMMTracker, RoadTracker

M1_LAMBDAS = (0.0, 1e-3, 1e-2, 0.1, 1.0)  # the profile grid of M1 (0: the CV member)


@dataclass(frozen=True)
class Parameter:
    """A tunable parameter: name, unit, starting value and search bounds (> 0)."""

    name: str
    unit: str
    start: float
    lower: float
    upper: float


@dataclass(frozen=True)
class Family:
    """A candidate estimator family (see the module docstring)."""

    key: str
    label: str
    parameters: tuple[Parameter, ...]

    def tracker(
        self, values: dict[str, float], backend: Backend = "auto"
    ) -> RoadTracker | IMMTracker:
        """Return the family's tracker with the given parameter values."""
        missing = [p.name for p in self.parameters if p.name not in values]
        if missing:
            raise ValueError(f"family {self.key!r} needs {', '.join(missing)}")
        v = {p.name: float(values[p.name]) for p in self.parameters}
        if self.key == "imm":
            return IMMTracker(
                (ConstantVelocity(accel_psd=v["accel_psd"]), ConstantAcceleration(v["jerk_psd"])),
                (v["sojourn_s"], v["sojourn_s"]),
                backend,
            )
        return RoadTracker(_model(self.key, v), backend)


def _model(key: str, v: dict[str, float]) -> MotionModel:
    if key == "cv":
        return ConstantVelocity(accel_psd=v["accel_psd"])
    if key == "ca":
        return ConstantAcceleration(jerk_psd=v["jerk_psd"])
    if key == "singer":
        return Singer(time_constant_s=v["time_constant_s"], accel_std_mps2=v["accel_std_mps2"])
    if key == "m1":
        return InverseDynamics(lambda_per_s2=v["lambda_per_s2"], accel_psd=v["accel_psd"])
    return ShapingFilter(
        lambda_per_s2=v["lambda_per_s2"], alpha_per_s=v["alpha_per_s"], shaping_std=v["shaping_std"]
    )


_SIGMA_A = singer_accel_std(9.0, 0.05, 0.5)  # Singer's rule for road vehicles (DOMAIN 7(a))

FAMILIES = {
    f.key: f
    for f in (
        Family("cv", "road EKF (CV)", (Parameter("accel_psd", "m^2/s^3", 1.0, 1e-3, 1e3),)),
        Family("ca", "road EKF (CA)", (Parameter("jerk_psd", "m^2/s^5", 3.0, 1e-2, 1e4),)),
        Family(
            "singer",
            "road EKF (Singer)",
            (
                Parameter("time_constant_s", "s", 3.0, 0.1, 100.0),
                Parameter("accel_std_mps2", "m/s^2", 2.0, 0.05, 20.0),
            ),
        ),
        Family(
            "m1",
            "road EKF (M1)",
            (
                Parameter("lambda_per_s2", "1/s^2", 0.0, 0.0, max(M1_LAMBDAS)),
                Parameter("accel_psd", "m^2/s^3", 1.0, 1e-3, 1e3),
            ),
        ),
        Family(
            "m2",
            "road EKF (M2)",
            (
                Parameter("lambda_per_s2", "1/s^2", 0.05, 1e-4, 10.0),
                Parameter("alpha_per_s", "1/s", 1.0 / 3.0, 1e-2, 10.0),
                Parameter("shaping_std", "m/s", _SIGMA_A / math.sqrt(0.05), 1e-2, 1e3),
            ),
        ),
        Family(
            "imm",
            "road IMM (CV + CA)",
            (
                Parameter("accel_psd", "m^2/s^3", 0.1, 1e-3, 1e2),
                Parameter("jerk_psd", "m^2/s^5", 10.0, 1e-2, 1e4),
                Parameter("sojourn_s", "s", 5.0, 0.2, 100.0),
            ),
        ),
    )
}


__all__ = ["FAMILIES", "M1_LAMBDAS", "Family", "Parameter"]
