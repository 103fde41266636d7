"""Lanelet2 import: the hand-made T-junction map (examples/maps) into a site, against its geometry.

The map's geometry is known exactly (examples/maps/make_t_junction.py): a main road along
y = 0 with one 3.5 m lane each way, a side road along x = 30 m leaving it northwards, stop
lines 15 m either side of x = -40 m. With the crossing at (-40, 0) the site's west and east
roads start at the origin, the north road at (70, 0) on the east road.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
import tomllib

if sys.platform != "linux":  # on Linux the test extra installs it: a missing one fails here
    pytest.skip("lanelet2 publishes Linux wheels only", allow_module_level=True)

from adaptrack.crossing.site.lanelet_map import read_lanelet_map
from adaptrack.crossing.site.map_import import site_from_map, site_toml
from adaptrack.crossing.site.model import site_from_mapping
from adaptrack.crossing.site.network import route

MAP = Path(__file__).parents[2] / "examples" / "maps" / "t_junction.osm"  # shipped, hand-made


@pytest.fixture(scope="module")
def lane_map():
    return read_lanelet_map(MAP)


@pytest.fixture(scope="module")
def imported(lane_map):
    return site_from_map(lane_map, (-40.0, 0.0), "t_junction", rails_deg=0.0)


def test_map_reads_lanes_widths_and_topology(lane_map):
    assert len(lane_map.lanes) == 12
    assert len(lane_map.stop_lines) == 3
    widths = [lane.width_m for lane in lane_map.lanes.values()]
    assert np.allclose(widths, 3.5, atol=0.02)
    # the westbound lane into the junction goes straight on or turns right into the side road
    into = next(k for k, ln in lane_map.lanes.items() if np.allclose(ln.centre[0], [100.0, 1.75]))
    ends = sorted(
        tuple(lane_map.lanes[s].centre[-1].round(2)) for s in lane_map.lanes[into].successors
    )
    assert ends == [(22.0, 1.75), (31.75, 8.0)]


def test_roads_follow_the_surveyed_centrelines(imported):
    site = site_from_mapping(imported, "imported")
    assert set(site.roads) == {"west", "east", "north"}
    west, east, north = site.roads["west"], site.roads["east"], site.roads["north"]
    assert np.allclose(west.xy[0], 0.0) and np.allclose(east.xy[0], 0.0)
    assert np.hypot(*(north.xy[0] - [70.0, 0.0])) < 0.05
    on_map = lambda road: road.s <= road.length_m - 100.0  # noqa: E731
    assert np.abs(west.xy[on_map(west), 1]).max() < 0.05  # main road centre y = 0
    assert np.abs(east.xy[on_map(east), 1]).max() < 0.05
    assert np.abs(north.xy[north.s < 90.0, 0] - 70.0).max() < 0.05  # side road x = 30 + 40
    assert west.xy[-1, 0] < -190.0 and east.xy[-1, 0] > 190.0  # continued to zone + run-in
    assert west.lane_width_m == pytest.approx(3.5)
    assert site.stop_line_of("west") == pytest.approx(15.0, abs=0.1)
    assert site.stop_line_of("east") == pytest.approx(15.0, abs=0.1)
    assert site.rails is not None


def test_flows_are_the_lane_connections_and_all_route(imported):
    site = site_from_mapping(imported, "imported")
    pairs = {(f["entry"], f["exit"]) for f in imported["scene"]["flows"]}
    expected = {(a, b) for a in ("west", "east", "north") for b in ("west", "east", "north")}
    assert pairs == {p for p in expected if p[0] != p[1]}
    for entry, exit_ in pairs:
        assert route(site.roads, entry, exit_) is not None
    assert len(site.corridors) >= 3


def test_radars_see_every_road(imported):
    site = site_from_mapping(imported, "imported")
    for name, road in site.roads.items():
        radar = next(r for r in site.radars if r.name == site.radar_of_road[name])
        s = np.arange(0.0, site.zone_m, 5.0)
        assert radar.covers(road.lane_point(s)).mean() > 0.9, name


def test_site_toml_reloads_to_the_same_mapping(imported):
    text = site_toml(imported, "a header\nsecond line")
    assert text.startswith("# a header\n# second line\n")
    assert tomllib.loads(text) == imported


def test_a_crossing_point_off_every_road_is_an_error(lane_map):
    with pytest.raises(ValueError, match="no lane of the map passes within 15 m"):
        site_from_map(lane_map, (0.0, 60.0), "off")


def test_a_crossing_point_by_latitude_and_longitude():
    from lanelet2.core import BasicPoint3d
    from lanelet2.io import Origin
    from lanelet2.projection import UtmProjector

    from adaptrack.crossing.site.lanelet_map import project_latlon

    g = UtmProjector(Origin(0.0, 0.0)).reverse(BasicPoint3d(-40.0, 3.0, 0.0))
    assert np.allclose(project_latlon((g.lat, g.lon), (0.0, 0.0)), [-40.0, 3.0], atol=1e-3)
