"""Bad command lines of ``serve`` and ``replay``: one-line errors, exit status 1."""

import socket
import subprocess
import sys

import pytest


def adaptrack(*args):
    return subprocess.run(
        [sys.executable, "-m", "adaptrack", *args], capture_output=True, text=True, timeout=120
    )


SERVE = ("serve", "--site", "lx_default")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((*SERVE, "--listen", "http://x:1"), "expected one of udp://HOST:PORT, tcp://HOST:PORT"),
        ((*SERVE, "--listen", "udp://127.0.0.1"), "endpoint 'udp://127.0.0.1'"),
        ((*SERVE, "--listen", "stdin", "--publish", "udp://127.0.0.1:1"), "tcp://HOST:PORT"),
        (("serve", "--listen", "stdin", "--site", "nowhere"), "nowhere"),
        ((*SERVE, "--listen", "stdin", "--config", "missing.toml"), "missing.toml"),
        (("serve", "--listen", "stdin"), "--site is required"),
        (("replay", "det.csv", "--rate", "0"), "--rate must be a positive number or 'max'"),
        (("replay", "missing.csv", "--rate", "max"), "missing.csv"),
    ],
)
def test_bad_arguments_are_one_line_errors(tmp_path, args, message):
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", *args], capture_output=True, text=True,
        timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    assert message in proc.stderr and proc.stderr.startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_port_in_use_is_a_one_line_error():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        proc = adaptrack("serve", "--site", "lx_default", "--listen", f"tcp://127.0.0.1:{port}")
    assert proc.returncode == 1 and "cannot listen" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_stdin_input_ends_with_its_stats():
    lines = "radar_A,1.0,30,0.1,-5\nradar_A,1.05,29.7,0.1,-5\ngarbage\n"
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", "serve", "--site", "lx_default", "--listen", "stdin"],
        input=lines, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    last = proc.stdout.splitlines()[-1]
    assert '"type":"stats"' in last and '"received":3' in last and '"rejected":1' in last
