"""Monte-Carlo evidence of compliance with the operator requirements (seed 001, table 1.1).

Per estimator x vehicle class x case: RMS of the planar position error [m] and of the speed
error ``|v_hat| - |v|`` [km/h] over all runs and epochs in the controlled zone (front of the
vehicle 0-150 m from the crossing), from 1 s after the track starts, while the vehicle moves
(true speed > 0.2 m/s; a stopped vehicle vanishes behind the Doppler gate). Speed RMS is
restricted to true speeds <= 100 km/h; above that the relative speed error RMS is compared with
2 %. Runs of a case are one batch; every (class, case) has its own seed stream.
"""

from __future__ import annotations

import math
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .._typing import BoolArray, FloatArray
from ..models.adaptive import InverseDynamics, ShapingFilter, singer_accel_std
from ..models.continuous import ConstantAcceleration, ConstantVelocity, MotionModel
from ..parallel import TaskPool
from .radar_sim import CrossingRuns, simulate_site_case, site_scan_count
from .site import Site
from .tracking import (
    TrackEstimates,
    road_pcrlb,
    track_converted,
    track_free_2d,
    track_on_road,
)
from .traffic import DEFAULT_CASES, VEHICLES, Case, VehicleClass, applicable

POSITION_LIMIT_M = 0.7
SPEED_LIMIT_KMH = 2.0
SPEED_LIMIT_REL = 0.02
SPEED_SPLIT_KMH = 100.0


@dataclass(frozen=True)
class ComplianceRow:
    """Accuracy of one estimator on one class and case, and the verdict."""

    filter: str
    vehicle_class: str
    case: str
    position_rms_m: float
    speed_rms_kmh: float
    speed_rel_rms_pct: float
    passed: bool
    n_epochs: int
    pcrlb_position_m: float = math.nan
    pcrlb_speed_kmh: float = math.nan


@dataclass(frozen=True)
class ComplianceResult:
    """All rows, the run configuration and summaries."""

    site: str
    runs: int
    seed: int
    rows: list[ComplianceRow]
    elapsed_s: float
    worst: dict[str, dict[str, float]] = field(default_factory=dict)
    gain_pct: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Plain data for ``summary.json``."""
        return {
            "site": self.site,
            "runs": self.runs,
            "seed": self.seed,
            "requirements": {
                "position_rms_m": POSITION_LIMIT_M,
                "speed_rms_kmh": SPEED_LIMIT_KMH,
                "speed_rel_rms_pct_above_100_kmh": 100 * SPEED_LIMIT_REL,
            },
            "rows": [{**asdict(r), "pass": r.passed} for r in self.rows],
            "worst_case": self.worst,
            "gain_over_cv_pct": self.gain_pct,
            "elapsed_s": self.elapsed_s,
        }


Tracker = Callable[[CrossingRuns, Site, Case, VehicleClass], TrackEstimates]


@dataclass(frozen=True)
class PlanarTracker:
    """A planar tracker (:func:`track_free_2d`, :func:`track_converted`) on a case's radar."""

    track: Callable[..., TrackEstimates]

    def __call__(
        self, runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass
    ) -> TrackEstimates:
        """Track the runs of one class x case."""
        return self.track(
            runs.times,
            runs.measurements,
            runs.detected,
            site.radar_for(case.road),
            scatter_std_m=veh.scatter_std_m,
        )


@dataclass(frozen=True)
class RoadTracker:
    """The road-constrained EKF with ``model`` along the case's road."""

    model: MotionModel

    def __call__(
        self, runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass
    ) -> TrackEstimates:
        """Track the runs of one class x case."""
        return track_on_road(
            runs.times,
            runs.measurements,
            runs.detected,
            site.radar_for(case.road),
            site.roads[case.road],
            model=self.model,
            scatter_std_m=veh.scatter_std_m,
        )


def default_trackers(tuned_m1: tuple[float, float] | None = None) -> dict[str, Tracker]:
    """Free 2-D EKF and CMKF, road-constrained CV (the rectilinear baseline), CA, M2.

    ``tuned_m1 = (lambda_per_s2, accel_psd)`` adds the road EKF with the site-tuned M1.
    """
    sig_a = singer_accel_std(9.0, 0.05, 0.5)
    tuned: dict[str, Tracker] = {}
    if tuned_m1 is not None:
        tuned["road EKF (M1, tuned)"] = RoadTracker(
            InverseDynamics(lambda_per_s2=tuned_m1[0], accel_psd=tuned_m1[1])
        )
    return {
        **tuned,
        "free 2-D EKF (CV)": PlanarTracker(track_free_2d),
        "CMKF (2-D, no Doppler)": PlanarTracker(track_converted),
        "road EKF (CV)": RoadTracker(ConstantVelocity(accel_psd=3.0)),
        "road EKF (CA)": RoadTracker(ConstantAcceleration(jerk_psd=3.0)),
        "road EKF (M2)": RoadTracker(
            ShapingFilter(
                lambda_per_s2=0.05, alpha_per_s=1 / 3, shaping_std=sig_a / math.sqrt(0.05)
            )
        ),
    }


BOUND_MODEL = ConstantAcceleration(jerk_psd=3.0)
RUN_BLOCK_STEPS = 1_000_000  # run-steps simulated and tracked together (one task, ~250 MB)


@dataclass(frozen=True)
class _Sum:
    """Sum of squares over scored epochs and their count (mergeable across run blocks)."""

    total: float = 0.0
    count: int = 0

    def __add__(self, other: _Sum) -> _Sum:
        return _Sum(self.total + other.total, self.count + other.count)

    def rms(self) -> float:
        return math.sqrt(self.total / self.count) if self.count else math.nan


def _sum(values: FloatArray) -> _Sum:
    return _Sum(float(np.sum(values)), int(values.size))


def _bound_sums(runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass) -> tuple[_Sum, _Sum]:
    """Road-aligned PCRLB variances of position [m^2] and speed [m^2/s^2] over the zone."""
    pos_var, spd_var = road_pcrlb(
        runs.times,
        runs.detected,
        runs.along_road_m,
        runs.speed,
        runs.lateral_offset_m,
        site.radar_for(case.road),
        site.roads[case.road],
        model=BOUND_MODEL,
        scatter_std_m=veh.scatter_std_m,
    )
    zone = scored_epochs(np.isfinite(pos_var), runs, site.zone_m)
    slow = zone & (3.6 * runs.speed <= SPEED_SPLIT_KMH)
    return _sum(pos_var[zone]), _sum(spd_var[slow])


def case_bound(
    runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass
) -> tuple[float, float]:
    """Road-aligned PCRLB (constant-acceleration model, jerk PSD 3 m^2/s^5) over the zone.

    Returns RMS position [m] and speed [km/h, true speed <= 100 km/h] bounds of the case.
    """
    pos, spd = _bound_sums(runs, site, case, veh)
    return pos.rms(), 3.6 * spd.rms()


def scored_epochs(started: BoolArray, runs: CrossingRuns, zone_m: float) -> BoolArray:
    """Scored epochs: in the zone, 1 s after the track start, while moving."""
    first = np.argmax(started, axis=1)
    t0 = np.take_along_axis(runs.true_times, first[:, None], axis=1)
    return (
        started
        & (runs.along_road_m >= 0)
        & (runs.along_road_m <= zone_m)
        & (runs.speed > 0.2)
        & (runs.true_times >= t0 + 1.0)
    )


def _score_sums(est: TrackEstimates, runs: CrossingRuns, zone_m: float) -> tuple[_Sum, _Sum, _Sum]:
    """Sum squared errors: position [m^2], speed [(km/h)^2] (<= 100 km/h), relative speed."""
    zone = scored_epochs(np.isfinite(est.speed), runs, zone_m)
    ep = np.sum((est.position - runs.position) ** 2, axis=-1)[zone]
    ev = (est.speed - runs.speed)[zone]
    slow = 3.6 * runs.speed[zone] <= SPEED_SPLIT_KMH
    return _sum(ep), _sum((3.6 * ev[slow]) ** 2), _sum((ev[~slow] / runs.speed[zone][~slow]) ** 2)


def score(
    est: TrackEstimates, runs: CrossingRuns, zone_m: float
) -> tuple[float, float, float, int]:
    """Position RMS [m], speed RMS [km/h] (<= 100 km/h), relative speed RMS (> 100), epochs."""
    pos, spd, rel = _score_sums(est, runs, zone_m)
    return pos.rms(), spd.rms(), rel.rms(), pos.count


BlockSums = tuple[dict[str, tuple[_Sum, _Sum, _Sum]], tuple[_Sum, _Sum]]


def _block(
    site: Site,
    case: Case,
    veh: VehicleClass,
    n_runs: int,
    seed: np.random.SeedSequence,
    trackers: dict[str, Tracker],
    bound: bool,
) -> BlockSums:
    """Simulate one block of runs of a class x case; sums of every tracker (and the bound)."""
    runs = simulate_site_case(site, case, veh, n_runs=n_runs, rng=np.random.default_rng(seed))
    sums = {
        name: _score_sums(tracker(runs, site, case, veh), runs, site.zone_m)
        for name, tracker in trackers.items()
    }
    return sums, _bound_sums(runs, site, case, veh) if bound else (_Sum(), _Sum())


def _blocks(
    n_runs: int, n_steps: int, seed: np.random.SeedSequence
) -> list[tuple[int, np.random.SeedSequence]]:
    """Run blocks of a class x case of ``n_steps`` scans, with their seeds.

    Up to ``RUN_BLOCK_STEPS`` run-steps per block (memory per task stays bounded); the first
    block uses ``seed`` itself, so a case that fits one block is simulated as before blocks.
    """
    block = max(1, RUN_BLOCK_STEPS // n_steps)
    sizes = [min(block, n_runs - i) for i in range(0, n_runs, block)]
    seeds = [seed] + [
        np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, j))
        for j in range(len(sizes) - 1)
    ]
    return list(zip(sizes, seeds, strict=True))


def _rows(case: Case, veh: VehicleClass, blocks: list[BlockSums]) -> list[ComplianceRow]:
    """Merge the blocks of a class x case into one row per tracker."""
    bound_p = sum((b[1][0] for b in blocks), _Sum()).rms()
    bound_s = 3.6 * sum((b[1][1] for b in blocks), _Sum()).rms()
    rows = []
    for name in blocks[0][0]:
        pos_s, spd_s, rel_s = (sum((b[0][name][j] for b in blocks), _Sum()) for j in range(3))
        pos, spd, rel = pos_s.rms(), spd_s.rms(), rel_s.rms()
        ok = (
            pos <= POSITION_LIMIT_M
            and (math.isnan(spd) or spd <= SPEED_LIMIT_KMH)
            and (math.isnan(rel) or rel <= SPEED_LIMIT_REL)
        )
        rows.append(
            ComplianceRow(
                name, veh.name, case.name, pos, spd, 100 * rel, ok, pos_s.count, bound_p, bound_s
            )
        )
    return rows


def evaluate_pair(
    site: Site,
    case: Case,
    veh: VehicleClass,
    n_runs: int,
    seed: np.random.SeedSequence,
    trackers: dict[str, Tracker] | None = None,
    tuned_m1: tuple[float, float] | None = None,
    bound: bool = True,
) -> list[ComplianceRow]:
    """Simulate one class x case ``n_runs`` times and score every tracker on the same runs.

    Runs go in blocks of up to ``RUN_BLOCK_STEPS`` run-steps with their own seed streams.
    ``bound=False`` skips the PCRLB (NaN in the rows).
    """
    trackers = default_trackers(tuned_m1) if trackers is None else trackers
    blocks = [
        _block(site, case, veh, size, ss, trackers, bound)
        for size, ss in _blocks(n_runs, site_scan_count(site, case, veh), seed)
    ]
    return _rows(case, veh, blocks)


def evaluate_site(
    site: Site,
    n_runs: int,
    seed: int,
    *,
    cases: tuple[Case, ...] = DEFAULT_CASES,
    classes: dict[str, VehicleClass] | None = None,
    trackers: dict[str, Tracker] | None = None,
    pool: TaskPool | None = None,
    tuned_m1: tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    bound: bool = True,
) -> ComplianceResult:
    """Simulate every applicable class x case ``n_runs`` times and score every tracker.

    ``bound=False`` leaves out the road-aligned PCRLB of each case (a diagnostic; the verdict
    does not use it).

    Blocks of up to ``RUN_BLOCK_STEPS`` run-steps of each (class, case) pair are the tasks of
    ``pool`` (in-process when None, e.g. a Dask cluster from
    :func:`adaptrack.parallel.task_pool`); every block has its own seed stream, so the result
    does not depend on the pool.
    """
    start = time.perf_counter()
    classes = VEHICLES if classes is None else classes
    pairs = [(c, v) for v in classes.values() for c in cases if applicable(c, v)]
    seeds = np.random.SeedSequence(seed).spawn(len(pairs))
    trackers = default_trackers(tuned_m1) if trackers is None else trackers
    pool = TaskPool() if pool is None else pool
    site_handle = pool.share(site)
    tasks = [
        (pair, (site_handle, c, v, size, ss, trackers, bound))
        for pair, ((c, v), pair_seed) in enumerate(zip(pairs, seeds, strict=True))
        for size, ss in _blocks(n_runs, site_scan_count(site, c, v), pair_seed)
    ]
    left = Counter(pair for pair, _ in tasks)  # blocks still running per pair

    def done(k: int) -> None:
        i = tasks[k][0]
        left[i] -= 1
        if progress and not left[i]:
            progress(f"{pairs[i][1].name} / {pairs[i][0].name}")

    results = pool.map(_block, [args for _, args in tasks], progress=done)
    by_pair: dict[int, list[BlockSums]] = defaultdict(list)
    for (pair, _), result in zip(tasks, results, strict=True):
        by_pair[pair].append(result)
    per_pair = [_rows(c, v, by_pair[i]) for i, (c, v) in enumerate(pairs)]
    rows = [row for pair_rows in per_pair for row in pair_rows]
    names = list(trackers)
    worst = {}
    for name in names:
        mine = [r for r in rows if r.filter == name]
        worst[name] = {
            "position_rms_m": max(r.position_rms_m for r in mine),
            "speed_rms_kmh": max(
                (r.speed_rms_kmh for r in mine if not math.isnan(r.speed_rms_kmh)), default=math.nan
            ),
            "all_pass": float(all(r.passed for r in mine)),
        }
    gain = {}
    base = {(r.vehicle_class, r.case): r for r in rows if r.filter == "road EKF (CV)"}
    for name in names:
        if name == "road EKF (CV)" or not base:
            continue
        mine = [r for r in rows if r.filter == name]
        p0 = math.sqrt(np.mean([base[(r.vehicle_class, r.case)].position_rms_m ** 2 for r in mine]))
        p1 = math.sqrt(np.mean([r.position_rms_m**2 for r in mine]))
        s_pairs = [
            (base[(r.vehicle_class, r.case)].speed_rms_kmh, r.speed_rms_kmh)
            for r in mine
            if not math.isnan(r.speed_rms_kmh)
        ]
        s0 = math.sqrt(np.mean([a**2 for a, _ in s_pairs]))
        s1 = math.sqrt(np.mean([b**2 for _, b in s_pairs]))
        gain[name] = {"position": 100 * (1 - p1 / p0), "speed": 100 * (1 - s1 / s0)}
    return ComplianceResult(site.name, n_runs, seed, rows, time.perf_counter() - start, worst, gain)


__all__ = [
    "ComplianceResult",
    "ComplianceRow",
    "PlanarTracker",
    "RoadTracker",
    "default_trackers",
    "evaluate_pair",
    "evaluate_site",
    "score",
    "scored_epochs",
]
