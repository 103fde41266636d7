"""Atomic file writes: a file is either complete or absent, whatever stops the writer."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def write_atomic(path: str | Path, write: Callable[[str], object]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path``.

    Nothing half-written is ever at ``path``, and the temporary file is removed whatever
    stops the write (an error, Ctrl-C).
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + p.name + ".", suffix=".tmp", dir=p.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def check_writable(path: str | Path, *, folder: bool = False) -> None:
    """Raise ValueError if ``path`` cannot receive an output (checked before any work).

    A file output must not be an existing folder (a folder output not an existing file), and
    its nearest existing parent must be a writable folder (missing ones are created when
    written). Nothing is created here.
    """
    p = Path(path)
    if folder and p.exists() and not p.is_dir():
        raise ValueError(f"{p} is a file; give a folder for the outputs")
    if not folder and p.is_dir():
        raise ValueError(f"{p} is a folder; give a file name")
    parent = (p if folder else p.parent).absolute()
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{p}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{p}: the folder {parent} is not writable")
