"""Progress of long commands: a rich bar with an ETA on a terminal, lines in a log or a pipe.

``with progress(console, "tuning", total=40) as bar: bar.advance("cv tuned")``. On a
terminal the bar is transient (gone when done); elsewhere (a CI log, ``| tee``, a file) a
line ``progress: tuning 12/40 (30 %), 1m05s elapsed, ETA 2m31s: cv tuned`` goes to stderr
at most every ``ADAPTRACK_PROGRESS_EVERY_S`` seconds (default 10), and one when done.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from ._backend import kernels_cached

LINE_PREFIX = "progress: "
FIRST_RUN_NOTE = (
    "note: first run on this machine: numba compiles the kernels now (once; about "
    "{duration} on 2 cores); later runs reuse them and start in seconds"
)


def announce_compilation(
    duration: str, kernel: str = "radar_kernel.detections_kernel", package: str = "crossing"
) -> None:
    """Say so on stderr when this run will compile ``kernel`` (not in numba's cache)."""
    if not kernels_cached(kernel, package):
        print(FIRST_RUN_NOTE.format(duration=duration), file=sys.stderr, flush=True)


def _clock(seconds: float) -> str:
    """``1h02m`` / ``3m05s`` / ``7s``."""
    s = round(seconds)
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Bar:
    """One task's progress: ``advance``, ``set`` (done of total) and ``describe``."""

    def __init__(self, what: str, total: float | None, rich: Progress | None) -> None:
        self.what, self.total, self.done, self.note = what, total, 0.0, ""
        self._rich = rich
        self._task = rich.add_task(what, total=total) if rich is not None else None
        self._start = self._last = time.monotonic()
        self._every = float(os.environ.get("ADAPTRACK_PROGRESS_EVERY_S", "10"))

    def advance(self, note: str = "", by: float = 1.0) -> None:
        """Count ``by`` more units done (``note``: what was just done)."""
        self._change(self.done + by, self.total, note)

    def set(self, done: float, total: float | None = None) -> None:
        """Set the units done (and the total, if it is known only now)."""
        self._change(done, self.total if total is None else total, self.note)

    def describe(self, note: str) -> None:
        """Say what is being done now."""
        self._change(self.done, self.total, note)

    def _change(self, done: float, total: float | None, note: str) -> None:
        self.done, self.total, self.note = done, total, note
        if self._rich is not None and self._task is not None:
            label = f"{self.what}: {note}" if note else self.what
            self._rich.update(self._task, completed=done, total=total, description=label)
            return
        now = time.monotonic()
        if now - self._last >= self._every:
            self._last = now
            self._line(now)

    def _line(self, now: float) -> None:
        elapsed = now - self._start
        text = f"{LINE_PREFIX}{self.what}"
        if self.total:
            frac = min(self.done / self.total, 1.0)
            text += f" {self.done:g}/{self.total:g} ({100 * frac:.0f} %)"
            text += f", {_clock(elapsed)} elapsed"
            if 0 < frac < 1:
                text += f", ETA {_clock(elapsed * (1 - frac) / frac)}"
        else:  # the total not known: the count so far
            text += f" {self.done:g} done, {_clock(elapsed)} elapsed"
        if self.note:
            text += f": {self.note}"
        print(text, file=sys.stderr, flush=True)

    def finish(self) -> None:
        """Print the closing line (lines only, and only if a line was printed before)."""
        if self._rich is None and self._last != self._start:
            self._line(time.monotonic())


@contextmanager
def progress(console: Console, what: str, total: float | None = None) -> Iterator[Bar]:
    """Yield a progress :class:`Bar` for ``what`` (``total`` units; None: unknown yet)."""
    if console.is_terminal:
        columns = (
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
        )  # fmt: skip
        with Progress(*columns, console=console, transient=True) as rich:
            yield Bar(what, total, rich)
        return
    bar = Bar(what, total, None)
    yield bar
    bar.finish()
