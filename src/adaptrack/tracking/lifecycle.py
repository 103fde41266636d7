"""Track life cycle: M-of-N confirmation, coasting, deletion, stable identities."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from .._typing import FloatArray


class TrackStatus(IntEnum):
    """What a track is.

    Being confirmed, confirmed and seen, coasting without detections, stopped (a confirmed
    object at a standstill), or deleted.
    """

    TENTATIVE = 0
    CONFIRMED = 1
    COASTING = 2
    STOPPED = 3
    DELETED = 4


@dataclass(frozen=True)
class LifecycleRules:
    """Rules of the track life cycle.

    Confirm after ``confirm_hits`` hits in the last ``confirm_window`` scans; drop a tentative
    track after ``tentative_misses`` misses in a row or when it is not confirmed within
    ``max_tentative_s`` of its birth (misses that tell nothing, e.g. behind another object,
    must not keep a false alarm's track alive); delete a confirmed track not seen for
    ``max_coast_s`` (``max_coast_stopped_s`` while stopped, ``max_coast_hidden_s`` while
    possibly hidden behind another object) [s], or whose position sigma exceeds
    ``max_position_std_m`` while it is not stopped (it no longer says where the object is).
    Where the sensors detect objects at a standstill, a stopped track is also deleted after
    ``max_stopped_misses`` misses in a row that tell (in view, nothing hiding it): the object
    has left (a queued car that drove off), however long a stopped track may coast unseen.
    """

    confirm_hits: int = 3
    confirm_window: int = 4
    tentative_misses: int = 2
    max_tentative_s: float = 3.0
    max_coast_s: float = 1.5
    max_coast_stopped_s: float = 600.0
    max_coast_hidden_s: float = 10.0
    max_position_std_m: float = 10.0
    max_stopped_misses: int = 100

    def __post_init__(self) -> None:
        if not 1 <= self.confirm_hits <= self.confirm_window <= 62:
            raise ValueError("need 1 <= confirm_hits <= confirm_window <= 62")
        for name in ("tentative_misses", "max_stopped_misses"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        for name in ("max_tentative_s", "max_coast_s", "max_coast_stopped_s",
                     "max_coast_hidden_s", "max_position_std_m"):  # fmt: skip
            value = getattr(self, name)
            if not value > 0:  # NaN fails too; inf means no limit
                raise ValueError(f"{name} must be > 0 (inf: no limit); got {value}")


@dataclass
class TrackBook:
    """Identities and hit histories of live tracks (rows), in the order of creation."""

    rules: LifecycleRules = field(default_factory=LifecycleRules)
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    history: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    confirmed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    misses: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    last_hit_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    born_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    next_id: int = 1

    def add(self, n: int, time_s: float) -> np.ndarray:
        """Open ``n`` tentative tracks (each with its first hit); return their new ids."""
        new = np.arange(self.next_id, self.next_id + n, dtype=np.int64)
        self.next_id += n
        self.ids = np.concatenate([self.ids, new])
        self.history = np.concatenate([self.history, np.ones(n, dtype=np.int64)])
        self.confirmed = np.concatenate([self.confirmed, np.zeros(n, dtype=bool)])
        self.misses = np.concatenate([self.misses, np.zeros(n, dtype=np.int64)])
        self.last_hit_s = np.concatenate([self.last_hit_s, np.full(n, time_s)])
        self.born_s = np.concatenate([self.born_s, np.full(n, time_s)])
        return new

    def add_copies(self, rows: np.ndarray, time_s: float) -> np.ndarray:
        """Open new tracks born at ``time_s`` with the hit records of ``rows`` (a split)."""
        new = self.add(rows.size, time_s)
        for name in ("history", "confirmed", "misses", "last_hit_s"):
            getattr(self, name)[-rows.size :] = getattr(self, name)[rows]
        return new

    def record(
        self, rows: np.ndarray, hit: np.ndarray, time_s: float, ready: np.ndarray | None = None
    ) -> np.ndarray:
        """Record a scan's hits (bool) of the tracks in ``rows``; return the rows confirmed now.

        ``ready`` (bool per row, default all): a track is confirmed only once its state is
        determined well enough (e.g. its speed), whatever its hits.
        """
        mask = (1 << self.rules.confirm_window) - 1
        self.history[rows] = ((self.history[rows] << 1) | hit.astype(np.int64)) & mask
        self.misses[rows] = np.where(hit, 0, self.misses[rows] + 1)
        self.last_hit_s[rows] = np.where(hit, time_s, self.last_hit_s[rows])
        hits = np.bitwise_count(self.history[rows])
        ok = hits >= self.rules.confirm_hits
        if ready is not None:
            ok &= ready
        now = rows[~self.confirmed[rows] & ok]
        self.confirmed[now] = True
        return now

    def expired(
        self,
        time_s: float,
        stopped: np.ndarray,
        hidden: np.ndarray,
        position_std_m: FloatArray | None = None,
        stopped_detectable: bool = True,
    ) -> np.ndarray:
        """Return the rows to delete at ``time_s``.

        Failed tentative tracks, confirmed ones coasting too long (``stopped`` and ``hidden``
        rows by their own limits), moving ones whose ``position_std_m`` [m] (per row; none:
        not checked) is beyond the limit and, if ``stopped_detectable`` (the sensors detect
        objects at a standstill), stopped ones missed too often in a row.
        """
        r = self.rules
        limit = np.where(
            stopped, r.max_coast_stopped_s, np.where(hidden, r.max_coast_hidden_s, r.max_coast_s)
        )
        dead_tentative = ~self.confirmed & (
            (self.misses >= r.tentative_misses) | (time_s - self.born_s > r.max_tentative_s)
        )
        dead = dead_tentative | (self.confirmed & (time_s - self.last_hit_s > limit))
        if position_std_m is not None:
            dead |= ~stopped & (np.asarray(position_std_m) > r.max_position_std_m)
        if stopped_detectable:
            dead |= self.confirmed & stopped & (self.misses >= r.max_stopped_misses)
        return np.flatnonzero(dead)

    def remove(self, rows: np.ndarray) -> None:
        """Forget the tracks in ``rows``."""
        keep = np.ones(self.ids.size, dtype=bool)
        keep[rows] = False
        for name in ("ids", "history", "confirmed", "misses", "last_hit_s", "born_s"):
            setattr(self, name, getattr(self, name)[keep])


__all__ = ["LifecycleRules", "TrackBook", "TrackStatus"]
