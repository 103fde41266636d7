"""Road geometry, site files, traffic profiles."""

import math

import numpy as np
import pytest

from adaptrack.crossing.road import RoadElement, build_road
from adaptrack.crossing.site import builtin_sites, load_site, site_from_mapping
from adaptrack.crossing.traffic import (
    DEFAULT_CASES,
    VEHICLES,
    Case,
    _braking_distance,
    along_road_profile,
    case_duration,
)


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
    for name in ("lx_default", "lx_stress"):
        site = load_site(name)
        for road in site.roads.values():
            assert road.length_m >= site.zone_m + site.run_in_m
    assert load_site("lx_stress").radars[0].range_std_m == 0.5


def test_site_errors():
    base = {
        "roads": [
            {"name": "A", "heading_deg": 0.0, "elements": [{"kind": "straight", "length_m": 200.0}]}
        ],
        "radars": [{"position_m": [-5.0, 0.0], "boresight_deg": 0.0}],
    }
    assert site_from_mapping(base, "x.toml").roads["A"].length_m == pytest.approx(200.0)
    far = {**base, "roads": [{**base["roads"][0], "start_m": [30.0, 0.0]}]}
    with pytest.raises(ValueError, match="does not reach the crossing"):
        site_from_mapping(far, "x.toml")
    blind = {**base, "radars": [{"position_m": [-5.0, 0.0], "boresight_deg": 180.0}]}
    with pytest.raises(ValueError, match="has no road in view"):
        site_from_mapping(blind, "x.toml")
    with pytest.raises(ValueError, match="unknown site 'x'"):
        load_site("x")


def test_braking_matches_the_spec_stand_in():
    # spec 5.1: 60 km/h, jerk 2, 3.4 m/s^2 -> braking starts at y = 69.607 m; 90 km/h, jerk 12,
    # 8 m/s^2 -> 62.248 m (stop line at 15 m)
    assert 15 + _braking_distance(60 / 3.6, 3.4, 2.0) == pytest.approx(69.607, abs=1e-3)
    assert 15 + _braking_distance(90 / 3.6, 8.0, 12.0) == pytest.approx(62.248, abs=1e-3)


@pytest.mark.parametrize(
    "case",
    [c for c in DEFAULT_CASES if c.kind in ("stop", "emergency") and c.dwell_s == 0],
    ids=lambda c: c.name,
)
def test_stops_end_at_the_stop_line(case):
    veh = VEHICLES["car"]
    t = 0.05 * np.arange(int(case_duration(case, veh, 200.0, 15.0) / 0.05) + 1)
    s, v, a = along_road_profile(case, veh, 200.0, 15.0, t)
    assert abs(s[-1] - 15.0) < 0.2 and v[-1] == 0.0
    assert np.all(np.diff(s) <= 1e-12) and a.min() >= -8.0 - 1e-9
    moving = v[1:] > 0  # jerk-limited while braking (the deceleration ends at standstill)
    assert np.all(np.abs(np.diff(a))[moving] <= 12.0 * 0.05 + 1e-9)


def test_bad_case_kind():
    with pytest.raises(ValueError, match="case kind must be"):
        along_road_profile(
            Case("x", "drift", 50.0, "B"), VEHICLES["car"], 200.0, 15.0, np.arange(10.0)
        )


def test_stop_and_go_dwells_then_pulls_away():
    case = next(c for c in DEFAULT_CASES if c.dwell_s > 0)
    veh = VEHICLES["car"]
    t = 0.05 * np.arange(int(case_duration(case, veh, 200.0, 15.0) / 0.05) + 1)
    s, v, a = along_road_profile(case, veh, 200.0, 15.0, t)
    stopped = v == 0
    assert 0.05 * stopped.sum() == pytest.approx(case.dwell_s, abs=0.1)
    assert s[-1] < 0 and a.max() == pytest.approx(veh.accel_mps2)
    assert np.all(np.diff(s) <= 1e-12)


def test_random_approaches_respect_the_class_limits():
    from adaptrack.crossing.traffic import random_profiles

    case = next(c for c in DEFAULT_CASES if c.kind == "random")
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
