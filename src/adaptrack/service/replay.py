"""Feed a detection file to the service in real or accelerated time.

A scene CSV in the service's column order is sent line by line as written (the service reads
the same numbers as offline ``track``); any other table (another column order,
``azimuth_deg``, Parquet) is validated like offline input and sent as JSON lines. Lines are
paced by ``time_s``: at ``rate`` times real time, or as fast as the transport takes them
(``rate=inf``). Over UDP, the lines of one timestamp share datagrams of up to
``DATAGRAM_BYTES``.
"""

from __future__ import annotations

import json
import socket
import sys
import time
from collections.abc import Iterator
from itertools import groupby
from pathlib import Path

from ..crossing.measurements_io import read_scene_detections
from ..crossing.site.model import Site
from .messages import CSV_HEADER
from .server import Endpoint

DATAGRAM_BYTES = 1400  # below a typical MTU


def detection_lines(path: Path, site: Site) -> Iterator[tuple[float, str]]:
    """(timestamp [s], line) of every detection of a file.

    A CSV in the service's layout in file order, any other table in time order (stably).
    """
    if path.suffix.lower() == ".csv":
        with open(path) as f:
            header = f.readline().strip().replace(" ", "")
            if header == CSV_HEADER:
                for line in f:
                    if line.strip():
                        yield float(line.split(",", 2)[1]), line.rstrip("\n") + "\n"
                return
    frame = read_scene_detections(path, site)  # in time order, stably
    for row in frame.itertuples(index=False):
        record = dict(
            zip(("radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps"), row, strict=True)
        )
        yield float(row.time_s), json.dumps(record) + "\n"


def replay(path: Path, site: Site, to: Endpoint | None, rate: float) -> int:
    """Send the file's detections to ``to`` (None: stdout) at ``rate``; return the count."""
    sock = None
    if to is not None:
        kind = socket.SOCK_DGRAM if to.scheme == "udp" else socket.SOCK_STREAM
        sock = socket.socket(socket.AF_INET, kind)
        sock.connect((to.host, to.port))
    start = time.monotonic()
    first: float | None = None
    sent = 0
    try:
        for stamp, group in groupby(detection_lines(path, site), key=lambda x: x[0]):
            lines = [line for _, line in group]
            first = stamp if first is None else first
            if rate != float("inf"):
                wait = start + (stamp - first) / rate - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            if sock is None:
                sys.stdout.write("".join(lines))
            elif to is not None and to.scheme == "udp":
                for datagram in _pack(lines):
                    sock.send(datagram)
            else:
                sock.sendall("".join(lines).encode())
            sent += len(lines)
    finally:
        if sock is not None:
            sock.close()
        sys.stdout.flush()
    return sent


def _pack(lines: list[str]) -> Iterator[bytes]:
    """Datagrams of whole lines, each up to ``DATAGRAM_BYTES`` (a longer line alone)."""
    chunk = b""
    for line in lines:
        data = line.encode()
        if chunk and len(chunk) + len(data) > DATAGRAM_BYTES:
            yield chunk
            chunk = b""
        chunk += data
    if chunk:
        yield chunk


__all__ = ["DATAGRAM_BYTES", "detection_lines", "replay"]
