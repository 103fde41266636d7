"""Sites as surveyed: polyline roads, junctions away from the crossing, lanes, turning routes,
rails, trains and parked road users."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import tomllib

from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.corridor import TURN_RADIUS_M
from adaptrack.crossing.site.model import load_site, site_from_mapping
from adaptrack.crossing.site.network import Leg, route
from adaptrack.crossing.site.road import STEP_M, RoadElement, build_road, polyline_road

JUNCTION = Path(__file__).parents[2] / "examples" / "sites" / "junction_crossing.toml"


def junction_data():
    return tomllib.loads(JUNCTION.read_text())


def test_polyline_road_through_circle_points_is_the_circle():
    """Survey points of a quarter circle (R = 50 m), taken exactly: arc, heading, curvature."""
    r = 50.0
    t = np.linspace(0.0, math.pi / 2, 30)
    pts = np.stack([r - r * np.cos(t), r * np.sin(t)], -1)  # north, then turning right to east
    road = polyline_road("arc", pts, 3.5, survey_std_m=0.0)
    assert road.length_m == pytest.approx(math.pi / 2 * r, abs=STEP_M)
    assert np.abs(np.hypot(road.xy[:, 0] - r, road.xy[:, 1]) - r).max() < 1e-3
    assert np.abs(road.curvature - 1 / r).max() < 1e-3  # positive: a right turn
    assert road.heading[-1] == pytest.approx(math.pi / 2, abs=1e-3)
    ext = polyline_road("arc", pts, 3.5, extend_m=20.0, survey_std_m=0.0)
    assert ext.length_m == pytest.approx(road.length_m + 20.0, abs=STEP_M)
    # on from the last point along its heading (1e-3 rad over 20 m: 0.02 m)
    assert ext.xy[-1] == pytest.approx([r + 20.0, r], abs=0.03)
    with pytest.raises(ValueError, match="coincide"):
        polyline_road("bad", [[0, 0], [0, 0], [1, 1]], 3.5)


def test_elements_road_starts_where_told():
    elements = (RoadElement("straight", 100.0),)
    moved = build_road("b", math.radians(90.0), 3.5, elements, start_m=(0.0, 30.0))
    assert moved.xy[0] == pytest.approx([0.0, 30.0])
    assert moved.xy[-1] == pytest.approx([100.0, 30.0])


def test_junction_site_routes_turn_through_the_junction():
    site = load_site(JUNCTION)
    legs = route(site.roads, "east", "south")
    assert legs is not None
    assert [leg.road for leg in legs] == ["east", "north", "south"]
    assert legs[1] == Leg("north", pytest.approx(30.0, abs=STEP_M), 0.0)
    assert legs[0].inbound and legs[1].inbound and not legs[2].inbound
    pairs = {(c.first, c.second) for c in site.corridors}
    for f in site.source["scene"]["flows"]:
        assert (f["entry"], f["exit"]) in pairs or (f["exit"], f["entry"]) in pairs
    for c in site.corridors:  # continuous paths that a vehicle can drive
        step = np.hypot(*np.diff(c.path.xy, axis=0).T)
        assert step.max() < 1.5 * STEP_M, (c.first, c.second)
        assert np.abs(c.path.curvature).max() < 2.5 / TURN_RADIUS_M, (c.first, c.second)
    main = next(c for c in site.corridors if {c.first, c.second} == {"north", "south"})
    assert main.lanes == (2, 2)
    assert site.stop_line_of("north") == 12.0 and site.stop_line_of("south") == 15.0
    assert site.rails is not None and site.rails.tracks == 2


def test_junction_scene_has_turns_lanes_trains_and_a_parked_car():
    site = load_site(JUNCTION)
    spec = scene_spec(site, duration_s=500.0)
    rec = simulate_scene(site, spec, seed=4)
    users, tab = rec.truth.users, rec.truth.table
    # a car parked from the start, standing where the file puts it for the whole scene
    parked = users[users["corridor"] == -1]
    car = tab[tab["object_id"] == parked[parked["vehicle_class"] == "car"]["object_id"].iloc[0]]
    assert car["time_s"].min() == 0.0 and car["time_s"].max() == pytest.approx(500.0)
    assert car[["east_m", "north_m"]].to_numpy() == pytest.approx(
        np.tile([8.5, 60.0], (len(car), 1))
    )
    # a train in each closure, on a track, within the closure
    trains = users[users["vehicle_class"] == "train"]
    assert len(trains) == len(spec.closures())
    for (c0, c1), oid in zip(spec.closures(), trains["object_id"], strict=True):
        tr = tab[tab["object_id"] == oid]
        assert c0 <= tr["time_s"].min() and tr["time_s"].max() <= c1
        assert np.abs(tr["north_m"]).max() <= 2.25 + 1e-9  # the tracks are 4.5 m apart
        assert not tr["in_zone"].any()
    # turning traffic from the side street crosses the rails; the main road uses two lanes
    on_turn = users[users["corridor"].isin(
        [i for i, c in enumerate(site.corridors) if (c.first, c.second) == ("east", "south")]
    )]  # fmt: skip
    assert len(on_turn) > 3
    cars = users[(users["vehicle_class"] == "car") & (users["corridor"] == 0)]
    lane = np.round((np.abs(cars["lateral_m"]) - 1.75) / 3.5)
    assert set(lane) == {0.0, 1.0}
    assert (rec.sources >= 0).sum() > 1000


def test_topology_errors_name_the_flow_or_the_key():
    data = junction_data()
    data["roads"].append({"name": "island", "start_m": [60.0, 60.0], "heading_deg": 45.0,
                          "elements": [{"kind": "straight", "length_m": 220.0}]})  # fmt: skip
    data["scene"]["flows"].append({"entry": "north", "exit": "island", "vehicles_per_h": 10.0})
    with pytest.raises(ValueError, match=r"scene.flows\[7\] north->island: no path"):
        site_from_mapping(data, "x.toml")
    data = junction_data()
    data["connections"] = [{"entry": "east", "exit": "nowhere"}]
    with pytest.raises(ValueError, match=r"connections\[0\].exit: unknown road 'nowhere'"):
        site_from_mapping(data, "x.toml")
    data = junction_data()
    del data["rails"]
    site = site_from_mapping(data, "x.toml")
    with pytest.raises(ValueError, match="no \\[rails\\]"):
        scene_spec(site)
    data = junction_data()
    data["roads"][0]["points_m"] = [[0.0, 0.0], [0.0, 50.0]]
    with pytest.raises(ValueError, match="points_m, or heading_deg with elements"):
        site_from_mapping(data, "x.toml")


def test_added_keys_at_their_defaults_keep_a_site_fingerprint():
    """A site written without the new keys and with them at their defaults is one site."""
    plain = tomllib.loads((Path(__file__).parents[2] / "src/adaptrack/crossing/site/sites/"
                           "lx_default.toml").read_text())  # fmt: skip
    explicit = dict(plain)
    explicit["roads"] = [{**r, "lanes_in": 1, "lanes_out": 1} for r in plain["roads"]]
    explicit["connections"] = []
    a, b = site_from_mapping(plain, "a.toml"), site_from_mapping(explicit, "a.toml")
    assert a.fingerprint == b.fingerprint
    two_lanes = {**plain, "roads": [{**plain["roads"][0], "lanes_in": 2}, *plain["roads"][1:]]}
    assert site_from_mapping(two_lanes, "a.toml").fingerprint != a.fingerprint
