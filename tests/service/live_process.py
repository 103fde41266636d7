"""Run ``adaptrack serve`` as a separate process on 127.0.0.1 and talk to it over sockets."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

START_TIMEOUT_S = 120.0  # the first start may compile the tracker's kernels


class LiveProcess:
    """``adaptrack serve ARGS`` with every input, publisher and page on a free port."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "adaptrack", "serve", *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.stderr: list[str] = []
        self._reader = threading.Thread(target=self._read_stderr, daemon=True)
        self._reader.start()

    def _read_stderr(self) -> None:
        assert self.proc.stderr is not None
        with self.proc.stderr:
            for line in self.proc.stderr:
                self.stderr.append(line)

    def wait_for(self, announcement: str) -> tuple[str, int]:
        """Host and port of the first ``announcement`` (e.g. 'listening udp') on stderr."""
        verb, scheme = announcement.split()
        pattern = re.compile(rf"^{verb} {scheme}://([\d.]+):(\d+)")
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            for line in list(self.stderr):
                m = pattern.match(line)
                if m:
                    return m.group(1), int(m.group(2))
            if self.proc.poll() is not None:
                raise AssertionError(f"serve exited early: {''.join(self.stderr)}")
            time.sleep(0.05)
        raise AssertionError(f"no '{announcement}' within {START_TIMEOUT_S} s: {self.stderr}")

    def terminate(self, timeout_s: float = 120.0) -> int:
        """SIGTERM; return the exit status."""
        self.proc.send_signal(signal.SIGTERM)
        status = self.proc.wait(timeout_s)
        self._reader.join(10)
        return status

    def kill(self) -> None:
        """SIGKILL (no chance to flush)."""
        self.proc.kill()
        self.proc.wait(30)
        self._reader.join(10)


def send_udp(address: tuple[str, int], payloads: list[bytes]) -> None:
    """Send each payload as one datagram."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for p in payloads:
            s.sendto(p, address)


def replay(path: Path, to: str, rate: str = "max") -> None:
    """``adaptrack replay PATH --to TO --rate RATE`` (waits for it)."""
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", "replay", str(path), "--to", to, "--rate", rate],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr


def read_records(path: Path) -> list[dict]:
    """The JSON-line records of an output file."""
    return [json.loads(line) for line in path.read_text().splitlines()]


def wait_until(condition, timeout_s: float = 60.0, what: str = "condition") -> None:
    """Poll ``condition()`` until true."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)
