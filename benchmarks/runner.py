"""Benchmark runner: 3-state Singer model, position measured, adaptrack vs peers.

Workloads (sizes in parentheses are the full run; --quick shrinks them):

* ``single``: one track of 100,000 steps.
* ``batch``: 10,000 tracks x 1,000 steps. Peers without batching (FilterPy, pykalman) run a
  subset of tracks and are reported per track-step.
* ``rts``: smoothing of the single-track result.

Every implementation filters the same measurements with the same model, and the final
estimates are compared so that a fast but wrong result cannot go unnoticed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

import adaptrack as at

DT = 0.05
MODEL = at.models.Singer(time_constant_s=5.0, accel_std_mps2=2.0)
H = np.array([[1.0, 0.0, 0.0]])
R = np.array([[0.25]])
P0 = np.diag([1.0, 100.0, 10.0])


@dataclass
class Result:
    workload: str
    impl: str
    per_step_us: float | None
    track_steps_per_s: float | None
    note: str = ""


def machine() -> dict[str, object]:
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if "model name" in line)
    except (OSError, StopIteration):
        pass
    import scipy

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "platform": platform.platform(),
        "adaptrack": at.__version__,
    }


def best_time(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    """Best wall time of ``repeats`` calls (after the caller's warm-up)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def data(n_tracks: int, n_steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = DT * np.arange(n_steps)
    truth = at.simulation.simulate_linear_trajectory(
        MODEL, t, [0.0, 10.0, 0.0], P0, n_runs=n_tracks, rng=rng
    )
    z = at.simulation.simulate_linear_measurements(truth, H, R, rng=rng)
    return t, z


def adaptrack_filter(t: np.ndarray, z: np.ndarray, backend: str = "auto") -> np.ndarray:
    prior = at.GaussianState(np.zeros(3), P0, t[0])
    return at.kalman_filter(t, z, MODEL, H, R, prior, backend=backend).filtered.mean


def adaptrack_filter_per_track_cov(
    t: np.ndarray, z: np.ndarray, backend: str = "auto"
) -> np.ndarray:
    """The general path: every track carries its own covariance recursion."""
    prior = at.GaussianState(
        np.zeros(z.shape[:-2] + (3,)), np.broadcast_to(P0, z.shape[:-2] + (3, 3)), t[0]
    )
    return at.kalman_filter(t, z, MODEL, H, R, prior, backend=backend).filtered.mean


def filterpy_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from filterpy.kalman import KalmanFilter

    phi, qd = at.discretize(MODEL, DT)
    out = np.empty(z.shape[:-1] + (3,))
    for i in range(z.shape[0]):
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = np.zeros(3), P0.copy(), phi, qd, H, R
        for k in range(z.shape[1]):
            if k:
                kf.predict()
            kf.update(z[i, k])
            out[i, k] = kf.x
    return out


def pykalman_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from pykalman import KalmanFilter

    phi, qd = at.discretize(MODEL, DT)
    out = np.empty(z.shape[:-1] + (3,))
    for i in range(z.shape[0]):
        kf = KalmanFilter(
            transition_matrices=phi,
            observation_matrices=H,
            transition_covariance=qd,
            observation_covariance=R,
            initial_state_mean=np.zeros(3),
            initial_state_covariance=P0,
        )
        out[i] = kf.filter(z[i])[0]
    return out


def simdkalman_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    import simdkalman

    phi, qd = at.discretize(MODEL, DT)
    kf = simdkalman.KalmanFilter(
        state_transition=phi, process_noise=qd, observation_model=H, observation_noise=R
    )
    res = kf.compute(z[..., 0], 0, initial_value=np.zeros(3), initial_covariance=P0, filtered=True)
    return res.filtered.states.mean


def run(quick: bool) -> list[Result]:
    results: list[Result] = []
    n_single = 2_000 if quick else 100_000
    n_tracks, n_steps = (200, 100) if quick else (10_000, 1_000)
    subset = 2 if quick else 10
    repeats = 1 if quick else 3

    # --- single sequence ------------------------------------------------------------------
    t, z = data(1, n_single)
    impls: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
        "adaptrack": lambda t, z: adaptrack_filter(t, z[0], "numba")[None],
        "adaptrack (numpy reference)": lambda t, z: adaptrack_filter(t, z[0], "numpy")[None],
        "filterpy": filterpy_filter,
        "pykalman": pykalman_filter,
        "simdkalman": simdkalman_filter,
    }
    ref = None
    for name, fn in impls.items():
        fn(t[:20], z[:, :20])  # warm-up: JIT compilation and imports are not timed
        n = n_single if name.startswith(("adaptrack", "simdkalman")) or quick else n_single // 10
        secs, out = best_time(lambda fn=fn, n=n: fn(t[:n], z[:, :n]), repeats)
        ref = out if ref is None else ref
        _check(name, out, ref)
        note = "" if n == n_single else f"first {n} steps"
        results.append(Result("single", name, 1e6 * secs / n, n / secs, note))

    # --- batch ----------------------------------------------------------------------------
    t, z = data(n_tracks, n_steps, seed=1)
    batch_impls: dict[str, tuple[Callable[[np.ndarray, np.ndarray], np.ndarray], int]] = {
        "adaptrack": (adaptrack_filter, n_tracks),
        "adaptrack (per-track covariances, numba)": (
            lambda t, z: adaptrack_filter_per_track_cov(t, z, "numba"),
            n_tracks,
        ),
        "adaptrack (per-track covariances, numpy)": (
            lambda t, z: adaptrack_filter_per_track_cov(t, z, "numpy"),
            n_tracks,
        ),
        "simdkalman": (simdkalman_filter, n_tracks),
        "filterpy": (filterpy_filter, subset),
        "pykalman": (pykalman_filter, subset),
    }
    ref = None
    for name, (fn, n) in batch_impls.items():
        fn(t[:20], z[:2, :20])  # warm-up
        secs, out = best_time(lambda fn=fn, n=n: fn(t, z[:n]), repeats if n > subset else 1)
        ref = out if ref is None else ref
        _check(name, out, ref[:n])
        note = "" if n == n_tracks else f"{n} tracks, no batching"
        steps = n * n_steps
        results.append(Result("batch", name, 1e6 * secs / steps, steps / secs, note))

    # --- RTS smoother ---------------------------------------------------------------------
    t, z = data(1, n_single, seed=2)
    prior = at.GaussianState(np.zeros(3), P0, t[0])
    res = at.kalman_filter(t, z[0], MODEL, H, R, prior)
    secs, _ = best_time(lambda: at.rts_smooth(res), repeats)
    results.append(Result("rts", "adaptrack", 1e6 * secs / n_single, n_single / secs))
    from filterpy.kalman import rts_smoother

    phi, qd = at.discretize(MODEL, DT)
    n = n_single if quick else n_single // 10
    fs, qs = np.broadcast_to(phi, (n, 3, 3)), np.broadcast_to(qd, (n, 3, 3))
    secs, _ = best_time(
        lambda: rts_smoother(res.filtered.mean[:n], res.filtered.cov[:n], fs, qs), repeats
    )
    results.append(
        Result(
            "rts", "filterpy", 1e6 * secs / n, n / secs, "" if n == n_single else f"first {n} steps"
        )
    )
    return results


def _check(name: str, out: np.ndarray, ref: np.ndarray) -> None:
    n = out.shape[1]
    err = np.max(np.abs(out - ref[:, :n])) / np.max(np.abs(ref[:, :n]))
    if err > 1e-6:
        raise RuntimeError(f"{name} disagrees with the reference estimates (rel. {err:.1e})")


def table(results: list[Result]) -> str:
    lines = [
        f"{'workload':<8} {'impl':<36} {'us/step':>10} {'track-steps/s':>14} "
        f"{'adaptrack is x faster':>22}  note"
    ]
    base = {r.workload: r for r in results if r.impl == "adaptrack"}
    for r in results:
        ratio = (
            r.per_step_us / base[r.workload].per_step_us
            if r.per_step_us and r.workload in base
            else float("nan")
        )
        lines.append(
            f"{r.workload:<8} {r.impl:<36} {r.per_step_us:>10.4f} "
            f"{r.track_steps_per_s:>14.3g} {ratio:>22.1f}  {r.note}"
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
    args = parser.parse_args(argv)
    results = run(args.quick)
    print(json.dumps(machine()))
    print(table(results))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine(), "results": [asdict(r) for r in results]}, f, indent=2)


__all__ = ["main"]
