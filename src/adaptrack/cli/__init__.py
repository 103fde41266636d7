"""Command-line interface (typer + rich). It parses, calls the library and writes files."""

from __future__ import annotations

import os
import sys

import typer
from rich.console import Console

from .. import __version__
from . import crossing, evaluate, fit, score, serve
from .errors import err_console
from .site import site_app

app = typer.Typer(
    help="adaptrack: adaptive motion estimation.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)
app.command("serve")(serve.serve)
app.command("replay")(serve.replay)
app.add_typer(site_app, name="site")
app.command("fit")(fit.fit)
app.command("filter")(fit.filter_log)
app.command("score")(score.score)
for command in (crossing.demo, crossing.report, crossing.simulate, crossing.tune, crossing.track):
    app.command()(command)
app.command()(evaluate.evaluate)
app.command()(evaluate.smooth)


def _print_version(value: bool) -> None:
    if value:
        Console().print(f"adaptrack {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="Print the version."
    ),
) -> None:
    """Adaptive motion estimation from noisy measurements."""


__all__ = ["app"]


def main(argv: list[str] | None = None) -> None:
    """Run the command line (the ``adaptrack`` script); every failure is one ``error:`` line.

    Exit status: 0 done, 1 bad input or a failed run (the command's message), 2 a usage error
    (unknown option, bad value, missing argument), 3 an internal error (a bug: its traceback
    with ``ADAPTRACK_DEBUG=1``), 130 interrupted (no output file is left half-written); the
    demo's verdict: 4 the site does not comply, 5 undecided (its outputs are written).
    """
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        code = app(args=args or ["--help"], prog_name="adaptrack", standalone_mode=False)
    except typer.TyperException as exc:  # usage errors (status 2) carry their command
        ctx = getattr(exc, "ctx", None)
        see = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
        err_console.print(f"error: {exc.format_message()}{see}", markup=False, highlight=False)
        code = exc.exit_code
    except (typer.Abort, KeyboardInterrupt):
        code = 130
    except Exception as exc:
        if os.environ.get("ADAPTRACK_DEBUG"):
            raise
        err_console.print(
            f"error: internal error ({type(exc).__name__}: {exc}); rerun with ADAPTRACK_DEBUG=1 "
            "for the traceback and please report it",
            markup=False,
            highlight=False,
        )
        code = 3
    if code == 130:  # typer turns Ctrl-C into a silent exit status 130
        err_console.print("error: interrupted", markup=False, highlight=False)
    raise SystemExit(code if isinstance(code, int) else 0)
