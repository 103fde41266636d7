"""Benchmark runner: 3-state Singer model, position measured, adaptrack vs peers in one run.

Workloads (full sizes; ``--quick`` shrinks them to a smoke test):

* ``single``: one track of 100,000 steps;
* ``batch``: 10,000 tracks x 1,000 steps sharing model, start and sampling (peers without
  batching run a subset of tracks and are reported per track-step);
* ``batch_jitter``: 2,000 tracks x 1,000 steps, each on its own jittered times (every step
  length new), against the same tracks on shared times; checked against FilterPy given each
  step's Van Loan discretisation;
* ``rts``/``rts_batch``: fixed-interval smoothing of one long track and of the batch;
* ``stream``: one online update per call from Python (20,000 measurements), also with
  jittered timestamps (``stream_jitter``); with the Joseph and square-root forms beside the
  default ``auto``;
* ``imm``: a two-mode IMM over 1,000 tracks x 1,000 steps, the default ``auto`` beside the
  Joseph and square-root forms, against FilterPy's ``IMMEstimator``;
* ``radar_ekf``: a 3-D radar (range, azimuth, elevation, range-rate) constant-velocity EKF
  over 1,000 tracks x 200 scans, and (``radar_ekf_1``) over one track of 5,000 scans, compiled
  and in NumPy, against FilterPy's ``ExtendedKalmanFilter``;
* ``radar_ukf``: the same radar, a constant-velocity UKF on one track of 2,000 scans, against
  FilterPy's ``UnscentedKalmanFilter``;
* ``radar_imm``: the same radar, an IMM-EKF of two CV modes (the compiled kernel and its NumPy
  reference) against FilterPy's ``IMMEstimator`` of two ``ExtendedKalmanFilter``;
* ``lx_mc``: the ``lx_default`` level-crossing compliance Monte Carlo;
* ``scene``: ``lx_default`` mixed traffic (reflections about each body's centre), the scene
  tracker against Stone Soup's trackers;
* ``scene_faces``: the same traffic seen by the face radar (reflections on the faces each
  antenna sees), the extended-object tracker against the corridor tracker and Stone Soup's
  GNN and JPDA;
* ``memory``: peak traced memory of the batch filter over its input + output arrays.

The ratio column is the row's time per track-step over adaptrack's (first row) in the same
workload: how many times faster adaptrack is.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
from dataclasses import asdict

import numpy as np

import adaptrack as at

from . import workloads
from .workloads import Result


def machine() -> dict[str, object]:
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if "model name" in line)
    except (OSError, StopIteration):
        pass
    import numba
    import scipy

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "numba_threads": numba.get_num_threads(),
        "platform": platform.platform(),
        "adaptrack": at.__version__,
    }


def run(quick: bool, only: list[str] | None = None, workers: int = 2) -> list[Result]:
    repeats = 1 if quick else 3
    steps = {
        "single": lambda: workloads.single(quick, repeats),
        "batch": lambda: workloads.batch(quick, repeats),
        "batch_jitter": lambda: workloads.batch_jitter(quick, repeats),
        "rts": lambda: workloads.rts(quick, repeats),
        "stream": lambda: workloads.streaming(quick, repeats),
        "imm": lambda: workloads.imm(quick, repeats),
        "radar_ekf": lambda: workloads.radar_ekf(quick, repeats),
        "radar_ukf": lambda: workloads.radar_ukf(quick, repeats),
        "radar_imm": lambda: workloads.radar_imm(quick, repeats),
        "lx_mc": lambda: workloads.crossing(quick, workers),
        "scene": lambda: workloads.scene(quick),
        "scene_faces": lambda: workloads.scene_faces(quick),
        "memory": lambda: workloads.memory(quick),
    }
    results: list[Result] = []
    for name, step in steps.items():
        if only is None or name in only:
            results += step()
    return results


def table(results: list[Result]) -> str:
    lines = [
        f"{'workload':<10} {'impl':<44} {'us/step':>10} {'track-steps/s':>14} "
        f"{'adaptrack x faster':>19}  note"
    ]
    base = {r.workload: r for r in results if r.impl == "adaptrack"}
    for r in results:
        b = base.get(r.workload)
        ratio = r.per_step_us / b.per_step_us if r.per_step_us and b and b.per_step_us else math.nan

        def fmt(v: float | None, spec: str) -> str:
            return format(v, spec) if v is not None else "-"

        note = r.note
        if r.peak_memory_ratio is not None:
            note = f"peak / (input + output) = {r.peak_memory_ratio:.2f}; {note}"
        lines.append(
            f"{r.workload:<10} {r.impl:<44} {fmt(r.per_step_us, '>10.4f'):>10} "
            f"{fmt(r.track_steps_per_s, '>14.3g'):>14} {ratio:>19.1f}  {note}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    parser.add_argument("--only", nargs="+", metavar="WORKLOAD", help="run only these workloads")
    parser.add_argument("--workers", type=int, default=2, help="Dask workers of the lx_mc workload")
    args = parser.parse_args(argv)
    results = run(args.quick, args.only, args.workers)
    print(json.dumps(machine()))
    print(table(results))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine(), "results": [asdict(r) for r in results]}, f, indent=2)


__all__ = ["main"]
