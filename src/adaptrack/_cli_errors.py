"""The command line's error reporting: one line on stderr, exit status 1."""

from __future__ import annotations

from typing import NoReturn

import typer
from rich.console import Console

err_console = Console(stderr=True, soft_wrap=True)  # one line, whatever the width


def fail(message: str) -> NoReturn:
    """Print ``error: message`` on stderr and exit with status 1."""
    err_console.print(f"error: {message}", markup=False, highlight=False)
    raise typer.Exit(code=1)
