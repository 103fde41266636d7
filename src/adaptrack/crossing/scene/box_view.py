"""Where a radar's reflections of a box lie: the tracker's model of the faces it sees.

A road user is a rectangle on the ground (centre, heading, length, width). Seen from a radar
at ``radar_xy``, a vertical face reflects when the radar lies outside the face's plane; its
reflections fall uniformly along the face with a weight proportional to the face's length
projected on the line of sight (its apparent size). The reflections' mean is then offset
from the centre towards the radar (on the near faces) and their covariance is that of the
uniform mixture over the visible faces. The tracker measures a body by this mean, so its
estimate is the box centre whichever faces reflect. The roof and the faces' heights are left
out (a radar on a mast sees a car's roof at a grazing angle). Vectorised over boxes (axis 0).
"""

from __future__ import annotations

import numpy as np

from ..._typing import FloatArray


def face_moments(
    centre: FloatArray,
    heading_rad: FloatArray,
    length_m: FloatArray,
    width_m: FloatArray,
    radar_xy: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Mean offset (N, 2) from the centre and covariance (N, 2, 2) of the visible reflections.

    ``centre`` (N, 2) east, north [m]; ``heading_rad`` (N,) direction of the length axis,
    counter-clockwise from east (as ``atan2(north, east)``); ``radar_xy`` (2,) or (N, 2). A
    radar inside a box sees no face: offset 0, the covariance of the box's area.
    """
    c = np.asarray(centre, float).reshape(-1, 2)
    h = np.asarray(heading_rad, float).reshape(-1)
    half_l = 0.5 * np.asarray(length_m, float).reshape(-1)
    half_w = 0.5 * np.asarray(width_m, float).reshape(-1)
    ax = np.stack([np.cos(h), np.sin(h)], -1)  # length axis
    ay = np.stack([-ax[:, 1], ax[:, 0]], -1)  # width axis (left)
    to_radar = np.asarray(radar_xy, float) - c
    dist = np.linalg.norm(to_radar, axis=-1, keepdims=True)
    sight = to_radar / np.maximum(dist, 1e-9)
    mean = np.zeros_like(c)
    second = np.zeros((c.shape[0], 2, 2))
    total = np.zeros(c.shape[0])
    # faces: (outward normal, its distance, the face's half length, the face's tangent)
    for normal, reach, half_len, tangent in (
        (ax, half_l, half_w, ay), (-ax, half_l, half_w, ay),
        (ay, half_w, half_l, ax), (-ay, half_w, half_l, ax),
    ):  # fmt: skip
        facing = np.einsum("ni,ni->n", to_radar, normal)
        weight = np.where(facing > reach, 2.0 * half_len * np.einsum("ni,ni->n", sight, normal), 0)
        mid = reach[:, None] * normal
        spread = (half_len**2 / 3.0)[:, None, None] * tangent[:, :, None] * tangent[:, None, :]
        mean += weight[:, None] * mid
        second += weight[:, None, None] * (mid[:, :, None] * mid[:, None, :] + spread)
        total += weight
    seen = total > 0
    safe = np.where(seen, total, 1.0)
    mean = mean / safe[:, None]
    cov = second / safe[:, None, None] - mean[:, :, None] * mean[:, None, :]
    inside = (half_l**2 / 3.0)[:, None, None] * ax[:, :, None] * ax[:, None, :] + (half_w**2 / 3.0)[
        :, None, None
    ] * ay[:, :, None] * ay[:, None, :]
    return np.where(seen[:, None], mean, 0.0), np.where(seen[:, None, None], cov, inside)


__all__ = ["face_moments"]
