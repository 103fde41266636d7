r"""A UDP socket drained by its own process, so that no datagram waits on the tracker.

In the service's process a receiving thread shares the interpreter lock with the tracker and
gets it too rarely: at a replay's full speed the kernel's receive buffer overflowed and
datagrams were lost. This process (``python -m adaptrack.service.udp_receiver HOST PORT``)
only receives: one thread takes every datagram into memory (no lock per datagram), the main
thread writes them to stdout as frames (``ADDRESS LENGTH\n`` then the datagram), where the
pipe's flow control makes the service take them at its pace. Its first line is ``PORT\n``
(the bound port); at the end of its stdin it drains the socket and writes ``END DROPS\n``
(datagrams the kernel dropped, -1 if unknown). SIGINT and SIGTERM are left to the service.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import sys
import threading
import time
from collections import deque

UDP_BUFFER_BYTES = 16 << 20  # requested receive buffer (the kernel may cap it)
POLL_S = 0.0005  # the writer looks for datagrams this often when it has none [s]


def udp_drops(sock: socket.socket) -> int | None:
    """Datagrams the kernel dropped on ``sock`` (receive buffer full): Linux only, else None."""
    try:
        inode = os.fstat(sock.fileno()).st_ino
        with open("/proc/net/udp") as f:
            for line in f.readlines()[1:]:
                cols = line.split()
                if int(cols[9]) == inode:
                    return int(cols[-1])
    except (OSError, ValueError, IndexError):
        return None
    return None


class _Receiver:
    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.queue: deque[tuple[bytes, tuple[str, int]]] = deque()  # appends are atomic
        self.stop = threading.Event()
        self.done = False

    def receive(self) -> None:
        """Take datagrams until stopped, then what the kernel still holds."""
        self.sock.settimeout(0.1)
        append, recvfrom = self.queue.append, self.sock.recvfrom
        while not self.stop.is_set():
            try:
                append(recvfrom(65535))
            except TimeoutError:
                continue
        self.sock.setblocking(False)
        with contextlib.suppress(OSError):
            while True:
                append(recvfrom(65535))
        self.done = True

    def write(self, out: object) -> None:
        """Write frames until the receiver is done and everything is out.

        Polls the queue (``POLL_S`` when empty): no lock or signal per datagram.
        """
        while True:
            finished = self.done
            items = [self.queue.popleft() for _ in range(len(self.queue))]
            if items:
                frames = b"".join(
                    f"{addr[0]}:{addr[1]} {len(data)}\n".encode() + data for data, addr in items
                )
                out.write(frames)  # type: ignore[attr-defined]
                out.flush()  # type: ignore[attr-defined]
            elif finished:
                return
            else:
                time.sleep(POLL_S)


def _stop_at_end_of_stdin(stop: threading.Event) -> None:
    sys.stdin.read()
    stop.set()


def main(host: str, port: int) -> None:
    """Receive on ``host:port`` until stdin ends (module docstring)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_BUFFER_BYTES)
    sock.bind((host, port))
    out = sys.stdout.buffer
    out.write(f"{sock.getsockname()[1]}\n".encode())
    out.flush()
    rx = _Receiver(sock)
    threading.Thread(target=_stop_at_end_of_stdin, args=(rx.stop,), daemon=True).start()
    thread = threading.Thread(target=rx.receive)
    thread.start()
    rx.write(out)
    thread.join()
    drops = udp_drops(sock)
    out.write(f"END {-1 if drops is None else drops}\n".encode())
    out.flush()
    sock.close()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
