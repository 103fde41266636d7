"""The face radar model against an independent ray cast.

The oracle here shares no code with the simulator: each box is 12 triangles (its 8 corners
built from the heading here), and rays from the antenna are intersected with every triangle
by the Moller-Trumbore test; the first triangle hit is what the antenna sees.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from adaptrack.crossing.simulation.faces import (
    OBJECT_SAMPLES,
    FaceRadar,
    draw_points,
    face_frames,
    face_returns,
    occluded_points,
    visible_weights,
)
from adaptrack.crossing.simulation.scene import ScanStates, SceneSpec
from adaptrack.crossing.site.model import load_site

FACE_NAMES = ("front", "rear", "right", "left", "roof")


def box_triangles(cx, cy, heading, length, width, height):
    """Triangles (12, 3, 3) and the face name of each, from the corners of the box."""
    fx, fy = math.sin(heading), math.cos(heading)  # clockwise from north
    rx, ry = fy, -fx

    def corner(a, b, z):  # a: +1 front / -1 rear, b: +1 right / -1 left, z: 0 or 1
        return np.array([
            cx + a * 0.5 * length * fx + b * 0.5 * width * rx,
            cy + a * 0.5 * length * fy + b * 0.5 * width * ry,
            z * height,
        ])  # fmt: skip

    quads = {
        "front": [corner(1, -1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, -1, 1)],
        "rear": [corner(-1, -1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(-1, -1, 1)],
        "right": [corner(-1, 1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(-1, 1, 1)],
        "left": [corner(-1, -1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(-1, -1, 1)],
        "roof": [corner(-1, -1, 1), corner(1, -1, 1), corner(1, 1, 1), corner(-1, 1, 1)],
        "floor": [corner(-1, -1, 0), corner(1, -1, 0), corner(1, 1, 0), corner(-1, 1, 0)],
    }
    tris, names = [], []
    for name, q in quads.items():
        tris += [np.stack([q[0], q[1], q[2]]), np.stack([q[0], q[2], q[3]])]
        names += [name, name]
    return np.stack(tris), names


def first_hit(origin, direction, triangles):
    """Distance along ``direction`` (unit) to the nearest triangle hit, and its index."""
    best, which = np.inf, -1
    for k, (a, b, c) in enumerate(triangles):
        e1, e2 = b - a, c - a
        pvec = np.cross(direction, e2)
        det = e1 @ pvec
        if abs(det) < 1e-12:
            continue
        tvec = origin - a
        u = (tvec @ pvec) / det
        qvec = np.cross(tvec, e1)
        v = (direction @ qvec) / det
        t = (e2 @ qvec) / det
        if u < -1e-9 or v < -1e-9 or u + v > 1 + 1e-9 or t <= 1e-9:
            continue
        if t < best:
            best, which = t, k
    return best, which


def random_scene(rng, n_boxes):
    """Boxes near an antenna on a pole: centre (N, 2), heading, length, width, height."""
    centre = rng.uniform(-25.0, 25.0, (n_boxes, 2)) + np.array([0.0, 30.0])
    heading = rng.uniform(0.0, 2 * math.pi, n_boxes)
    length = rng.uniform(0.5, 12.0, n_boxes)
    width = rng.uniform(0.5, 2.6, n_boxes)
    height = rng.uniform(1.0, 3.8, n_boxes)
    return centre, heading, length, width, height


def test_visible_faces_are_the_faces_a_ray_cast_sees():
    rng = np.random.default_rng(4)
    for _ in range(60):
        centre, heading, length, width, height = random_scene(rng, 1)
        antenna = np.array([rng.uniform(-10, 10), rng.uniform(-10, 5), rng.uniform(0.3, 8.0)])
        fwd = np.stack([np.sin(heading), np.cos(heading)], -1)
        mid, normal, sa, sb = face_frames(centre, fwd, length, width, height)
        model = visible_weights(antenna, mid, normal, sa, sb)[0] > 0
        tris, names = box_triangles(centre[0, 0], centre[0, 1], heading[0], length[0],
                                    width[0], height[0])  # fmt: skip
        seen = set()
        for f in range(5):  # rays to a grid of points inside every face
            for a in np.linspace(-0.9, 0.9, 7):
                for b in np.linspace(-0.9, 0.9, 7):
                    target = mid[0, f] + a * sa[0, f] + b * sb[0, f]
                    d = target - antenna
                    dist = np.linalg.norm(d)
                    _, k = first_hit(antenna, d / dist, tris)
                    if k >= 0:
                        seen.add(names[k])
        oracle = np.array([name in seen for name in FACE_NAMES])
        assert np.array_equal(model, oracle), (model, oracle, antenna, heading)


def test_drawn_points_are_first_hits_and_occlusion_matches_the_ray_cast():
    rng = np.random.default_rng(9)
    checked_hidden = checked_open = 0
    for _ in range(25):
        centre, heading, length, width, height = random_scene(rng, 6)
        antenna = np.array([0.0, 0.0, rng.uniform(0.5, 7.0)])
        fwd = np.stack([np.sin(heading), np.cos(heading)], -1)
        mid, normal, sa, sb = face_frames(centre, fwd, length, width, height)
        weights = visible_weights(antenna, mid, normal, sa, sb)
        rows = np.repeat(np.arange(6), 30)
        point, _ = draw_points(rows, weights, mid, sa, sb, rng)
        hidden = occluded_points(antenna, point, rows, np.zeros(6, np.int64), centre, fwd,
                                 0.5 * np.stack([length, width], -1), height)  # fmt: skip
        boxes = [box_triangles(*centre[i], heading[i], length[i], width[i], height[i])[0]
                 for i in range(6)]  # fmt: skip
        for p, owner, h in zip(point, rows, hidden, strict=True):
            d = p - antenna
            dist = np.linalg.norm(d)
            own, _ = first_hit(antenna, d / dist, boxes[owner])
            assert own == pytest.approx(dist, abs=1e-6)  # on a face the antenna sees
            others = min(first_hit(antenna, d / dist, boxes[j])[0] for j in range(6) if j != owner)
            if abs(others - dist) < 1e-6:
                continue  # grazing an edge: either answer is right
            assert h == (others < dist), (p, owner)
            checked_hidden += h
            checked_open += not h
    assert checked_hidden > 50 and checked_open > 500  # both outcomes were exercised


def _states(centre, heading, length, width, speed, cls="car", scans=200):
    n = len(centre)
    fwd = np.stack([np.sin(heading), np.cos(heading)], -1)
    rep = np.tile(np.arange(n), scans)
    return ScanStates(
        np.arange(scans) * 0.05, np.repeat(np.arange(scans), n), rep,
        np.array([cls] * (n * scans), dtype=object), np.asarray(centre, float)[rep], fwd[rep],
        (np.asarray(speed, float)[:, None] * fwd)[rep], np.asarray(length, float)[rep],
        np.asarray(width, float)[rep], np.full(n * scans, np.nan), np.zeros(n * scans),
    )  # fmt: skip


SITE = load_site("lx_default")
RADAR = SITE.radars[0]


def test_an_object_list_reports_the_near_faces_not_the_centre():
    """A car broadside to the radar: its returns lie on its near side, half its width nearer."""
    rx, ry = RADAR.position_m
    along = RADAR.boresight_rad
    centre = np.array([[rx + 30 * math.sin(along), ry + 30 * math.cos(along)]])
    st = _states(centre, np.array([along + math.pi / 2]), [4.5], [1.8], [0.0])
    ret = face_returns(FaceRadar.of_kind("object"), RADAR, SceneSpec(), st,
                       np.random.default_rng(1))  # fmt: skip
    h = FaceRadar().antenna_height(RADAR)
    ground = np.sqrt(ret.range_m**2 - (h - 0.75) ** 2)  # the middle of the side face's span
    assert ret.source.size > 150  # one per scan, detected with the site's P_D
    assert np.mean(ground) == pytest.approx(30.0 - 0.9, abs=0.1)


def test_cloud_counts_fluctuate_and_doppler_is_quantised():
    rx, ry = RADAR.position_m
    centre = np.array([[rx, ry + 8.0]])
    st = _states(centre, np.array([0.0]), [0.5], [0.5], [1.4], cls="pedestrian", scans=3000)
    fr = FaceRadar.of_kind("cloud")
    ret = face_returns(fr, RADAR, SceneSpec(), st, np.random.default_rng(2))
    counts = np.bincount(ret.scan_of, minlength=3000)
    # negative binomial: mean m, variance m + m^2 / shape (the RCS fluctuation)
    m = counts.mean()
    assert 5 < m < 60
    assert counts.var() == pytest.approx(m + m**2 / fr.cloud_count_shape, rel=0.2)
    assert ret.elevation_rad is not None and ret.elevation_rad.size == ret.source.size
    assert fr.doppler_step_mps == 0.44


def test_face_radar_rejects_bad_parameters():
    with pytest.raises(ValueError, match="radar kind"):
        FaceRadar(kind="lidar")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cloud_points_per_m2"):
        FaceRadar(cloud_points_per_m2=0.0)
    assert OBJECT_SAMPLES > 1
