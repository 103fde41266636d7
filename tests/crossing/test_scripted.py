"""Scripted road users in a scene: emergency stops, U-turns, reversing, against closed forms."""

import re
from pathlib import Path

import numpy as np
import pytest
import tomllib

from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.model import site_from_mapping

SITE = Path(__file__).parents[2] / "examples" / "sites" / "junction_crossing.toml"


def _scene(scripted, duration_s=40.0, seed=1):
    data = tomllib.loads(SITE.read_text(encoding="utf-8"))
    data["scene"]["scripted"] = scripted
    data["scene"]["flows"] = [{"entry": "east", "exit": "west", "vehicles_per_h": 0.0},
                              {"entry": "west", "exit": "east", "vehicles_per_h": 1.0}]  # fmt: skip
    site = site_from_mapping(data, "scripted test")
    rec = simulate_scene(site, scene_spec(site, duration_s=duration_s), seed)
    table = rec.truth.table
    table = table[table["vehicle_class"] != "train"]  # added after the scripted users
    last = sorted(table["object_id"].unique())[-len(scripted) :]
    return rec, [table[table["object_id"] == k].reset_index(drop=True) for k in last]


def test_an_emergency_stop_stops_where_the_closed_form_says():
    # 90 km/h for 5 s, then 9 m/s^2 to a standstill (25 / 9 s), then stands
    brake = 25.0 / 9.0
    profile = [[0.0, 90.0], [5.0, 90.0], [5.0 + brake, 0.0], [20.0, 0.0]]
    _, (car,) = _scene([{"path_m": [[1.75, 200.0], [1.75, -200.0]], "speed_profile": profile,
                         "start_s": 3.0}])  # fmt: skip
    assert car["time_s"].iloc[0] == pytest.approx(3.0)
    travelled = 200.0 - car["north_m"].iloc[-1]
    assert travelled == pytest.approx(25.0 * 5.0 + 25.0**2 / (2 * 9.0), abs=0.01)
    braking = car[(car["time_s"] > 8.1) & (car["time_s"] < 8.0 + brake - 0.1)]
    decel = -np.diff(braking["speed_mps"]) / np.diff(braking["time_s"])
    assert np.allclose(decel, 9.0, atol=1e-6)
    assert np.allclose(car["east_m"], 1.75, atol=1e-3)
    assert (car["to_crossing_m"] > 0).all() and car["in_zone"].iloc[-1]


def test_a_reversing_car_faces_against_its_motion():
    profile = [[0.0, 0.0], [2.0, -8.0], [10.0, -8.0], [12.0, 0.0]]
    _, (car,) = _scene([{"path_m": [[1.75, 5.0], [1.75, 60.0]], "speed_profile": profile}])
    moving = car[car["speed_mps"] > 0.5]
    assert np.allclose(np.cos(moving["heading_rad"]), -1.0, atol=1e-6)  # faces south
    assert (moving["north_speed_mps"] > 0).all()  # moves north
    # distance: 2 s ramp (avg 4 km/h) twice plus 8 s at 8 km/h
    travelled = car["north_m"].iloc[-1] - 5.0
    assert travelled == pytest.approx((2 * 2.0 * 4.0 + 8.0 * 8.0) / 3.6, abs=0.01)
    assert (car["to_crossing_m"].iloc[5:] < 0).all()  # leaving the crossing


def test_a_u_turn_keeps_its_speed_and_its_velocity_matches_its_positions():
    path = [[-1.75, -150.0], [-1.75, -20.0], [-4.0, -5.0], [-7.0, -1.0], [-10.0, -5.0],
            [-8.75, -20.0], [-8.75, -150.0]]  # fmt: skip
    _, (car,) = _scene([{"path_m": path, "speed_profile": [[0.0, 30.0], [30.0, 30.0]]}])
    pos = car[["east_m", "north_m"]].to_numpy()
    vel = car[["east_speed_mps", "north_speed_mps"]].to_numpy()
    dt = np.diff(car["time_s"].to_numpy())[:, None]
    mid = 0.5 * (vel[1:] + vel[:-1])
    assert np.abs(np.diff(pos, axis=0) / dt - mid).max() < 0.3  # rounded corner: curvature
    assert np.allclose(np.hypot(*vel.T), 30.0 / 3.6)
    assert car["north_m"].max() > -5.0 and car["north_m"].iloc[-1] < -100.0
    heading = np.unwrap(car["heading_rad"].to_numpy())
    assert abs(np.degrees(heading[-1] - heading[0])) == pytest.approx(180.0, abs=0.5)


def test_radial_speeds_follow_the_motion_not_the_heading():
    profile = [[0.0, -10.0], [12.0, -10.0]]
    rec, _ = _scene([{"path_m": [[1.75, 20.0], [1.75, 150.0]], "speed_profile": profile}],
                         duration_s=12.0)  # fmt: skip
    det = rec.detections
    pole = det[det["radar"] == "pole_n"]  # at (-9, -12) looking north: the car recedes
    near_car = pole[pole["range_m"].between(35.0, 150.0) & (pole["radial_speed_mps"].abs() > 1)]
    assert len(near_car) > 50
    assert np.median(near_car["radial_speed_mps"]) == pytest.approx(10.0 / 3.6, abs=0.3)


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"path_m": [[0, 0], [0, 9]], "speed_profile": [[0, 0], [1, 50]]}, "at most 10 m/s^2"),
        ({"path_m": [[0, 0], [0, 9]], "speed_profile": [[1, 0], [2, 5]]}, "the first at time 0"),
        ({"path_m": [[0, 0]], "speed_profile": [[0, 0], [2, 5]]}, "scene.scripted[0].path_m"),
        (
            {"path_m": [[0, float("nan")], [0, 9]], "speed_profile": [[0, 5], [2, 5]]},
            "scene.scripted[0].path_m[0][1]: Input should be a finite number (got nan)",
        ),
        (
            {"path_m": [[0, 0], [0, 9]], "speed_profile": [[0, 5], [2, float("inf")]]},
            "speeds must be finite",
        ),
        (
            {
                "path_m": [[0, 0], [0, 9]],
                "speed_profile": [[0, 5], [2, 5]],
                "vehicle_class": "tram",
            },
            "scene scripted[0]: unknown class 'tram'",
        ),
    ],
)
def test_bad_scripts_are_errors_naming_them(entry, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        _scene([entry], duration_s=5.0)


def test_sites_without_scripts_keep_their_fingerprint():
    data = tomllib.loads(SITE.read_text(encoding="utf-8"))
    del data["scene"]["scripted"]
    plain = site_from_mapping(data, "a").fingerprint
    data["scene"]["scripted"] = []
    assert site_from_mapping(data, "b").fingerprint == plain
