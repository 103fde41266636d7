"""The extended-object scene tracker on motion it was not built around, seen by the face radar.

Free motion on the built-in site: a car turning off the road, a 10 m lorry, a car standing
from before it is first seen, a pedestrian crossing diagonally and a car driving through. The
reflections come from the face model of the simulator (its own geometry: nothing shared with
the tracker's box view), and the scorer shares no code with the tracker. Each road user must
meet the crossing's requirement (0.7 m, 2 km/h RMS over its epochs in the zone, paired at
90 % of them) with every radar kind, and nothing else may be reported.
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
def motion(tmp_path_factory):
    path = tmp_path_factory.mktemp("motion") / "free_motion.csv"
    _motion_table().to_csv(path, index=False)
    return read_motion(path)


@pytest.mark.parametrize("kind", ["object", "cluster", "cloud"])
def test_every_road_user_meets_the_requirement_and_nothing_else_is_reported(motion, kind):
    site = load_site("lx_default")
    rec = simulate_replay(site, motion, seed=7, radar=FaceRadar.of_kind(kind))
    tracks, events, log = track_scene_extended(site, rec.detections)
    assert log.total == len(rec.detections)  # every detection accounted for
    score = score_scene(rec.truth, tracks, site.zone_m)
    users = score.users.set_index("object_id")
    assert len(users) == 5
    for oid, row in users.iterrows():
        assert row.coverage >= 0.9, (kind, oid, row.to_dict())
        assert row.position_rms_m <= 0.7, (kind, oid, row.to_dict())
        assert row.speed_rms_kmh <= 2.0, (kind, oid, row.to_dict())
    assert score.false_tracks == 0


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
