"""Vehicle classes and scripted approach cases (DOMAIN 7(a)), along-road kinematics.

A vehicle's reference point is its front (the face nearest the crossing). Its along-road
position ``s`` (distance of the front to the crossing centre along the road) decreases while it
approaches; speed and acceleration follow jerk-limited profiles integrated exactly on a fine
grid. Cases: constant-speed passes, a normal stop at the stop line, an emergency stop at the
stop line, and curve approaches (the same profiles on a curved road). A stopped vehicle stays
stopped (the pull-away after the dwell is not scripted yet).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray

KMH = 1 / 3.6


@dataclass(frozen=True)
class VehicleClass:
    """Kinematic limits (SUMO-derived, DOMAIN 3 and 7(a)) and size."""

    name: str
    length_m: float
    accel_mps2: float
    decel_mps2: float
    emergency_decel_mps2: float
    max_speed_kmh: float

    @property
    def scatter_std_m(self) -> float:
        """RMS wander of the reflection point along the body, 0.15 L [m]."""
        return 0.15 * self.length_m


VEHICLES = {
    "motorcycle": VehicleClass("motorcycle", 2.2, 6.0, 4.5, 9.0, 250.0),
    "car": VehicleClass("car", 5.0, 2.6, 3.4, 9.0, 250.0),
    "truck": VehicleClass("truck", 7.1, 1.3, 3.0, 7.0, 130.0),
    "bus": VehicleClass("bus", 12.0, 1.2, 3.0, 7.0, 100.0),
}
JERK_NORMAL = 2.0
JERK_EMERGENCY = 12.0


@dataclass(frozen=True)
class Case:
    """An approach script: ``kind`` "pass", "stop" or "emergency" at ``speed_kmh`` on ``road``."""

    name: str
    kind: str
    speed_kmh: float
    road: str


DEFAULT_CASES = (
    Case("pass_5", "pass", 5.0, "B"),
    Case("pass_20", "pass", 20.0, "B"),
    Case("pass_60", "pass", 60.0, "B"),
    Case("pass_100", "pass", 100.0, "B"),
    Case("pass_250", "pass", 250.0, "B"),
    Case("stop_60", "stop", 60.0, "B"),
    Case("emergency_90", "emergency", 90.0, "B"),
    Case("curve_60", "pass", 60.0, "A"),
    Case("curve_stop_60", "stop", 60.0, "A"),
)


def applicable(case: Case, vehicle: VehicleClass) -> bool:
    """Whether a vehicle class can drive a case (its top speed)."""
    return case.speed_kmh <= vehicle.max_speed_kmh


def _braking_distance(v0: float, decel: float, jerk: float) -> float:
    t_j = decel / jerk
    v_after = v0 - decel * t_j / 2
    if v_after <= 0:  # never reaches full deceleration
        t_stop = np.sqrt(2 * v0 / jerk)
        return float(v0 * t_stop - jerk * t_stop**3 / 6)
    return float(v0 * t_j - jerk * t_j**3 / 6 + v_after**2 / (2 * decel))


def _braking(case: Case, vehicle: VehicleClass) -> tuple[float, float]:
    if case.kind == "stop":
        return min(vehicle.decel_mps2, 3.4), JERK_NORMAL
    if case.kind == "emergency":
        return min(vehicle.emergency_decel_mps2, 8.0), JERK_EMERGENCY
    raise ValueError(f"case kind must be 'pass', 'stop' or 'emergency'; got {case.kind!r}")


def case_duration(case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float) -> float:
    """Time [s] until the front reaches the crossing centre (passes) or 2 s after the stop."""
    v0 = case.speed_kmh * KMH
    if case.kind == "pass":
        return start_m / v0
    decel, jerk = _braking(case, vehicle)
    t_brake = (start_m - stop_line_m - _braking_distance(v0, decel, jerk)) / v0
    t_j = decel / jerk
    t_stop = (
        t_j + max(v0 - decel * t_j / 2, 0.0) / decel
        if v0 > decel * t_j / 2
        else float(np.sqrt(2 * v0 / jerk))
    )
    return t_brake + t_stop + 2.0


def along_road_profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Along-road position, speed and acceleration of the front at ``times`` [s from start].

    Integrated exactly with piecewise-constant jerk on a grid 10x finer than ``times``. The
    vehicle drives until the end of ``times`` (past the crossing for passes; stopped, then
    pulling away for stops).
    """
    v0 = case.speed_kmh * KMH
    if case.kind == "pass":
        return start_m - v0 * times, np.full(times.shape, v0), np.zeros(times.shape)
    decel, jerk = _braking(case, vehicle)
    brake_at = stop_line_m + _braking_distance(v0, decel, jerk)
    t_brake = (start_m - brake_at) / v0
    if t_brake < 0:
        raise ValueError(f"case {case.name}: braking must start before the track start")
    dt = float(np.min(np.diff(times))) / 10 if times.size > 1 else 0.005
    n = int(np.ceil(times[-1] / dt)) + 2
    tf = dt * np.arange(n)
    s = np.empty(n)
    v = np.empty(n)
    a = np.empty(n)
    s_c, v_c, a_c = start_m, v0, 0.0
    stopped_at = None
    for i, t in enumerate(tf):
        s[i], v[i], a[i] = s_c, v_c, a_c
        if stopped_at is not None:
            continue
        j = 0.0 if t < t_brake else (-jerk if a_c > -decel else 0.0)
        j_eff = (-decel - a_c) / dt if j < 0 and a_c + j * dt < -decel else j
        dv = a_c * dt + j_eff * dt**2 / 2
        ds = v_c * dt + a_c * dt**2 / 2 + j_eff * dt**3 / 6
        if stopped_at is None and t >= t_brake and v_c + dv <= 0:
            frac = v_c / max(-dv, 1e-12)  # stop inside this step (linear in the speed)
            s_c, v_c, a_c = s_c - max(ds * frac, 0.0), 0.0, 0.0
            stopped_at = t + dt
            continue
        s_c, v_c, a_c = s_c - ds, v_c + dv, a_c + j_eff * dt
    return (np.interp(times, tf, s), np.interp(times, tf, v), np.interp(times, tf, a))


__all__ = [
    "DEFAULT_CASES",
    "VEHICLES",
    "Case",
    "VehicleClass",
    "along_road_profile",
    "applicable",
    "case_duration",
]
