"""The live page: site map, current tracks, event log and counters, pushed over a WebSocket.

A Starlette app (served by uvicorn in its own thread): ``/`` the page (no external
resources), ``/site.json`` the site geometry (roads, barriers, stop lines, radars and their
fields of view, local metres), ``/ws`` a WebSocket pushing the current picture five times a
second. A track's class is the site's class nearest in length to the body length its
reflections spread over (``sqrt(12)`` times the learnt spread: reflections uniform along the
body), shown with that length: an estimate, not a classification the radar made. A static
object (stopped since it was first seen: a post, a rail) is a "fixed object".
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from importlib.resources import files
from typing import Any

import numpy as np
import uvicorn
from starlette.applications import Starlette
from starlette.responses import HTMLResponse, JSONResponse
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from ..crossing.site.model import Site
from .engine import track_lines
from .server import Service

PUSH_PERIOD_S = 0.2
GEOMETRY_STEP_M = 2.0


def site_geometry(site: Site) -> dict[str, Any]:
    """Roads (centreline points, lane width), barrier and stop-line marks, radars [m, rad]."""
    roads = []
    for name, road in site.roads.items():
        s = np.arange(0.0, min(road.length_m, site.zone_m + site.run_in_m), GEOMETRY_STEP_M)
        xy, _ = road.centreline(s)
        marks = {}
        for key, at in (("barrier", site.barrier_m), ("stop_line", site.stop_line_m)):
            p, heading = road.centreline(at)
            marks[key] = [float(p[0]), float(p[1]), float(heading)]
        roads.append({"name": name, "lane_width_m": road.lane_width_m,
                      "points": np.round(xy, 2).tolist(), **marks})  # fmt: skip
    radars = [
        {
            "name": r.name,
            "east_m": r.position_m[0],
            "north_m": r.position_m[1],
            "boresight_rad": r.boresight_rad,
            "fields": [[f.max_range_m, f.half_angle_rad] for f in r.fields],
        }
        for r in site.radars
    ]
    return {"name": site.name, "zone_m": site.zone_m, "roads": roads, "radars": radars}


class LiveView:
    """The current picture as one JSON text, refreshed at most every ``PUSH_PERIOD_S``."""

    def __init__(self, site: Site) -> None:
        self.classes = sorted((c.length_m, name) for name, c in site.classes.items())
        self.text = json.dumps({"tracks": [], "events": [], "stats": {}})
        self._next = 0.0

    def update(self, svc: Service) -> None:
        """Refresh from the service (called by its loop; cheap when not due)."""
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + PUSH_PERIOD_S
        tr = svc.live.tracker
        tracks = [json.loads(line) for line in track_lines(tr.columns(tr.last_scan_s)).splitlines()]
        lengths = np.sqrt(12.0) * tr.tracks.spread[tr.book.confirmed]
        for rec, length in zip(tracks, lengths.tolist(), strict=True):
            rec["length_m"] = round(length, 1)
            nearest = min(self.classes, key=lambda c: abs(c[0] - length))[1]
            rec["class"] = "fixed object" if rec["status"] == "static" else nearest
        events = [{k: v for k, v in e.items() if v == v} for e in tr.events[-30:]]
        self.text = json.dumps(
            {
                "time_s": tr.last_scan_s if np.isfinite(tr.last_scan_s) else None,
                "tracks": tracks,
                "events": events[::-1],
                "stats": svc.stats(),
            },
            default=float,
            allow_nan=False,  # the page's JSON.parse takes no NaN (None above)
        )


def live_app(site: Site, view: LiveView) -> Starlette:
    """Return the page's ASGI app (module docstring)."""
    page = files("adaptrack.service").joinpath("live.html").read_text()
    geometry = site_geometry(site)

    async def index(_: Any) -> HTMLResponse:
        return HTMLResponse(page)

    async def site_json(_: Any) -> JSONResponse:
        return JSONResponse(geometry)

    async def stream(ws: WebSocket) -> None:
        await ws.accept()
        try:
            while True:
                await ws.send_text(view.text)
                await asyncio.sleep(PUSH_PERIOD_S)
        except (WebSocketDisconnect, RuntimeError):
            return

    return Starlette(routes=[Route("/", index), Route("/site.json", site_json),
                             WebSocketRoute("/ws", stream)])  # fmt: skip


class PageServer:
    """uvicorn serving :func:`live_app` on ``host:port`` in a daemon thread."""

    def __init__(self, app: Starlette, host: str, port: int) -> None:
        config = uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="off")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def start(self, timeout_s: float = 10.0) -> tuple[str, int]:
        """Start serving; return the bound address (port 0: the one chosen)."""
        self.thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise OSError("the live page's server did not start")
            time.sleep(0.02)
        sock = self.server.servers[0].sockets[0]
        host, port = sock.getsockname()[:2]
        return str(host), int(port)

    def stop(self) -> None:
        """Stop serving."""
        self.server.should_exit = True
        self.thread.join(timeout=5.0)


__all__ = ["LiveView", "PageServer", "live_app", "site_geometry"]
