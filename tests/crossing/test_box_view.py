"""The tracker's visible-face model against rays cast from the radar onto the box."""

import numpy as np
import pytest

from adaptrack.crossing.scene.box_view import face_moments


def _ray_hits(centre, heading, length, width, radar, n_rays=200_001):
    """First boundary points of rays spread evenly in bearing over the box (slab method)."""
    c, s = np.cos(heading), np.sin(heading)
    to_body = np.array([[c, s], [-s, c]])  # world -> body frame
    r_body = to_body @ (np.asarray(radar) - centre)
    corners = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]]) * [length / 2, width / 2]
    bearings = np.arctan2(corners[:, 1] - r_body[1], corners[:, 0] - r_body[0])
    mid = np.arctan2(-r_body[1], -r_body[0])
    spread = np.angle(np.exp(1j * (bearings - mid)))
    angles = mid + np.linspace(spread.min(), spread.max(), n_rays)
    d = np.stack([np.cos(angles), np.sin(angles)], -1)
    half = np.array([length / 2, width / 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - r_body) / d
        t2 = (half - r_body) / d
    t_near = np.nanmax(np.minimum(t1, t2), axis=1)
    t_far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = t_near <= t_far
    points = r_body + t_near[hit, None] * d[hit]
    # rays evenly spread in bearing hit a face at a density proportional to its projected
    # length over the squared distance; at a far radar, the projected length alone
    return centre + points @ to_body


@pytest.mark.parametrize(
    ("heading", "radar"),
    [(0.0, (2000.0, 0.0)), (0.3, (1500.0, 1500.0)), (2.0, (-300.0, 1900.0)),
     (-1.2, (0.0, -2500.0))],
)  # fmt: skip
def test_mean_and_spread_match_cast_rays(heading, radar):
    centre = np.array([3.0, -2.0])
    length, width = 4.6, 1.8
    pts = _ray_hits(centre, heading, length, width, radar)
    offset, cov = face_moments(centre[None], np.array([heading]), np.array([length]),
                               np.array([width]), np.array(radar))  # fmt: skip
    assert offset[0] == pytest.approx(pts.mean(axis=0) - centre, abs=0.01)
    assert cov[0] == pytest.approx(np.cov(pts.T), abs=0.01)


def test_the_offset_points_towards_the_radar_by_half_the_seen_face():
    # seen end-on, only the front face: offset half the length, spread the width's
    offset, cov = face_moments(np.zeros((1, 2)), np.zeros(1), np.array([4.0]), np.array([2.0]),
                               np.array([500.0, 0.0]))  # fmt: skip
    assert offset[0] == pytest.approx([2.0, 0.0])
    assert cov[0] == pytest.approx(np.diag([0.0, 2.0**2 / 12]))


def test_a_radar_inside_the_box_sees_no_face():
    offset, cov = face_moments(np.zeros((1, 2)), np.zeros(1), np.array([4.0]), np.array([2.0]),
                               np.array([0.5, 0.2]))  # fmt: skip
    assert offset[0] == pytest.approx([0.0, 0.0])
    assert cov[0] == pytest.approx(np.diag([4.0**2 / 12, 2.0**2 / 12]))
