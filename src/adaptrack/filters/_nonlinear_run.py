"""The time loop shared by the EKF and the UKF.

A linear motion model is predicted with its exact discretisation (the unscented transform of
a linear map is exact, so the UKF loses nothing); a
:class:`~adaptrack.models.NonlinearMotionModel` with the filter's own prediction step
(linearised or by sigma points). The update is the filter's; the loop runs every track of
the batch at once, each on its own time grid.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._typing import ArrayLike, BoolArray, FloatArray
from ..models.continuous import MotionModel, as_motion_model
from ..models.discretize import Method, Noise
from ..models.measurement import MeasurementModel, state_indices
from ..models.turn import NonlinearMotionModel
from ..types import FilterResult, GaussianState, StepInfo, _trusted, as_gaussian_state
from .kalman import CovarianceError, predict
from .run import (
    NanPolicy,
    _per_track,
    _Recorder,
    _transitions,
    check_initial,
    check_measurement_cov,
    check_sequence,
    present_mask,
)
from .square_root import covariance, lower_factor, sqrt_predict

Predict = Callable[
    [GaussianState, NonlinearMotionModel, FloatArray, FloatArray],
    tuple[GaussianState, FloatArray, FloatArray],
]
"""Nonlinear prediction ``(state, model, dt, time) -> (prior, F, Q)``; ``F`` is the step's
(statistical) linearisation, stored for the RTS smoother."""

Update = Callable[
    [GaussianState, FloatArray, MeasurementModel, np.ndarray, FloatArray, BoolArray],
    tuple[GaussianState, StepInfo, FloatArray],
]


@dataclass(frozen=True)
class NonlinearRun:
    """A validated run, broadcast to its batch of tracks ``batch``.

    ``times``, ``steps`` [s] (..., T); ``measurements`` (..., T, m) and ``mask``; ``r`` as
    given (shared, per track or per step: ``r_per_step``); ``model`` the motion model, with
    ``transition``, ``process_cov``, ``control`` (..., T, n[, n]) of each step if it is linear
    (else ``moving`` is it, and they are empty); ``reads`` the state indices that
    ``measurement_model`` reads.
    """

    batch: tuple[int, ...]
    times: FloatArray
    steps: FloatArray
    measurements: FloatArray
    mask: BoolArray
    r: FloatArray
    r_per_step: bool
    initial: GaussianState
    model: MotionModel | NonlinearMotionModel
    moving: NonlinearMotionModel | None
    measurement_model: MeasurementModel
    reads: np.ndarray
    transition: FloatArray
    process_cov: FloatArray
    control: FloatArray

    def noise_per_step(self) -> FloatArray:
        """``R`` broadcast to the result's shape, (..., [T,] m, m)."""
        m = self.measurements.shape[-1]
        per_step = (self.times.shape[-1],) if self.r_per_step else ()
        return np.broadcast_to(self.r, self.batch + per_step + (m, m))


Compiled = Callable[[NonlinearRun], FilterResult | None]
"""A compiled path for a validated run: its result, or None where it does not apply."""


def check_measurement_model(value: object) -> MeasurementModel:
    """Return ``value`` if it implements :class:`~adaptrack.models.MeasurementModel`."""
    if not isinstance(value, MeasurementModel):
        raise TypeError(
            "measurement_model must provide names, reads, angular, noise_cov, predict() and "
            f"jacobian() (see adaptrack.models.MeasurementModel); got {type(value).__name__}"
        )
    return value


def run_nonlinear(
    times: ArrayLike,
    measurements: ArrayLike,
    model: MotionModel | NonlinearMotionModel,
    measurement_model: MeasurementModel,
    initial: GaussianState,
    measurement_cov: ArrayLike | None,
    mask: ArrayLike | None,
    nan_policy: NanPolicy,
    method: Method,
    noise: Noise,
    order: int,
    update: Update,
    predict_nonlinear: Predict,
    compiled: Compiled | None = None,
    square_root: bool = False,
) -> FilterResult:
    """Validate a run's inputs, then filter it step by step.

    The ``compiled`` path's result is taken where it gives one; else each step predicts and
    calls ``update`` over the whole batch (NumPy). ``square_root``: the states carry a
    covariance factor (``GaussianState.factor``) that ``update`` and ``predict_nonlinear`` use
    and return; a linear prediction propagates it
    (:func:`~adaptrack.filters.square_root.sqrt_predict`).
    """
    moving = model if isinstance(model, NonlinearMotionModel) else None
    if moving is None:
        model = as_motion_model(model)
    mm = check_measurement_model(measurement_model)
    initial = as_gaussian_state(initial, "initial")
    idx = state_indices(mm, model.state_names)
    t, z = check_sequence(times, measurements)
    batch, n_steps, m = z.shape[:-2], z.shape[-2], z.shape[-1]
    if m != len(mm.names):
        raise ValueError(
            f"measurements must have {len(mm.names)} components {mm.names} per step; "
            f"got shape {z.shape}"
        )
    r, r_per_step = check_measurement_cov(
        mm.noise_cov if measurement_cov is None else measurement_cov, batch, n_steps, m
    )
    check_initial(initial, model, t, batch)
    mk = present_mask(mask, z, nan_policy)
    n = model.state_dim
    t_init = np.broadcast_to(initial.time, batch)
    if moving is None:
        phi, qd, u = _transitions(
            model,  # type: ignore[arg-type]
            np.broadcast_to(t, batch + (n_steps,)), t_init, method, noise, order,
        )  # fmt: skip
        tb, phi_b, qd_b, u_b = _per_track(batch, t, phi, qd, u)
    else:
        tb = np.broadcast_to(t, batch + (n_steps,))
        phi_b = qd_b = np.empty(0)  # the prediction's linearisation, filled step by step
        u_b = np.zeros(batch + (n_steps, n))
    dt = np.diff(tb, axis=-1, prepend=t_init[..., None])
    run = NonlinearRun(batch, tb, dt, z, mk, r, r_per_step, initial, model, moving, mm, idx,
                       phi_b, qd_b, u_b)  # fmt: skip
    result = None if compiled is None else compiled(run)
    return _steps(run, update, predict_nonlinear, square_root) if result is None else result


def _steps(
    run: NonlinearRun, update: Update, predict_nonlinear: Predict, square_root: bool
) -> FilterResult:
    """Predict and ``update`` step by step over the batch (NumPy)."""
    batch, tb, dt, z, mk, r = run.batch, run.times, run.steps, run.measurements, run.mask, run.r
    phi_b, qd_b, u_b, moving, mm, idx = (run.transition, run.process_cov, run.control,
                                         run.moving, run.measurement_model, run.reads)  # fmt: skip
    n_steps, m = z.shape[-2:]
    n = run.model.state_dim
    if moving is not None:
        phi_b, qd_b = np.empty(batch + (n_steps, n, n)), np.empty(batch + (n_steps, n, n))
    out = _Recorder(batch, n_steps, n, m, factors=square_root)
    h_all = np.empty(batch + (n_steps, m, n))
    initial = run.initial
    x = np.broadcast_to(initial.mean, batch + (n,))
    p = np.broadcast_to(initial.cov, batch + (n, n))
    f = None
    if square_root:
        f = np.broadcast_to(lower_factor(np.asarray(initial.cov)) if initial.factor is None
                            else initial.factor, batch + (n, n))  # fmt: skip
        sq = lower_factor(qd_b) if moving is None else None
    for k in range(n_steps):
        sv = (slice(None),) * len(batch) + (k,)
        state = _trusted(GaussianState, mean=x, cov=p, time=tb[sv], factor=f)
        if moving is None and f is not None:
            xp, fp = sqrt_predict(x, f, phi_b[sv], sq[sv], u_b[sv])  # type: ignore[index]
            prior = _trusted(GaussianState, mean=xp, cov=covariance(fp), time=tb[sv], factor=fp)
        elif moving is None:
            prior = predict(state, phi_b[sv], qd_b[sv], time=tb[sv], control=u_b[sv])
        else:
            prior, phi_b[sv], qd_b[sv] = predict_nonlinear(state, moving, dt[sv], tb[sv])
        rk = r[sv] if run.r_per_step else r
        try:
            post, info, h_all[sv] = update(prior, z[sv], mm, idx, rk, mk[sv])
        except np.linalg.LinAlgError:
            raise CovarianceError(
                f"a covariance is not positive definite at step {k}; check the model, "
                "measurement_cov and the prior"
            ) from None
        x, p, f = post.mean, post.cov, post.factor
        out.store(sv, prior.mean, prior.cov, x, p, info, f)
    return out.result(tb, phi_b, qd_b, u_b, mk, h_all, run.noise_per_step())


def observed(z: FloatArray, z_pred: FloatArray, mask: BoolArray) -> FloatArray:
    """Measurements with the missing components replaced by their prediction."""
    return np.where(mask, z, z_pred)


def full_jacobian(part: FloatArray, idx: np.ndarray, n: int) -> FloatArray:
    """Scatter ``dh/ds`` (..., m, k) over the read states into ``H`` (..., m, n)."""
    h = np.zeros(part.shape[:-1] + (n,))
    h[..., idx] = part
    return h
