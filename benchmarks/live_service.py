"""The live service on a replayed mixed-traffic scene: nothing lost, offline numbers, speed.

``python -m benchmarks.live_service --duration 3600 --seed 61`` simulates the scene
(``adaptrack simulate --scene``), tracks it offline (``adaptrack track``, Parquet), then
starts ``adaptrack serve`` on a loopback UDP port and replays the file at ``--rate max``
(``adaptrack replay``). It prints the detections in / used / rejected / lost in the kernel,
whether the live tracks equal the offline ones exactly, the tracker's processing time per
scan (p50 / p99, from the final stats record), and the sustained input rate: the scene's
duration over the wall time from the first datagram to the service's exit after SIGTERM
(times real time). Commands run as separate processes, as a user would run them.
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd


def adaptrack(*args: str) -> None:
    """Run an adaptrack command; fail loudly."""
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", *args], capture_output=True, text=True
    )
    if proc.returncode:
        raise SystemExit(f"adaptrack {args[0]} failed: {proc.stderr}")


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark (command line above)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="scene length [s]")
    ap.add_argument("--seed", type=int, default=61)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="live_bench_") as folder:
        run(Path(folder), args.duration, args.seed)


def run(work: Path, duration: float, seed: int) -> None:
    """Simulate, track offline, serve and replay in ``work``; print the figures."""
    det, warn, off = work / "det.csv", work / "warn.csv", work / "offline.parquet"
    adaptrack("simulate", "--scene", "--duration", str(duration), "--seed",
              str(seed), "--out", str(det), "--warnings", str(warn))  # fmt: skip
    with open(det) as f:
        n = sum(1 for _ in f) - 1
    start = time.perf_counter()
    adaptrack("track", str(det), "--site", "lx_default", "--out", str(off), "--warnings", str(warn))
    offline_s = time.perf_counter() - start
    out = work / "live.jsonl"
    serve = subprocess.Popen(
        [sys.executable, "-m", "adaptrack", "serve", "--site", "lx_default", "--listen",
         "udp://127.0.0.1:0", "--out", str(out), "--warnings", str(warn)],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert serve.stderr is not None
    port, said = None, []
    for line in serve.stderr:
        said.append(line)
        m = re.match(r"listening udp://127\.0\.0\.1:(\d+)", line)
        if m:
            port = m.group(1)
            break
    if port is None:
        serve.wait()
        serve.stderr.close()
        raise SystemExit(f"adaptrack serve did not start: {''.join(said)}")
    start = time.perf_counter()
    adaptrack("replay", str(det), "--to", f"udp://127.0.0.1:{port}", "--rate", "max")
    sent_s = time.perf_counter() - start
    serve.send_signal(signal.SIGTERM)
    code = serve.wait()
    serve.stderr.close()
    live_s = time.perf_counter() - start
    with open(out) as f:
        records = [json.loads(line) for line in f]
    stats = records[-1]
    tracks = pd.DataFrame([r for r in records if r["type"] == "track"]).drop(columns="type")
    offline = pd.read_parquet(off)
    try:
        pd.testing.assert_frame_equal(tracks, offline, check_exact=True)
        equal = "yes, exactly"
    except AssertionError as exc:
        equal = f"NO: {str(exc).splitlines()[0]}"
    print(f"scene: {duration:.0f} s, seed {seed}, {n} detections, {stats['scans']} scans")
    print(f"serve exit status {code}; detections in {n}, received {stats['received']}, used "
          f"{stats['used']}, rejected {stats['rejected']} {stats['rejected_by_reason']}, "
          f"pending {stats['pending']}, lost in the kernel {stats['udp_kernel_dropped']}; "
          f"in = used + rejected: {n == stats['used'] + stats['rejected']}")  # fmt: skip
    print(f"live tracks equal offline 'adaptrack track': {equal} ({len(tracks)} rows)")
    print(f"processing per scan: p50 {stats['scan_ms_p50']:.3f} ms, p99 "
          f"{stats['scan_ms_p99']:.3f} ms (tracker step and records)")  # fmt: skip
    print(f"replay sent in {sent_s:.1f} s; service done in {live_s:.1f} s: sustained "
          f"{duration / live_s:.1f}x real time (offline track: "
          f"{duration / offline_s:.1f}x, including start-up)")  # fmt: skip


if __name__ == "__main__":
    main()
