"""Design-time adaptation of model parameters (spec B.7).

Parameters are chosen to minimise the RMS estimation error over a set of typical
trajectories.

All candidate parameters are scored on the same measurement sequences (common random
numbers). The criterion is ``J_pos`` (RMS position error over every run and scored epoch),
``J_vel`` or the requirement-normalised ``J_req``. The search follows B.7: bounded Brent on
log-parameters for one-parameter models; for M1 a profile over a log grid of ``lambda``
(with ``lambda = 0``, the CV baseline, included), then Brent refinement; for M2 Nelder-Mead
on ``(log lambda, log alpha, log sigma_M)`` started from the M1 optimum and Singer's rule.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from .._typing import BoolArray, FloatArray
from ..filters.run import kalman_filter
from ..models.adaptive import InverseDynamics, ShapingFilter, singer_accel_std
from ..models.continuous import ConstantAcceleration, ConstantVelocity, MotionModel, Singer
from ..models.discretize import Noise
from ..parallel import TaskPool
from ..types import GaussianState
from .search import minimise_log

Objective = Literal["position", "velocity", "requirement"]
POSITION_LIMIT_M = 0.7
SPEED_LIMIT_MPS = 2.0 / 3.6


@dataclass(frozen=True, eq=False)
class TrackingData:
    """Measurements and truth of a set of runs, for scoring filters.

    Attributes
    ----------
    times : ndarray, shape (N, T)
    measurements : ndarray, shape (N, T, m)
        Measured positions of the ``n_axes`` axes (then velocities if measured); NaN where
        missing.
    measurement_cov : ndarray, shape (m, m) or (N, T, m, m)
    mask : ndarray of bool, shape (N, T)
    true_position, true_velocity : ndarray, shape (N, T, d)
    score : ndarray of bool, shape (N, T)
        Epochs that enter the criterion.
    """

    times: FloatArray
    measurements: FloatArray
    measurement_cov: FloatArray
    mask: BoolArray
    true_position: FloatArray
    true_velocity: FloatArray
    score: BoolArray

    @property
    def n_axes(self) -> int:
        """Number of axes d."""
        return int(self.true_position.shape[-1])

    @property
    def velocity_measured(self) -> bool:
        """Whether the measurements include velocities."""
        return int(self.measurements.shape[-1]) == 2 * self.n_axes


def two_point_prior(
    data: TrackingData, model: MotionModel, extra_var: float
) -> tuple[GaussianState, int]:
    """Prior at the second epoch from two-point differencing (spec B.6, C.3, check C1.14).

    Position ``z_1``, velocity ``(z_1 - z_0) / dt`` with covariance
    ``R [[1, 1/dt], [1/dt, 2/dt^2]]`` per axis (velocity from the velocity measurement when it
    is measured); any further state (acceleration, shaping state) gets mean 0 and variance
    ``extra_var``. Returns the prior and the index of the first epoch to filter (2).
    """
    d = data.n_axes
    n = model.state_dim
    z0, z1 = data.measurements[:, 0], data.measurements[:, 1]
    dt = data.times[:, 1] - data.times[:, 0]
    r = np.broadcast_to(data.measurement_cov, data.mask.shape + data.measurement_cov.shape[-2:])[
        :, 1
    ]
    mean = np.zeros((z0.shape[0], n))
    cov = np.zeros((z0.shape[0], n, n))
    rp = r[:, :d, :d]
    mean[:, :d] = z1[:, :d]
    cov[:, :d, :d] = rp
    if data.velocity_measured:
        mean[:, d : 2 * d] = z1[:, d:]
        cov[:, d : 2 * d, d : 2 * d] = r[:, d:, d:]
        cov[:, :d, d : 2 * d] = r[:, :d, d:]
        cov[:, d : 2 * d, :d] = r[:, d:, :d]
    else:
        mean[:, d : 2 * d] = (z1[:, :d] - z0[:, :d]) / dt[:, None]
        r0 = np.broadcast_to(
            data.measurement_cov, data.mask.shape + data.measurement_cov.shape[-2:]
        )[:, 0][:, :d, :d]
        cov[:, :d, d : 2 * d] = rp / dt[:, None, None]
        cov[:, d : 2 * d, :d] = rp / dt[:, None, None]
        cov[:, d : 2 * d, d : 2 * d] = (rp + r0) / dt[:, None, None] ** 2
    for i in range(2 * d, n):
        cov[:, i, i] = extra_var
    return GaussianState(mean, cov, data.times[:, 1]), 2


def run_filter(
    model: MotionModel, data: TrackingData, extra_var: float, noise: Noise = "white"
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Filter every run with ``model`` from the two-point prior.

    Returns estimated positions and velocities (N, T, d) (epoch 0: measured position and NaN
    velocity; epoch 1: the two-point estimate) and the filtered covariance of
    ``[positions, velocities]`` (N, T, 2 d, 2 d) (NaN at epoch 0).
    """
    d = data.n_axes
    prior, start = two_point_prior(data, model, extra_var)
    n_meas = data.measurements.shape[-1]
    h = np.zeros((n_meas, model.state_dim))
    h[np.arange(n_meas), np.arange(n_meas)] = 1.0
    r = data.measurement_cov
    r_run = r if r.ndim == 2 else r[:, start:]
    res = kalman_filter(
        data.times[:, start:],
        data.measurements[:, start:],
        model,
        h,
        r_run,
        prior,
        mask=data.mask[:, start:],
        noise=noise,
    )
    n_runs, n_steps = data.mask.shape
    pos = np.full((n_runs, n_steps, d), np.nan)
    vel = np.full((n_runs, n_steps, d), np.nan)
    cov = np.full((n_runs, n_steps, 2 * d, 2 * d), np.nan)
    pos[:, 0] = data.measurements[:, 0, :d]
    pos[:, 1], vel[:, 1] = prior.mean[:, :d], prior.mean[:, d : 2 * d]
    cov[:, 1] = prior.cov[:, : 2 * d, : 2 * d]
    pos[:, start:] = res.filtered.mean[..., :d]
    vel[:, start:] = res.filtered.mean[..., d : 2 * d]
    cov[:, start:] = res.filtered.cov[..., : 2 * d, : 2 * d]
    return pos, vel, cov


def rms_criterion(
    pos: FloatArray, vel: FloatArray, data: TrackingData, objective: Objective = "position"
) -> float:
    """``J_pos``, ``J_vel`` or ``J_req`` over the scored epochs of all runs (spec B.7)."""
    ep = np.sum((pos - data.true_position) ** 2, axis=-1)[data.score]
    ev = np.sum((vel - data.true_velocity) ** 2, axis=-1)[data.score]
    j_pos = math.sqrt(float(np.mean(ep)))
    if objective == "position":
        return j_pos
    j_vel = math.sqrt(float(np.mean(ev)))
    if objective == "velocity":
        return j_vel
    return math.sqrt(((j_pos / POSITION_LIMIT_M) ** 2 + (j_vel / SPEED_LIMIT_MPS) ** 2) / 2)


@dataclass(frozen=True)
class TuningResult:
    """Tuned parameters, the criterion there, and the search record.

    ``profile`` holds J(lambda) for M1 (``{"lambda_per_s2": [...], "criterion": [...],
    "accel_psd": [...]}``); ``params`` is what the model constructor takes.
    """

    model: str
    params: dict[str, Any]
    criterion: float
    objective: str
    n_evaluations: int
    profile: dict[str, list[float]] = field(default_factory=dict)

    def build(self, n_axes: int) -> MotionModel:
        """Build the tuned model for ``n_axes`` axes."""
        cls = {
            "constant_velocity": ConstantVelocity,
            "constant_acceleration": ConstantAcceleration,
            "singer": Singer,
            "inverse_dynamics": InverseDynamics,
            "shaping_filter": ShapingFilter,
        }[self.model]
        return cls(**self.params, n_axes=n_axes)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON/TOML serialisable)."""
        return asdict(self)


class _Scorer:
    """Criterion of a model family on fixed data, counting evaluations."""

    def __init__(
        self, data: TrackingData, objective: Objective, extra_var: float, noise: Noise = "white"
    ) -> None:
        self.data, self.objective, self.extra_var, self.noise = data, objective, extra_var, noise
        self.count = 0

    def __call__(self, model: MotionModel) -> float:
        self.count += 1
        pos, vel, _ = run_filter(model, self.data, self.extra_var, self.noise)
        j = rms_criterion(pos, vel, self.data, self.objective)
        return j if np.isfinite(j) else 1e300


def _brent_log(fn: Callable[[float], float], lo: float, hi: float) -> tuple[float, float]:
    res = minimise_log(lambda v: fn(v[0]), [lo], [(lo, hi)], max_evaluations=500)
    return res.values[0], res.criterion


def tune_constant_velocity(
    data: TrackingData,
    objective: Objective = "position",
    *,
    bounds: tuple[float, float] = (1e-3, 1e3),
) -> TuningResult:
    """CV baseline: ``accel_psd`` by bounded Brent on its log (spec B.7 step 1)."""
    sc = _Scorer(data, objective, 0.0)
    q, j = _brent_log(lambda q: sc(ConstantVelocity(accel_psd=q, n_axes=data.n_axes)), *bounds)
    return TuningResult("constant_velocity", {"accel_psd": q}, j, objective, sc.count)


def tune_constant_acceleration(
    data: TrackingData,
    objective: Objective = "position",
    *,
    bounds: tuple[float, float] = (1e-3, 1e4),
    accel_var: float = 100.0,
) -> TuningResult:
    """CA baseline: ``jerk_psd`` by bounded Brent on its log."""
    sc = _Scorer(data, objective, accel_var)
    q, j = _brent_log(lambda q: sc(ConstantAcceleration(jerk_psd=q, n_axes=data.n_axes)), *bounds)
    return TuningResult("constant_acceleration", {"jerk_psd": q}, j, objective, sc.count)


def tune_singer(
    data: TrackingData,
    objective: Objective = "position",
    *,
    start: tuple[float, float] = (5.0, 2.0),
) -> TuningResult:
    """Singer baseline: ``(time_constant_s, accel_std_mps2)`` by Nelder-Mead on logs."""
    sc = _Scorer(data, objective, start[1] ** 2)

    def f(u: FloatArray) -> float:
        return sc(
            Singer(
                time_constant_s=math.exp(u[0]), accel_std_mps2=math.exp(u[1]), n_axes=data.n_axes
            )
        )

    res = minimize(
        f,
        np.log(start),
        method="Nelder-Mead",
        options={
            "xatol": 1e-3,
            "fatol": 1e-3,
            "initial_simplex": np.log(start) + np.array([[0, 0], [0.5, 0], [0, 0.5]]),
        },
    )
    tau, sig = (float(v) for v in np.exp(res.x))
    return TuningResult(
        "singer",
        {"time_constant_s": tau, "accel_std_mps2": sig},
        float(res.fun),
        objective,
        sc.count,
    )


def _profile_point(
    lam: float, data: TrackingData, objective: Objective, q_lo: float, q_hi: float
) -> tuple[float, float, int]:
    """``(q*, J(lambda, q*), evaluations)``: bounded Brent on ``log q_a`` at one ``lambda``."""
    sc = _Scorer(data, objective, 0.0)
    q, j = _brent_log(
        lambda q: sc(InverseDynamics(lambda_per_s2=lam, accel_psd=q, n_axes=data.n_axes)),
        q_lo,
        q_hi,
    )
    return q, j, sc.count


def tune_inverse_dynamics(
    data: TrackingData,
    objective: Objective = "position",
    *,
    cv: TuningResult | None = None,
    lambdas: FloatArray | None = None,
    pool: TaskPool | None = None,
) -> TuningResult:
    """M1: profile ``J(lambda) = min_q J(lambda, q)`` on a log grid, then refine (B.7 2-3).

    ``lambda = 0`` with the CV optimum is part of the profile, so the result is never worse
    than the CV baseline on the training data (the nesting oracle). The grid points are tasks
    of ``pool`` (in-process when None); the result does not depend on the pool.
    """
    cv = tune_constant_velocity(data, objective) if cv is None else cv
    q_cv = float(cv.params["accel_psd"])
    grid = np.geomspace(1e-4, 1.0, 41) if lambdas is None else np.asarray(lambdas, float)
    pool = TaskPool() if pool is None else pool
    shared = pool.share(data)
    prof = pool.map(
        _profile_point,
        [(float(lam), shared, objective, q_cv / 100, q_cv * 100) for lam in grid],
    )
    count = cv.n_evaluations + sum(p[2] for p in prof)
    lam_all = [0.0] + [float(v) for v in grid]
    j_all = [cv.criterion] + [p[1] for p in prof]
    q_all = [q_cv] + [p[0] for p in prof]
    best = int(np.argmin(j_all))
    lam_opt, q_opt, j_opt = lam_all[best], q_all[best], j_all[best]
    if best > 0:
        lo = lam_all[best - 1] if best > 1 else grid[0] / 10
        hi = lam_all[best + 1] if best + 1 < len(lam_all) else grid[-1]

        def inner(lam: float) -> tuple[float, float]:
            nonlocal count
            q, j, n = _profile_point(lam, data, objective, q_cv / 100, q_cv * 100)
            count += n
            return q, j

        res = minimize_scalar(
            lambda u: inner(math.exp(u))[1],
            bounds=(math.log(lo), math.log(hi)),
            method="bounded",
            options={"xatol": 1e-3},
        )
        if float(res.fun) < j_opt:
            lam_opt = math.exp(float(res.x))
            q_opt, j_opt = inner(lam_opt)
    return TuningResult(
        "inverse_dynamics",
        {"lambda_per_s2": lam_opt, "accel_psd": q_opt},
        j_opt,
        objective,
        count,
        {"lambda_per_s2": lam_all, "criterion": j_all, "accel_psd": q_all},
    )


def tune_shaping_filter(
    data: TrackingData,
    objective: Objective = "position",
    *,
    m1: TuningResult | None = None,
    alpha_per_s: float = 1.0 / 3.0,
    max_accel_mps2: float = 9.0,
    prob_max_accel: float = 0.05,
    prob_no_accel: float = 0.5,
) -> TuningResult:
    """M2: Nelder-Mead on ``(log lambda, log alpha, log sigma_M)`` from the M1 optimum (B.7 4).

    The search is bounded to ``lambda`` in [1e-4, 10] 1/s^2, ``alpha`` in [1e-3, 10] 1/s and
    ``sigma_M`` in [1e-3, 1e4].
    """
    m1 = tune_inverse_dynamics(data, objective) if m1 is None else m1
    lam0 = max(float(m1.params["lambda_per_s2"]), 1e-4)
    sig_a = singer_accel_std(max_accel_mps2, prob_max_accel, prob_no_accel)
    x0 = np.log([lam0, alpha_per_s, sig_a / math.sqrt(lam0)])
    sc = _Scorer(data, objective, 0.0)

    def f(u: FloatArray) -> float:
        lam, al, sm = (float(v) for v in np.exp(u))
        sc.extra_var = sm**2
        return sc(
            ShapingFilter(lambda_per_s2=lam, alpha_per_s=al, shaping_std=sm, n_axes=data.n_axes)
        )

    simplex = x0 + np.vstack([np.zeros(3), 0.5 * np.eye(3)])
    # lambda >= 1e-4 (spec B.4: at lambda = 0 the shaping state no longer drives the motion)
    bounds = [
        (math.log(1e-4), math.log(10.0)),
        (math.log(1e-3), math.log(10.0)),
        (math.log(1e-3), math.log(1e4)),
    ]
    x0 = np.clip(x0, [b[0] for b in bounds], [b[1] for b in bounds])
    simplex = np.clip(simplex, [b[0] for b in bounds], [b[1] for b in bounds])
    res = minimize(
        f,
        x0,
        method="Nelder-Mead",
        bounds=bounds,
        options={"xatol": 1e-3, "fatol": 1e-3, "initial_simplex": simplex},
    )
    lam, al, sm = (float(v) for v in np.exp(res.x))
    return TuningResult(
        "shaping_filter",
        {"lambda_per_s2": lam, "alpha_per_s": al, "shaping_std": sm},
        float(res.fun),
        objective,
        sc.count + m1.n_evaluations,
    )


__all__ = [
    "TrackingData",
    "TuningResult",
    "rms_criterion",
    "run_filter",
    "tune_constant_acceleration",
    "tune_constant_velocity",
    "tune_inverse_dynamics",
    "tune_shaping_filter",
    "tune_singer",
    "two_point_prior",
]
