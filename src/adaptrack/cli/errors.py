"""The command line's error reporting: one line on stderr, exit status 1."""

from __future__ import annotations

from pathlib import Path
from typing import NoReturn

import typer
from rich.console import Console

from .._files import check_writable

err_console = Console(stderr=True, soft_wrap=True)  # one line, whatever the width


def fail(message: str) -> NoReturn:
    """Print ``error: message`` on stderr and exit with status 1."""
    err_console.print(f"error: {message}", markup=False, highlight=False)
    raise typer.Exit(code=1)


def check_outputs(*paths: Path | None, folder: Path | None = None) -> None:
    """Fail before any work if an output cannot be written (a folder as a file, ...)."""
    try:
        for p in paths:
            if p is not None:
                check_writable(p)
        if folder is not None:
            check_writable(folder, folder=True)
    except ValueError as exc:
        fail(str(exc))
