"""Road geometry, the strict site format, traffic profiles, blind zones."""

import copy
import dataclasses
import math

import numpy as np
import pytest

from adaptrack.crossing.site.model import blind_zones, builtin_sites, load_site, site_from_mapping
from adaptrack.crossing.site.road import RoadElement, build_road
from adaptrack.crossing.site.traffic import (
    VEHICLES,
    Case,
    along_road_profile,
    braking_distance,
    case_duration,
    default_cases,
    inapplicable_reason,
)

ONE_ARM = {
    "roads": [
        {"name": "main", "heading_deg": 0.0, "elements": [{"kind": "straight", "length_m": 200.0}]}
    ],
    "radars": [
        {
            "name": "r1",
            "position_m": [-5.0, 0.0],
            "boresight_deg": 0.0,
            "period_s": 0.05,
            "fov_half_deg": 50.0,
            "max_range_m": 250.0,
            "range_std_m": 0.25,
            "azimuth_std_deg": 0.3,
            "radial_speed_std_mps": 0.1,
        }
    ],
}


def with_change(path, value):
    """ONE_ARM with the value at a path ("radars.0.range_std_m") set (None: deleted)."""
    data = copy.deepcopy(ONE_ARM)
    *head, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    node = data
    for p in head:
        node = node[p]
    if value is None:
        del node[last]
    else:
        node[last] = value
    return data


def test_arc_and_clothoid_geometry():
    road = build_road(
        "A",
        0.0,
        3.5,
        (
            RoadElement("straight", 60.0),
            RoadElement("clothoid", 30.0, end_curvature_per_m=1 / 150),
            RoadElement("arc", 150 * math.pi / 4, radius_m=150.0),
        ),
    )
    s = np.linspace(95.0, 90 + 150 * math.pi / 4, 30)
    p, th = road.centreline(s)
    # on the arc the heading changes at 1/R and points stay on one circle
    np.testing.assert_allclose(np.diff(th) / np.diff(s), 1 / 150, rtol=1e-9)
    centre = p[0] + 150 * np.array([np.cos(th[0]), -np.sin(th[0])])
    # linear interpolation between 0.05 m samples: sagitta kappa ds^2 / 8 = 2.1e-6 m
    np.testing.assert_allclose(np.hypot(*(p - centre).T), 150.0, rtol=0, atol=3e-6)
    # the clothoid turns by L * kappa_end / 2
    assert road.centreline(90.0)[1] == pytest.approx(30 / 150 / 2, rel=1e-9)
    # lane centre: right of the inbound direction, as in the spec's stand-in (x = -1.75 m)
    np.testing.assert_allclose(road.lane_point([10.0, 50.0]), [[-1.75, 10.0], [-1.75, 50.0]])
    s0, d0 = road.project(road.lane_point(120.0, 0.4))
    assert abs(s0 - 120.0) < 0.05 and abs(d0 - 0.4) < 0.01


def test_builtin_sites_load():
    assert {"lx_default", "lx_stress"} <= set(builtin_sites())
    for name in builtin_sites():
        site = load_site(name)
        for road in site.roads.values():
            assert road.length_m >= site.zone_m + site.run_in_m
        assert site.pairs() and abs(sum(site.traffic_mix.values()) - 1) < 1e-9
        assert set(site.radar_of_road) == set(site.roads)
    stress = load_site("lx_stress")
    assert stress.radars[0].range_std_m(100.0) == 0.5
    assert stress.radars[0].azimuth_std_rad(0.3) == pytest.approx(math.radians(0.5))
    # every DOMAIN script on both arms; a class that cannot drive a case is named with why
    default = load_site("lx_default")
    assert {c.name for c in default.cases} >= {"A/stop_go_60", "B/pass_250"}
    skipped = {(c, v) for c, v, _ in default.skipped_pairs()}
    assert ("B/pass_250", "bus") in skipped and ("B/pass_100", "bus") not in skipped


def test_one_arm_site_with_any_road_name():
    site = site_from_mapping(ONE_ARM, "one.toml")
    assert site.name == "one" and site.radar_of_road == {"main": "r1"}
    assert {c.road for c in site.cases} == {"main"}
    assert "pass_60" in {c.name for c in site.cases}  # no road prefix with one road
    assert len(site.pairs()) == 4 * 9 - 2


@pytest.mark.parametrize(
    "path, value, message",
    [
        ("radars.0.range_std_far_m", 0.5, r"radars\[0\]: unknown key 'range_std_far_m' \(did "),
        ("traffic_mix", {"car": 1.0}, r"unknown key 'traffic_mix' \(did you mean 'traffic'\?\)"),
        ("radars.0.scatter_std_m", 0.5, r"radars\[0\]: unknown key 'scatter_std_m'"),
        ("roads.0.elements.0.lenght_m", 5.0, r"unknown key 'lenght_m' \(did you mean 'length_m'"),
        ("radars.0.period_s", True, r"radars\[0\]\.period_s: Input should be a valid number"),
        ("radars.0.period_s", "0.05", r"radars\[0\]\.period_s: Input should be a valid number"),
        ("radars.0.period_s", -0.05, r"period_s: Input should be greater than 0"),
        ("radars.0.range_std_m", [[100.0, 0.3], [50.0, 0.2]], "strictly increasing"),
        ("radars.0.range_std_m", [[0.0, 0.3], [50.0, 0.0]], r"values must be > 0"),
        ("radars.0.range_std_m", [[0.0, 0.3, 1.0]], r"list of \[argument, value\] pairs"),
        ("radars.0.azimuth_std_deg", None, r"radars\[0\]: missing key 'azimuth_std_deg'"),
        ("radars.0.detection_probability", {"car": 1.2}, r"probabilities must lie in \[0, 1\]"),
        ("radars.0.detection_probability", {"tank": 0.9}, "unknown class 'tank'"),
        ("radars.0.fields", [{"max_range_m": 70.0, "fov_half_deg": 60.0}], "not both"),
        ("radars.0.fov_half_deg", None, "needs fields, or fov_half_deg and max_range_m"),
        ("radars.0.boresight_deg", 180.0, "road 'main': no radar sees its controlled zone"),
        ("roads.0.elements.0.length_m", 150.0, "road 'main' is 150.0 m long"),
        ("roads.0.elements.0.radius_m", 50.0, "'radius_m' not used by kind 'straight'"),
        ("roads.0.radar", "r9", "unknown radar 'r9'"),
        ("traffic", {"mix": {"car": 0.5, "bus": 0.4}}, "must sum to 1; they sum to 0.9"),
        ("traffic", {"mix": {"car": 0.5, "tram": 0.5}}, "unknown class 'tram'"),
        ("classes", {"tractor": {"length_m": 6.0}}, "a new class needs width_m"),
        (
            "cases",
            [{"name": "x", "road": "main", "kind": "stop", "speed_kmh": 60.0, "decel_mps2": 11}],
            r"cases\[0\]\.decel_mps2: Input should be less than or equal to 10",
        ),
        (
            "cases",
            [{"name": "x", "road": "side", "kind": "pass", "speed_kmh": 60.0}],
            r"cases\[0\]\.road: unknown road 'side'",
        ),
        (
            "cases",
            [{"name": "x", "road": "main", "kind": "pass", "speed_kmh": 60.0, "dwell_s": 5.0}],
            "'dwell_s' not used by kind 'pass'",
        ),
        (
            "cases",
            [{"name": "x", "road": "main", "kind": "profile", "speed_profile": [[0, 50], [1, 0]]}],
            r"13\.9 m/s\^2 between 0 s and 1 s; at most 10 m/s\^2",
        ),
        (
            "cases",
            [{"name": "x", "road": "main", "kind": "stop", "speed_kmh": 60.0, "decel_mps2": 9.5}],
            "no class of the site can drive it",
        ),
    ],
)
def test_site_format_errors_name_the_place(path, value, message):
    data = with_change(path, value)
    if path.startswith("cases") and "9.5" in str(value):  # only buses and trucks here
        data["traffic"] = {"mix": {"bus": 0.5, "truck": 0.5}}
    with pytest.raises(ValueError, match=message):
        site_from_mapping(data, "site.toml")


def test_a_radar_that_sees_no_road_is_an_error():
    data = copy.deepcopy(ONE_ARM)
    data["radars"].append({**data["radars"][0], "name": "r2", "boresight_deg": 180.0})
    with pytest.raises(ValueError, match="radar 'r2' has no road in view"):
        site_from_mapping(data, "s.toml")
    data["radars"][1]["name"] = "r1"
    with pytest.raises(ValueError, match="radars: the name 'r1' is used twice"):
        site_from_mapping(data, "s.toml")


def test_unknown_builtin_and_missing_file():
    with pytest.raises(ValueError, match="unknown site 'x'"):
        load_site("x")
    with pytest.raises(ValueError, match="does not exist"):
        load_site("nowhere/site.toml")


def test_sensor_curves_and_fields_from_the_file():
    data = with_change(
        "radars.0.range_std_m", [[0.0, 0.1], [100.0, 0.4]]
    )  # range sigma grows with range
    r = data["radars"][0]
    del r["fov_half_deg"], r["max_range_m"]
    r["fields"] = [
        {"max_range_m": 70.0, "fov_half_deg": 60.0},
        {"max_range_m": 250.0, "fov_half_deg": 9.0},
    ]
    r["azimuth_std_deg"] = [[0.0, 0.1], [60.0, 1.3]]
    radar = site_from_mapping(data, "s.toml").radars[0]
    assert radar.range_std_m(50.0) == pytest.approx(0.25)
    assert radar.azimuth_std_rad(math.radians(30.0)) == pytest.approx(math.radians(0.7))
    # off boresight by 30 deg: in the near field at 60 m, in no field at 100 m
    pts = np.array([[-5.0 + 60 * math.sin(0.5236), 60 * math.cos(0.5236)], [-5.0, 200.0]])
    pts = np.concatenate([pts, [[-5.0 + 100 * math.sin(0.5236), 100 * math.cos(0.5236)]]])
    np.testing.assert_array_equal(radar.covers(pts), [True, True, False])


def test_class_overrides_and_new_classes():
    data = copy.deepcopy(ONE_ARM)
    data["classes"] = {
        "car": {"length_m": 4.0},
        "tractor": {
            "length_m": 6.5,
            "width_m": 2.5,
            "accel_mps2": 1.0,
            "decel_mps2": 2.5,
            "emergency_decel_mps2": 5.0,
            "max_speed_kmh": 40.0,
            "scatter_std_m": 1.2,
        },
    }
    data["traffic"] = {"mix": {"car": 0.9, "tractor": 0.1}}
    site = site_from_mapping(data, "s.toml")
    assert list(site.classes) == ["car", "tractor"]
    assert site.classes["car"].scatter_std_m == pytest.approx(0.6)  # 0.15 L of the new length
    assert site.classes["car"].width_m == VEHICLES["car"].width_m
    assert site.classes["tractor"].scatter_std_m == 1.2
    # the tractor drives only the passes up to 40 km/h
    tractor_cases = {c.name for c, v in site.pairs() if v.name == "tractor"}
    assert tractor_cases == {"pass_5", "pass_20"}


def test_braking_matches_the_spec_stand_in():
    # spec 5.1: 60 km/h, jerk 2, 3.4 m/s^2 -> braking starts at y = 69.607 m; 90 km/h, jerk 12,
    # 8 m/s^2 -> 62.248 m (stop line at 15 m)
    assert 15 + braking_distance(60 / 3.6, 3.4, 2.0) == pytest.approx(69.607, abs=1e-3)
    assert 15 + braking_distance(90 / 3.6, 8.0, 12.0) == pytest.approx(62.248, abs=1e-3)


@pytest.mark.parametrize(
    "case",
    [
        Case("stop_60", "stop", 60.0, "B"),
        Case("emergency_90", "emergency", 90.0, "B"),
        Case("hard_stop", "stop", 80.0, "B", decel_mps2=9.0, jerk_mps3=15.0),
        Case("ten", "emergency", 50.0, "B", decel_mps2=10.0, stop_at_m=30.0),
    ],
    ids=lambda c: c.name,
)
def test_stops_end_at_the_stop_position_at_the_asked_deceleration(case):
    veh = dataclasses.replace(VEHICLES["car"], emergency_decel_mps2=10.0)
    stop_at = 15.0 if case.stop_at_m is None else case.stop_at_m
    t = 0.05 * np.arange(int(case_duration(case, veh, 200.0, 15.0) / 0.05) + 1)
    s, v, a = along_road_profile(case, veh, 200.0, 15.0, t)
    assert abs(s[-1] - stop_at) < 0.2 and v[-1] == 0.0
    decel = {"stop_60": 3.4, "emergency_90": 8.0, "hard_stop": 9.0, "ten": 10.0}[case.name]
    assert -a.min() == pytest.approx(decel, abs=1e-9)  # not capped
    jerk = case.jerk_mps3 or (2.0 if case.kind == "stop" else 12.0)
    moving = v[1:] > 0  # jerk-limited while braking (the deceleration ends at standstill)
    assert np.all(np.abs(np.diff(a))[moving] <= jerk * 0.05 + 1e-9)
    assert np.all(np.diff(s) <= 1e-12)


def test_a_class_that_cannot_brake_that_hard_is_not_applicable():
    case = Case("hard", "stop", 60.0, "B", decel_mps2=9.0)
    assert inapplicable_reason(case, VEHICLES["car"]) is None
    assert "above the class's 7 m/s^2" in inapplicable_reason(case, VEHICLES["bus"])
    only = Case("m", "pass", 60.0, "B", classes=("motorcycle",))
    assert "for motorcycle only" in inapplicable_reason(only, VEHICLES["car"])


def test_speed_profile_against_an_independent_integration():
    knots = ((0.0, 72.0), (4.0, 72.0), (8.0, 18.0), (20.0, 18.0), (26.0, 54.0))
    case = Case("slow", "profile", 72.0, "B", profile=knots)
    veh = VEHICLES["car"]
    duration = case_duration(case, veh, 200.0, 15.0)
    t = np.linspace(0.0, duration, 4001)
    s, v, a = along_road_profile(case, veh, 200.0, 15.0, t)
    # fine cumulative trapezoid of the knot-interpolated speed
    fine = np.linspace(0.0, duration, 400_001)
    vf = np.interp(fine, [k[0] for k in knots], [k[1] / 3.6 for k in knots])
    sf = 200.0 - np.concatenate([[0.0], np.cumsum(0.5 * (vf[1:] + vf[:-1]) * np.diff(fine))])
    np.testing.assert_allclose(s, np.interp(t, fine, sf), atol=1e-6)
    np.testing.assert_allclose(v, np.interp(t, fine, vf), atol=1e-9)
    assert s[-1] == pytest.approx(0.0, abs=1e-6)  # the run ends at the crossing centre
    assert a.max() == pytest.approx(36 / 3.6 / 6) and a.min() == pytest.approx(-54 / 3.6 / 4)


def test_stop_and_go_dwells_then_pulls_away():
    case = next(c for c in default_cases(["B"]) if c.dwell_s > 0)
    veh = VEHICLES["car"]
    t = 0.05 * np.arange(int(case_duration(case, veh, 200.0, 15.0) / 0.05) + 1)
    s, v, a = along_road_profile(case, veh, 200.0, 15.0, t)
    stopped = v == 0
    assert case.dwell_s == 30.0
    assert 0.05 * stopped.sum() == pytest.approx(case.dwell_s, abs=0.1)
    assert s[-1] < 0 and a.max() == pytest.approx(veh.accel_mps2)
    assert np.all(np.diff(s) <= 1e-12)


def test_bad_case_kind():
    with pytest.raises(ValueError, match="case kind must be"):
        Case("x", "drift", 50.0, "B")


def test_random_approaches_respect_the_class_limits():
    from adaptrack.crossing.site.traffic import random_profiles

    case = next(c for c in default_cases(["B"]) if c.kind == "random")
    veh = VEHICLES["truck"]
    t = 0.05 * np.arange(400)
    s, v, a = random_profiles(case, veh, 200.0, t, 50, np.random.default_rng(0))
    assert s.shape == v.shape == (50, 400)
    assert np.all(v >= 0) and np.all(v <= veh.max_speed_kmh / 3.6 + 1e-9)
    assert np.all(a >= -veh.emergency_decel_mps2 - 1e-9)
    assert np.all(a <= veh.accel_mps2 + 1e-9)
    assert np.std(v[:, -1]) > 1.0  # runs differ
    np.testing.assert_allclose(
        np.diff(s, axis=1), -0.5 * (v[:, 1:] + v[:, :-1]) * 0.05, rtol=1e-12, atol=1e-12
    )
    with pytest.raises(ValueError, match="random cases need an rng"):
        along_road_profile(case, veh, 200.0, 15.0, t)


def test_blind_zones_from_the_field_of_view():
    """lx_default: the radar stands 3.25 m beside the lane centre with a +-50 deg field of view:
    the lane is out of view for s < 3.25 / tan(50 deg) = 2.73 m (sampled every 0.5 m)."""
    zones = blind_zones(load_site("lx_default"))
    assert zones == {"A": [(0.0, 2.5)], "B": [(0.0, 2.5)]}
    # a radar that reaches only 100 m leaves the far part of the zone blind
    short = with_change("radars.0.max_range_m", 100.0)
    short["roads"][0]["elements"][0]["length_m"] = 200.0
    site = site_from_mapping(short, "s.toml")
    (near, far) = blind_zones(site)["main"]
    # slant range 100 m at 6 m height and 3.25 m beside the lane: s = sqrt(100^2 - 36 - 3.25^2)
    assert far[0] == pytest.approx(math.sqrt(100**2 - 36 - 3.25**2), abs=0.5) and far[1] == 150.0
    assert near[0] == 0.0


@pytest.mark.parametrize(
    "points, message",
    [
        ((), "needs 1 to 32 points"),
        (((1.0, 0.1), (0.0, 0.2)), "strictly increasing"),
        (((0.0, math.nan),), "must be finite"),
        (tuple((float(i), 1.0) for i in range(33)), "needs 1 to 32 points"),
    ],
)
def test_curve_errors(points, message):
    from adaptrack.crossing.site.sensor import Curve

    with pytest.raises(ValueError, match=message):
        Curve(points)


def test_curve_values_and_packing():
    from adaptrack.crossing.site.sensor import Curve, curve_tables

    c = Curve(((10.0, 1.0), (20.0, 3.0)))
    np.testing.assert_allclose(c([0.0, 15.0, 99.0]), [1.0, 2.0, 3.0])
    assert Curve.constant(0.4)(123.0) == 0.4
    np.testing.assert_allclose(c.scaled(argument=2.0, value=0.5)(30.0), 1.0)
    table, counts = curve_tables((c, Curve.constant(5.0)))
    assert table.shape == (2, 2, 2) and list(counts) == [2, 1]
