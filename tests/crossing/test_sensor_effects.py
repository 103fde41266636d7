"""Sensor effects the trackers survive: folded radial speeds, timestamp latency.

Folding: a radar with an unambiguous interval of +-34 km/h reports a car at 60 km/h at about
-8 km/h. The simulated data folds after the noise is drawn, so the same seed gives the same
detections with and without folding: the unfolded run on identical noise is the oracle.
"""

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.estimators.kernels import innovation_into
from adaptrack.crossing.estimators.road_filters import (
    track_free_2d,
    track_on_road,
    track_on_road_imm,
)
from adaptrack.crossing.measurements_io import detections_frame, read_detections
from adaptrack.crossing.scene.tracker import (
    SceneTracker,
    SceneTrackerConfig,
    iter_scans,
    track_scene,
)
from adaptrack.crossing.simulation.radar import simulate_case
from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.site.traffic import VEHICLES
from adaptrack.crossing.studies.scene_metrics import score_scene
from adaptrack.models import ConstantAcceleration, ConstantVelocity

SITE = load_site("lx_default")
CASE = {c.name: c for c in SITE.cases}
FOLD_MPS = 34 / 3.6
CAR = VEHICLES["car"]


def test_innovation_unfolds_to_the_alias_nearest_the_prediction():
    radar = np.array([0, 0, 5, 0, 1, 0.3, 10.0])
    nu = np.zeros(3)
    innovation_into(np.array([50.0, 3.1, 9.5]), np.array([49.0, -3.1, -9.5]), radar, True, nu)
    np.testing.assert_allclose(nu, [1.0, 6.2 - 2 * np.pi, -1.0])  # 9.5 - (-9.5) - 20
    innovation_into(np.array([50.0, 0.0, 9.5]), np.array([50.0, 0.0, -9.5]), radar, False, nu)
    assert nu[2] == 0.0  # left out while the prediction cannot tell the alias
    radar[6] = 0.0  # no folding: plain difference
    innovation_into(np.array([50.0, 0.0, 9.5]), np.array([50.0, 0.0, -9.5]), radar, True, nu)
    assert nu[2] == 19.0


def runs_of(case, fold):
    radar = dataclasses.replace(SITE.radar_for(case.road), max_unambiguous_speed_mps=fold)
    runs = simulate_case(
        SITE.roads[case.road], radar, CAR, case, n_runs=30, rng=np.random.default_rng(5),
        start_m=200.0, stop_line_m=15.0, lateral_offset_std_m=0.3,
    )  # fmt: skip
    return radar, runs


def rms(est, runs):
    zone = (runs.along_road_m <= SITE.zone_m) & (runs.true_times >= 1.0)
    pos = np.sqrt(np.nanmean(np.sum((est.position - runs.position) ** 2, -1)[zone]))
    spd = np.sqrt(np.nanmean(((est.speed - runs.speed) * 3.6)[zone] ** 2))
    return pos, spd


TRACKERS = {
    "road": lambda t, z, d, radar, road, be: track_on_road(
        t, z, d, radar, road, model=ConstantAcceleration(jerk_psd=3.0),
        scatter_std_m=CAR.scatter_std_m, backend=be,
    ),
    "imm": lambda t, z, d, radar, road, be: track_on_road_imm(
        t, z, d, radar, road, models=(ConstantVelocity(accel_psd=0.5),
        ConstantAcceleration(jerk_psd=3.0)), sojourn_s=(5.0, 2.0),
        scatter_std_m=CAR.scatter_std_m, backend=be,
    ),
    "free": lambda t, z, d, radar, road, be: track_free_2d(
        t, z, d, radar, scatter_std_m=CAR.scatter_std_m, backend=be
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", ["A/pass_60", "B/pass_100", "B/stop_60"])
@pytest.mark.parametrize("tracker", ["road", "imm", "free"])
def test_folded_radial_speeds_track_as_well_as_unfolded_ones(case, tracker):
    """Before: a folding radar took the road EKF on B/pass_60 to about 44 m RMS."""
    road = SITE.roads[CASE[case].road]
    out = {}
    for fold in (None, FOLD_MPS):
        radar, runs = runs_of(CASE[case], fold)
        for be in ("numpy", "numba"):
            est = TRACKERS[tracker](runs.times, runs.measurements, runs.detected, radar, road, be)
            out[fold, be] = rms(est, runs)
    assert out[FOLD_MPS, "numpy"] == pytest.approx(out[FOLD_MPS, "numba"], rel=1e-6)
    pos, spd = out[FOLD_MPS, "numba"]
    pos0, spd0 = out[None, "numba"]
    # only the first scans differ (speed from positions until the alias is known); the free
    # filter starts from a vague 2-D velocity and needs longer (measured: 0.30 m / 0.90 km/h
    # against 0.28 m / 0.51 km/h on B/pass_100)
    slack = 1.1 if tracker != "free" else 2.0
    assert pos <= 1.1 * pos0 + 0.03 and spd <= slack * spd0 + 0.05, (out, case)
    if tracker != "free":  # the free EKF misses the limit in a stop, folding or not
        assert pos <= 0.7 and spd <= 2.0


def test_scene_tracker_with_folding_radars_meets_the_requirement():
    folded = dataclasses.replace(
        SITE,
        radars=tuple(
            dataclasses.replace(r, max_unambiguous_speed_mps=FOLD_MPS) for r in SITE.radars
        ),
    )
    spec = scene_spec(SITE, duration_s=60.0, first_closure_s=20.0, closure_s=30.0, stalls=())
    gospa = {"plain": 0.0, "folded": 0.0}
    for seed in (7, 8, 9):
        for name, site in (("plain", SITE), ("folded", folded)):
            rec = simulate_scene(site, spec, seed=seed)
            tracks, _, log = track_scene(site, rec.detections)
            assert log.total == len(rec.detections)
            score = score_scene(rec.truth, tracks, site.zone_m)
            gospa[name] += score.gospa_mean / 3
            for row in score.classes.itertuples():
                assert row.position_rms_m <= 0.7 and row.speed_rms_kmh <= 2.0, (name, seed, row)
    # measured plain / folded 0.93 / 1.93, 0.88 / 1.65, 1.30 / 1.73 (seeds 7-9; mean 1.04 /
    # 1.77): a new track goes without Doppler for its first scans (about 0.3 s), during which
    # short-lived false tracks beside the static clutter get as far as confirmation. (On seed
    # 7 alone the ratio was 1.56 before the life-cycle rules of max_tentative_s and
    # max_position_std_m improved the plain case more; the mean of three scenes is the
    # steadier figure.) Stone Soup's GNN tracker scores 12.3 on the plain detections of seed 7
    assert gospa["folded"] <= 2.0 * gospa["plain"], gospa


def with_latency(site, latency):
    radars = tuple(dataclasses.replace(r, latency_s=latency.get(r.name, 0.0)) for r in site.radars)
    return dataclasses.replace(site, radars=radars)


LATENCY = {"radar_A": 0.05, "radar_X": 0.08}


def test_declared_latency_is_taken_off_the_timestamps(tmp_path):
    site = with_latency(SITE, LATENCY)
    case = CASE["A/pass_60"]
    radar = site.radar_for(case.road)
    runs = simulate_case(
        SITE.roads[case.road], radar, CAR, case, n_runs=2, rng=np.random.default_rng(1),
        start_m=200.0, stop_line_m=15.0, lateral_offset_std_m=0.3,
    )  # fmt: skip
    assert np.allclose(runs.times - runs.true_times, 0.05, atol=radar.time_jitter_s + 1e-12)
    det, _ = detections_frame(runs, radar.name, 1, np.zeros(2))
    path = tmp_path / "det.csv"
    det.to_csv(path, index=False)
    objects = read_detections(path, site)
    stamps = det[det.object_id == 1]["time_s"].to_numpy()
    np.testing.assert_allclose(objects[0].times, stamps - 0.05)


def test_scene_with_declared_latencies_tracks_as_without_latency():
    """Latency shifts only the stamps (same noise draws): taken off, the tracks are the same."""
    spec = scene_spec(SITE, duration_s=40.0, first_closure_s=15.0, closure_s=20.0, stalls=())
    late = with_latency(SITE, LATENCY)
    plain = simulate_scene(SITE, spec, seed=1)
    shifted = simulate_scene(late, spec, seed=1)
    ref, _, _ = track_scene(SITE, plain.detections)
    declared, _, _ = track_scene(late, shifted.detections)
    cols = ["track_id", "time_s", "east_m", "north_m", "speed_mps", "status"]
    assert len(ref) > 1000
    np.testing.assert_allclose(declared["time_s"], ref["time_s"], atol=1e-9)
    assert declared[cols].round(6).equals(ref[cols].round(6))
    # not declared, the radars' views of one vehicle disagree by 50-80 ms of travel
    undeclared, _, _ = track_scene(SITE, shifted.detections)
    err = {
        name: score_scene(shifted.truth, t, SITE.zone_m).gospa_localisation
        for name, t in (("declared", declared), ("undeclared", undeclared))
    }
    assert err["undeclared"] > err["declared"], err


def test_azimuth_biases_are_estimated_against_the_lanes():
    """A 0.5 deg bias puts a vehicle 1.3 m off its lane at 150 m.

    Precision: vehicles keep their own lateral offset (sd 0.3 m) for the whole pass; with about
    20 vehicles in 120 s that limits the estimate to about 0.05 deg (1 sigma): 0.1 deg is 2 sigma.
    """
    bias_deg = {"radar_A": 0.5, "radar_B": 0.0, "radar_X": -0.3}
    biased = dataclasses.replace(
        SITE,
        radars=tuple(
            dataclasses.replace(r, azimuth_bias_rad=math.radians(bias_deg[r.name]))
            for r in SITE.radars
        ),
    )
    spec = scene_spec(SITE, duration_s=120.0, first_closure_s=40.0, closure_s=30.0, stalls=())
    rec = simulate_scene(biased, spec, seed=1)
    car_rms = {}
    for estimate in (True, False):
        tracker = SceneTracker(SITE, SceneTrackerConfig(estimate_azimuth_bias=estimate))
        rows = []
        for radar, t, z, _ in iter_scans(rec.detections):
            tracker.step(radar, t, z)
            rows.append(tracker.rows(tracker.last_scan_s))
        score = score_scene(rec.truth, pd.concat(rows), SITE.zone_m)
        car_rms[estimate] = score.classes.set_index("class").loc["car", "position_rms_m"]
        if estimate:
            for name, b in bias_deg.items():
                assert math.degrees(tracker.azimuth_bias_rad[name]) == pytest.approx(b, abs=0.1)
    assert car_rms[True] <= 0.7 and car_rms[True] < 0.7 * car_rms[False], car_rms
