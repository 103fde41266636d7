"""The crossing's clear / not-clear state, the background map and the class of a track."""

import math
from pathlib import Path

import numpy as np
import pytest

from adaptrack.crossing.scene.background import BackgroundMap
from adaptrack.crossing.scene.occupancy import ClearanceMonitor, CrossingArea
from adaptrack.crossing.scene.road_user_class import CLASSES, class_names, class_probabilities
from adaptrack.crossing.simulation.faces import FaceRadar
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.clearance import (
    clear_run,
    clearance_trials,
    empty_background,
    traffic_run,
)


@pytest.fixture(scope="module")
def site():
    return load_site("lx_default")


@pytest.mark.parametrize("kind", ["placed", "stalled"])
def test_an_object_between_the_barriers_makes_the_crossing_not_clear_within_a_second(site, kind):
    # seeded trials: random points of the area; 100 of them in benchmarks.crossing_clearance
    trials = clearance_trials(site, kind, range(4), duration_s=14.0, placed_at_s=6.0)
    for trial in trials:
        assert trial.delay_s <= 1.0, trial
        assert trial.false_events == 0, trial


def test_the_empty_site_stays_clear(site):
    assert clear_run(site, 60.0, seed=4) == 0


def test_traffic_raises_are_sorted_by_the_truth_near_them():
    """200 s of the junction site's traffic with its first train: every raise is sorted."""
    junction = load_site(
        Path(__file__).parents[2] / "examples" / "sites" / "junction_crossing.toml"
    )
    run = traffic_run(junction, 200.0, seed=2)
    assert run.trains == 1
    assert (
        run.raised
        == run.in_area + run.near + run.false
        == len(run.false_times_s) + (run.in_area + run.near)
    )
    assert run.in_area > 5  # road users drive over the crossing while it is open
    for bad in (0.0, -5.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="traffic_run: seconds must be finite and > 0"):
            traffic_run(junction, bad, seed=2)


def test_the_area_is_the_carriageway_between_the_barriers(site):
    area = CrossingArea(site)
    boxes = np.array([[0.0, 0.0], [1.75, site.barrier_m - 0.5], [1.75, site.barrier_m + 3.0],
                      [15.0, 0.0]])  # fmt: skip
    heading = np.array([0.0, math.pi / 2, math.pi / 2, 0.0])
    # in the middle, just inside the barrier, beyond it, beside the road
    assert list(area.touches(boxes, heading, 0.5, 0.5)) == [True, True, False, False]


def test_a_train_due_is_the_known_occupant_of_the_rails_and_nothing_else_there():
    junction = load_site(
        Path(__file__).parents[2] / "examples" / "sites" / "junction_crossing.toml"
    )
    assert junction.rails is not None
    along = 25.0 * np.asarray(junction.rails.direction)[None, :]
    monitor = ClearanceMonitor(junction, train_intervals=np.array([[10.0, 20.0]]))
    on_rails = np.zeros((1, 2))
    box = (np.array([0.0]), np.array([4.0]), np.array([3.0]))
    monitor.update(12.0, np.array([7]), on_rails, along, *box)
    assert monitor.events == []  # the train, moving along the rails while one is due
    monitor.update(25.0, np.array([7]), on_rails, along, *box)  # no train due: an obstacle
    assert [e["event"] for e in monitor.events] == ["crossing_not_clear"]
    none = (np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 2)), *(np.zeros(0),) * 3)
    monitor.update(26.0, *none)
    assert [e["event"] for e in monitor.events] == ["crossing_not_clear", "crossing_clear"]
    across = np.array([[-along[0, 1], along[0, 0]]])  # a car driving over the rails
    for k, velocity in enumerate((np.zeros((1, 2)), across)):  # a car stalled on the rails
        monitor = ClearanceMonitor(junction, train_intervals=np.array([[10.0, 20.0]]))
        monitor.update(12.0, np.array([8 + k]), on_rails, velocity, *box)
        assert [e["event"] for e in monitor.events] == ["crossing_not_clear"]


def test_the_background_map_round_trips_and_rejects_other_files(site, tmp_path):
    bg = empty_background(site, FaceRadar.of_kind("cluster"), 20.0, seed=3)
    assert bg.reflector_rate.size >= 1 and (bg.reflector_rate > 0.05).all()
    bg.save(tmp_path / "bg.npz")
    back = BackgroundMap.load(tmp_path / "bg.npz")
    assert back.radars == bg.radars and np.array_equal(back.regions, bg.regions)
    assert np.allclose(back.reflector_mean, bg.reflector_mean)
    # the site's static clutter points are where the reflectors were learnt
    (tmp_path / "other.npz").write_bytes(b"not a map")
    with pytest.raises(ValueError, match="not a background map"):
        BackgroundMap.load(tmp_path / "other.npz")


def test_classes_follow_the_box_and_the_speed():
    # a learnt bus-sized box, a car, and a pedestrian-sized one that walked, then raced
    p = class_probabilities(np.array([12.0, 4.6, 0.5, 0.5]), np.full(4, 0.09),
                            np.array([2.55, 1.8, 0.5, 0.5]), np.full(4, 0.01),
                            np.array([12.0, 20.0, 1.4, 15.0]))  # fmt: skip
    names, chance = class_names(p)
    assert list(names[:3]) == ["bus", "car", "pedestrian"]
    assert names[3] != "pedestrian" and p[3, CLASSES.index("pedestrian")] == 0.0
    assert np.allclose(p.sum(axis=1), 1.0) and (chance >= 0.5).all() | (names == "unknown").any()
    # a box known no better than the prior's spread leaves the class uncertain
    vague = class_probabilities(np.array([3.0]), np.array([6.25]), np.array([1.2]),
                                np.array([0.25]), np.array([3.0]))  # fmt: skip
    assert vague.max() < 0.9
