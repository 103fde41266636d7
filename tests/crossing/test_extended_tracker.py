"""The extended-object scene tracker on motion it was not built around, seen by the face radar.

Free motion on the built-in site: a car turning off the road, a 10 m lorry, a car standing
from before it is first seen, a pedestrian crossing diagonally and a car driving through. The
reflections come from the face model of the simulator (its own geometry: nothing shared with
the tracker's box view), and the scorer shares no code with the tracker; the background is
learnt from the empty site with another seed. Each road user must meet the crossing's
requirement (0.7 m, 2 km/h RMS over its epochs in the zone, paired at 90 % of them) with every
radar kind; the cases the tracker does not yet meet are listed with the reason
(``KNOWN_LIMITS``) as strict expected failures, so that one that starts to pass is noticed.
"""

import math

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.scene.extended_tracker import (
    ExtendedTracker,
    ExtendedTrackerConfig,
    track_scene_extended,
)
from adaptrack.crossing.simulation.faces import FaceRadar
from adaptrack.crossing.simulation.motion import read_motion, simulate_replay
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.clearance import empty_background
from adaptrack.crossing.studies.scene_metrics import score_scene

DURATION_S = 16.0


def _path(object_id, cls, length, width, t, xy, heading):
    speed = np.hypot(*np.gradient(xy, t, axis=0).T)
    return pd.DataFrame({
        "time_s": t, "object_id": object_id, "class": cls, "x_m": xy[:, 0], "y_m": xy[:, 1],
        "length_m": length, "width_m": width, "speed_mps": speed,
        "heading_deg": np.degrees(heading) % 360.0,
    })  # fmt: skip


def _motion_table() -> pd.DataFrame:
    t = np.arange(0.0, DURATION_S + 1e-9, 0.1)
    # a car southbound at 7 m/s (25 km/h), turning right (west) on a 12 m radius at y = 50 m
    v, radius, straight_m = 7.0, 12.0, 40.0
    straight = np.minimum(t * v, straight_m)
    arc = np.clip(t * v - straight_m, 0.0, 0.5 * math.pi * radius)
    beyond = np.maximum(t * v - straight_m - 0.5 * math.pi * radius, 0.0)
    phi = arc / radius
    x = 1.75 - radius * (1 - np.cos(phi)) - beyond
    y = 90.0 - straight - radius * np.sin(phi)
    heading = math.pi + phi  # azimuth: south, turning to west
    turning = _path(1, "car", 4.6, 1.8, t, np.stack([x, y], -1), heading)
    # a 10 m lorry northbound at 10 m/s
    lorry = _path(2, "truck", 10.0, 2.5, t, np.stack([np.full_like(t, -1.75), -110.0 + 10.0 * t],
                                                     -1), np.zeros_like(t))  # fmt: skip
    # a car that stands at 30 m on the southbound lane the whole time
    standing = _path(3, "car", 4.5, 1.8, t, np.tile([1.75, 30.0], (t.size, 1)),
                     np.full_like(t, math.pi))  # fmt: skip
    # a pedestrian crossing the road diagonally at 1.4 m/s
    d = np.array([0.8, 0.6])
    walk = np.array([-8.0, 14.0]) + 1.4 * t[:, None] * d
    walker = _path(4, "pedestrian", 0.5, 0.6, t, walk, np.full_like(t, math.atan2(*d)))
    # a car southbound at 70 km/h through the crossing, overtaking in the outer lane
    through = _path(5, "car", 4.4, 1.8, t, np.stack([np.full_like(t, 5.25), 140.0 - 19.4 * t],
                                                     -1), np.full_like(t, math.pi))  # fmt: skip
    return pd.concat([turning, lorry, standing, walker, through], ignore_index=True)


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """The scene tracked with each radar kind: kind -> (score, tracks, events, log, n)."""
    site = load_site("lx_default")
    root = tmp_path_factory.mktemp("motion")
    _motion_table().to_csv(root / "free_motion.csv", index=False)
    motion = read_motion(root / "free_motion.csv")
    out = {}
    for kind in ("object", "cluster", "cloud"):
        radar = FaceRadar.of_kind(kind)
        background = empty_background(site, radar, 60.0, seed=99)
        rec = simulate_replay(site, motion, seed=7, radar=radar)
        tracks, events, log = track_scene_extended(site, rec.detections, background=background)
        out[kind] = (score_scene(rec.truth, tracks, site.zone_m), tracks, events, log,
                     len(rec.detections))  # fmt: skip
    return out


_LORRY = "a 10 m lorry seen end-on: its length is not observed, the prior box (4.5 m) puts " \
    "the centre half the excess off"  # fmt: skip
_TURN_THEN_OUT = "the 0.58 rad/s turn entered at once lags the turn rate's random walk " \
    "(0.5-1 m), then the car drives on out of every field of view inside the zone and its " \
    "coasting track drifts 2-5 m"  # fmt: skip
KNOWN_LIMITS = {
    ("object", 2): _LORRY, ("cluster", 2): _LORRY, ("cloud", 2): _LORRY,
    ("object", 4): "an object list does not show a pedestrian's size: the car prior box "
    "offsets it by its near face",
    ("cluster", 1): _TURN_THEN_OUT,
    ("cloud", 1): _TURN_THEN_OUT,
    ("cloud", 5): "at 100-140 m the cloud gives the 70 km/h car few points: its first tracks "
    "flicker below the reported existence (coverage 0.80)",
}  # fmt: skip
USERS = {1: "turning car", 2: "lorry", 3: "car standing from before first seen",
         4: "pedestrian crossing diagonally", 5: "car at 70 km/h"}  # fmt: skip


@pytest.mark.parametrize(
    ("kind", "user"),
    [pytest.param(k, u, id=f"{k}-{USERS[u]}", marks=[pytest.mark.xfail(
        reason=KNOWN_LIMITS[(k, u)], strict=True)] if (k, u) in KNOWN_LIMITS else [])
     for k in ("object", "cluster", "cloud") for u in USERS],
)  # fmt: skip
def test_each_road_user_meets_the_requirement(scored, kind, user):
    score = scored[kind][0]
    row = score.users.set_index("object_id").loc[user]
    assert row.coverage >= 0.9, row.to_dict()
    assert row.position_rms_m <= 0.7, row.to_dict()
    assert row.speed_rms_kmh <= 2.0, row.to_dict()


@pytest.mark.parametrize("kind", ["object", "cluster", "cloud"])
def test_every_detection_is_accounted_for_and_standing_reflectors_are_background(scored, kind):
    score, _, events, log, n = scored[kind]
    assert log.total == n
    assert log.background > 0  # the site's posts and barrier arms, explained
    assert len(score.users) == 5
    # the lorry and the car at 70 km/h drive over the crossing: not clear while they do
    assert set(events["event"]) <= {"crossing_not_clear", "crossing_clear"}
    assert (events["event"] == "crossing_not_clear").sum() >= 1


@pytest.mark.parametrize(
    "kind",
    ["object", "cluster", pytest.param("cloud", marks=pytest.mark.xfail(
        reason="the 10 m lorry's point cloud holds extra tracks on its body and its multipath "
        "ghosts (4.5 m boxes on a 10 m body do not overlap)", strict=True))],
)  # fmt: skip
def test_false_tracks_come_only_from_the_lorry(scored, kind):
    score, *_ = scored[kind]
    assert score.false_tracks <= 1  # the lorry's far end, seen from the other side (~1.5 s)


def test_a_scan_out_of_time_order_or_with_bad_values_is_an_error():
    site = load_site("lx_default")
    tracker = ExtendedTracker(site)
    tracker.step("radar_A", 1.0, np.array([[30.0, 0.01, -3.0]]))
    with pytest.raises(ValueError, match="not after its previous scan"):
        tracker.step("radar_A", 1.0, np.zeros((0, 3)))
    with pytest.raises(ValueError, match="not finite"):
        tracker.step("radar_A", 2.0, np.array([[np.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="unknown radar"):
        tracker.step("radar_Q", 3.0, np.zeros((0, 3)))
    with pytest.raises(ValueError, match="keep_existence"):
        ExtendedTrackerConfig(keep_existence=0.999)
    with pytest.raises(ValueError, match="accel_psd"):
        ExtendedTrackerConfig(accel_psd=-1.0)


def test_bad_detections_are_errors_naming_what_is_wrong():
    site = load_site("lx_default")
    tracker = ExtendedTracker(site)
    with pytest.raises(ValueError, match=r"must be \(n, 3\).*got shape \(2, 2\)"):
        tracker.step("radar_A", 1.0, np.zeros((2, 2)))
    good = pd.DataFrame({"radar": ["radar_A"] * 2, "time_s": [0.0, 0.05],
                         "range_m": [30.0, 30.5], "azimuth_rad": [0.01, 0.01],
                         "radial_speed_mps": [-3.0, -3.0]})  # fmt: skip
    with pytest.raises(ValueError, match=r"missing column\(s\) \['radial_speed_mps'\]"):
        track_scene_extended(site, good.drop(columns="radial_speed_mps"))
    nan = good.assign(range_m=[30.0, np.inf])
    with pytest.raises(ValueError, match=r"row 2, column 'range_m': expected a finite number"):
        track_scene_extended(site, nan)
    from adaptrack.crossing.scene.background import learn_background

    with pytest.raises(ValueError, match=r"row 1, column 'azimuth_rad'"):
        learn_background(site, good.assign(azimuth_rad=[np.nan, 0.0]))
    with pytest.raises(ValueError, match="radars the site does not have"):
        learn_background(site, good.assign(radar="radar_Q"))


def test_bad_train_intervals_and_clutter_points_are_errors():
    from adaptrack.crossing.scene.occupancy import ClearanceMonitor
    from adaptrack.tracking.clutter_map import ClutterMap

    site = load_site("lx_default")
    with pytest.raises(ValueError, match=r"train interval 1: expected finite start_s < end_s"):
        ClearanceMonitor(site, np.array([[0.0, 5.0], [9.0, 3.0]]))
    with pytest.raises(ValueError, match=r"must be \(K, 2\)"):
        ClearanceMonitor(site, np.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="point 1 is not finite"):
        ClutterMap(prior_density=1e-5).end_scan(np.array([[0.0, 0.0], [np.nan, 1.0]]))
