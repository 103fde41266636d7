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
from functools import lru_cache

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
    """An approach script on ``road`` starting at ``speed_kmh``.

    ``kind``: "pass" (constant speed), "stop" or "emergency" (to the stop line; with
    ``dwell_s > 0`` the vehicle then waits and pulls away at its class acceleration, jerk
    2 m/s^3, up to the initial speed), or "random" (Singer acceleration, DOMAIN 7(a): time
    constant 3 s, RMS 4.35 m/s^2, clipped to the class limits, speed >= 0).
    """

    name: str
    kind: str
    speed_kmh: float
    road: str
    dwell_s: float = 0.0


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
    Case("stop_go_60", "stop", 60.0, "B", dwell_s=5.0),
    Case("random_60", "random", 60.0, "B"),
)
RANDOM_TIME_CONSTANT_S = 3.0
RANDOM_ACCEL_STD_MPS2 = 4.35


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
    if case.kind == "random":
        return 1.2 * start_m / v0
    decel, jerk = _braking(case, vehicle)
    t_brake = (start_m - stop_line_m - _braking_distance(v0, decel, jerk)) / v0
    t_j = decel / jerk
    t_stop = (
        t_j + max(v0 - decel * t_j / 2, 0.0) / decel
        if v0 > decel * t_j / 2
        else float(np.sqrt(2 * v0 / jerk))
    )
    if case.dwell_s > 0:  # dwell, then pull away over the stop line to the crossing
        t_up = vehicle.accel_mps2 / JERK_NORMAL
        return (
            t_brake
            + t_stop
            + case.dwell_s
            + t_up
            + float(np.sqrt(2 * stop_line_m / vehicle.accel_mps2))
            + 1.0
        )
    return t_brake + t_stop + 2.0


def along_road_profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Along-road position, speed and acceleration of the front at ``times`` [s from start].

    Integrated exactly with piecewise-constant jerk on a grid 10x finer than ``times``. The
    vehicle drives until the end of ``times`` (past the crossing for passes; stopped, then
    pulling away for stops). Results are cached (read-only arrays): every block of Monte-Carlo
    runs of a scripted case drives the same profile.
    """
    times = np.asarray(times, dtype=float)
    return _profile(case, vehicle, float(start_m), float(stop_line_m), times.tobytes())


@lru_cache(maxsize=256)
def _profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times_bytes: bytes
) -> tuple[FloatArray, FloatArray, FloatArray]:
    out = _integrate_profile(
        case, vehicle, start_m, stop_line_m, np.frombuffer(times_bytes, dtype=float)
    )
    for a in out:
        a.setflags(write=False)
    return out


def _integrate_profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    v0 = case.speed_kmh * KMH
    if case.kind == "pass":
        return start_m - v0 * times, np.full(times.shape, v0), np.zeros(times.shape)
    if case.kind == "random":
        raise ValueError("random cases need an rng: use random_profiles()")
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
        pulling = stopped_at is not None and case.dwell_s > 0 and t >= stopped_at + case.dwell_s
        if stopped_at is not None and not pulling:
            continue
        if pulling:  # jerk-limited pull-away up to the class acceleration, then to v0
            j = JERK_NORMAL if (a_c < vehicle.accel_mps2 and v_c < v0) else 0.0
            j_eff = min(j, (vehicle.accel_mps2 - a_c) / dt)
            if v_c >= v0:
                a_c, j_eff = 0.0, 0.0
            dv = a_c * dt + j_eff * dt**2 / 2
            ds = v_c * dt + a_c * dt**2 / 2 + j_eff * dt**3 / 6
            s_c, v_c, a_c = s_c - ds, v_c + dv, a_c + j_eff * dt
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


def random_profiles(
    case: Case,
    vehicle: VehicleClass,
    start_m: float,
    times: FloatArray,
    n_runs: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per-run along-road position, speed, acceleration (n_runs, T) of a random approach.

    The acceleration is sampled exactly as a Singer (Gauss-Markov) process on the sample grid,
    clipped to ``[-emergency decel, class accel]``; the speed is kept in ``[0, class top
    speed]`` and the position integrated with the trapezoidal rule.
    """
    v0 = case.speed_kmh * KMH
    n = times.size
    dt = np.diff(times, prepend=times[0])
    rho = np.exp(-dt / RANDOM_TIME_CONSTANT_S)
    a = np.zeros((n_runs, n))
    xi = rng.standard_normal((n_runs, n))
    for k in range(1, n):
        a[:, k] = rho[k] * a[:, k - 1] + np.sqrt(1 - rho[k] ** 2) * RANDOM_ACCEL_STD_MPS2 * xi[:, k]
    a = np.clip(a, -vehicle.emergency_decel_mps2, vehicle.accel_mps2)
    v = np.empty((n_runs, n))
    v[:, 0] = v0
    for k in range(1, n):
        v[:, k] = np.clip(v[:, k - 1] + a[:, k - 1] * dt[k], 0.0, vehicle.max_speed_kmh * KMH)
    a_eff = np.diff(v, axis=1, prepend=v[:, :1]) / np.where(dt > 0, dt, 1.0)
    s = start_m - np.concatenate(
        [np.zeros((n_runs, 1)), np.cumsum(0.5 * (v[:, 1:] + v[:, :-1]) * dt[1:], axis=1)], 1
    )
    return s, v, a_eff


__all__ = [
    "DEFAULT_CASES",
    "VEHICLES",
    "Case",
    "VehicleClass",
    "along_road_profile",
    "applicable",
    "case_duration",
    "random_profiles",
]
