"""Object-list radars: simulated sensor ids, and the scene tracker taking them as hints."""

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.measurements_io import read_scene_detections
from adaptrack.crossing.scene.tracker import SceneTracker, SceneTrackerConfig, track_scene
from adaptrack.crossing.simulation.object_list import object_list_ids
from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.scene_metrics import score_scene

SITE = load_site("lx_default")


@pytest.fixture(scope="module")
def scene():
    spec = scene_spec(SITE, duration_s=90.0, closure_s=0.0, stalls=())
    return simulate_scene(SITE, spec, seed=5)


def test_a_road_user_keeps_its_id_while_seen_and_gets_a_new_one_after_a_gap(scene):
    ids = object_list_ids(scene, 0, swap_probability=0.0, reissue_after_s=1.0)
    det = scene.detections.assign(sensor_id=ids, source=scene.sources)
    users = det[det.source >= 0]
    for (_, _), g in users.groupby(["radar", "source"]):
        t = g.time_s.to_numpy()
        new_run = np.concatenate([[True], np.diff(t) > 1.0])
        run = np.cumsum(new_run)
        # one id per run of detections without a 1 s gap, a different one per run
        per_run = g.groupby(run).sensor_id.nunique()
        assert (per_run == 1).all()
        assert g.groupby(run).sensor_id.first().is_unique
    # ids of different users never coincide within a radar; false alarms are all unique
    for _, g in det.groupby("radar"):
        assert (g[g.source >= 0].groupby("sensor_id").source.nunique() == 1).all()
        assert g[g.source == -1].sensor_id.is_unique
        assert not set(g[g.source == -1].sensor_id) & set(g[g.source >= 0].sensor_id)


def test_close_road_users_swap_ids_when_the_sensor_confuses_them(scene):
    never = object_list_ids(scene, 0, swap_probability=0.0, swap_radius_m=1e4)
    always = object_list_ids(scene, 0, swap_probability=1.0, swap_radius_m=1e4)
    src = scene.sources
    per_user = pd.Series(always[src >= 0]).groupby(src[src >= 0]).nunique()
    assert (per_user > 1).any()  # every scan swaps every pair: users change ids
    n_ids = pd.Series(never[src >= 0]).groupby(src[src >= 0]).nunique()
    assert n_ids.sum() < pd.Series(always[src >= 0]).groupby(src[src >= 0]).nunique().sum()


def test_sensor_ids_change_nothing_without_a_bonus_and_the_assignment_with_one(scene):
    ids = object_list_ids(scene, 0)
    plain, _, _ = track_scene(SITE, scene.detections)
    listed, _, _ = track_scene(SITE, scene.detections.assign(object_id=ids))
    pd.testing.assert_frame_equal(listed, plain)  # default bonus 0: ids are read, not used
    hinted, _, _ = track_scene(
        SITE, scene.detections.assign(object_id=ids), SceneTrackerConfig(sensor_id_bonus=4.0)
    )
    assert not hinted[["east_m", "north_m"]].equals(plain[["east_m", "north_m"]])
    score = score_scene(scene.truth, hinted, SITE.zone_m)
    assert score.gospa_mean < 5.0  # a working tracker (c = 5 m is all missed or false)


@pytest.mark.parametrize(
    "ids, message",
    [
        (np.array([1, 2]), "must be 3 integers"),
        (np.array([1.0, 2.0, 3.0]), "must be 3 integers"),
        (np.array([1, -2, 3]), "must be 3 integers >= -1"),
    ],
)
def test_bad_sensor_ids_are_refused_with_the_scan_named(ids, message):
    tracker = SceneTracker(SITE)
    z = np.array([[30.0, 0.1, -5.0], [40.0, 0.1, -5.0], [50.0, 0.1, -5.0]])
    with pytest.raises(ValueError, match=f"radar 'radar_A' at 1.0 s: sensor ids {message}"):
        tracker.step("radar_A", 1.0, z, ids)


def test_an_object_id_column_that_is_not_an_integer_is_refused_with_its_row(tmp_path):
    det = pd.DataFrame(
        {"radar": ["radar_A"] * 2, "time_s": [0.0, 0.05], "range_m": [30.0, 30.0],
         "azimuth_rad": [0.1, 0.1], "radial_speed_mps": [-5.0, -5.0], "object_id": [3, 3.5]}
    )  # fmt: skip
    path = tmp_path / "det.csv"
    det.to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"row 2, column 'object_id': 3.5 is not an integer"):
        read_scene_detections(path, SITE)
    det.assign(object_id=[3, 4]).to_csv(path, index=False)
    assert read_scene_detections(path, SITE).object_id.tolist() == [3, 4]
