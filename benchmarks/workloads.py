"""Benchmark workloads; each returns rows for the table (adaptrack first, then peers).

Every implementation filters the same measurements; results are compared with the first
row's before its timing is kept, so a fast but wrong result cannot go unnoticed.
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import peers

if TYPE_CHECKING:
    from adaptrack.crossing.studies.scene_metrics import SceneScore

Impl = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Result:
    workload: str
    impl: str
    per_step_us: float | None
    track_steps_per_s: float | None
    note: str = ""
    peak_memory_ratio: float | None = None


def best_time(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    """Best wall time of ``repeats`` calls (after the caller's warm-up)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _check(name: str, out: np.ndarray, ref: np.ndarray, last_only: bool = False) -> None:
    n_tr, n = out.shape[:2]
    a, b = (out[:, -1:], ref[:n_tr, n - 1 : n]) if last_only else (out, ref[:n_tr, :n])
    err = np.max(np.abs(a - b)) / np.max(np.abs(b))
    if not err <= 1e-6:
        raise RuntimeError(f"{name} disagrees with the reference estimates (rel. {err:.1e})")


def _compare(
    workload: str,
    t: np.ndarray,
    z: np.ndarray,
    impls: dict[str, tuple[Impl, int, int]],
    repeats: int,
    reference: np.ndarray | None = None,
) -> list[Result]:
    """Time ``impl(t[:steps], z[:tracks, :steps])`` for every ``(impl, tracks, steps)``.

    Results are checked against ``reference`` (the final estimates only) or the first row's.
    """
    rows, ref = [], reference
    n_tracks, n_steps = z.shape[:2]
    for name, (fn, tracks, steps) in impls.items():
        # warm-up (compilation, imports, page faults are not timed): adaptrack's kernels are
        # generated and compiled per size class, so its warm-up is the timed call itself
        if name.startswith("adaptrack"):
            fn(t[:steps], z[:tracks, :steps])
        else:
            fn(t[:20], z[:2, :20])
        reps = repeats if tracks * steps >= n_tracks * n_steps // 10 else 1
        secs, out = best_time(lambda fn=fn, k=tracks, s=steps: fn(t[:s], z[:k, :s]), reps)
        assert isinstance(out, np.ndarray)
        ref = out if ref is None else ref
        _check(name, out, ref, last_only=reference is not None)
        note = [] if tracks == n_tracks else [f"{tracks} tracks"]
        note += [] if steps == n_steps else [f"first {steps} steps"]
        work = tracks * steps
        rows.append(Result(workload, name, 1e6 * secs / work, work / secs, ", ".join(note)))
    return rows


def single(quick: bool, repeats: int) -> list[Result]:
    """One track of 100,000 steps (2,000 with ``quick``).

    ``adaptrack``: ``OnlineFilter.update_many`` (per-step means, variances and NIS, the state
    kept for going on live); ``kalman_filter`` also stores every covariance, gain and
    transition (what smoothing needs).
    """
    n = 2_000 if quick else 100_000
    few = n if quick else n // 10
    t, z = peers.data(1, n)
    return _compare(
        "single",
        t,
        z,
        {
            "adaptrack": (peers.adaptrack_update_many, 1, n),
            "adaptrack (kalman_filter, full result)": (peers.adaptrack_filter, 1, n),
            "adaptrack (fleet path, means + shared cov)": (peers.adaptrack_fleet, 1, n),
            "adaptrack (numpy reference)": (
                lambda t, z: peers.adaptrack_filter(t, z, "numpy"),
                1,
                n,
            ),
            "filterpy": (peers.filterpy_filter, 1, few),
            "pykalman": (peers.pykalman_filter, 1, few),
            "simdkalman": (peers.simdkalman_filter, 1, n),
            "stonesoup": (peers.stonesoup_filter, 1, min(few, 2_000)),
        },
        repeats,
    )


def batch(quick: bool, repeats: int) -> list[Result]:
    """10,000 tracks x 1,000 steps sharing model, start and sampling (200 x 100 ``quick``)."""
    n_tracks, n_steps = (200, 100) if quick else (10_000, 1_000)
    subset = 2 if quick else 10
    t, z = peers.data(n_tracks, n_steps, seed=1)
    out = np.empty(z.shape[:-1] + (3,))
    return _compare(
        "batch",
        t,
        z,
        {
            "adaptrack": (
                lambda t, z: peers.adaptrack_fleet(t, z, _buffer(out, z)),
                n_tracks,
                n_steps,
            ),
            "adaptrack (fleet path, new output)": (peers.adaptrack_fleet, n_tracks, n_steps),
            "adaptrack (kalman_filter, full result)": (peers.adaptrack_filter, n_tracks, n_steps),
            "adaptrack (per-track covariances, numba)": (
                lambda t, z: peers.adaptrack_per_track_cov(t, z, "numba"),
                n_tracks,
                n_steps,
            ),
            "adaptrack (per-track covariances, numba, Joseph form)": (
                lambda t, z: peers.adaptrack_per_track_cov(t, z, "numba", "joseph"),
                n_tracks,
                n_steps,
            ),
            "adaptrack (per-track covariances, numba, square-root form)": (
                lambda t, z: peers.adaptrack_per_track_cov(t, z, "numba", "sqrt"),
                n_tracks,
                n_steps,
            ),
            "adaptrack (per-track covariances, numpy, square-root form)": (
                lambda t, z: peers.adaptrack_per_track_cov(t, z, "numpy", "sqrt"),
                subset * 10,
                n_steps,
            ),
            "simdkalman": (peers.simdkalman_filter, n_tracks, n_steps),
            "filterpy": (peers.filterpy_filter, subset, n_steps),
            "pykalman": (peers.pykalman_filter, subset, n_steps),
            "pykalman (Cholesky square-root filter)": (
                lambda t, z: peers.pykalman_filter(t, z, square_root=True),
                subset,
                n_steps,
            ),
            "stonesoup": (peers.stonesoup_filter, min(subset, 2), n_steps),
        },
        repeats,
    )


def batch_jitter(quick: bool, repeats: int) -> list[Result]:
    """2,000 tracks x 1,000 steps, each track on its own jittered times (every step length
    new; 200 x 100 ``quick``): ``kalman_filter``'s per-track path against the same tracks on
    shared times (one discretisation per step), results checked against FilterPy on two
    tracks given each step's Phi and Q from a Van Loan matrix exponential (scipy)."""
    n_tracks, n_steps = (200, 100) if quick else (2_000, 1_000)
    t, z = peers.data(n_tracks, n_steps, seed=2)
    jitter = np.random.default_rng(6).uniform(-0.2, 0.2, (n_tracks, n_steps)) * peers.DT
    times = t[None] + jitter
    reference = peers.filterpy_jittered(times[:2], z[:2], float(times[:, 0].min()))
    rows = []
    cases = (("adaptrack (per-track jittered times)", times), ("adaptrack (shared times)", t))
    for name, tt in cases:
        run = lambda tt=tt: peers.adaptrack_per_track_cov(tt, z, "numba")  # noqa: E731
        run()  # compilation
        secs, out = best_time(run, repeats)
        if tt is times:
            _check(name, np.asarray(out)[:2], reference)
        work = n_tracks * n_steps
        rows.append(Result("batch_jitter", name, 1e6 * secs / work, work / secs, "3-state Singer"))
    return rows


def _buffer(out: np.ndarray, z: np.ndarray) -> np.ndarray | None:
    """The reusable output buffer when the call covers the whole batch (warm-up does not)."""
    return out if out.shape[:2] == z.shape[:2] else None


def rts(quick: bool, repeats: int) -> list[Result]:
    """Fixed-interval smoothing: one long track, and the batch."""
    n = 2_000 if quick else 100_000
    t, z = peers.data(1, n, seed=2)
    rows = _compare(
        "rts",
        t,
        z,
        {
            "adaptrack": (peers.adaptrack_rts, 1, n),
            "adaptrack (square-root smoother)": (
                lambda t, z: peers.adaptrack_rts(t, z, form="sqrt"),
                1,
                n,
            ),
            "adaptrack (fleet path)": (
                lambda t, z: peers.adaptrack_fleet(t, z, smooth=True),
                1,
                n,
            ),
            "filterpy": (peers.filterpy_rts, 1, n),  # smoothing needs the whole interval
            "simdkalman": (peers.simdkalman_smoother, 1, n),
        },
        repeats,
    )
    n_tracks, n_steps = (200, 100) if quick else (10_000, 1_000)
    t, z = peers.data(n_tracks, n_steps, seed=3)
    out = np.empty(z.shape[:-1] + (3,))
    rows += _compare(
        "rts_batch",
        t,
        z,
        {
            "adaptrack": (
                lambda t, z: peers.adaptrack_fleet(t, z, _buffer(out, z), smooth=True),
                n_tracks,
                n_steps,
            ),
            "simdkalman": (peers.simdkalman_smoother, n_tracks, n_steps),
        },
        repeats,
    )
    return rows


def streaming(quick: bool, repeats: int) -> list[Result]:
    """One measurement at a time from Python (online update), 20,000 steps; then the same with
    jittered timestamps (every step length new: no peer caches discretisations)."""
    n = 1_000 if quick else 20_000
    t, z = peers.data(1, n, seed=4)
    rows = _compare(
        "stream",
        t,
        z,
        {
            "adaptrack": (peers.stream_adaptrack, 1, n),
            "adaptrack (Joseph form)": (lambda t, z: peers.stream_adaptrack(t, z, "joseph"), 1, n),
            "adaptrack (square-root form)": (
                lambda t, z: peers.stream_adaptrack(t, z, "sqrt"),
                1,
                n,
            ),
            "filterpy": (peers.stream_filterpy, 1, n),
            "pykalman": (peers.stream_pykalman, 1, n // 10),
            "stonesoup": (peers.stonesoup_filter, 1, n // 10),
        },
        repeats,
        reference=peers.adaptrack_filter(t, z),
    )
    jittered = t + np.random.default_rng(5).uniform(-0.2, 0.2, n) * peers.DT
    return rows + _compare(
        "stream_jitter",
        jittered,
        z,
        {"adaptrack": (peers.stream_adaptrack, 1, n)},
        repeats,
        reference=peers.adaptrack_filter(jittered, z),
    )


def imm(quick: bool, repeats: int) -> list[Result]:
    """Two-mode IMM over 1,000 tracks x 1,000 steps (20 x 100 ``quick``): the default
    (``"auto"``, Joseph on this well-conditioned problem), the Joseph and square-root forms,
    and FilterPy's ``IMMEstimator``."""
    n_tracks, n_steps = (20, 100) if quick else (1_000, 1_000)
    subset = 2 if quick else 5
    t, z = peers.data(n_tracks, n_steps, seed=6)
    return _compare(
        "imm",
        t,
        z,
        {
            "adaptrack": (peers.adaptrack_imm, n_tracks, n_steps),
            "adaptrack (Joseph form)": (
                lambda t, z: peers.adaptrack_imm(t, z, "joseph"),
                n_tracks,
                n_steps,
            ),
            "adaptrack (square-root form)": (
                lambda t, z: peers.adaptrack_imm(t, z, "sqrt"),
                n_tracks,
                n_steps,
            ),
            "filterpy": (peers.filterpy_imm, subset, n_steps),
        },
        repeats,
    )


def radar_ekf(quick: bool, repeats: int) -> list[Result]:
    """3-D radar with range-rate, constant-velocity EKF over 1,000 tracks x 200 scans (20 x 50
    ``quick``), then over one track of 5,000 scans (200 ``quick``): adaptrack's ``ekf_filter``
    compiled and in NumPy, FilterPy's ``ExtendedKalmanFilter``."""
    rows = []
    for workload, (n_tracks, n_steps) in (
        ("radar_ekf", (20, 50) if quick else (1_000, 200)),
        ("radar_ekf_1", (1, 200) if quick else (1, 5_000)),
    ):
        t, z = peers.radar_data(n_tracks, n_steps, seed=8)
        rows += _compare(
            workload,
            t,
            z,
            {
                "adaptrack": (
                    lambda t, z: peers.adaptrack_radar_ekf(t, z, "numba"),
                    n_tracks,
                    n_steps,
                ),
                "adaptrack (NumPy)": (
                    lambda t, z: peers.adaptrack_radar_ekf(t, z, "numpy"),
                    n_tracks,
                    n_steps,
                ),
                "filterpy": (peers.filterpy_radar_ekf, min(n_tracks, 2 if quick else 20), n_steps),
            },
            repeats,
        )
    return rows


def radar_ukf(quick: bool, repeats: int) -> list[Result]:
    """The same radar, a constant-velocity UKF on one track of 2,000 scans (100 ``quick``):
    adaptrack's ``ukf_filter`` (NumPy) and FilterPy's ``UnscentedKalmanFilter``."""
    n_steps = 100 if quick else 2_000
    t, z = peers.radar_data(1, n_steps, seed=10)
    return _compare(
        "radar_ukf_1",
        t,
        z,
        {
            "adaptrack": (peers.adaptrack_radar_ukf, 1, n_steps),
            "filterpy": (peers.filterpy_radar_ukf, 1, n_steps),
        },
        repeats,
    )


def radar_imm(quick: bool, repeats: int) -> list[Result]:
    """The same radar, an IMM-EKF of two CV modes over 1,000 tracks x 200 scans (20 x 50
    ``quick``): adaptrack's compiled kernel and its NumPy reference, FilterPy's
    ``IMMEstimator`` of two ``ExtendedKalmanFilter``."""
    n_tracks, n_steps = (20, 50) if quick else (1_000, 200)
    t, z = peers.radar_data(n_tracks, n_steps, seed=9)
    return _compare(
        "radar_imm",
        t,
        z,
        {
            "adaptrack": (lambda t, z: peers.adaptrack_radar_imm(t, z, "numba"), n_tracks,
                          n_steps),
            "adaptrack (NumPy)": (lambda t, z: peers.adaptrack_radar_imm(t, z, "numpy"),
                                  n_tracks, n_steps),
            "filterpy": (peers.filterpy_radar_imm, 2 if quick else 20, n_steps),
        },
        repeats,
    )  # fmt: skip


def crossing(quick: bool, workers: int) -> list[Result]:
    """``lx_default`` compliance Monte Carlo: the deployed estimator, and the demo's table.

    Every class x case is simulated ``runs`` times. The compliance proof runs the deployed
    estimator (road EKF with constant acceleration, the demo's best) on 1,000 runs; the
    demo's comparison table (6 estimators + the PCRLB) runs 100 and is extrapolated.
    """
    from adaptrack.crossing.site.model import load_site
    from adaptrack.crossing.studies.compliance import evaluate_site
    from adaptrack.crossing.studies.trackers import RoadTracker
    from adaptrack.models import ConstantAcceleration
    from adaptrack.parallel import task_pool

    site = load_site("lx_default")
    subset = {"cases": site.cases[:1], "classes": ("car",)} if quick else {}
    deployed = {"road EKF (CA)": RoadTracker(ConstantAcceleration(jerk_psd=3.0))}
    configs = [
        ("adaptrack", 2 if quick else 1_000, deployed, False),  # the deployed estimator
        ("adaptrack (demo table: 6 estimators + PCRLB)", 1 if quick else 100, None, True),
    ]
    rows = []
    with task_pool(workers if not quick else 1) as pool:
        for impl, runs, trackers, bound in configs:
            kw = {"trackers": trackers, "bound": bound, **subset}
            evaluate_site(site, 20 if not quick else 1, 0, pool=pool, **kw)  # compilation
            t0 = time.perf_counter()
            res = evaluate_site(site, runs, 0, pool=pool, **kw)
            secs = time.perf_counter() - t0
            run_steps = sum(r.n_epochs for r in res.rows)  # scored (run, epoch, estimator)
            per_1000 = secs * 1000 / runs
            rows.append(
                Result(
                    "lx_mc",
                    impl,
                    None,
                    run_steps / secs,
                    ("road CA EKF, compliance verdict only; " if trackers else "")
                    + f"{runs} runs per class x case ({'car, 1 case' if quick else 'all 42'}) in "
                    f"{secs:.1f} s on {pool.n_workers} worker(s)"
                    + ("" if runs >= 1000 else f"; 1,000 runs ~ {per_1000:.0f} s (linear)")
                    + "; no peer has this workload",
                )
            )
    return rows


def scene(quick: bool) -> list[Result]:
    """``lx_default`` mixed traffic with a barrier closure: the scene tracker and Stone Soup.

    Stone Soup as three trackers (``benchmarks/scene_peer.py``: the moving-target GNN, and
    GNN and JPDA that keep stopped vehicles). All track the identical raw detections (no
    ids) and are scored by the same GOSPA code (c = 5 m, p = 2, every 0.5 s) before their
    times per scan are kept; a scene tracker that misses the vehicles (car coverage < 0.9)
    fails the workload.
    """
    from adaptrack.crossing.scene.tracker import track_scene
    from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
    from adaptrack.crossing.site.model import load_site

    from .scene_peer import stonesoup_scene

    site = load_site("lx_default")
    duration = 6.0 if quick else 60.0
    spec = scene_spec(
        site, duration_s=duration, first_closure_s=duration / 3, closure_s=duration / 2,
        stalls=(),
    )  # fmt: skip
    rec = simulate_scene(site, spec, 1)
    fa = spec.false_alarms_per_scan
    n_scans = rec.detections.groupby(["radar", "time_s"]).ngroups
    track_scene(site, rec.detections)  # compilation (or loading) of every kernel it calls
    impls = {  # name: (run, repeats); the peer's minutes-long run varies by a few per cent
        "adaptrack": (lambda: track_scene(site, rec.detections)[0], 1 if quick else 3),
        "stonesoup (GNN 2-D, EKF CV, same gate)": (
            lambda: stonesoup_scene(site, rec.detections, "moving"),
            1,
        ),
        "stonesoup GNN (stopped kept, site noise, same coasting)": (
            lambda: stonesoup_scene(site, rec.detections, "gnn", false_alarms_per_scan=fa),
            1,
        ),
        "stonesoup JPDA (stopped kept, site noise, same coasting)": (
            lambda: stonesoup_scene(site, rec.detections, "jpda", false_alarms_per_scan=fa),
            1,
        ),
    }

    def describe(name: str, sc: SceneScore) -> str:
        by_class = sc.classes.set_index("class") if len(sc.classes) else None
        cars = by_class["coverage"].get("car", np.nan) if by_class is not None else np.nan
        if name == "adaptrack" and cars < 0.9:  # (NaN: no car reached the zone)
            raise RuntimeError(f"scene tracker covers {cars:.2f} of the car epochs (< 0.9)")
        worst = (
            f"worst class {by_class.position_rms_m.idxmax()} "
            f"{by_class.position_rms_m.max():.2f} m / {by_class.speed_rms_kmh.max():.2f} km/h"
            if by_class is not None
            else "no road user in the zone"
        )
        return f"id switches {sc.id_switches}, car coverage {cars:.2f}, {worst}"

    return _scene_results("scene", impls, rec, site.zone_m, n_scans, duration, describe)


def _scene_results(
    workload: str,
    impls: dict[str, tuple[Callable[[], Any], int]],
    rec: Any,
    zone_m: float,
    n_scans: int,
    duration: float,
    describe: Callable[[str, SceneScore], str],
) -> list[Result]:
    """Time each tracker of a scene, score its tracks on the truth (GOSPA and ``describe``)."""
    from adaptrack.crossing.studies.scene_metrics import score_scene

    rows = []
    for name, (run, repeats) in impls.items():
        secs, tracks = best_time(run, repeats)
        sc = score_scene(rec.truth, tracks, zone_m)
        rows.append(
            Result(
                workload, name, secs / n_scans * 1e6, n_scans / secs,
                f"{duration:.0f} s, {n_scans} scans ({duration / secs:.0f}x real time); GOSPA "
                f"{sc.gospa_mean:.2f} (GOSPA^2 parts: loc {sc.gospa_localisation:.2f}, missed "
                f"{sc.gospa_missed:.2f}, false {sc.gospa_false:.2f}), {describe(name, sc)}",
            )
        )  # fmt: skip
    return rows


def scene_faces(quick: bool) -> list[Result]:
    """The ``scene`` workload's traffic seen by the face radar (a few points per body).

    The reflections lie on the faces each antenna sees (``FaceRadar`` cluster kind), not about
    the body centre. The extended-object tracker (the base of the ratios, NumPy) with the
    empty site's background learnt first (another seed), the corridor scene tracker, and Stone
    Soup's GNN and JPDA that keep stopped vehicles; identical detections, the same GOSPA code.
    """
    from adaptrack.crossing.scene.extended_tracker import track_scene_extended
    from adaptrack.crossing.scene.tracker import track_scene
    from adaptrack.crossing.simulation.faces import FaceRadar, face_returns_of
    from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
    from adaptrack.crossing.site.model import load_site
    from adaptrack.crossing.studies.clearance import empty_background

    from .scene_peer import stonesoup_scene

    site = load_site("lx_default")
    duration = 6.0 if quick else 60.0
    spec = scene_spec(
        site, duration_s=duration, first_closure_s=duration / 3, closure_s=duration / 2,
        stalls=(),
    )  # fmt: skip
    radar = FaceRadar.of_kind("cluster")
    rec = simulate_scene(site, spec, 1, face_returns_of(radar))
    background = empty_background(site, radar, 60.0, seed=10_000)
    fa = spec.false_alarms_per_scan
    n_scans = rec.detections.groupby(["radar", "time_s"]).ngroups
    track_scene(site, rec.detections)  # compilation (or loading)
    impls = {
        "adaptrack": (
            lambda: track_scene_extended(site, rec.detections, background=background)[0],
            1,
        ),
        "adaptrack corridor tracker": (lambda: track_scene(site, rec.detections)[0], 3),
        "stonesoup GNN (stopped kept, site noise, same coasting)": (
            lambda: stonesoup_scene(site, rec.detections, "gnn", false_alarms_per_scan=fa),
            1,
        ),
        "stonesoup JPDA (stopped kept, site noise, same coasting)": (
            lambda: stonesoup_scene(site, rec.detections, "jpda", false_alarms_per_scan=fa),
            1,
        ),
    }

    def describe(name: str, sc: SceneScore) -> str:
        return (f"{sc.users_meeting()} of {len(sc.users)} road users within 0.7 m / 2 km/h, "
                f"{sc.false_tracks} false tracks")  # fmt: skip

    return _scene_results("scene_faces", impls, rec, site.zone_m, n_scans, duration, describe)


def memory(quick: bool) -> list[Result]:
    """Peak traced memory of the batch filter relative to its input + output arrays."""
    n_tracks, n_steps = (200, 100) if quick else (10_000, 1_000)
    t, z = peers.data(n_tracks, n_steps, seed=1)
    rows = []
    for name, fn in (
        ("adaptrack", lambda: peers.adaptrack_fleet(t, z)),
        ("simdkalman", lambda: peers.simdkalman_filter(t, z)),
    ):
        fn()  # warm-up
        tracemalloc.start()
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        out = fn()
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        ratio = (peak + z.nbytes) / (z.nbytes + out.nbytes)
        rows.append(
            Result(
                "memory",
                name,
                None,
                None,
                f"peak {(peak + z.nbytes) / 2**20:.0f} MiB for input + output "
                f"{(z.nbytes + out.nbytes) / 2**20:.0f} MiB",
                ratio,
            )
        )
    return rows
