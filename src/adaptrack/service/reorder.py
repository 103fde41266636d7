"""Merge several radars' detections into scans in time order within a bounded window.

A scan is the detections of one radar with one timestamp. Scans are released in the order of
the times they were made (timestamp less the radar's declared latency; radar name breaks
ties: the order of offline :func:`adaptrack.crossing.scene.tracker.iter_scans`) once the
newest time seen is ``window_s`` past them, or all at once on :meth:`ReorderBuffer.flush`.
A detection of a scan that was released already, or older than the last released scan, is
late: :meth:`ReorderBuffer.push` returns the reason instead of buffering it.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

from .._typing import FloatArray
from .messages import Detection


@dataclass(order=True)
class Scan:
    """Detections (n, 3: range, azimuth, radial speed) of one radar at one timestamp."""

    made_s: float
    radar: str
    time_s: float = field(compare=False)
    rows: list[tuple[float, float, float]] = field(compare=False, default_factory=list)

    @property
    def z(self) -> FloatArray:
        """Detections as an (n, 3) array."""
        return np.asarray(self.rows, dtype=float).reshape(-1, 3)


class ReorderBuffer:
    """Scans waiting for the reorder window (module docstring).

    ``latency_s`` maps each radar to its declared timestamp delay [s].
    """

    def __init__(self, window_s: float, latency_s: dict[str, float]) -> None:
        if not window_s >= 0:
            raise ValueError(f"reorder window must be >= 0 s; got {window_s}")
        self.window_s = float(window_s)
        self.latency_s = dict(latency_s)
        self._open: dict[tuple[str, float], Scan] = {}
        self._heap: list[Scan] = []
        self.newest_s = -np.inf  # newest made time seen [s]
        self.released: tuple[float, str] = (-np.inf, "")  # (made time, radar) of the last
        self.pending = 0  # detections buffered

    def push(self, d: Detection) -> str | None:
        """Buffer one detection; return None, or why it is late (not buffered)."""
        made = d.time_s - self.latency_s[d.radar]
        if (made, d.radar) <= self.released:
            return (
                f"radar {d.radar!r} at {d.time_s} s: that scan or a later one was processed "
                f"already (reorder window {self.window_s} s)"
            )
        key = (d.radar, d.time_s)
        scan = self._open.get(key)
        if scan is None:
            scan = self._open[key] = Scan(made, d.radar, d.time_s)
            heapq.heappush(self._heap, scan)
        scan.rows.append((d.range_m, d.azimuth_rad, d.radial_speed_mps))
        self.pending += 1
        self.newest_s = max(self.newest_s, made)
        return None

    def ready(self) -> list[Scan]:
        """Release the scans the window has passed, in order."""
        return self._release(self.newest_s - self.window_s)

    def flush(self) -> list[Scan]:
        """Release every buffered scan, in order (end of input, or the input fell silent)."""
        return self._release(np.inf)

    def _release(self, until_s: float) -> list[Scan]:
        out = []
        while self._heap and self._heap[0].made_s <= until_s:
            scan = heapq.heappop(self._heap)
            del self._open[(scan.radar, scan.time_s)]
            self.pending -= len(scan.rows)
            self.released = (scan.made_s, scan.radar)
            out.append(scan)
        return out


__all__ = ["ReorderBuffer", "Scan"]
