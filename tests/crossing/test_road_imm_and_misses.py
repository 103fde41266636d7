"""The road IMM, and what missed detections tell the road trackers (Doppler gate, geometry)."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm

from adaptrack.crossing.estimators import road_filters as tracking
from adaptrack.crossing.estimators.road_filters import (
    switching_generator,
    track_on_road,
    track_on_road_imm,
)
from adaptrack.crossing.simulation.radar import simulate_case
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.site.sensor import Curve
from adaptrack.crossing.site.traffic import VEHICLES
from adaptrack.models import ConstantAcceleration, ConstantVelocity

SITE = load_site("lx_default")
CASE = {c.name: c for c in SITE.cases}
CV, CA = ConstantVelocity(accel_psd=0.2), ConstantAcceleration(jerk_psd=3.0)


def runs_of(case, vehicle="car", n_runs=6, seed=1, site=SITE, **radar_change):
    radar = dataclasses.replace(site.radar_for(case.road), **radar_change)
    runs = simulate_case(
        site.roads[case.road], radar, VEHICLES[vehicle], case, n_runs=n_runs,
        rng=np.random.default_rng(seed), start_m=200.0, stop_line_m=15.0,
        lateral_offset_std_m=0.3,
    )  # fmt: skip
    return radar, site.roads[case.road], runs


def test_switching_chain_oracle():
    gen = switching_generator((10.0, 2.0))
    np.testing.assert_allclose(gen.sum(axis=1), 0.0, atol=1e-15)
    a, b = 0.1, 0.5  # leave rates of the two modes
    for dt in (0.05, 1.0, 30.0):
        lam = a + b
        e = math.exp(-lam * dt)
        closed = np.array([[b + a * e, a * (1 - e)], [b * (1 - e), a + b * e]]) / lam
        np.testing.assert_allclose(expm(gen * dt), closed, rtol=1e-12)
    # stationary probabilities proportional to the sojourn times
    stat = np.array([10.0, 2.0]) / 12.0
    np.testing.assert_allclose(stat @ gen, 0.0, atol=1e-15)
    three = switching_generator((1.0, 2.0, 4.0))
    np.testing.assert_allclose(np.array([1.0, 2.0, 4.0]) / 7 @ three, 0.0, atol=1e-15)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_one_mode_imm_is_the_road_ekf(backend):
    radar, road, runs = runs_of(CASE["A/stop_60"])
    args = (runs.times, runs.measurements, runs.detected, radar, road)
    ekf = track_on_road(*args, model=CA, scatter_std_m=0.75, backend=backend)
    imm = track_on_road_imm(*args, models=(CA,), sojourn_s=(5.0,), scatter_std_m=0.75,
                            backend=backend)  # fmt: skip
    for f in ("position", "velocity", "speed", "position_cov"):
        x, y = getattr(ekf, f), getattr(imm, f)
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
        assert np.nanmax(np.abs(x - y)) <= 1e-10 * np.nanmax(np.abs(x))
    assert np.allclose(imm.mode_probabilities[np.isfinite(imm.speed)], 1.0)


@pytest.mark.parametrize("case_name", ["A/stop_go_60", "B/random_60"])
def test_compiled_road_imm_equals_the_numpy_reference(case_name):
    radar, road, runs = runs_of(CASE[case_name], vehicle="bus", n_runs=4, seed=3)
    args = (runs.times, runs.measurements, runs.detected, radar, road)
    kw = {"models": (CV, CA), "sojourn_s": (8.0, 3.0), "scatter_std_m": 1.8}
    ref = track_on_road_imm(*args, backend="numpy", **kw)
    got = track_on_road_imm(*args, backend="numba", **kw)
    for f in ("position", "velocity", "speed", "position_cov", "mode_probabilities"):
        x, y = getattr(ref, f), getattr(got, f)
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
        assert np.nanmax(np.abs(x - y)) <= 1e-9 * np.nanmax(np.abs(x)), f
    mu = got.mode_probabilities[np.isfinite(got.speed)]
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, rtol=1e-12)
    assert np.all((mu >= 0) & (mu <= 1))
    # while the vehicle stands behind the Doppler gate, the decelerating (CA) mode explains
    # the misses better than a coasting CV mode would
    if case_name == "A/stop_go_60":
        stopped = (runs.speed == 0) & np.isfinite(got.speed)
        assert np.mean(got.mode_probabilities[..., 1][stopped]) > 0.5


def test_imm_rejects_bad_modes():
    radar, road, runs = runs_of(CASE["B/pass_60"], n_runs=1)
    args = (runs.times, runs.measurements, runs.detected, radar, road)
    with pytest.raises(ValueError, match="one entry per mode"):
        track_on_road_imm(*args, models=(CV, CA), sojourn_s=(1.0,))
    with pytest.raises(ValueError, match="sojourn_s must be > 0"):
        track_on_road_imm(*args, models=(CV,), sojourn_s=(0.0,))
    with pytest.raises(ValueError, match="one-axis models"):
        track_on_road_imm(*args, models=(ConstantVelocity(n_axes=2),), sojourn_s=(1.0,))


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_vehicle_stopped_behind_the_doppler_gate_is_held(backend):
    """30 s at the stop line without a detection: with the gate's information a CV track stays
    within centimetres of the stop; told there is no gate, it coasts on towards the crossing."""
    radar, road, runs = runs_of(CASE["B/stop_go_60"], n_runs=5)
    stopped = runs.speed == 0
    args = (runs.times, runs.measurements, runs.detected)
    with_gate = track_on_road(*args, radar, road, model=CV, scatter_std_m=0.75, backend=backend)
    blind = dataclasses.replace(radar, min_radial_speed_mps=0.0)
    without = track_on_road(*args, blind, road, model=CV, scatter_std_m=0.75, backend=backend)

    def stop_error(est):
        return np.max(np.linalg.norm(est.position - runs.position, axis=-1)[stopped])

    assert stop_error(with_gate) < 0.6 < 3.0 < stop_error(without)
    sd = np.sqrt(np.trace(with_gate.position_cov, axis1=-2, axis2=-1))[stopped]
    assert sd.max() < 5.0  # bounded while stopped (without the gate it grows without bound)


def test_the_gate_informs_only_where_the_radial_speed_measures_the_speed():
    """One missed scan of a crawling car: seen along the road (|cos| ~ 1) the gate is applied;
    seen across the road (|cos| ~ 0: v_r ~ 0 whatever the speed) the miss changes nothing."""
    road = SITE.roads["B"]  # leaves the crossing southwards; lane at x = +1.75 m
    along = SITE.radar_for("B")  # 3.25 m beside the lane, looking down it
    across = dataclasses.replace(along, position_m=(31.75, -60.0), boresight_rad=-math.pi / 2)
    k = CV.state_dim
    prior = tracking.GaussianState(
        mean=np.array([[60.0, -0.15, 0.0]]),
        cov=np.diag([0.01, 0.04, 0.01])[None],
        time=np.zeros(1),
    )
    for radar, applied in ((along, True), (across, False)):
        measure = tracking._road_measure(road, radar, k, 0.0)
        zpred, h, r = measure(prior.mean)
        misses = tracking._misses(radar, None, tracking.ROAD)
        assert (abs(h[0, 2, 1]) > 0.9) == applied
        post, ll, run = tracking._detection_step(
            prior, zpred, h, r, np.full((1, 3), np.nan), np.zeros(1, bool), np.ones(1, bool),
            misses, np.ones(1),
        )  # fmt: skip
        moved = not np.allclose(post.mean, prior.mean, rtol=0, atol=1e-12)
        assert moved == applied and (run[0] < 1.0) == applied
        assert ll[0] <= 0  # log P(no detection) under the prediction (0 across: v_r = 0)
        if applied:  # the pseudo-measurement pulls the crawling speed towards the gate
            assert abs(post.mean[0, 1]) < 0.15 and post.cov[0, 1, 1] < 0.04


@pytest.mark.parametrize("case_name, gap_scans", [("B/pass_20", 20), ("B/pass_5", 3)])
def test_a_run_of_misses_the_gate_cannot_explain_does_not_stop_a_track(case_name, gap_scans):
    """Missed scans of a moving car: at 20 km/h (|v_r| far above the 0.1 m/s gate) even 20 in
    a row leave the track coasting at its speed (their probability under independent misses,
    1e-26, is floored at 1e-4: occlusion, interference); at 5 km/h three misses do not stop
    it."""
    radar, road, runs = runs_of(
        CASE[case_name], n_runs=3, detection_probability={"default": Curve.constant(0.95)}
    )
    detected = runs.detected.copy()
    first = int(np.argmax(runs.along_road_m[0] < 100.0))
    gap = slice(first, first + gap_scans)
    detected[:, gap] = False
    est = track_on_road(runs.times, runs.measurements, detected, radar, road, model=CA)
    # coasting (a CA track extrapolates its acceleration estimate): within 0.1 m/s + 20 %
    # of the speed; a track stopped by the gate would be off by the whole speed
    assert np.all(np.abs(est.speed[:, gap] - runs.speed[:, gap]) < 0.1 + 0.2 * runs.speed[:, gap])
