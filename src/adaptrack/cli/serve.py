"""``adaptrack serve`` and ``adaptrack replay`` (registered by :mod:`adaptrack.cli`).

The heavy imports (the tracker, uvicorn) happen when a command runs, not when the CLI starts.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from .._files import check_writable
from .errors import err_console as _err
from .errors import fail as _fail


def serve(
    site: str | None = typer.Option(
        None,
        "--site",
        help="Built-in site name or a .toml (default: the site a tuned --config records).",
    ),
    listen: list[str] = typer.Option(
        ..., "--listen", help="Input: udp://HOST:PORT, tcp://HOST:PORT or stdin (repeatable)."
    ),
    out: str = typer.Option("-", "--out", help="Output JSON lines: a file, or - for stdout."),
    publish: list[str] = typer.Option(
        [], "--publish", help="Serve the output to TCP subscribers at tcp://HOST:PORT."
    ),
    http: str | None = typer.Option(
        None, "--http", help="Serve the live page at HOST:PORT (e.g. 127.0.0.1:8080)."
    ),
    config: Path | None = typer.Option(
        None, "--config", help="TOML with a [scene_tracker] table (tracker settings)."
    ),
    warnings: Path | None = typer.Option(
        None, "--warnings", help="The crossing's warning intervals (start_s, end_s) table."
    ),
    window: float = typer.Option(
        0.2, "--window", min=0.0, help="Reorder window [s]: how late a detection may arrive."
    ),
    state: Path | None = typer.Option(
        None, "--state", help="Snapshot file: resumed from if it exists, written every few s."
    ),
    state_every: float = typer.Option(2.0, "--state-every", min=0.1, help="Snapshot period [s]."),
    stats_every: float = typer.Option(
        10.0, "--stats-every", min=0.1, help="Period of the stats record [s]."
    ),
    subscriber_buffer: int = typer.Option(
        4096,
        "--subscriber-buffer",
        min=1,
        help="Unsent output per subscriber [kB] beyond which its output is dropped (counted).",
    ),
) -> None:
    """Track live detections: tracks, events, rejections and stats as JSON lines.

    Reads one detection per line (JSON or CSV, see the guide) from every --listen input,
    merges the radars by time within --window, runs the scene tracker and writes
    ``{"type": "track" | "event" | "rejection" | "stats", ...}`` records to --out and to every
    --publish subscriber. SIGTERM or SIGINT: flush, final snapshot and stats, exit 0.
    """
    from ..crossing.measurements_io import read_warnings
    from ..crossing.scene.tracker import load_scene_config
    from ..crossing.studies.selection import site_for
    from ..service.engine import LiveTracker, load_state
    from ..service.server import Endpoint, Service, announce

    try:
        if out != "-":
            check_writable(out)
        st = site_for(site, config)
        inputs = [Endpoint.parse(x) for x in listen]
        outputs = [Endpoint.parse(x, ("tcp",)) for x in publish]
        page = Endpoint.parse(f"http://{http}", ("http",)) if http else None
        cfg = load_scene_config(config) if config is not None else None
        intervals = read_warnings(warnings) if warnings is not None else None
        resume = state is not None and state.exists()
        live = (
            load_state(state, st) if resume and state is not None
            else LiveTracker(st, cfg, window, intervals)
        )  # fmt: skip
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    if resume:
        announce(f"resumed from {state}: {live.scans} scans, next track id "
                 f"{live.tracker.book.next_id}")  # fmt: skip
    stream = sys.stdout if out == "-" else open(out, "a" if resume else "w")
    svc = Service(live, stream, state, state_every, stats_every, subscriber_buffer << 10)
    pages = None
    try:
        for ep in inputs:
            svc.listen(ep)
        for ep in outputs:
            svc.publish(ep)
        if page is not None:
            from ..service.web import LiveView, PageServer, live_app

            view = LiveView(st)
            svc.on_output = view.update
            pages = PageServer(live_app(st, view), page.host, page.port)
            announce("serving http://{}:{}/ (the live page)".format(*pages.start()))
    except OSError as exc:
        _fail(f"cannot listen: {exc}")
    try:
        svc.run()
    finally:
        if pages is not None:
            pages.stop()
        if stream is not sys.stdout:
            stream.close()


def replay(
    detections: Path = typer.Argument(..., help="Detections table (CSV or Parquet)."),
    to: str = typer.Option("-", "--to", help="udp://HOST:PORT, tcp://HOST:PORT, or - for stdout."),
    rate: str = typer.Option("1", "--rate", help="Times real time (e.g. 1, 10), or max."),
    site: str = typer.Option("lx_default", "--site", help="Built-in site name or a .toml."),
) -> None:
    """Send a detection file to a running service in real or accelerated time."""
    from ..crossing.site.model import load_site
    from ..service.replay import replay as send
    from ..service.server import Endpoint

    try:
        speed = float("inf") if rate == "max" else float(rate)
        if not speed > 0:
            raise ValueError
    except ValueError:
        _fail(f"--rate must be a positive number or 'max'; got {rate!r}")
    try:
        st = load_site(site)
        target = None if to == "-" else Endpoint.parse(to, ("udp", "tcp"))
        n = send(detections, st, target, speed)
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    _err.print(f"sent {n} detections")


__all__ = ["replay", "serve"]
