"""Curve kinematics: a lane point moves at (1 + kappa (w/2 + d)) x the centreline speed.

Checked against geometry computed independently of the road module: the lane of a circular arc
is a concentric circle, so its points lie at radius R + o from the arc's centre and a vehicle
driving at speed v turns at v / (R + o) rad/s.
"""

import dataclasses
import math

import numpy as np
import pytest

from adaptrack.crossing.estimators.road_filters import _road_estimates, _road_measure
from adaptrack.crossing.simulation.radar import simulate_case
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.site.road import RoadElement, build_road
from adaptrack.crossing.site.sensor import Curve
from adaptrack.crossing.site.traffic import VEHICLES, Case

RADIUS_M = 80.0
HEADING = 0.3
SITE = load_site("lx_default")


def arc_road(turn: str):
    return build_road(
        "arc", HEADING, 3.5, (RoadElement("arc", 250.0, radius_m=RADIUS_M, turn=turn),)
    )


def arc_centre(turn: str) -> np.ndarray:
    """Centre of the arc: R to the right of the outbound direction for a right turn."""
    side = 1.0 if turn == "right" else -1.0
    return side * RADIUS_M * np.array([math.cos(HEADING), -math.sin(HEADING)])


@pytest.mark.parametrize("turn", ["right", "left"])
def test_simulated_lane_point_moves_at_the_vehicle_speed(turn):
    road = arc_road(turn)
    radar = dataclasses.replace(
        SITE.radar_for("B"), detection_probability={"default": Curve.constant(1.0)}
    )
    runs = simulate_case(
        road, radar, VEHICLES["car"], Case("c", "pass", 60.0, "arc"),
        n_runs=4, rng=np.random.default_rng(1), start_m=200.0, stop_line_m=15.0,
        lateral_offset_std_m=0.5,
    )  # fmt: skip
    # the right of the inbound direction is the outside of a right-turning (outbound) arc
    side = 1.0 if turn == "right" else -1.0
    radius = RADIUS_M + side * (0.5 * road.lane_width_m + runs.lateral_offset_m)
    dist = np.linalg.norm(runs.position - arc_centre(turn), axis=-1)
    np.testing.assert_allclose(dist, np.broadcast_to(radius[:, None], dist.shape), atol=2e-3)
    # speed from the positions' own time derivative (central differences)
    dt = np.diff(runs.true_times, axis=1)
    step = np.linalg.norm(np.diff(runs.position, axis=1), axis=-1) / dt
    mid_speed = 0.5 * (runs.speed[:, 1:] + runs.speed[:, :-1])
    np.testing.assert_allclose(step, mid_speed, rtol=2e-4)
    # angular rate v / (R + o): the outside lane sweeps less angle than the centreline would
    ang = np.unwrap(np.arctan2(*(runs.position - arc_centre(turn)).transpose(2, 0, 1)), axis=1)
    rate = np.abs(np.diff(ang, axis=1)) / dt
    np.testing.assert_allclose(rate, mid_speed / radius[:, None], rtol=2e-4)
    np.testing.assert_allclose(np.linalg.norm(runs.velocity, axis=-1), runs.speed, rtol=1e-12)


@pytest.mark.parametrize("turn", ["right", "left"])
def test_tracker_measurement_model_matches_finite_differences(turn):
    """Radial speed and Jacobian of the road EKF against differences of the lane geometry."""
    road = arc_road(turn)
    radar = SITE.radar_for("B")
    k = 3
    measure = _road_measure(road, radar, k, 0.0)
    x = np.array([[120.0, -15.0, 0.4, 0.6], [60.0, -8.0, -1.0, -0.4]])
    zp, h, _ = measure(x)
    side = 1.0 if turn == "right" else -1.0
    for i in range(x.shape[0]):
        s, vs, d = x[i, 0], x[i, 1], x[i, k]
        # independent geometry: angle on the arc and radius of the lane
        o = side * (0.5 * road.lane_width_m + d)

        def point(s_, o=o):
            phi = HEADING - side * math.pi / 2 + side * s_ / RADIUS_M  # polar angle from centre
            return arc_centre(turn) + (RADIUS_M + o) * np.array([math.sin(phi), math.cos(phi)])

        eps = 1e-4
        vel = (point(s + vs * eps) - point(s - vs * eps)) / (2 * eps)
        assert np.linalg.norm(vel) == pytest.approx(abs(vs) * (RADIUS_M + o) / RADIUS_M, rel=1e-6)
        rel = point(s) - np.asarray(radar.position_m)
        rng = math.sqrt(rel @ rel + radar.height_m**2)
        assert zp[i, 0] == pytest.approx(rng, abs=1e-3)
        assert zp[i, 2] == pytest.approx(rel @ vel / rng, abs=2e-4)
        # Jacobian columns against central differences of the model's own prediction
        for j in (0, 1, k):
            dx = np.zeros_like(x[i])
            dx[j] = 1e-4
            num = (measure((x[i] + dx)[None])[0] - measure((x[i] - dx)[None])[0])[0] / 2e-4
            np.testing.assert_allclose(h[i, :, j], num, atol=3e-5 * max(1.0, abs(vs)))
    est = _road_estimates(x[None], np.broadcast_to(np.eye(4), (1, 2, 4, 4)), road, k)
    lever = road.lane_speed_factor(x[:, 0], x[:, k])
    np.testing.assert_allclose(est.speed[0], np.abs(x[:, 1]) * lever)
    np.testing.assert_allclose(side * (lever - 1.0) * RADIUS_M, 0.5 * 3.5 + x[:, k], rtol=1e-3)
