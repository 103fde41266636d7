"""The service's core without sockets: lines in, output records out, every detection counted.

:class:`LiveTracker` parses input lines (:mod:`.messages`), merges the radars' scans
(:mod:`.reorder`), runs the scene tracker on each released scan and returns the records to
write: the confirmed tracks after the scan (the columns of offline ``adaptrack track``, so a
replayed file gives the same numbers), new hazard events, and a rejection record for every
detection that was not used. Its counters keep ``received = used + rejected + pending``.
:meth:`LiveTracker.save` / :func:`load_state` snapshot and resume the whole state (atomic
write: a crash leaves the previous snapshot).
"""

from __future__ import annotations

import os
import pickle
import time
from collections import Counter
from pathlib import Path

import numpy as np
import orjson

from .._files import write_atomic
from .._typing import FloatArray
from ..crossing.scene.tracker import STATUS_NAMES, SceneTracker, SceneTrackerConfig
from ..crossing.site.model import Site
from .messages import Rejected, is_header, parse_line, record_line
from .reorder import ReorderBuffer, Scan

STATE_VERSION = 5  # 2: merged warning intervals; 3: moments of reflections; 4: sensor ids;
# 5: the compiled scan loop's site tables and per-radar state
LATENCY_SAMPLES = 1 << 18  # processing times kept for the percentiles (an hour of scans)

Record = dict[str, object]  # an output record before encoding


class LiveTracker:
    """Incremental scene tracking of a line stream (module docstring).

    ``window_s``: reorder window [s]; ``warnings`` (K, 2): the crossing's warning intervals
    [s] (stop-line prediction), as in :func:`adaptrack.crossing.scene.tracker.track_scene`.
    """

    def __init__(
        self,
        site: Site,
        config: SceneTrackerConfig | None = None,
        window_s: float = 0.2,
        warnings: FloatArray | None = None,
    ) -> None:
        self.site = site
        self.tracker = SceneTracker(site, config, warnings)
        self.buffer = ReorderBuffer(window_s, {r.name: r.latency_s for r in site.radars})
        self.radars = frozenset(r.name for r in site.radars)
        self.received = 0
        self.used = 0
        self.rejected: Counter[str] = Counter()
        self.scans = 0
        self._events_out = 0
        self._latency = np.full(LATENCY_SAMPLES, np.nan)  # processing time per scan [s]

    # -- input --------------------------------------------------------------------------
    def feed(self, line: str, source: str = "") -> list[str]:
        """Take one input line; return the JSON lines it makes (scans the window released)."""
        if is_header(line):
            return []
        self.received += 1
        try:
            det = parse_line(line, self.radars)
        except Rejected as exc:
            return [self._reject(exc.reason, exc.detail, source, line)]
        late = self.buffer.push(det)
        if late is not None:
            return [self._reject("late", late, source, line)]
        return self._process(self.buffer.ready())

    def flush(self) -> list[str]:
        """Process every buffered scan (end of input, or the input fell silent)."""
        return self._process(self.buffer.flush())

    # -- scans ----------------------------------------------------------------------------
    def _process(self, scans: list[Scan]) -> list[str]:
        out: list[str] = []
        for scan in scans:
            start = time.perf_counter()
            out.extend(self._scan(scan))
            self._latency[self.scans % LATENCY_SAMPLES] = time.perf_counter() - start
            self.scans += 1
        return out

    def _scan(self, scan: Scan) -> list[str]:
        tr = self.tracker
        z = scan.z
        before = tr.log.total - tr.log.rejected_outside_view
        tr.step(scan.radar, scan.time_s, z)
        self.used += tr.log.total - tr.log.rejected_outside_view - before
        out = []
        if tr.outside_view.any():
            detail = f"radar {scan.radar!r} at {scan.time_s} s: beyond its field of view"
            out = [
                self._reject("outside_view", detail, scan.radar, row) for row in z[tr.outside_view]
            ]
        out.append(track_lines(tr.columns(tr.last_scan_s)))
        for event in tr.events[self._events_out :]:
            out.append(record_line({"type": "event", **event}))
        self._events_out = len(tr.events)
        return out

    def _reject(self, reason: str, detail: str, source: str, line: object) -> str:
        self.rejected[reason] += 1
        text = line if isinstance(line, str) else [float(v) for v in np.asarray(line)]
        return record_line({"type": "rejection", "reason": reason, "detail": detail,
                            "source": source,
                            "input": text.strip() if isinstance(text, str) else text})  # fmt: skip

    # -- counters -------------------------------------------------------------------------
    def stats(self) -> Record:
        """Return the counters: ``received = used + rejected + pending`` (detections)."""
        lat = self._latency[np.isfinite(self._latency)]
        p50, p99 = (1e3 * np.percentile(lat, [50, 99])).tolist() if lat.size else (None, None)
        return {
            "type": "stats",
            "received": self.received,
            "used": self.used,
            "rejected": sum(self.rejected.values()),
            "pending": self.buffer.pending,
            "rejected_by_reason": dict(sorted(self.rejected.items())),
            "scans": self.scans,
            "live_tracks": int(self.tracker.book.confirmed.sum()),
            "scan_ms_p50": p50,  # None before the first scan
            "scan_ms_p99": p99,
        }

    # -- state ----------------------------------------------------------------------------
    def save(self, path: Path) -> None:
        """Snapshot the whole state to ``path`` atomically (temporary file, then rename)."""
        state = {"version": STATE_VERSION, "site": self.site.name, "live": self}

        def dump(tmp: str) -> None:
            with open(tmp, "wb") as f:
                pickle.dump(state, f)
                f.flush()
                os.fsync(f.fileno())

        write_atomic(path, dump)


def track_lines(columns: dict[str, np.ndarray]) -> str:
    """JSON lines of the track records of :meth:`SceneTracker.columns` (status named).

    The output's bulk (one line per track and scan), encoded by ``orjson``: numbers exact
    (shortest round trip), a non-finite one as null.
    """
    names = list(columns)
    values = [
        [STATUS_NAMES[v] for v in col.tolist()] if key == "status" else col.tolist()
        for key, col in columns.items()
    ]
    return b"".join(
        orjson.dumps({"type": "track", **dict(zip(names, row, strict=True))}) + b"\n"
        for row in zip(*values, strict=True)
    ).decode()


def load_state(path: Path, site: Site) -> LiveTracker:
    """Resume a :class:`LiveTracker` from a snapshot of :meth:`LiveTracker.save`.

    The snapshot is a pickle: load only files this service wrote. Raises ``ValueError`` if
    it is not one, or is of another site.
    """
    try:
        with open(path, "rb") as f:
            state = pickle.load(f)
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError) as exc:
        raise ValueError(f"{path}: not a state snapshot of 'adaptrack serve' ({exc})") from None
    if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
        raise ValueError(f"{path}: not a state snapshot of this version of 'adaptrack serve'")
    if state["site"] != site.name:
        raise ValueError(f"{path}: snapshot of site {state['site']!r}, not {site.name!r}")
    live: LiveTracker = state["live"]
    return live


__all__ = ["LiveTracker", "load_state", "track_lines"]
