"""Radar simulation, trackers and the compliance Monte Carlo."""

import dataclasses
import math

import numpy as np
import pytest

from adaptrack.angles import wrapped
from adaptrack.crossing.estimators.road_filters import track_free_2d, track_on_road
from adaptrack.crossing.simulation.radar import simulate_case
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.site.sensor import Curve
from adaptrack.crossing.site.traffic import VEHICLES
from adaptrack.crossing.studies.compliance import ComplianceResult, evaluate_site
from adaptrack.models import ConstantAcceleration

SITE = load_site("lx_default")
CASE = {c.name: c for c in SITE.cases}  # road A is curved, road B straight


def simulate(case, vehicle="car", n_runs=50, seed=0, **radar_change):
    radar = dataclasses.replace(
        SITE.radar_for(case.road), detection_probability={"default": Curve.constant(0.95)}
    )
    radar = dataclasses.replace(radar, **radar_change)
    return radar, simulate_case(
        SITE.roads[case.road],
        radar,
        VEHICLES[vehicle],
        case,
        n_runs=n_runs,
        rng=np.random.default_rng(seed),
        start_m=200.0,
        stop_line_m=15.0,
        lateral_offset_std_m=0.3,
    )


def point_target(n_runs, seed, detection_probability=1.0):
    """A car without body scatter on road B, radar without bias or jitter, no lane offset."""
    radar = dataclasses.replace(
        SITE.radar_for("B"),
        azimuth_bias_rad=0.0,
        time_jitter_s=0.0,
        detection_probability={"default": Curve.constant(detection_probability)},
    )
    veh = dataclasses.replace(VEHICLES["car"], length_m=0.0, scatter_std_m=0.0)
    return radar, simulate_case(
        SITE.roads["B"],
        radar,
        veh,
        CASE["B/pass_60"],
        n_runs=n_runs,
        rng=np.random.default_rng(seed),
        start_m=200.0,
        stop_line_m=15.0,
        lateral_offset_std_m=0.0,
    )


def test_detections_noise_and_gates():
    radar, runs = simulate(CASE["B/pass_60"], azimuth_bias_rad=0.0, time_jitter_s=0.0)
    assert runs.detected.mean() == pytest.approx(0.95, abs=0.02)
    # a point target (no body scatter): range and radial-speed noise have the radar's sigma
    veh = dataclasses.replace(VEHICLES["car"], length_m=0.0, scatter_std_m=0.0)
    pt = simulate_case(
        SITE.roads["B"],
        dataclasses.replace(radar, detection_probability={"default": Curve.constant(1.0)}),
        veh,
        CASE["B/pass_60"],
        n_runs=50,
        rng=np.random.default_rng(3),
        start_m=200.0,
        stop_line_m=15.0,
        lateral_offset_std_m=0.0,
    )
    from adaptrack.crossing.site.geometry import radial_geometry

    r_true, _, vr_true = radial_geometry(pt.position, pt.velocity, radar.position_m, radar.height_m)
    ok = pt.detected
    # ~12,000 draws: the sample sd has a relative sd of 0.65 %; 5 sigma = 3.3 %
    assert np.std((pt.measurements[..., 0] - r_true)[ok]) == pytest.approx(0.25, rel=0.033)
    assert np.std((pt.measurements[..., 2] - vr_true)[ok]) == pytest.approx(0.10, rel=0.033)
    # stopped vehicles vanish behind the Doppler gate
    _, stop = simulate(CASE["B/stop_60"])
    assert not stop.detected[stop.speed == 0].any()
    # folding of the radial speed
    _, fold = simulate(CASE["B/pass_100"], max_unambiguous_speed_mps=10.0)
    vr = fold.measurements[..., 2][fold.detected]
    assert np.all(np.abs(vr) <= 10.0)


def test_jitter_keeps_times_increasing():
    _, runs = simulate(CASE["B/pass_20"])
    assert np.all(np.diff(runs.times, axis=1) > 0)
    assert np.max(np.abs(runs.times - runs.true_times)) <= 0.005


@pytest.mark.statistical
def test_road_constrained_filter_on_point_targets_is_near_the_bound():
    """No scatter, no bias, no jitter, no offset: CROSSING-LIMITS gives ~0.04 m / 0.2-0.4 km/h
    for the road filters on the nominal radar; allow a factor ~3 for this simple CA filter."""
    radar, runs = point_target(100, 1)
    est = track_on_road(
        runs.times,
        runs.measurements,
        runs.detected,
        radar,
        SITE.roads["B"],
        model=ConstantAcceleration(jerk_psd=3.0),
    )
    zone = (runs.along_road_m <= 150) & (runs.true_times >= 1.0)
    pos = np.sqrt(np.mean(np.sum((est.position - runs.position) ** 2, -1)[zone]))
    spd = np.sqrt(np.mean(((est.speed - runs.speed) * 3.6)[zone] ** 2))
    assert pos < 0.12 and spd < 0.6
    free = track_free_2d(runs.times, runs.measurements, runs.detected, radar)
    pos_free = np.sqrt(np.mean(np.sum((free.position - runs.position) ** 2, -1)[zone]))
    assert pos < pos_free < 0.5  # the road map takes the cross-range error out


def test_tracks_start_at_first_detection_and_coast():
    radar, runs = simulate(CASE["B/stop_60"], n_runs=5)
    est = track_on_road(
        runs.times,
        runs.measurements,
        runs.detected,
        radar,
        SITE.roads["B"],
        model=ConstantAcceleration(jerk_psd=3.0),
    )
    first = np.argmax(runs.detected, axis=1)
    for i, f in enumerate(first):
        assert np.all(np.isnan(est.speed[i, :f])) and np.all(np.isfinite(est.speed[i, f:]))
    # after the stop (no detections) the track coasts: estimates stay finite
    assert np.all(np.isfinite(est.position[:, -1]))


@pytest.mark.distributed
def test_compliance_on_a_dask_cluster_is_bit_identical_and_structured(dask_pool, monkeypatch):
    from adaptrack.crossing.studies import compliance

    monkeypatch.setattr(compliance, "RUN_BLOCK_STEPS", 1_000)  # several blocks per pair
    cases = (CASE["B/pass_60"], CASE["A/pass_60"])
    classes = ("car", "bus")
    a = evaluate_site(SITE, 3, 7, cases=cases, classes=classes)
    b = evaluate_site(SITE, 3, 7, cases=cases, classes=classes, pool=dask_pool)
    np.testing.assert_equal(
        [dataclasses.astuple(r) for r in a.rows], [dataclasses.astuple(r) for r in b.rows]
    )  # NaN == NaN here
    assert len(a.rows) == 2 * 2 * 5
    out = a.to_json()
    assert out["requirements"]["position_rms_m"] == 0.7
    assert set(out["summary"]) == {
        "free 2-D EKF (CV)",
        "CMKF (2-D, no Doppler)",
        "road EKF (CV)",
        "road EKF (CA)",
        "road EKF (M2)",
    }
    assert ComplianceResult.from_json(out) == dataclasses.replace(a, elapsed_s=a.elapsed_s)


@pytest.mark.distributed
def test_custom_trackers_run_on_the_cluster_too(dask_pool):
    from adaptrack.crossing.studies.trackers import RoadTracker

    mine = {"road EKF (CA, q = 1)": RoadTracker(ConstantAcceleration(jerk_psd=1.0))}
    cases = (CASE["B/pass_60"],)
    classes = ("car",)
    a = evaluate_site(SITE, 2, 3, cases=cases, classes=classes, trackers=mine)
    b = evaluate_site(SITE, 2, 3, cases=cases, classes=classes, trackers=mine, pool=dask_pool)
    assert [r.filter for r in a.rows] == ["road EKF (CA, q = 1)"]
    np.testing.assert_equal(
        [dataclasses.astuple(r) for r in a.rows], [dataclasses.astuple(r) for r in b.rows]
    )


def test_run_blocks_merge_to_the_pooled_rms(monkeypatch):
    """Blocks of runs (own seed streams) pool into the RMS over all their epochs."""
    import math

    from adaptrack.crossing.simulation.radar import site_scan_count
    from adaptrack.crossing.studies import compliance
    from adaptrack.crossing.studies.compliance import _blocks, evaluate_pair
    from adaptrack.crossing.studies.trackers import RoadTracker

    case, veh = CASE["B/pass_60"], VEHICLES["car"]
    mine = {"ca": RoadTracker(ConstantAcceleration(jerk_psd=3.0))}
    seed = np.random.SeedSequence(11)
    n_steps = site_scan_count(SITE, case, veh)
    monkeypatch.setattr(compliance, "RUN_BLOCK_STEPS", 2 * n_steps)
    blocks = _blocks(5, n_steps, seed)
    assert [size for size, _ in blocks] == [2, 2, 1]
    assert blocks[0][1] is seed  # one block: the pair's own stream, as without blocks
    whole = evaluate_pair(SITE, case, veh, 5, seed, mine)[0]
    parts = [evaluate_pair(SITE, case, veh, size, ss, mine)[0] for size, ss in blocks]
    n = sum(p.n_epochs for p in parts)
    assert whole.n_epochs == n and len({p.position_rms_m for p in parts}) == 3
    for field in ("position_rms_m", "speed_rms_kmh"):  # 60 km/h: every epoch scores speed
        pooled = math.sqrt(sum(getattr(p, field) ** 2 * p.n_epochs for p in parts) / n)
        assert getattr(whole, field) == pytest.approx(pooled, rel=1e-12)


def test_road_pcrlb_matches_the_filter_covariance_on_point_targets():
    """On a point target the EKF linearises at (nearly) the truth: its reported position and
    speed variances must approach the bound's (same model, same Jacobians)."""
    from adaptrack.crossing.estimators.road_filters import road_pcrlb

    radar, runs = point_target(20, 2)
    model = ConstantAcceleration(jerk_psd=3.0)
    pos_var, spd_var = road_pcrlb(
        runs.times,
        runs.detected,
        runs.along_road_m,
        runs.speed,
        runs.lateral_offset_m,
        radar,
        SITE.roads["B"],
        model=model,
    )
    est = track_on_road(
        runs.times, runs.measurements, runs.detected, radar, SITE.roads["B"], model=model
    )
    filt_pos_var = np.trace(est.position_cov, axis1=-2, axis2=-1)
    late = slice(60, -5)
    np.testing.assert_allclose(filt_pos_var[:, late], pos_var[:, late], rtol=0.15)
    assert np.all(np.diff(pos_var[0, :40]) < 0)  # information accumulates while converging
    assert np.all(spd_var[:, 5:] > 0)


def test_converted_measurement_kf_tracks_but_needs_doppler_for_speed():
    from adaptrack.crossing.estimators.road_filters import track_converted

    radar, runs = point_target(30, 5, detection_probability=0.95)
    zone = (runs.along_road_m <= 150) & (runs.true_times >= 1.0)
    cm = track_converted(runs.times, runs.measurements, runs.detected, radar)
    ekf = track_free_2d(runs.times, runs.measurements, runs.detected, radar)

    def rms(est):
        p = np.sqrt(np.mean(np.sum((est.position - runs.position) ** 2, -1)[zone]))
        s = np.sqrt(np.mean(((est.speed - runs.speed) * 3.6)[zone] ** 2))
        return p, s

    (p_cm, s_cm), (_, s_ekf) = rms(cm), rms(ekf)
    assert p_cm < 0.5
    assert s_cm > 2 * s_ekf  # speed from differentiated positions vs radial speed
    first = np.argmax(runs.detected, axis=1)
    assert np.isnan(cm.speed[first > 0, 0]).all()


@pytest.mark.parametrize("case_name", ["B/pass_20", "A/pass_60", "B/stop_60"])
def test_compiled_trackers_and_bound_equal_the_numpy_reference(case_name):
    """The compiled EKFs and PCRLB give the NumPy loops' numbers to rounding. (Cases whose
    vehicles pass close under the radar are left out: there the linearisation is so
    ill-conditioned that rounding differences grow along the track, as between two builds.)"""
    from adaptrack.crossing.estimators.road_filters import road_pcrlb
    from adaptrack.models import ShapingFilter

    case = CASE[case_name]
    radar, runs = simulate(case, n_runs=6, seed=3)
    road = SITE.roads[case.road]
    args = (runs.times, runs.measurements, runs.detected, radar)

    def same(a, b):
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        assert np.nanmax(np.abs(a - b)) <= 1e-9 * np.nanmax(np.abs(a))

    for model in (ConstantAcceleration(jerk_psd=3.0), ShapingFilter(0.05, 1 / 3, 5.0)):
        ref = track_on_road(*args, road, model=model, scatter_std_m=0.5, backend="numpy")
        got = track_on_road(*args, road, model=model, scatter_std_m=0.5, backend="numba")
        for x, y in zip(dataclasses.astuple(ref), dataclasses.astuple(got), strict=True):
            same(x, y)
    ref = track_free_2d(*args, scatter_std_m=0.5, backend="numpy")
    got = track_free_2d(*args, scatter_std_m=0.5, backend="numba")
    for x, y in zip(dataclasses.astuple(ref), dataclasses.astuple(got), strict=True):
        same(x, y)
    truth = (runs.times, runs.detected, runs.along_road_m, runs.speed, runs.lateral_offset_m)
    kw = {"model": ConstantAcceleration(jerk_psd=3.0), "scatter_std_m": 0.5}
    for x, y in zip(
        road_pcrlb(*truth, radar, road, backend="numpy", **kw),
        road_pcrlb(*truth, radar, road, backend="numba", **kw),
        strict=True,
    ):
        same(x, y)
    with pytest.raises(ValueError, match="backend must be"):
        track_free_2d(*args, backend="gpu")


def test_generated_ekf_kernel_equals_the_generic_kernel(monkeypatch):
    """The straight-line kernel (per state size) and the generic-loop one agree to rounding."""
    from adaptrack.crossing.estimators import codegen, kernels

    case = CASE["A/stop_60"]
    radar, runs = simulate(case, vehicle="truck", n_runs=8, seed=5)
    args = (runs.times, runs.measurements, runs.detected, radar)
    road = SITE.roads[case.road]
    generated = [
        track_on_road(*args, road, model=ConstantAcceleration(jerk_psd=3.0), backend="numba"),
        track_free_2d(*args, scatter_std_m=0.7, backend="numba"),
    ]
    monkeypatch.setattr(codegen, "ekf_kernel", lambda *_: kernels.ekf_kernel)
    generic = [
        track_on_road(*args, road, model=ConstantAcceleration(jerk_psd=3.0), backend="numba"),
        track_free_2d(*args, scatter_std_m=0.7, backend="numba"),
    ]
    for a, b in zip(generated, generic, strict=True):
        for x, y in zip(dataclasses.astuple(a), dataclasses.astuple(b), strict=True):
            np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
            assert np.nanmax(np.abs(x - y)) <= 1e-10 * np.nanmax(np.abs(x))


def test_detection_kernel_equals_the_numpy_geometry():
    """Detections of the compiled simulation equal :func:`radial_geometry` plus unit noise
    scaled by the radar's curves at the true geometry, gated by near/far fields of view."""
    from adaptrack.crossing.simulation.radar_kernel import detections_kernel
    from adaptrack.crossing.site.geometry import radial_geometry
    from adaptrack.crossing.site.sensor import FieldOfView

    radar = dataclasses.replace(
        SITE.radar_for("A"),
        azimuth_bias_rad=0.01,
        fields=(FieldOfView(60.0, np.radians(60.0)), FieldOfView(200.0, np.radians(9.0))),
        range_std_m=Curve(((0.0, 0.1), (100.0, 0.3))),
        azimuth_std_rad=Curve(((0.0, 0.002), (1.0, 0.02))),
        radial_speed_std_mps=Curve.constant(0.2),
    )
    _, runs = simulate(CASE["A/pass_60"], n_runs=4, seed=2)
    n_runs, n_steps = runs.speed.shape
    direction = runs.velocity / np.maximum(runs.speed, 1e-12)[..., None]
    zeros = np.zeros((n_runs, n_steps))
    unit = np.ones((n_runs, n_steps, 3))
    radar_arr = np.array(
        [*radar.position_m, radar.height_m, radar.azimuth_bias_rad, radar.boresight_rad]
        + [radar.min_range_m, 0.1, 0.0]
    )
    meas = np.empty((n_runs, n_steps, 3))
    detected = np.empty((n_runs, n_steps), dtype=bool)
    pd_tab = np.array([[[0.0], [1.0]]]), np.array([1])
    detections_kernel(
        runs.position, direction, runs.speed, zeros, unit, zeros, radar_arr,
        radar.field_table(), *radar.noise_table(), *pd_tab, meas, detected,
    )  # fmt: skip
    rng_m, az, vr = radial_geometry(runs.position, runs.velocity, radar.position_m, radar.height_m)
    off = np.abs((az - radar.boresight_rad + np.pi) % (2 * np.pi) - np.pi)
    # near field: up to 60 m within +-60 deg; far field: up to 200 m within +-9 deg
    near = (rng_m <= 60.0) & (off <= np.radians(60.0))
    far = (rng_m <= 200.0) & (off <= np.radians(9.0))
    gate = (near | far) & (rng_m >= radar.min_range_m) & (np.abs(vr) >= 0.1)
    np.testing.assert_array_equal(detected, gate)
    assert gate.any() and not gate.all() and (far & ~near).any()
    np.testing.assert_array_equal(radar.covers(runs.position), (near | far) & (rng_m >= 0.5))
    sig_r = np.interp(rng_m, [0.0, 100.0], [0.1, 0.3])  # independent of the Curve class
    sig_az = np.interp(off, [0.0, 1.0], [0.002, 0.02])
    ref = np.stack(
        [
            rng_m + sig_r,
            (az + radar.azimuth_bias_rad + sig_az + np.pi) % (2 * np.pi) - np.pi,
            vr + 0.2,
        ],
        -1,
    )
    np.testing.assert_allclose(meas[gate], ref[gate], rtol=1e-13, atol=1e-13)
    assert np.isnan(meas[~gate]).all()


def test_detection_probability_follows_class_and_range():
    """P_D by class and range: the detected fraction in range bins matches the curve."""
    radar = dataclasses.replace(
        SITE.radar_for("B"),
        detection_probability={
            "default": Curve.constant(0.95),
            "motorcycle": Curve(((50.0, 0.9), (150.0, 0.5))),
        },
    )
    runs = simulate_case(
        SITE.roads["B"], radar, VEHICLES["motorcycle"], CASE["B/pass_60"], n_runs=400,
        rng=np.random.default_rng(8), start_m=200.0, stop_line_m=15.0, lateral_offset_std_m=0.3,
    )  # fmt: skip
    from adaptrack.crossing.site.geometry import radial_geometry

    rng_m, _, _ = radial_geometry(runs.position, runs.velocity, radar.position_m, radar.height_m)
    for lo, hi in ((20.0, 40.0), (95.0, 105.0), (170.0, 190.0)):
        sel = (rng_m > lo) & (rng_m < hi) & radar.covers(runs.position)
        expected = float(np.mean(radar.detection_curve("motorcycle")(rng_m[sel])))
        # binomial: > 3,000 draws per bin, sd < 0.01; 5 sd
        assert runs.detected[sel].mean() == pytest.approx(expected, abs=0.05)
    assert radar.detection_curve("car")(100.0) == 0.95


def test_wrapped_angles_equal_pythons_floored_remainder_to_the_last_bit():
    """The compiled wrap avoids the remainder call within a turn either side: every value,
    the turn's edges included, equals Python's ``(a + h) % (2 h) - h`` exactly."""
    rng = np.random.default_rng(3)
    two_pi = 2.0 * math.pi
    edges = [k * math.pi + e for k in range(-5, 6) for e in (0.0, 1e-15, -1e-15, 5e-324, -5e-324)]
    values = [*edges, *rng.uniform(-8 * math.pi, 8 * math.pi, 20000), 0.0, -0.0, 1e6, -1e6]
    for half in (math.pi, 0.5 * math.pi, 17.0):
        for a in values:
            expected = (a + half) % (2.0 * half) - half
            got = wrapped(a, half)
            same_sign = math.copysign(1.0, got) == math.copysign(1.0, expected)
            assert got == expected and same_sign, (a, half, got, expected)
    assert wrapped(-3.0 * math.pi / 2, math.pi) == math.pi / 2
    assert abs(wrapped(two_pi + 0.25, math.pi) - 0.25) < 1e-15
