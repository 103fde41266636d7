"""Options and helpers shared by the commands: scale-out (Dask) and JSON outputs."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import typer

from ..io.tables import (
    write_text_atomic,
)
from ..parallel import TaskPool, WorkerLost, task_pool
from .errors import fail as _fail

WORKERS = typer.Option(
    None,
    "--workers",
    min=1,
    help="Local worker processes (a Dask LocalCluster; default one per CPU core, 1: in-process).",
)
SCHEDULER = typer.Option(
    None, "--scheduler", help="Address of an existing Dask scheduler, e.g. tcp://host:8786."
)


@contextmanager
def worker_pool(workers: int | None, scheduler: str | None) -> Iterator[TaskPool]:
    """Task pool of the --workers/--scheduler options (errors reported, not raised)."""
    if scheduler is not None and workers is not None:
        raise typer.BadParameter("give --workers or --scheduler, not both")
    n = workers if workers is not None else (1 if scheduler else os.cpu_count() or 1)
    stack = ExitStack()
    try:
        pool = stack.enter_context(task_pool(n, scheduler))
    except OSError as exc:
        _fail(f"cannot start the task pool ({exc})")
    with stack:
        try:
            yield pool
        except WorkerLost as exc:
            _fail(str(exc))


def number_pair(text: str, option: str) -> tuple[float, float]:
    """Parse an option's ``A,B`` into two numbers, or fail naming the option."""
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        _fail(f"{option} takes two numbers A,B; got {text!r}")
    return a, b


def write_json(path: Path, payload: object) -> None:
    """Write JSON atomically."""
    write_text_atomic(path, json.dumps(payload, indent=2))
