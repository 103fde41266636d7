"""``adaptrack track`` end to end (start-up, reading, tracking, writing) against real time.

``python -m benchmarks.track_end_to_end --duration 600 --seed 61`` simulates ``lx_default``
mixed traffic seen by its radars (``adaptrack simulate --scene``, CSV, also saved as
Parquet), then runs ``adaptrack track --tracker extended`` (and the corridor tracker) on
each file as a separate process pinned to one core, as a user would run it: once to fill
numba's cache (that run is reported apart), then ``--repeats`` times, best wall time
reported. Times real time is the scene's duration over that wall time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd


def _one_core() -> None:
    """Pin the child process to one core (the lowest it may run on)."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def run_track(det: Path, out: Path, tracker: str) -> float:
    """Wall time [s] of one ``adaptrack track`` process on ``det``; fail loudly."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "adaptrack", "track", str(det), "--site", "lx_default",
         "--tracker", tracker, "--out", str(out)],
        capture_output=True, text=True, preexec_fn=_one_core,
    )  # fmt: skip
    wall = time.perf_counter() - start
    if proc.returncode:
        raise SystemExit(f"adaptrack track failed: {proc.stderr}")
    return wall


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark (command line above)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="scene length [s]")
    ap.add_argument("--seed", type=int, default=61)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="track_e2e_") as folder:
        work = Path(folder)
        csv, parquet = work / "det.csv", work / "det.parquet"
        proc = subprocess.run(
            [sys.executable, "-m", "adaptrack", "simulate", "--scene", "--duration",
             str(args.duration), "--seed", str(args.seed), "--out", str(csv)],
            capture_output=True, text=True,
        )  # fmt: skip
        if proc.returncode:
            raise SystemExit(f"adaptrack simulate failed: {proc.stderr}")
        pd.read_csv(csv).to_parquet(parquet, index=False)
        n = len(pd.read_parquet(parquet, columns=["time_s"]))
        no_pyc = os.environ.get("PYTHONDONTWRITEBYTECODE", "")
        print(f"lx_default, {args.duration:.0f} s scene, {n} detections; one core; "
              f"PYTHONDONTWRITEBYTECODE={no_pyc!r}")  # fmt: skip
        for tracker in ("extended", "corridor"):
            for det in (csv, parquet):
                first = run_track(det, work / f"tracks_{tracker}.parquet", tracker)
                best = min(
                    run_track(det, work / f"tracks_{tracker}.parquet", tracker)
                    for _ in range(args.repeats)
                )
                rate = args.duration / best
                print(f"  --tracker {tracker:8s} {det.suffix[1:]:7s}: best {best:5.2f} s "
                      f"({rate:5.0f}x real time; first run {first:.1f} s)")  # fmt: skip


if __name__ == "__main__":
    main()
