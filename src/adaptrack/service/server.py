"""The running service: listeners, the tracking loop, output sinks, state snapshots, signals.

Threads: one per input (TCP server, stdin; a UDP socket is drained by a process of its own,
:mod:`.udp_receiver`, and read from its pipe) putting received lines on one queue
(unbounded: input is never dropped); the main thread (at a lower CPU priority: receiving
never waits on tracking) takes them in arrival order through :class:`~.engine.LiveTracker`
and writes the records to the output file (or stdout) and to every TCP subscriber (each
behind a bounded buffer: a subscriber that does not read loses *output*, counted, and never
stalls the tracker); the live page (:mod:`.web`) runs in its own thread. SIGTERM or SIGINT:
the listeners stop, what they received is processed, the reorder window is flushed, a final
snapshot and a ``stats`` record are written, exit status 0.

Every bound address is announced on stderr (``listening udp://127.0.0.1:PORT``), so port 0
(any free port) can be used.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import socketserver
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any
from urllib.parse import urlsplit

from . import udp_receiver
from .engine import LiveTracker, Record
from .messages import record_line

UDP_DRAIN_TIMEOUT_S = 120.0  # at exit, the UDP receivers' buffered datagrams are taken
SUBSCRIBER_BUFFER_BYTES = 4 << 20  # a subscriber's unsent output beyond this is dropped
FLUSH_PERIOD_S = 0.5  # the output file is flushed this often [s]
TRACKER_NICENESS = 5  # the tracking thread yields the CPU to the receiving ones


@dataclass(frozen=True)
class Endpoint:
    """Where to listen or publish: ``udp://HOST:PORT``, ``tcp://HOST:PORT`` or ``stdin``."""

    scheme: str
    host: str = ""
    port: int = 0

    @classmethod
    def parse(cls, text: str, schemes: tuple[str, ...] = ("udp", "tcp", "stdin")) -> Endpoint:
        """Parse an endpoint; raise ``ValueError`` naming what was expected."""
        if text in ("stdin", "-") and "stdin" in schemes:
            return cls("stdin")
        parts = urlsplit(text)
        try:
            port = parts.port
        except ValueError:
            port = None
        if parts.scheme not in schemes or not parts.hostname or port is None:
            raise ValueError(
                f"endpoint {text!r}: expected one of "
                + ", ".join(("stdin" if s == "stdin" else f"{s}://HOST:PORT") for s in schemes)
            )
        return cls(parts.scheme, parts.hostname, port)


def _yield_to_inputs() -> None:
    """Lower the calling (tracking) thread's CPU priority by ``TRACKER_NICENESS`` (Linux).

    Receiving is cheap and must never wait (a UDP socket's kernel buffer overflows within a
    fraction of a second); tracking may lag, its input queued. On a loaded machine the
    scheduler then serves the receivers first. Elsewhere (no per-thread priority) a no-op.
    """
    if sys.platform == "linux":
        tid = threading.get_native_id()
        with contextlib.suppress(OSError):
            os.setpriority(
                os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + TRACKER_NICENESS
            )


def announce(message: str) -> None:
    """Print a line on stderr (listening addresses, snapshots)."""
    print(message, file=sys.stderr, flush=True)


class Subscriber:
    """Output waiting for one TCP subscriber: bounded (bytes), overflow dropped and counted."""

    def __init__(self, limit_bytes: int) -> None:
        self.limit_bytes = limit_bytes
        self.chunks: deque[str] = deque()
        self.size = 0
        self.dropped_lines = 0
        self.cond = threading.Condition()
        self.closed = False

    def offer(self, text: str) -> None:
        """Queue ``text`` (whole lines) unless the buffer is full (then count its lines)."""
        with self.cond:
            if self.size + len(text) > self.limit_bytes:
                self.dropped_lines += text.count("\n")
                return
            self.chunks.append(text)
            self.size += len(text)
            self.cond.notify()

    def take(self, timeout_s: float) -> str:
        """Everything queued (waits up to ``timeout_s`` for something)."""
        with self.cond:
            if not self.chunks and not self.closed:
                self.cond.wait(timeout_s)
            text = "".join(self.chunks)
            self.chunks.clear()
            self.size = 0
            return text


class _Threaded(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True
    service: Service


class _InputHandler(socketserver.StreamRequestHandler):
    """One TCP input connection: each line is one detection."""

    def handle(self) -> None:
        svc = self.server.service  # type: ignore[attr-defined]
        source = "tcp {}:{}".format(*self.client_address[:2])
        for raw in self.rfile:
            svc.inbox.put(([raw.decode("utf-8", "replace")], source))
            if svc.stopping.is_set():
                break


class _PublishHandler(socketserver.BaseRequestHandler):
    """One TCP subscriber: receives the output records as JSON lines."""

    def handle(self) -> None:
        svc: Service = self.server.service  # type: ignore[attr-defined]
        sub = svc.subscribe()
        try:
            while not (svc.done.is_set() and not sub.chunks):
                text = sub.take(0.2)
                if text:
                    self.request.sendall(text.encode())
        except OSError:
            pass
        finally:
            svc.unsubscribe(sub)


@dataclass
class Service:
    """The live service around a :class:`LiveTracker` (module docstring).

    ``out``: the output stream; ``state``: snapshot file (written every ``state_every_s``
    [s] and at exit); ``stats_every_s``: a ``stats`` record this often [s].
    """

    live: LiveTracker
    out: IO[str]
    state: Path | None = None
    state_every_s: float = 2.0
    stats_every_s: float = 10.0
    subscriber_limit_bytes: int = SUBSCRIBER_BUFFER_BYTES
    # received lines with their source (a datagram's lines together); None: end of stdin
    inbox: queue.SimpleQueue[tuple[list[str], str] | None] = field(
        default_factory=queue.SimpleQueue
    )
    stopping: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)
    subscribers: list[Subscriber] = field(default_factory=list)
    dropped_output_lines: int = 0
    on_output: Callable[[Service], None] | None = None  # after each write (the live page)
    _threads: list[threading.Thread] = field(default_factory=list)
    _servers: list[socketserver.TCPServer] = field(default_factory=list)
    _udp: list[subprocess.Popen[bytes]] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _input_kinds: list[str] = field(default_factory=list)  # schemes listened to
    arrivals: deque[tuple[float, int]] = field(default_factory=lambda: deque(maxlen=64))
    kernel_dropped: int | None = None  # UDP datagrams the kernel dropped (known at exit)

    # -- inputs ---------------------------------------------------------------------------
    def listen(self, ep: Endpoint) -> None:
        """Start receiving detections from ``ep``."""
        self._input_kinds.append(ep.scheme)
        if ep.scheme == "udp":
            child = subprocess.Popen(
                [sys.executable, str(Path(udp_receiver.__file__)), ep.host, str(ep.port)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
            )
            assert child.stdout is not None
            first = child.stdout.readline()
            if not first.strip().isdigit():
                child.wait()
                raise OSError(f"cannot receive on udp://{ep.host}:{ep.port}")
            self._udp.append(child)
            name = f"udp {ep.host}:{int(first)}"
            self._start(self._receive_udp, child, name)
            announce(f"listening udp://{ep.host}:{int(first)}")
        elif ep.scheme == "tcp":
            srv = self._tcp_server(ep, _InputHandler)
            announce("listening tcp://{}:{}".format(*srv.server_address[:2]))
        else:
            self._start(self._receive_stdin, join=False)  # a blocked read cannot be stopped

    def publish(self, ep: Endpoint) -> None:
        """Serve the output records to every TCP client connecting to ``ep``."""
        srv = self._tcp_server(ep, _PublishHandler, join=False)
        announce("publishing tcp://{}:{}".format(*srv.server_address[:2]))

    def _tcp_server(self, ep: Endpoint, handler: type, join: bool = True) -> _Threaded:
        srv = _Threaded((ep.host, ep.port), handler)
        srv.service = self
        self._servers.append(srv)
        self._start(srv.serve_forever, 0.1, join=join)
        return srv

    def _start(self, target: Callable[..., Any], *args: Any, join: bool = True) -> None:
        """Run ``target(*args)`` in a daemon thread (joined at exit if ``join``: an input)."""
        thread = threading.Thread(target=target, args=args, daemon=True)
        thread.start()
        if join:
            self._threads.append(thread)

    def _receive_udp(self, child: subprocess.Popen[bytes], name: str) -> None:
        """Put the datagrams of a receiving process (:mod:`.udp_receiver`) on the inbox."""
        assert child.stdout is not None
        with child.stdout as frames:
            for header in frames:
                address, _, size = header.decode().partition(" ")
                if address == "END":
                    self.kernel_dropped = (self.kernel_dropped or 0) + max(int(size), 0)
                    break
                text = frames.read(int(size)).decode("utf-8", "replace")
                self.inbox.put((text.splitlines() or [""], f"{name} from {address}"))
        child.wait()

    def _receive_stdin(self) -> None:
        for line in sys.stdin:
            self.inbox.put(([line], "stdin"))
            if self.stopping.is_set():
                return
        self.inbox.put(None)  # end of stdin

    # -- subscribers ----------------------------------------------------------------------
    def subscribe(self) -> Subscriber:
        """Register a new output subscriber."""
        sub = Subscriber(self.subscriber_limit_bytes)
        with self._lock:
            self.subscribers.append(sub)
        return sub

    def unsubscribe(self, sub: Subscriber) -> None:
        """Forget a subscriber (its dropped output stays counted)."""
        with self._lock:
            if sub in self.subscribers:
                self.subscribers.remove(sub)
                self.dropped_output_lines += sub.dropped_lines

    # -- the loop -------------------------------------------------------------------------
    def run(self) -> None:
        """Process input until SIGTERM / SIGINT (or the end of stdin if it is the only input)."""
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: self.stopping.set())
        _yield_to_inputs()
        only_stdin = set(self._input_kinds) == {"stdin"}
        next_state = next_stats = next_flush = time.monotonic()
        last_input = time.monotonic()
        while True:
            try:
                item = self.inbox.get(timeout=0.05)
                idle = False
            except queue.Empty:
                item, idle = None, True
            now = time.monotonic()
            if item is not None:
                last_input = now
                self._feed(*item)
                self.arrivals.append((now, self.live.received))
            elif not idle and only_stdin:
                break  # the end of stdin, the only input
            elif self.live.buffer.pending and now - last_input >= self.live.buffer.window_s:
                self._emit(self.live.flush())  # the input fell silent: release the window
            if self.stopping.is_set() and item is None:
                break
            if now >= next_flush:
                self.out.flush()  # readers of the file see the output within a period
                next_flush = now + FLUSH_PERIOD_S
            if self.state is not None and now >= next_state:
                self.out.flush()  # the output up to the snapshot is on disk before it
                self.live.save(self.state)
                next_state = now + self.state_every_s
            if now >= next_stats:
                self._emit([record_line(self.stats())])
                next_stats = now + self.stats_every_s
        self._finish()

    def _finish(self) -> None:
        self.stopping.set()
        for srv in self._servers:
            if srv.RequestHandlerClass is _InputHandler:
                srv.shutdown()
        for child in self._udp:
            assert child.stdin is not None
            child.stdin.close()  # the receiver drains its socket and ends its frames
        for thread in self._threads:
            thread.join(timeout=UDP_DRAIN_TIMEOUT_S if self._udp else 0.5)
        while True:  # what the inputs received before they stopped
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                self._feed(*item)
        self._emit(self.live.flush())
        self._emit([record_line(self.stats())])
        self.out.flush()
        if self.state is not None:
            self.live.save(self.state)
        self.done.set()
        for srv in self._servers:
            srv.shutdown()
            srv.server_close()

    def _feed(self, lines: list[str], source: str) -> None:
        """Give received lines to the tracker; write what they make."""
        out = []
        for line in lines:
            out += self.live.feed(line, source)
        self._emit(out)

    def _emit(self, lines: list[str]) -> None:
        if not lines:
            return
        text = "".join(lines)
        self.out.write(text)
        with self._lock:
            for sub in self.subscribers:
                sub.offer(text)
        if self.on_output is not None:
            self.on_output(self)

    def stats(self) -> Record:
        """Return the tracker's counters plus output drops, subscribers and kernel drops."""
        with self._lock:
            dropped = self.dropped_output_lines + sum(s.dropped_lines for s in self.subscribers)
            n_sub = len(self.subscribers)
        return {
            **self.live.stats(),
            "output_dropped_lines": dropped,
            "subscribers": n_sub,
            "udp_kernel_dropped": self.kernel_dropped,  # at exit (None: no UDP input)
            "input_rate_per_s": self.input_rate(),
        }

    def input_rate(self) -> float:
        """Return the detections received per second over the recent arrivals."""
        if len(self.arrivals) < 2:
            return 0.0
        (t0, n0), (t1, n1) = self.arrivals[0], self.arrivals[-1]
        return (n1 - n0) / (t1 - t0) if t1 > t0 else 0.0


__all__ = ["Endpoint", "Service", "Subscriber", "announce"]
