"""Named simulation scenarios, stored as TOML files shipped with the package.

A scenario fixes the truth (manoeuvre segments, or the attitude dynamics of a UAV), the
sampling, the sensor and the evaluation intervals. ``load_scenario("atc_turns")`` loads a
built-in scenario; a path loads a user file of the same form. ``simulate_scenario`` draws
``n_runs`` runs from a seed, with independent streams for truth, sampling and noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._toml import builtin_names, load_named_toml
from ..models.continuous import LinearSDE
from .linear import simulate_linear_trajectory
from .measurements import Measurements, simulate_cartesian, simulate_polar_2d
from .segments import TrajectorySpec, Truth, segment_from_mapping, simulate_truth


@dataclass(frozen=True)
class AttitudeSpec:
    """Attitude (roll, pitch, yaw) of a UAV in stabilisation mode under random gust torques.

    Per angle: ``theta' = omega``, ``omega' = -w_n^2 theta - 2 zeta w_n omega + g`` and the gust
    angular acceleration ``g`` is a Gauss-Markov process (``gust_time_constant_s``,
    ``gust_std_radps2``).
    """

    natural_freq_radps: float
    damping: float
    gust_time_constant_s: float
    gust_std_radps2: float
    initial_angle_std_rad: float

    def model(self) -> LinearSDE:
        """Return the 9-state linear SDE [angles, rates, gust accelerations]."""
        wn, z, tau = self.natural_freq_radps, self.damping, self.gust_time_constant_s
        i3 = np.eye(3)
        f = np.block(
            [
                [0 * i3, i3, 0 * i3],
                [-(wn**2) * i3, -2 * z * wn * i3, i3],
                [0 * i3, 0 * i3, -i3 / tau],
            ]
        )
        g = np.vstack([0 * i3, 0 * i3, i3])
        names = (
            "roll",
            "pitch",
            "yaw",
            "roll_rate",
            "pitch_rate",
            "yaw_rate",
            "gust_roll",
            "gust_pitch",
            "gust_yaw",
        )
        return LinearSDE(f, g, 2 * self.gust_std_radps2**2 / tau * i3, names)


@dataclass(frozen=True)
class SensorSpec:
    """Sensor: ``kind`` "cartesian" (position, optional velocity) or "polar_2d" (r, azimuth)."""

    kind: str = "cartesian"
    position_std_m: float = 1.0
    velocity_std_mps: float | None = None
    range_std_m: float = 1.0
    azimuth_std_rad: float = 1e-3
    sensor_xy_m: tuple[float, float] = (0.0, 0.0)
    detection_probability: float = 1.0


@dataclass(frozen=True)
class Scenario:
    """A complete simulation scenario (see module docstring)."""

    name: str
    description: str
    step_s: float
    duration_s: float
    sensor: SensorSpec
    trajectory: TrajectorySpec | None = None
    attitude: AttitudeSpec | None = None
    jitter_s: float = 0.0
    intervals_s: tuple[tuple[float, float], ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def n_axes(self) -> int:
        """Number of axes (generalised coordinates)."""
        return 3 if self.trajectory is None else self.trajectory.n_axes

    def interval_names(self) -> list[str]:
        """Keys such as ``"20-30"`` of the evaluation intervals (seconds)."""
        return [f"{_fmt(a)}-{_fmt(b)}" for a, b in self.intervals_s]


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else str(x)


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped with adaptrack."""
    return builtin_names("adaptrack.simulation", "scenarios")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name, or a scenario TOML file by path."""
    return scenario_from_mapping(
        *load_named_toml(name_or_path, "adaptrack.simulation", "scenarios", "scenario")
    )


def _require(data: dict[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise ValueError(f"{where}: missing key {key!r}")
    return data[key]


def scenario_from_mapping(data: dict[str, Any], where: str) -> Scenario:
    """Build a Scenario from parsed TOML; errors name the file and the key path."""
    sampling = _require(data, "sampling", where)
    sensor = dict(_require(data, "sensor", where))
    # attitude sensors: angles are the generalised coordinates (spec B.1)
    if "angle_std_deg" in sensor:
        sensor["position_std_m"] = float(np.deg2rad(sensor.pop("angle_std_deg")))
    if "rate_std_degps" in sensor:
        sensor["velocity_std_mps"] = float(np.deg2rad(sensor.pop("rate_std_degps")))
    if "azimuth_std_deg" in sensor:
        sensor["azimuth_std_rad"] = float(np.deg2rad(sensor.pop("azimuth_std_deg")))
    if "sensor_xy_m" in sensor:
        sensor["sensor_xy_m"] = tuple(float(v) for v in sensor["sensor_xy_m"])
    try:
        sensor_spec = SensorSpec(**sensor)
    except TypeError as exc:
        raise ValueError(f"{where}: [sensor]: {exc}") from None
    if sensor_spec.kind not in ("cartesian", "polar_2d"):
        raise ValueError(
            f"{where}: [sensor].kind must be 'cartesian' or 'polar_2d'; got {sensor_spec.kind!r}"
        )
    trajectory = attitude = None
    if "trajectory" in data:
        tr = data["trajectory"]
        segs = tuple(
            segment_from_mapping(s, f"{where}: [[trajectory.segments]][{i}]")
            for i, s in enumerate(tr.get("segments", []))
        )
        trajectory = TrajectorySpec(
            tuple(float(v) for v in _require(tr, "initial_position_m", f"{where}: [trajectory]")),
            tuple(float(v) for v in _require(tr, "initial_velocity_mps", f"{where}: [trajectory]")),
            segs,
        )
    elif "attitude" in data:
        try:
            attitude = AttitudeSpec(**data["attitude"])
        except TypeError as exc:
            raise ValueError(f"{where}: [attitude]: {exc}") from None
    else:
        raise ValueError(f"{where}: needs a [trajectory] or an [attitude] table")
    intervals = tuple(
        (float(a), float(b)) for a, b in data.get("evaluation", {}).get("intervals_s", [])
    )
    return Scenario(
        name=str(data.get("name", Path(where).stem)),
        description=str(data.get("description", "")),
        step_s=float(_require(sampling, "step_s", f"{where}: [sampling]")),
        duration_s=float(_require(sampling, "duration_s", f"{where}: [sampling]")),
        jitter_s=float(sampling.get("jitter_s", 0.0)),
        sensor=sensor_spec,
        trajectory=trajectory,
        attitude=attitude,
        intervals_s=intervals,
        settings=dict(data.get("settings", {})),
    )


def sample_times(scenario: Scenario, n_runs: int, rng: np.random.Generator) -> np.ndarray:
    """Sample times (n_runs, T): a regular grid, optionally jittered (uniform +-jitter_s)."""
    n = round(scenario.duration_s / scenario.step_s) + 1
    grid = scenario.step_s * np.arange(n)
    if scenario.jitter_s <= 0:
        return np.broadcast_to(grid, (n_runs, n)).copy()
    if scenario.jitter_s >= scenario.step_s / 2:
        raise ValueError("jitter_s must be below half the step (times must stay increasing)")
    jit = rng.uniform(-scenario.jitter_s, scenario.jitter_s, (n_runs, n))
    jit[:, 0] = 0.0
    return grid + jit


def simulate_scenario(scenario: Scenario, n_runs: int, seed: int) -> tuple[Truth, Measurements]:
    """Draw ``n_runs`` runs of a scenario: truth and measurements (independent seeded streams)."""
    if n_runs < 1:
        raise ValueError(f"n_runs must be >= 1; got {n_runs}")
    r_time, r_truth, r_meas = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)
    )
    times = sample_times(scenario, n_runs, r_time)
    if scenario.trajectory is not None:
        truth = simulate_truth(scenario.trajectory, times, n_runs=n_runs, rng=r_truth)
    elif scenario.attitude is not None:
        att = scenario.attitude
        p0 = np.diag([att.initial_angle_std_rad**2] * 3 + [0.0] * 3 + [att.gust_std_radps2**2] * 3)
        x = simulate_linear_trajectory(att.model(), times, np.zeros(9), p0, rng=r_truth)
        wn, zeta = att.natural_freq_radps, att.damping
        ang_acc = -(wn**2) * x[..., :3] - 2 * zeta * wn * x[..., 3:6] + x[..., 6:]
        truth = Truth(times, x[..., :3], x[..., 3:6], ang_acc)
    else:
        raise ValueError(f"scenario {scenario.name!r} has neither a trajectory nor an attitude")
    s = scenario.sensor
    if s.kind == "polar_2d":
        meas = simulate_polar_2d(
            truth,
            s.range_std_m,
            s.azimuth_std_rad,
            rng=r_meas,
            sensor_xy_m=s.sensor_xy_m,
            detection_probability=s.detection_probability,
        )
    else:
        meas = simulate_cartesian(
            truth,
            s.position_std_m,
            rng=r_meas,
            velocity_std_mps=s.velocity_std_mps,
            detection_probability=s.detection_probability,
        )
    return truth, meas


__all__ = [
    "AttitudeSpec",
    "Scenario",
    "SensorSpec",
    "builtin_scenarios",
    "load_scenario",
    "sample_times",
    "scenario_from_mapping",
    "simulate_scenario",
]
