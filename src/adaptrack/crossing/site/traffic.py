"""Vehicle classes and approach cases (DOMAIN 7(a)), along-road kinematics.

A vehicle's reference point is its front (the face nearest the crossing). Its along-road
position ``s`` (distance of the front to the crossing centre along the road) decreases while it
approaches; speed and acceleration follow jerk-limited profiles integrated exactly on a fine
grid. Case kinds:

* ``pass``: constant speed;
* ``stop`` / ``emergency``: cruise, then jerk-limited braking to a standstill at the stop line
  (default deceleration and jerk: DOMAIN S2, ``min(class decel, 3.4 m/s^2)`` at 2 m/s^3, and
  S3, ``min(class emergency decel, 8 m/s^2)`` at 12 m/s^3; a site may give any deceleration up
  to 10 m/s^2), optionally a dwell and a pull-away at the class acceleration;
* ``random``: Singer acceleration (time constant 3 s, RMS 4.35 m/s^2 unless given), clipped to
  the class limits, speed >= 0;
* ``profile``: speed given at time knots, linear in between (a user's speed profile).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..._typing import FloatArray

KMH = 1 / 3.6
MAX_DECEL_MPS2 = 10.0
JERK_NORMAL = 2.0
JERK_EMERGENCY = 12.0
RANDOM_TIME_CONSTANT_S = 3.0
RANDOM_ACCEL_STD_MPS2 = 4.35
STOPPED_TAIL_S = 2.0  # a run ending at a standstill goes on this long after the stop


@dataclass(frozen=True)
class VehicleClass:
    """Kinematic limits (SUMO-derived, DOMAIN 3 and 7(a)) and size of a road-user class.

    ``scatter_std_m`` is the RMS wander of the radar reflection point along the body [m]
    (default ``0.15 length_m``, DOMAIN 7(a)).
    """

    name: str
    length_m: float
    width_m: float
    accel_mps2: float
    decel_mps2: float
    emergency_decel_mps2: float
    max_speed_kmh: float
    scatter_std_m: float = math.nan

    def __post_init__(self) -> None:
        if math.isnan(self.scatter_std_m):
            object.__setattr__(self, "scatter_std_m", 0.15 * self.length_m)


VEHICLES = {
    "motorcycle": VehicleClass("motorcycle", 2.2, 0.8, 6.0, 4.5, 9.0, 250.0),
    "car": VehicleClass("car", 5.0, 1.8, 2.6, 3.4, 9.0, 250.0),
    "truck": VehicleClass("truck", 7.1, 2.5, 1.3, 3.0, 7.0, 130.0),
    "bus": VehicleClass("bus", 12.0, 2.55, 1.2, 3.0, 7.0, 100.0),
}
WALKERS_AND_RIDERS = {  # road users of every scene besides the site's vehicle classes
    "pedestrian": VehicleClass("pedestrian", 0.5, 0.5, 1.0, 2.0, 3.0, 8.0, 0.1),
    "cyclist": VehicleClass("cyclist", 1.8, 0.6, 1.0, 2.5, 4.0, 40.0, 0.3),
}


@dataclass(frozen=True)
class Case:
    """An approach script on ``road`` (see the module docstring for the kinds).

    ``speed_kmh`` is the initial speed (for ``profile`` the speed of the first knot);
    ``decel_mps2``/``jerk_mps3`` override the braking defaults of ``stop``/``emergency``;
    ``stop_at_m`` (default: the site's stop line) is where the front stops; after a
    ``dwell_s > 0`` the vehicle pulls away (jerk 2 m/s^3, class acceleration, back to its
    initial speed). ``profile`` holds ``(time_s, speed_kmh)`` knots. ``classes`` restricts
    the case to some vehicle classes (None: every class that can drive it).
    """

    name: str
    kind: str
    speed_kmh: float
    road: str
    dwell_s: float = 0.0
    decel_mps2: float | None = None
    jerk_mps3: float | None = None
    stop_at_m: float | None = None
    profile: tuple[tuple[float, float], ...] = ()
    classes: tuple[str, ...] | None = None
    time_constant_s: float = RANDOM_TIME_CONSTANT_S
    accel_std_mps2: float = RANDOM_ACCEL_STD_MPS2

    def __post_init__(self) -> None:
        if self.kind not in ("pass", "stop", "emergency", "random", "profile"):
            raise ValueError(
                "case kind must be 'pass', 'stop', 'emergency', 'random' or 'profile'; "
                f"got {self.kind!r}"
            )


def default_cases(roads: list[str]) -> tuple[Case, ...]:
    """Return DOMAIN 7(a)'s scripts on every road.

    Passes 5-250 km/h, the S2 stop with a 30 s dwell and pull-away, normal and emergency
    stops, a random (Singer) approach.

    Case names are ``"<road>/<script>"`` when the site has several roads.
    """
    scripts = (
        ("pass_5", "pass", 5.0, 0.0),
        ("pass_20", "pass", 20.0, 0.0),
        ("pass_60", "pass", 60.0, 0.0),
        ("pass_100", "pass", 100.0, 0.0),
        ("pass_250", "pass", 250.0, 0.0),
        ("stop_60", "stop", 60.0, 0.0),
        ("stop_go_60", "stop", 60.0, 30.0),
        ("emergency_90", "emergency", 90.0, 0.0),
        ("random_60", "random", 60.0, 0.0),
    )
    prefix = len(roads) > 1
    return tuple(
        Case(f"{road}/{name}" if prefix else name, kind, speed, road, dwell_s=dwell)
        for road in roads
        for name, kind, speed, dwell in scripts
    )


def inapplicable_reason(case: Case, vehicle: VehicleClass) -> str | None:
    """Why a vehicle class cannot drive a case (None: it can)."""
    if case.classes is not None and vehicle.name not in case.classes:
        return f"the case is for {', '.join(case.classes)} only"
    top = max([case.speed_kmh, *(v for _, v in case.profile)])
    if top > vehicle.max_speed_kmh:
        return f"{top:g} km/h is above the class's {vehicle.max_speed_kmh:g} km/h"
    if case.decel_mps2 is not None and case.decel_mps2 > vehicle.emergency_decel_mps2:
        return (
            f"braking at {case.decel_mps2:g} m/s^2 is above the class's "
            f"{vehicle.emergency_decel_mps2:g} m/s^2"
        )
    if case.kind == "profile":
        accel = _profile_accels(case)
        if accel.max(initial=0.0) > vehicle.accel_mps2 + 1e-9:
            return f"the profile accelerates above the class's {vehicle.accel_mps2:g} m/s^2"
        if -accel.min(initial=0.0) > vehicle.emergency_decel_mps2 + 1e-9:
            return f"the profile brakes above the class's {vehicle.emergency_decel_mps2:g} m/s^2"
    return None


def applicable(case: Case, vehicle: VehicleClass) -> bool:
    """Whether a vehicle class can drive a case (speed, braking, class filter)."""
    return inapplicable_reason(case, vehicle) is None


def _profile_accels(case: Case) -> FloatArray:
    t = np.array([p[0] for p in case.profile])
    v = np.array([p[1] for p in case.profile]) * KMH
    return np.diff(v) / np.diff(t) if t.size > 1 else np.zeros(0)


def braking(case: Case, vehicle: VehicleClass) -> tuple[float, float]:
    """Deceleration [m/s^2] and jerk [m/s^3] of a stopping case for a class."""
    if case.kind == "stop":
        decel = min(vehicle.decel_mps2, 3.4) if case.decel_mps2 is None else case.decel_mps2
        return decel, JERK_NORMAL if case.jerk_mps3 is None else case.jerk_mps3
    if case.kind == "emergency":
        decel = (
            min(vehicle.emergency_decel_mps2, 8.0) if case.decel_mps2 is None else case.decel_mps2
        )
        return decel, JERK_EMERGENCY if case.jerk_mps3 is None else case.jerk_mps3
    raise ValueError(f"case {case.name}: kind {case.kind!r} does not brake to a stop")


def braking_distance(v0: float, decel: float, jerk: float) -> float:
    """Distance [m] from ``v0`` [m/s] to standstill with a jerk-limited onset."""
    t_j = decel / jerk
    v_after = v0 - decel * t_j / 2
    if v_after <= 0:  # never reaches full deceleration
        t_stop = math.sqrt(2 * v0 / jerk)
        return float(v0 * t_stop - jerk * t_stop**3 / 6)
    return float(v0 * t_j - jerk * t_j**3 / 6 + v_after**2 / (2 * decel))


def case_duration(case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float) -> float:
    """Time [s] until the front reaches the crossing centre, or 2 s after a final stop."""
    v0 = case.speed_kmh * KMH
    if case.kind == "pass":
        return start_m / v0
    if case.kind == "random":
        return 1.2 * start_m / v0
    if case.kind == "profile":
        return _profile_duration(case, start_m)
    stop_m = stop_line_m if case.stop_at_m is None else case.stop_at_m
    decel, jerk = braking(case, vehicle)
    t_brake = (start_m - stop_m - braking_distance(v0, decel, jerk)) / v0
    t_j = decel / jerk
    t_stop = (
        t_j + max(v0 - decel * t_j / 2, 0.0) / decel
        if v0 > decel * t_j / 2
        else math.sqrt(2 * v0 / jerk)
    )
    if case.dwell_s > 0:  # dwell, then pull away over the stop position to the crossing
        t_up = vehicle.accel_mps2 / JERK_NORMAL
        return (
            t_brake
            + t_stop
            + case.dwell_s
            + t_up
            + math.sqrt(2 * max(stop_m, 0.0) / vehicle.accel_mps2)
            + 1.0
        )
    return t_brake + t_stop + STOPPED_TAIL_S


def _profile_knots(case: Case) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Knot times [s], speeds [m/s] and the distance driven up to each knot [m]."""
    t = np.array([p[0] for p in case.profile])
    v = np.array([p[1] for p in case.profile]) * KMH
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    return t, v, dist


def _profile_duration(case: Case, start_m: float) -> float:
    t, v, dist = _profile_knots(case)
    if dist[-1] >= start_m:  # reaches the crossing within the knots
        j = int(np.searchsorted(dist, start_m)) - 1
        a = (v[j + 1] - v[j]) / (t[j + 1] - t[j])
        rest = start_m - dist[j]
        if abs(a) < 1e-12:
            return float(t[j] + rest / v[j])
        return float(t[j] + (-v[j] + math.sqrt(max(v[j] ** 2 + 2 * a * rest, 0.0))) / a)
    if v[-1] > 0:
        return float(t[-1] + (start_m - dist[-1]) / v[-1])
    return float(t[-1] + STOPPED_TAIL_S)


def along_road_profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Along-road position, speed and acceleration of the front at ``times`` [s from start].

    Stops are integrated exactly with piecewise-constant jerk on a grid 10x finer than
    ``times``; profiles exactly (speed linear between knots). The vehicle drives until the end
    of ``times``. Results are cached (read-only arrays): every block of Monte-Carlo runs of a
    scripted case drives the same profile.
    """
    times = np.asarray(times, dtype=float)
    return _profile(case, vehicle, float(start_m), float(stop_line_m), times.tobytes())


@lru_cache(maxsize=256)
def _profile(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times_bytes: bytes
) -> tuple[FloatArray, FloatArray, FloatArray]:
    out = _integrate(case, vehicle, start_m, stop_line_m, np.frombuffer(times_bytes, dtype=float))
    for a in out:
        a.setflags(write=False)
    return out


def _integrate(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    v0 = case.speed_kmh * KMH
    if case.kind == "pass":
        return start_m - v0 * times, np.full(times.shape, v0), np.zeros(times.shape)
    if case.kind == "random":
        raise ValueError("random cases need an rng: use random_profiles()")
    if case.kind == "profile":
        t, v, dist = _profile_knots(case)
        j = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 1)
        a = np.where(j < t.size - 1, _profile_accels(case)[np.minimum(j, t.size - 2)], 0.0)
        tau = times - t[j]
        return start_m - (dist[j] + v[j] * tau + 0.5 * a * tau**2), v[j] + a * tau, a
    return _integrate_stop(case, vehicle, start_m, stop_line_m, times)


def _integrate_stop(
    case: Case, vehicle: VehicleClass, start_m: float, stop_line_m: float, times: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    v0 = case.speed_kmh * KMH
    decel, jerk = braking(case, vehicle)
    stop_m = stop_line_m if case.stop_at_m is None else case.stop_at_m
    brake_at = stop_m + braking_distance(v0, decel, jerk)
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
    rho = np.exp(-dt / case.time_constant_s)
    a = np.zeros((n_runs, n))
    xi = rng.standard_normal((n_runs, n))
    for k in range(1, n):
        a[:, k] = rho[k] * a[:, k - 1] + np.sqrt(1 - rho[k] ** 2) * case.accel_std_mps2 * xi[:, k]
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
    "MAX_DECEL_MPS2",
    "VEHICLES",
    "WALKERS_AND_RIDERS",
    "Case",
    "VehicleClass",
    "along_road_profile",
    "applicable",
    "braking",
    "braking_distance",
    "case_duration",
    "default_cases",
    "inapplicable_reason",
    "random_profiles",
]
