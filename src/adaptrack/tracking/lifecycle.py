"""Track life cycle: M-of-N confirmation, coasting, deletion, stable identities."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numba
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
        return record_hits(
            self.history, self.misses, self.last_hit_s, self.confirmed,
            np.asarray(rows, np.int64), np.asarray(hit, bool), float(time_s),
            np.ones(len(rows), bool) if ready is None else np.asarray(ready, bool),
            (1 << self.rules.confirm_window) - 1, self.rules.confirm_hits,
        )  # fmt: skip

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
        std = np.zeros(self.ids.size) if position_std_m is None else np.asarray(position_std_m)
        return expired_rows(
            self.confirmed, self.misses, self.born_s, self.last_hit_s, float(time_s),
            np.asarray(stopped, bool), np.asarray(hidden, bool), std.astype(float),
            position_std_m is not None, stopped_detectable, r.tentative_misses,
            r.max_tentative_s, r.max_coast_s, r.max_coast_stopped_s, r.max_coast_hidden_s,
            r.max_position_std_m, r.max_stopped_misses,
        )  # fmt: skip

    def remove(self, rows: np.ndarray) -> None:
        """Forget the tracks in ``rows``."""
        keep = np.ones(self.ids.size, dtype=bool)
        keep[rows] = False
        for name in ("ids", "history", "confirmed", "misses", "last_hit_s", "born_s"):
            setattr(self, name, getattr(self, name)[keep])


@numba.njit(cache=True)
def record_hits(  # type: ignore[no-untyped-def]
    history, misses, last_hit_s, confirmed, rows, hit, time_s, ready, window_mask, confirm_hits
):  # fmt: skip
    """:meth:`TrackBook.record` on a book's arrays in place (for compiled callers).

    ``window_mask``: ``2**confirm_window - 1``. Returns the rows confirmed now.
    """
    now = np.zeros(rows.size, np.int64)
    n = 0
    for k in range(rows.size):
        i = rows[k]
        history[i] = ((history[i] << 1) | (1 if hit[k] else 0)) & window_mask
        if hit[k]:
            misses[i] = 0
            last_hit_s[i] = time_s
        else:
            misses[i] += 1
        hits, bits = 0, history[i]
        while bits:
            hits += bits & 1
            bits >>= 1
        if not confirmed[i] and hits >= confirm_hits and ready[k]:
            confirmed[i] = True
            now[n] = i
            n += 1
    return now[:n]


@numba.njit(cache=True)
def expired_rows(  # type: ignore[no-untyped-def]
    confirmed, misses, born_s, last_hit_s, time_s, stopped, hidden, position_std, check_std,
    stopped_detectable, tentative_misses, max_tentative_s, max_coast_s, max_coast_stopped_s,
    max_coast_hidden_s, max_position_std_m, max_stopped_misses,
):  # fmt: skip
    """:meth:`TrackBook.expired` on a book's arrays (for compiled callers): rows to delete."""
    dead = np.zeros(confirmed.size, np.bool_)
    for i in range(confirmed.size):
        if not confirmed[i]:
            dead[i] = misses[i] >= tentative_misses or time_s - born_s[i] > max_tentative_s
        else:
            limit = (
                max_coast_stopped_s if stopped[i]
                else (max_coast_hidden_s if hidden[i] else max_coast_s)
            )  # fmt: skip
            dead[i] = time_s - last_hit_s[i] > limit
            if stopped_detectable and stopped[i] and misses[i] >= max_stopped_misses:
                dead[i] = True
        if check_std and not stopped[i] and position_std[i] > max_position_std_m:
            dead[i] = True
    return np.flatnonzero(dead)


__all__ = ["LifecycleRules", "TrackBook", "TrackStatus"]  # the kernels: compiled callers only
