"""The railway at a crossing: its axis, its tracks, and where a train is.

The axis passes through ``centre_m`` with azimuth ``axis_rad`` (clockwise from north); the
tracks lie side by side ``track_spacing_m`` apart, centred on the axis. A train runs along one
track's centreline: ``track_offset(k)`` is that line's offset to the right of the axis
direction [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..._typing import FloatArray


@dataclass(frozen=True)
class Rails:
    """The railway (module docstring); ``gauge_m`` is the distance between a track's rails."""

    axis_rad: float
    centre_m: tuple[float, float] = (0.0, 0.0)
    tracks: int = 1
    track_spacing_m: float = 4.5
    gauge_m: float = 1.435

    @property
    def direction(self) -> FloatArray:
        """Unit vector (2,) along the axis (east, north)."""
        return np.array([math.sin(self.axis_rad), math.cos(self.axis_rad)])

    def track_offset(self, k: int) -> float:
        """Offset [m] of track ``k`` (0-based) to the right of the axis direction."""
        return (k - 0.5 * (self.tracks - 1)) * self.track_spacing_m

    def track_point(self, k: int, along_m: FloatArray) -> FloatArray:
        """Points (..., 2) of track ``k``'s centreline ``along_m`` from the centre [m]."""
        d = self.direction
        right = np.array([d[1], -d[0]])
        a = np.asarray(along_m, dtype=float)[..., None]
        return np.asarray(self.centre_m) + a * d + self.track_offset(k) * right

    def rail_lines(self, half_length_m: float) -> list[FloatArray]:
        """Both rails of every track as (2, 2) segments ``half_length_m`` either side."""
        out: list[FloatArray] = []
        d = self.direction
        right = np.array([d[1], -d[0]])
        for k in range(self.tracks):
            for side in (-0.5, 0.5):
                ends = self.track_point(k, np.array([-half_length_m, half_length_m]))
                out.append(ends + side * self.gauge_m * right)
        return out


__all__ = ["Rails"]
