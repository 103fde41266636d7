"""Whether the crossing is clear: any object between the barriers, seen moving or not.

The area between the barriers is, on every corridor through the crossing, the carriageway
(all its lanes) within ``barrier_m`` of the crossing along the road; it is rasterised once in
cells of ``AREA_CELL_M``. After each scan the reported objects (not the background) whose box
(centre and corners) touches the area occupy it; the crossing is "not clear" from the first
scan with an occupant until the first scan without one, raising ``crossing_not_clear`` and then
``crossing_clear``. While the controller says a train is due (``train_intervals``) an object
on the rails (within ``RAIL_CORRIDOR_M`` of the rails' axis) that moves along them (at least
``TRAIN_SPEED_MPS`` along their axis, within ``TRAIN_ALIGN_DEG`` of it) is the train, a known
occupant; anything else there (a car stalled on the rails, a fallen load, a track that
crosses them) makes the crossing not clear whether a train is due or not.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..._typing import FloatArray
from ..site.corridor import nearest_corridor
from ..site.model import Site

AREA_CELL_M = 0.25
RAIL_CORRIDOR_M = 2.5  # half width of what a train occupies beside the rails' axis [m]
TRAIN_SPEED_MPS = 2.0  # a train due moves along the rails at least this fast [m/s] ...
TRAIN_ALIGN_DEG = 30.0  # ... within this of their axis
EVENT_NOT_CLEAR, EVENT_CLEAR = "crossing_not_clear", "crossing_clear"


class CrossingArea:
    """The raster of the area between the barriers of a site, and the train's corridor."""

    def __init__(self, site: Site) -> None:
        corridors = site.corridors
        reach = (
            site.barrier_m
            + max(0.5 * (r.lanes_in + r.lanes_out) * r.lane_width_m for r in site.roads.values())
            + 1.0
        )
        n = math.ceil(2 * reach / AREA_CELL_M)
        self.origin = np.array([-reach, -reach])
        centres = -reach + (np.arange(n) + 0.5) * AREA_CELL_M
        ee, nn = np.meshgrid(centres, centres, indexing="ij")
        pts = np.stack([ee.ravel(), nn.ravel()], -1)
        index, u, d = nearest_corridor(corridors, pts)
        crossing_u = np.array([c.crossing_u for c in corridors])[index]
        half = np.array([
            0.5 * (site.roads[c.first].lanes_in + site.roads[c.first].lanes_out)
            * site.roads[c.first].lane_width_m for c in corridors
        ])[index]  # fmt: skip
        inside = (np.abs(u - crossing_u) <= site.barrier_m) & (np.abs(d) <= half)
        self.inside = inside.reshape(n, n)
        self.rails = site.rails

    def touches(self, centre: ArrayLike, heading_rad: ArrayLike, length_m: ArrayLike,
                width_m: ArrayLike) -> np.ndarray:  # fmt: skip
        """Whether each box's centre or a corner lies in the area (boxes (N, 2) ... (N,))."""
        centre = np.asarray(centre, float).reshape(-1, 2)
        h = np.asarray(heading_rad, float).reshape(-1)
        half_l = 0.5 * np.asarray(length_m, float).reshape(-1, 1)
        half_w = 0.5 * np.asarray(width_m, float).reshape(-1, 1)
        ax = np.stack([np.cos(h), np.sin(h)], -1) * half_l
        ay = np.stack([-np.sin(h), np.cos(h)], -1) * half_w
        signs = np.array([[0, 0], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)
        pts = centre[:, None] + signs[None, :, :1] * ax[:, None] + signs[None, :, 1:] * ay[:, None]
        ij = np.floor((pts - self.origin) / AREA_CELL_M).astype(int)
        n = self.inside.shape[0]
        ok = (ij >= 0).all(axis=-1) & (ij < n).all(axis=-1)
        hit = np.zeros(ok.shape, bool)
        hit[ok] = self.inside[ij[ok][:, 0], ij[ok][:, 1]]
        return np.asarray(hit.any(axis=1), bool)

    def on_rails(self, centre: FloatArray) -> bool:
        """Whether a point lies within ``RAIL_CORRIDOR_M`` of the rails' axis (no rails: False)."""
        if self.rails is None:
            return False
        d = self.rails.direction
        rel = np.asarray(centre) - np.asarray(self.rails.centre_m)
        return abs(-rel[0] * d[1] + rel[1] * d[0]) <= self.rails_half_width_m

    @property
    def rails_half_width_m(self) -> float:
        """Half width of the train's corridor about the rails' axis, every track in it [m]."""
        if self.rails is None:
            return -1.0
        return RAIL_CORRIDOR_M + 0.5 * (self.rails.tracks - 1) * self.rails.track_spacing_m

    def is_train(self, centre: FloatArray, velocity: FloatArray) -> bool:
        """Whether an object at ``centre`` [m] moving at ``velocity`` [m/s] is a train."""
        if not self.on_rails(centre):
            return False
        d = self.rails.direction  # type: ignore[union-attr]
        along = abs(velocity[0] * d[0] + velocity[1] * d[1])
        across = abs(-velocity[0] * d[1] + velocity[1] * d[0])
        aligned = across <= along * math.tan(math.radians(TRAIN_ALIGN_DEG))
        return along >= TRAIN_SPEED_MPS and aligned


class ClearanceMonitor:
    """The crossing's clear / not-clear state and its events (module docstring)."""

    def __init__(self, site: Site, train_intervals: FloatArray | None = None) -> None:
        self.area = CrossingArea(site)
        trains = np.asarray([] if train_intervals is None else train_intervals, float)
        if trains.size and (trains.ndim != 2 or trains.shape[1] != 2):
            raise ValueError(f"train intervals must be (K, 2) (start_s, end_s); got {trains.shape}")
        self.trains = trains.reshape(-1, 2)
        bad = ~(np.isfinite(self.trains).all(axis=1) & (self.trains[:, 0] < self.trains[:, 1]))
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(
                f"train interval {k}: expected finite start_s < end_s; "
                f"got {self.trains[k].tolist()}"
            )
        self.occupant: int | None = None  # track id of the object that made it not clear
        self.events: list[dict[str, object]] = []

    def train_due(self, time_s: float) -> bool:
        """Whether the controller has a train due at ``time_s``."""
        return bool(np.any((self.trains[:, 0] <= time_s) & (time_s < self.trains[:, 1])))

    def update(self, time_s: float, ids: np.ndarray, centres: FloatArray, velocity: FloatArray,
               heading: FloatArray, length: FloatArray, width: FloatArray) -> None:  # fmt: skip
        """Take the objects after a scan (centres m, velocities m/s, boxes); raise the changes."""
        train = self.train_due(time_s)
        touching = (
            self.area.touches(centres, heading, length, width) if ids.size else np.zeros(0, bool)
        )
        inside = [
            k for k in np.flatnonzero(touching)
            if not (train and self.area.is_train(centres[k], velocity[k]))
        ]  # fmt: skip
        if inside and self.occupant is None:
            k = inside[0]
            self.occupant = int(ids[k])
            self._event(time_s, EVENT_NOT_CLEAR, self.occupant, centres[k])
        elif not inside and self.occupant is not None:
            self._event(time_s, EVENT_CLEAR, self.occupant, np.array([np.nan, np.nan]))
            self.occupant = None

    def _event(self, time_s: float, name: str, track: int, where: FloatArray) -> None:
        self.events.append({"time_s": time_s, "event": name, "track_id": track,
                            "east_m": float(where[0]), "north_m": float(where[1]),
                            "lead_s": np.nan})  # fmt: skip


__all__ = ["EVENT_CLEAR", "EVENT_NOT_CLEAR", "ClearanceMonitor", "CrossingArea"]
