"""Truth segments, measurements and scenarios."""

import numpy as np
import pytest

from adaptrack.simulation.measurements import simulate_cartesian, simulate_polar_2d
from adaptrack.simulation.scenario import (
    builtin_scenarios,
    load_scenario,
    scenario_from_mapping,
    simulate_scenario,
)
from adaptrack.simulation.segments import Segment, TrajectorySpec, simulate_truth


def table1_truth(step=0.1, t_end=70.0):
    """Spec 5.3 truth integrated step by step (independent of the segment code)."""
    t = step * np.arange(round(t_end / step) + 1)
    x = np.zeros(t.size)
    xi, vi = 0.0, 200.0
    for i, ti in enumerate(t):
        x[i] = xi
        a, j = (
            (-20.0, 0.0)
            if 20 <= ti < 30 - 1e-9
            else ((2.0 * (ti - 50), 2.0) if 50 <= ti < 70 - 1e-9 else (0.0, 0.0))
        )
        xi += vi * step + a * step**2 / 2 + j * step**3 / 6
        vi += a * step + j * step**2 / 2
    return t, x


def test_zimchuk_truth_matches_step_integration():
    sc = load_scenario("zimchuk_table1")
    truth, meas = simulate_scenario(sc, 2, 0)
    t, x = table1_truth()
    np.testing.assert_allclose(truth.times[0], t, atol=1e-12)
    np.testing.assert_allclose(truth.position[0, :, 0], x, rtol=1e-12, atol=1e-9)
    assert meas.values.shape == (2, 701, 1)


def test_polynomial_segments_closed_form():
    spec = TrajectorySpec(
        (1.0, 2.0),
        (3.0, -1.0),
        (
            Segment("constant_acceleration", 2.0, accel_mps2=(1.0, 0.5)),
            Segment("constant_jerk", 1.0, accel_mps2=(0.0, 1.0), jerk_mps3=(0.6, 0.0)),
        ),
    )
    truth = simulate_truth(spec, np.array([0.0, 1.0, 2.0, 2.5, 3.0, 4.0]))
    np.testing.assert_allclose(truth.position[0, 1], [1 + 3 + 0.5, 2 - 1 + 0.25])
    p2, v2 = np.array([1 + 6 + 2, 2 - 2 + 1]), np.array([5.0, 0.0])
    np.testing.assert_allclose(truth.position[0, 2], p2)
    tau = 0.5
    np.testing.assert_allclose(
        truth.position[0, 3],
        p2 + v2 * tau + np.array([0, 1]) * tau**2 / 2 + np.array([0.6, 0]) * tau**3 / 6,
    )
    np.testing.assert_allclose(truth.acceleration[0, 3], [0.6 * tau, 1.0])
    # after the last segment: constant velocity
    v3 = v2 + np.array([0, 1]) + np.array([0.6, 0]) / 2
    np.testing.assert_allclose(truth.velocity[0, 5], v3)
    np.testing.assert_allclose(truth.acceleration[0, 5], 0.0)


def test_coordinated_turn_keeps_speed_and_radius():
    w = np.deg2rad(3.0)
    spec = TrajectorySpec(
        (0.0, 0.0), (-120.0, 0.0), (Segment("coordinated_turn", 30.0, turn_rate_radps=w),)
    )
    t = np.linspace(0, 30, 61)
    truth = simulate_truth(spec, t)
    speed = np.hypot(*np.moveaxis(truth.velocity[0], -1, 0))
    np.testing.assert_allclose(speed, 120.0, rtol=1e-12)
    centre = np.array([0.0, -120.0 / w])  # left turn from westward flight: centre to the south
    np.testing.assert_allclose(np.hypot(*(truth.position[0] - centre).T), 120.0 / w, rtol=1e-9)
    # heading turned by 90 degrees: now flying south
    np.testing.assert_allclose(truth.velocity[0, -1], [0.0, -120.0], atol=1e-9)
    # the turn ends at t = 30 s, where the trailing constant-velocity segment begins
    np.testing.assert_allclose(np.hypot(*truth.acceleration[0, :-1].T), 120.0 * w, rtol=1e-12)
    np.testing.assert_allclose(truth.acceleration[0, -1], 0.0)


def test_singer_segment_statistics():
    rng = np.random.default_rng(5)
    spec = TrajectorySpec(
        (0.0,), (10.0,), (Segment("singer", 20.0, time_constant_s=2.0, accel_std_mps2=1.5),)
    )
    t = np.linspace(0, 19.5, 40)
    truth = simulate_truth(spec, t, n_runs=4000, rng=rng)
    # stationary acceleration RMS 1.5: the sample RMS of 4000 runs has relative sd 1.1 %;
    # 5 sigma = 6 %
    rms = np.sqrt(np.mean(truth.acceleration[:, -1, 0] ** 2))
    assert rms == pytest.approx(1.5, rel=0.06)
    runs_differ = np.std(truth.position[:, -1, 0])
    assert runs_differ > 0


def test_measurement_noise_and_detection(rng):
    spec = TrajectorySpec((0.0, 0.0), (1.0, 1.0))
    truth = simulate_truth(spec, np.arange(200.0), n_runs=50)
    meas = simulate_cartesian(truth, 2.0, rng=rng, velocity_std_mps=0.5, detection_probability=0.7)
    err = meas.values - np.concatenate([truth.position, truth.velocity], axis=-1)
    ok = meas.mask
    # sample sd over ~7000 draws per axis: relative sd ~0.85 %; 5 sigma = 4.3 %
    np.testing.assert_allclose(np.nanstd(err[ok], axis=0), [2.0, 2.0, 0.5, 0.5], rtol=0.043)
    assert np.all(np.isnan(meas.values[~ok]))
    assert np.all(meas.mask[:, :2])  # tracks are initiated from two detections
    # detection rate 0.7 on the rest: binomial sd 0.0023 over 9900 epochs; 5 sigma
    assert abs(meas.mask[:, 2:].mean() - 0.7) < 0.012


def test_polar_conversion_covariance_monte_carlo():
    rng = np.random.default_rng(11)
    spec = TrajectorySpec((20000.0, 30000.0), (0.0, 0.0))
    truth = simulate_truth(spec, np.arange(20000.0))
    meas = simulate_polar_2d(truth, 30.0, np.deg2rad(0.08), rng=rng)
    err = meas.values[0] - truth.position[0]
    emp = np.cov(err.T)
    np.testing.assert_allclose(emp, meas.cov[0].mean(axis=0), rtol=0.05, atol=5.0)


def test_scenarios_load_and_simulate():
    assert {"zimchuk_table1", "atc_turns", "air_default", "uav_attitude"} <= set(
        builtin_scenarios()
    )
    for name in builtin_scenarios():
        sc = load_scenario(name)
        truth, meas = simulate_scenario(sc, 2, 1)
        assert truth.position.shape[:2] == meas.values.shape[:2] == meas.mask.shape
        assert np.all(np.isfinite(truth.position))
    uav = load_scenario("uav_attitude")
    assert uav.sensor.velocity_std_mps == pytest.approx(np.deg2rad(0.05))


def test_simulation_is_reproducible_and_seed_dependent():
    sc = load_scenario("air_default")
    a = simulate_scenario(sc, 3, 7)[1].values
    b = simulate_scenario(sc, 3, 7)[1].values
    c = simulate_scenario(sc, 3, 8)[1].values
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(np.nan_to_num(a), np.nan_to_num(c))


def test_scenario_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown scenario 'nope'"):
        load_scenario("nope")
    with pytest.raises(ValueError, match="does not exist"):
        load_scenario(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[sampling]\nstep_s = 0.1\n")
    with pytest.raises(ValueError, match="missing key 'sensor'"):
        load_scenario(bad)
    bad.write_text("not = [toml")
    with pytest.raises(ValueError, match="invalid TOML"):
        load_scenario(bad)
    base = {
        "sampling": {"step_s": 1.0, "duration_s": 5.0},
        "sensor": {"position_std_m": 1.0},
        "trajectory": {
            "initial_position_m": [0.0],
            "initial_velocity_mps": [1.0],
            "segments": [{"kind": "warp", "duration_s": 1.0}],
        },
    }
    with pytest.raises(ValueError, match=r"segments\]\]\[0\]: segment kind must be one of"):
        scenario_from_mapping(base, "x.toml")
    base["trajectory"]["segments"] = [{"kind": "constant_velocity", "duration_s": 1.0, "colour": 1}]
    with pytest.raises(ValueError, match=r"unknown keys \['colour'\]"):
        scenario_from_mapping(base, "x.toml")
    with pytest.raises(ValueError, match="a coordinated turn needs at least 2 axes"):
        TrajectorySpec((0.0,), (1.0,), (Segment("coordinated_turn", 1.0),))
    with pytest.raises(ValueError, match="duration_s must be finite and > 0"):
        Segment("constant_velocity", -1.0)
    with pytest.raises(TypeError, match="rng must be a numpy.random.Generator"):
        simulate_truth(TrajectorySpec((0.0,), (1.0,), (Segment("singer", 1.0),)), [0.0, 1.0])
