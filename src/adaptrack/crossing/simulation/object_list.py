"""Object ids as a radar's own tracker would report them (an object-list radar, simulated).

An object-list radar labels its detections with the ids of its internal tracks. Those ids are
hints, not truth: the simulated sensor

- keeps one id per road user while it sees it, and issues a new one after ``reissue_after_s``
  unseen (an occlusion or a missed stretch ends the sensor's track);
- swaps the ids of two road users whose detections in one scan lie within ``swap_radius_m``
  of each other, with ``swap_probability`` per such scan and pair (its own association
  error between close objects), keeping the swapped ids afterwards;
- gives every false alarm and multipath ghost a new id, and static clutter an id per
  ``CLUTTER_CELL`` of range and azimuth (it tracks a post or a rail as an object).

Ids of different radars are independent numbers.
"""

from __future__ import annotations

import itertools

import numpy as np

from .scene import SceneRecording

CLUTTER_CELL = (2.0, 0.05)  # range [m], azimuth [rad] of one static-clutter id


def object_list_ids(
    rec: SceneRecording,
    seed: int,
    *,
    swap_probability: float = 0.001,
    swap_radius_m: float = 5.0,
    reissue_after_s: float = 1.0,
) -> np.ndarray:
    """Return the sensor object id (int64) of each of ``rec.detections`` (rows in order)."""
    if not 0.0 <= swap_probability <= 1.0 or swap_radius_m < 0.0 or reissue_after_s <= 0.0:
        raise ValueError(
            "object-list ids: swap_probability in [0, 1], swap_radius_m >= 0 and "
            "reissue_after_s > 0 expected"
        )
    rng = np.random.default_rng(seed)
    det = rec.detections
    t = det["time_s"].to_numpy()
    rng_m = det["range_m"].to_numpy()
    az = det["azimuth_rad"].to_numpy()
    radar = det["radar"].astype(str).to_numpy()
    src = np.asarray(rec.sources)
    gx, gy = rng_m * np.sin(az), rng_m * np.cos(az)  # slant plane: enough to tell near pairs
    out = np.full(t.size, -1, np.int64)
    fresh = itertools.count()
    for name in np.unique(radar):
        rows = np.flatnonzero(radar == name)
        current: dict[int, int] = {}  # road user -> the id it carries
        last_seen: dict[int, float] = {}
        clutter: dict[tuple[int, int], int] = {}
        cut = np.flatnonzero(np.diff(t[rows]) != 0) + 1
        for scan in np.split(rows, cut):
            now = t[scan[0]]
            users = np.unique(src[scan][src[scan] >= 0])
            for u in users.tolist():
                if u not in current or now - last_seen[u] > reissue_after_s:
                    current[u] = next(fresh)
                last_seen[u] = now
            _swap_close_pairs(scan, src, gx, gy, users, current, swap_radius_m,
                              swap_probability, rng)  # fmt: skip
            for j in scan.tolist():
                s = int(src[j])
                if s >= 0:
                    out[j] = current[s]
                elif s == -2:
                    cell = (int(rng_m[j] // CLUTTER_CELL[0]), int(az[j] // CLUTTER_CELL[1]))
                    out[j] = clutter.setdefault(cell, next(fresh))
                else:
                    out[j] = next(fresh)
    return out


def _swap_close_pairs(  # type: ignore[no-untyped-def]
    scan, src, gx, gy, users, current, radius_m, probability, rng
) -> None:
    """Swap the ids of road users detected within ``radius_m`` of each other (at random)."""
    if users.size < 2 or probability == 0.0:
        return
    first = np.array([scan[np.argmax(src[scan] == u)] for u in users])
    dx = gx[first][:, None] - gx[first][None, :]
    dy = gy[first][:, None] - gy[first][None, :]
    close = np.argwhere(np.triu(np.hypot(dx, dy) <= radius_m, 1))
    for a, b in close.tolist():
        if rng.random() < probability:
            ua, ub = int(users[a]), int(users[b])
            current[ua], current[ub] = current[ub], current[ua]


__all__ = ["CLUTTER_CELL", "object_list_ids"]
