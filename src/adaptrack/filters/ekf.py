"""Extended Kalman filter over a measurement model (radar, GNSS, any ``h(x)``).

The update linearises ``h`` at the predicted mean: ``H = dh/dx(x_pred)``,
``nu = z - h(x_pred)`` (angles wrapped), then the linear update with ``H`` in Joseph or
standard form. Prediction is exact for a linear motion model; a nonlinear one
(:class:`~adaptrack.models.CoordinatedTurn`) is linearised at the filtered mean:
``x_pred = f(x)``, ``P_pred = F P F^T + Q`` with ``F = df/dx(x)``.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Literal

import numpy as np

from .._backend import Backend, use_compiled
from .._linalg import matvec, mT, symmetrize
from .._typing import ArrayLike, BoolArray, FloatArray
from ..models.continuous import MotionModel
from ..models.discretize import Method, Noise
from ..models.measurement import MeasurementModel, PositionMeasurement, RadarMeasurement, residual
from ..models.turn import CoordinatedTurn, NonlinearMotionModel
from ..types import FilterResult, GaussianState, StepInfo, _trusted
from ._measurement import masked_model
from ._nonlinear_run import NonlinearRun, full_jacobian, observed, run_nonlinear
from .kalman import CovarianceError, _covariance_update, _gain, _innovation_stats
from .run import JOSEPH_MAX_RATIO, NanPolicy, _result, worst_joseph_ratio
from .square_root import covariance, lower_factor, sqrt_update, tria

EKFForm = Literal["auto", "joseph", "standard", "sqrt"]


def ekf_update_step(
    prior: GaussianState,
    z: FloatArray,
    model: MeasurementModel,
    idx: np.ndarray,
    r: FloatArray,
    mask: BoolArray,
    form: Literal["joseph", "standard"] = "joseph",
) -> tuple[GaussianState, StepInfo, FloatArray]:
    """One batched EKF update; returns the posterior, its StepInfo and ``H`` (..., m, n).

    ``idx``: the indices of ``model.reads`` in the state; missing components (``mask``
    False) get a zero row of ``H`` and carry no information.
    """
    s = prior.mean[..., idx]
    z_pred = model.predict(s)
    h = full_jacobian(model.jacobian(s), idx, prior.dim)
    nu = residual(model, observed(z, z_pred, mask), z_pred) * mask
    hm, rm = masked_model(h, r, None if bool(mask.all()) else mask)
    k, s_cov, logdet = _gain(prior.cov, hm, rm)
    cov = _covariance_update(prior.cov, k, hm, rm, form)
    mean = prior.mean + matvec(k, nu)
    n_obs = mask.sum(axis=-1).astype(np.float64)
    nis, loglik = _innovation_stats(nu, s_cov, logdet, n_obs)
    post = _trusted(GaussianState, mean=mean, cov=cov, time=prior.time)
    info = _trusted(
        StepInfo, innovation=nu, innovation_cov=s_cov, nis=nis, log_likelihood=loglik,
        gain=k, n_observed=n_obs,
    )  # fmt: skip
    return post, info, hm


def ekf_predict_step(
    state: GaussianState, model: NonlinearMotionModel, dt: FloatArray, time: FloatArray
) -> tuple[GaussianState, FloatArray, FloatArray]:
    """Predict ``state`` through a nonlinear motion model, linearised at its mean.

    ``dt`` (...) [s]; returns the prior, ``F`` and ``Q`` (..., n, n). A state that carries a
    covariance factor gets a predicted factor, ``tria([F S, sqrt(Q)])``.
    """
    mean, f = model.propagate(state.mean, dt)
    q = model.process_cov(dt)
    if state.factor is not None:
        factor = tria(f @ state.factor, lower_factor(q))
        prior = _trusted(GaussianState, mean=mean, cov=covariance(factor), time=time,
                         factor=factor)  # fmt: skip
        return prior, f, q
    cov = symmetrize(f @ state.cov @ mT(f) + q)
    return _trusted(GaussianState, mean=mean, cov=cov, time=time), f, q


def ekf_sqrt_update_step(
    prior: GaussianState,
    z: FloatArray,
    model: MeasurementModel,
    idx: np.ndarray,
    r: FloatArray,
    mask: BoolArray,
) -> tuple[GaussianState, StepInfo, FloatArray]:
    """One batched EKF update in square-root form, from the prior's covariance factor.

    The linearised measurement ``H`` at the predicted mean and the innovation ``z - h(x)`` go
    through :func:`~adaptrack.filters.square_root.sqrt_update`: the posterior factor comes from
    an orthogonal triangularisation, positive semi-definite by construction. Returns as
    :func:`ekf_update_step`.
    """
    s = prior.mean[..., idx]
    z_pred = model.predict(s)
    h = full_jacobian(model.jacobian(s), idx, prior.dim)
    nu = residual(model, observed(z, z_pred, mask), z_pred) * mask
    factor = lower_factor(prior.cov) if prior.factor is None else prior.factor
    mean, post_factor, info = sqrt_update(prior.mean, factor, z, h, r, mask, None, nu)
    post = _trusted(GaussianState, mean=mean, cov=covariance(post_factor), time=prior.time,
                    factor=post_factor)  # fmt: skip
    return post, info, h * mask[..., :, None]


def ekf_filter(
    times: ArrayLike,
    measurements: ArrayLike,
    model: MotionModel | NonlinearMotionModel,
    measurement_model: MeasurementModel,
    initial: GaussianState,
    *,
    measurement_cov: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    nan_policy: NanPolicy = "raise",
    method: Method = "expm",
    noise: Noise = "white",
    order: int = 2,
    form: EKFForm = "auto",
    backend: Backend = "auto",
) -> FilterResult:
    """Run an extended Kalman filter over one track or a batch of tracks.

    Parameters
    ----------
    times : array_like, shape (T,) or (N, T)
        Measurement times [s], strictly increasing per track (per-track grids allowed).
    measurements : array_like, shape (T, m) or (N, T, m)
        Measured components in the order of ``measurement_model.names`` (angles [rad]).
    model : MotionModel or NonlinearMotionModel
        Linear continuous-time motion model, discretised exactly for every step; or a
        nonlinear one (e.g. :class:`~adaptrack.models.CoordinatedTurn`), linearised at each
        filtered mean (``method``, ``noise``, ``order`` do not apply to it).
    measurement_model : MeasurementModel
        E.g. :class:`~adaptrack.models.RadarMeasurement`; it reads the motion model's
        states by name.
    initial : GaussianState
        Prior at ``initial.time`` (at or before the first measurement), scalar or per track.
    measurement_cov : array_like, optional
        ``R`` overriding ``measurement_model.noise_cov``: shape (m, m), (N, m, m) or
        (..., T, m, m) (per step, e.g. reported fix accuracies).
    mask : array_like of bool, shape (..., T) or (..., T, m), optional
        True where a measurement (component) is present; missing ones are predicted
        through (values ignored, may be NaN).
    nan_policy : {"raise", "missing"}
        A NaN under a True mask is an error, or a missing component.
    method, noise, order
        Discretisation options of :func:`adaptrack.discretize`.
    form : {"auto", "joseph", "standard", "sqrt"}
        Covariance update with the linearised ``H``: Joseph, the textbook ``(I - K H) P``, or
        the square-root (array) form (:func:`ekf_sqrt_update_step`, NumPy). ``"auto"``: Joseph
        unless it would lose digits (a covariance not positive definite, or a step whose
        ``trace(S) / lambda_min(R)``, both scaled by ``R``'s standard deviations, exceeds
        :data:`~adaptrack.filters.run.JOSEPH_MAX_RATIO`), then the square root.
    backend : {"auto", "numpy", "numba"}
        ``"numba"`` runs the compiled kernel where it covers the models (a linear motion
        model or :class:`~adaptrack.models.CoordinatedTurn`, with a
        :class:`~adaptrack.models.PositionMeasurement` or
        :class:`~adaptrack.models.RadarMeasurement`; others run in NumPy): the same
        arithmetic, tens of times faster per step on one track. ``"auto"`` does so from
        20,000 track-steps (a first call compiles it, then it is cached on disk).

    Returns
    -------
    FilterResult
        As :func:`adaptrack.kalman_filter`, with ``measurement_matrix`` the Jacobian of each
        step (..., T, m, n); :func:`adaptrack.rts_smooth` smooths it (the extended RTS
        smoother, exact prediction).

    Examples
    --------
    >>> import numpy as np
    >>> from adaptrack.models import ConstantVelocity, RadarMeasurement
    >>> radar = RadarMeasurement(noise_cov=[25.0, 1e-6])
    >>> t = np.arange(5.0)
    >>> truth = np.stack([1000.0 + 10 * t, 2000.0 + 0 * t], -1)
    >>> z = np.stack([np.hypot(*truth.T), np.arctan2(*truth.T)], -1)
    >>> prior = GaussianState([1000.0, 2000.0, 0.0, 0.0], np.diag([1e4, 1e4, 400, 400]), 0.0)
    >>> res = ekf_filter(t, z, ConstantVelocity(0.1, n_axes=2), radar, prior)
    >>> res.filtered.mean.shape
    (5, 4)
    """
    if form not in ("auto", "joseph", "standard", "sqrt"):
        raise ValueError(f"form must be 'auto', 'joseph', 'standard' or 'sqrt'; got {form!r}")
    z_size = np.size(measurements) // max(1, len(getattr(measurement_model, "names", ())))
    compiled = use_compiled(backend, z_size)

    def run(chosen: str) -> FilterResult:
        if chosen == "sqrt":
            return run_nonlinear(
                times, measurements, model, measurement_model, initial, measurement_cov, mask,
                nan_policy, method, noise, order, ekf_sqrt_update_step, ekf_predict_step,
                square_root=True,
            )  # fmt: skip
        joseph = chosen == "joseph"
        return run_nonlinear(
            times, measurements, model, measurement_model, initial, measurement_cov, mask,
            nan_policy, method, noise, order,
            partial(ekf_update_step, form="joseph" if joseph else "standard"), ekf_predict_step,
            partial(_compiled_run, joseph=joseph) if compiled else None,
        )  # fmt: skip

    if form != "auto":
        return run(form)
    return auto_square_root(lambda: run("joseph"), lambda: run("sqrt"))


def auto_square_root(
    joseph: Callable[[], FilterResult], square_root: Callable[[], FilterResult]
) -> FilterResult:
    """Apply the ``form="auto"`` rule of the EKF and UKF.

    The ``joseph()`` run, unless it raised :class:`CovarianceError` or its
    :func:`~adaptrack.filters.run.worst_joseph_ratio` passes
    :data:`~adaptrack.filters.run.JOSEPH_MAX_RATIO`; then
    the ``square_root()`` run.
    """
    try:
        result = joseph()
    except CovarianceError:
        return square_root()
    return result if worst_joseph_ratio(result) <= JOSEPH_MAX_RATIO else square_root()


def _compiled_run(run: NonlinearRun, joseph: bool) -> FilterResult | None:
    """Return the run's result from the compiled kernel (:mod:`adaptrack.filters._ekf_kernel`).

    None where the kernel does not cover its models, or a covariance stopped being positive
    definite (the NumPy path then names the step).
    """
    mm, moving = run.measurement_model, run.moving
    if not isinstance(mm, PositionMeasurement | RadarMeasurement) or not (
        moving is None or isinstance(moving, CoordinatedTurn)
    ):
        return None
    from ._ekf_kernel import ekf_kernel
    from ._radar_update import radar_layout
    from ._turn_kernel import turn_parameters

    batch, (n_steps, m), n = run.batch, run.measurements.shape[-2:], run.model.state_dim
    n_tr = int(np.prod(batch, dtype=int))

    def tracks(a: np.ndarray, tail: tuple[int, ...]) -> np.ndarray:  # (N, ...), writable
        return _writable(np.broadcast_to(a, batch + tail).reshape((n_tr, *tail)))

    turn_par: np.ndarray = np.zeros(4)
    if moving is None:
        phi, qd = (tracks(a, (n_steps, n, n)) for a in (run.transition, run.process_cov))
    else:  # the kernel writes each step's F and Q
        phi, qd = np.zeros((n_tr, n_steps, n, n)), np.zeros((n_tr, n_steps, n, n))
        turn_par = turn_parameters(moving)
    h = np.zeros((m, n))
    codes: np.ndarray = np.zeros(0, np.int64)
    pose: np.ndarray = np.zeros(8)
    if isinstance(mm, RadarMeasurement):
        codes, pose = radar_layout(mm)
    else:
        h[np.arange(m), run.reads] = 1.0
    r = run.r
    r4 = (r.reshape(n_tr, n_steps, m, m) if run.r_per_step
          else r[None, None] if r.shape == (m, m) else r.reshape(n_tr, 1, m, m))  # fmt: skip
    *out, h_steps, status = ekf_kernel(
        _writable(run.initial.mean.reshape(-1, n)),
        _writable(run.initial.cov.reshape(-1, n, n)),
        phi, qd, tracks(run.control, (n_steps, n)), tracks(run.steps, (n_steps,)),
        tracks(run.measurements, (n_steps, m)), tracks(run.mask, (n_steps, m)),
        _writable(r4), h, turn_par, codes, pose, run.reads.astype(np.int64), joseph,
    )  # fmt: skip
    if status.any():
        return None
    pm, pc, fm, fc, nu, s, nis, ll, k, nobs = (a.reshape(batch + a.shape[1:]) for a in out)
    return _result(
        run.times, pm, pc, fm, fc, phi.reshape(batch + phi.shape[1:]),
        qd.reshape(batch + qd.shape[1:]), run.control, nu, s, nis, ll, k, nobs, run.mask,
        h_steps.reshape(batch + h_steps.shape[1:]), run.noise_per_step(),
    )  # fmt: skip


def _writable(a: np.ndarray) -> np.ndarray:
    """Return ``a`` as a C-contiguous writable array (a copy only if it is not one)."""
    return np.require(a, requirements=("C", "W"))


__all__ = ["ekf_filter", "ekf_predict_step", "ekf_sqrt_update_step", "ekf_update_step"]
