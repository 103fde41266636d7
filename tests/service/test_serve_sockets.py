"""``adaptrack serve`` over real sockets on 127.0.0.1: no data loss, faults, restart."""

import json
import os
import socket
import subprocess
import sys
import threading

import pandas as pd
import pytest

from adaptrack.crossing.measurements_io import read_warnings
from adaptrack.service.engine import LiveTracker, load_state

from .live_process import read_records, replay, send_udp, wait_until
from .records import live_records, tracks_of


@pytest.fixture(scope="module")
def offline_tracks(scene_files, tmp_path_factory):
    """Offline ``adaptrack track`` of the scene, as Parquet (exact floats)."""
    out = tmp_path_factory.mktemp("offline") / "tracks.parquet"
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", "track", str(scene_files.detections), "--site",
         "lx_default", "--out", str(out), "--warnings", str(scene_files.warnings)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return pd.read_parquet(out)


def test_replay_at_max_rate_over_udp_loses_nothing_and_equals_offline(
    serve, scene_files, offline_tracks, tmp_path
):
    out = tmp_path / "live.jsonl"
    svc = serve("--site", "lx_default", "--listen", "udp://127.0.0.1:0", "--out", str(out),
                      "--warnings", str(scene_files.warnings))  # fmt: skip
    host, port = svc.wait_for("listening udp")
    replay(scene_files.detections, f"udp://{host}:{port}", "max")
    assert svc.terminate() == 0, "".join(svc.stderr)
    records = read_records(out)
    stats = records[-1]
    assert stats["type"] == "stats"
    n = len(scene_files.lines)
    assert stats["received"] == n and stats["used"] + stats["rejected"] == n
    assert stats["pending"] == 0 and stats["udp_kernel_dropped"] == 0
    assert set(stats["rejected_by_reason"]) <= {"outside_view"}
    pd.testing.assert_frame_equal(tracks_of(records), offline_tracks, check_exact=True)


def test_faults_become_rejections_and_the_service_runs_on(serve, scene_files, tmp_path):
    """Garbage datagrams, an unknown radar, NaN, a clock jumping back, a TCP input, a radar
    that stops sending, a subscriber that never reads."""
    out = tmp_path / "live.jsonl"
    svc = serve(
        "--site", "lx_default", "--listen", "udp://127.0.0.1:0", "--listen", "tcp://127.0.0.1:0",
        "--out", str(out),
        "--publish", "tcp://127.0.0.1:0", "--subscriber-buffer", "64",
    )  # fmt: skip
    udp = svc.wait_for("listening udp")
    tcp = svc.wait_for("listening tcp")
    pub = svc.wait_for("publishing tcp")
    sleeper = socket.create_connection(pub)  # subscribes, never reads
    sleeper.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    watcher = socket.create_connection(pub)  # reads
    lines = scene_files.lines
    half = len(lines) // 2
    t_half = float(lines[half].split(",")[1])
    junk = [b"\xff\xfe\x00 not a detection", b"radar_Q,1.0,20,0.1,0", b"radar_A,1.0,nan,0.1,0",
            f"radar_A,{t_half - 5.0},20,0.1,0".encode()]  # fmt: skip
    send_udp(udp, [(line + "\n").encode() for line in lines[:half]])
    wait_until(lambda: out.exists() and '"type":"track"' in out.read_text(), what="tracks")
    send_udp(udp, junk)
    # the rest over TCP, and radar_B falls silent
    rest = [line for line in lines[half:] if line.startswith("radar_A")]
    with socket.create_connection(tcp) as s:
        s.sendall("".join(line + "\n" for line in rest).encode())
    last_sent = float(rest[-1].split(",")[1])
    seen = []
    watcher.settimeout(1.0)
    buf = b""

    def caught_up():
        nonlocal buf
        try:
            buf += watcher.recv(1 << 20)
        except TimeoutError:
            pass
        *done, buf = buf.split(b"\n")
        seen.extend(json.loads(x) for x in done)
        times = [r["time_s"] for r in seen if r["type"] == "track"]
        return bool(times) and max(times) >= last_sent - 0.5  # within the reorder window

    wait_until(caught_up, timeout_s=120, what="radar_A's tracks to go on without radar_B")
    assert svc.proc.poll() is None  # still running
    assert svc.terminate() == 0, "".join(svc.stderr)
    records = read_records(out)
    stats = records[-1]
    assert stats["type"] == "stats"
    received = half + len(junk) + len(rest)
    assert stats["received"] == received == stats["used"] + stats["rejected"]
    reasons = stats["rejected_by_reason"]
    assert reasons["malformed"] == 1 and reasons["unknown_radar"] == 1
    assert reasons["not_finite"] == 1 and reasons["late"] == 1
    rejections = [r for r in records if r["type"] == "rejection" and r["reason"] != "outside_view"]
    assert len(rejections) == 4 and all(r["source"].startswith("udp") for r in rejections)
    assert stats["output_dropped_lines"] > 0  # the subscriber that never reads lost output...
    assert len(tracks_of(records)) > 1000  # ...while the file got every scan's tracks
    sleeper.close()
    watcher.close()


def test_kill_9_and_restart_from_the_state_continues_the_tracks(
    serve, scene_files, offline_tracks, tmp_path
):
    out, state = tmp_path / "live.jsonl", tmp_path / "state.pkl"
    args = ("--site", "lx_default", "--listen", "udp://127.0.0.1:0", "--out", str(out),
            "--state", str(state),
            "--state-every", "0.2", "--warnings", str(scene_files.warnings))  # fmt: skip
    lines = scene_files.lines
    first = serve(*args)
    udp = first.wait_for("listening udp")
    cut = int(0.6 * len(lines))
    send_udp(udp, [(line + "\n").encode() for line in lines[:cut]])

    def snapshot_has_everything():
        """A snapshot after the input fell silent (> the reorder window) and was released."""
        try:
            live = load_state(state, scene_files.site)
        except (ValueError, OSError):
            return False
        return live.received == cut and live.buffer.pending == 0

    wait_until(snapshot_has_everything, timeout_s=120, what="a snapshot after the input")
    first.kill()
    before = read_records(out)
    second = serve(*args)
    udp = second.wait_for("listening udp")
    assert any("resumed from" in line for line in second.stderr)
    send_udp(udp, [(line + "\n").encode() for line in lines[cut:]])
    assert second.terminate() == 0, "".join(second.stderr)
    records = read_records(out)
    after = records[len(before) :]
    assert after[-1]["type"] == "stats" and after[-1]["received"] == len(lines)
    # the same ids within one scan: every track of the last scan before the kill that is
    # still confirmed in the first scan after the restart keeps its id there
    last_before = tracks_of(before)
    last_before = last_before[last_before["time_s"] == last_before["time_s"].max()]
    first_after = tracks_of(after)
    first_after = first_after[first_after["time_s"] == first_after["time_s"].min()]
    assert set(last_before["track_id"]) & set(first_after["track_id"])
    assert first_after["track_id"].max() < last_before["track_id"].max() + 5
    # and indeed every number goes on as if nothing had happened: as in a service that ran
    # on through the same silence at the cut (the window released there, as the first did)
    reference = LiveTracker(scene_files.site, warnings=read_warnings(scene_files.warnings))
    expected = [*live_records(reference, lines[:cut]), *live_records(reference, lines[cut:])]
    assert len(tracks_of(records)) == len(offline_tracks)
    pd.testing.assert_frame_equal(tracks_of(records), tracks_of(expected), check_exact=True)
    assert after[-1]["scan_ms_p50"] > 0


@pytest.mark.skipif(sys.platform != "linux", reason="per-thread CPU priority is Linux only")
def test_the_tracking_thread_yields_the_cpu_to_the_receivers_alone():
    from adaptrack.service.server import TRACKER_NICENESS, _yield_to_inputs

    seen = {}

    def tracking():
        tid = threading.get_native_id()
        before = os.getpriority(os.PRIO_PROCESS, tid)
        _yield_to_inputs()
        seen["change"] = os.getpriority(os.PRIO_PROCESS, tid) - before

    main_before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    worker = threading.Thread(target=tracking)
    worker.start()
    worker.join()
    assert seen["change"] == min(TRACKER_NICENESS, 19 - main_before)  # 19: the lowest
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == main_before
