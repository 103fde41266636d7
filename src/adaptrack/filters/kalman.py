"""Linear Kalman filter steps as pure functions (batched over leading axes).

Spec 0.2. Predict: ``x = Phi x + u``, ``P = Phi P Phi^T + Qd``. Update (Joseph form by
default): ``nu = z - H x - m_eta``, ``S = H P H^T + R``, ``K = P H^T S^-1``,
``x = x + K nu``, ``P = (I - K H) P (I - K H)^T + K R K^T``, then ``P = sym(P)``.

Missing measurement components (``mask`` False) are handled exactly: their rows of ``H``
are zeroed and their rows/columns of ``R`` replaced by a unit variance decoupled from the
rest, so they carry no information; their innovation is reported as 0 and they are not
counted in the log-likelihood's dimension.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .._linalg import matvec, mT, symmetrize
from .._typing import ArrayLike, BoolArray, FloatArray
from .._validation import as_float_array, check_finite, check_symmetric_pd
from ..models.continuous import MotionModel, as_motion_model, named_measurement_matrix
from ..models.discretize import Method, Noise, discretize_with_input
from ..types import GaussianState, StepInfo, _trusted, as_gaussian_state
from ._measurement import LOG_2PI, masked_model
from .square_root import covariance, lower_factor, sqrt_predict, sqrt_update

UpdateForm = Literal["auto", "joseph", "standard", "sqrt"]

JOSEPH_MAX_RATIO = 1e8
"""Beyond this :func:`joseph_ratio` the ``"auto"`` forms take the square root.

The Joseph form builds ``I - K H`` by cancellation and loses about ``log10`` of that ratio in
digits (means about its 3/2 power in posterior sigmas): at 1e8, half of double precision.
"""


class CovarianceError(ValueError):
    """A covariance that must be positive definite is not (names step and tracks)."""


def predict(
    state: GaussianState,
    transition: FloatArray,
    process_cov: FloatArray,
    *,
    time: ArrayLike,
    control: FloatArray | None = None,
) -> GaussianState:
    """Propagate a Gaussian through a linear transition.

    Parameters
    ----------
    state : GaussianState
        Mean (..., n), cov (..., n, n).
    transition : ndarray, shape (..., n, n)
        ``Phi`` from ``state.time`` to ``time``.
    process_cov : ndarray, shape (..., n, n)
        ``Qd`` over the same step.
    time : array_like, shape (...)
        Time of the prediction [s].
    control : ndarray, shape (..., n), optional
        Known-input offset ``u``.

    Returns
    -------
    GaussianState
        The predicted belief.
    """
    mean = matvec(transition, state.mean)
    if control is not None:
        mean = mean + control
    cov = symmetrize(transition @ state.cov @ mT(transition) + process_cov)
    time_arr = np.broadcast_to(np.asarray(time, dtype=np.float64), mean.shape[:-1])
    return _trusted(GaussianState, mean=mean, cov=cov, time=time_arr)


def _gain(
    cov: FloatArray, h: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return (K, S, log det S); raises LinAlgError if S is not positive definite."""
    hp = h @ cov
    s = symmetrize(hp @ mT(h) + r)
    chol = np.linalg.cholesky(s)
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    k = mT(np.linalg.solve(s, hp))
    return k, s, logdet


def _covariance_update(
    cov: FloatArray, k: FloatArray, h: FloatArray, r: FloatArray, form: str
) -> FloatArray:
    ikh = np.eye(cov.shape[-1]) - k @ h
    if form == "joseph":
        return symmetrize(ikh @ cov @ mT(ikh) + k @ r @ mT(k))
    return symmetrize(ikh @ cov)


def covariance_recursion(
    phi: FloatArray,
    qd: FloatArray,
    h: FloatArray,
    r: FloatArray,
    mask: BoolArray,
    cov0: FloatArray,
    form: str,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Run the covariance recursion shared by tracks with common times, prior, R and mask.

    ``phi``, ``qd`` (T, n, n), ``mask`` (T, m), ``cov0`` (n, n). Returns predicted and filtered
    covariances (T, n, n), innovation covariances (T, m, m), gains (T, n, m), log det S (T,)
    and the masked measurement matrices (T, m, n).

    Raises
    ------
    CovarianceError
        When an innovation covariance is not positive definite (naming the step).
    """
    n_steps, n = phi.shape[0], phi.shape[-1]
    m = h.shape[0]
    pc, fc = np.empty((n_steps, n, n)), np.empty((n_steps, n, n))
    s_a, k_a = np.empty((n_steps, m, m)), np.empty((n_steps, n, m))
    logdet = np.empty(n_steps)
    hm_a = np.empty((n_steps, m, n))
    cov = cov0
    for k in range(n_steps):
        p = phi[k] @ cov @ phi[k].T + qd[k]
        pc[k] = p = 0.5 * (p + p.T)
        hm, rm = masked_model(h, r, None if bool(mask[k].all()) else mask[k])
        try:
            kg, s, ld = _gain(p, hm, rm)
        except np.linalg.LinAlgError:
            raise CovarianceError(
                f"innovation covariance is not positive definite at step {k}; check the "
                "model, measurement_cov and the prior"
            ) from None
        fc[k] = cov = _covariance_update(p, kg, hm, rm, form)
        s_a[k], k_a[k], logdet[k], hm_a[k] = s, kg, ld, hm
    return pc, fc, s_a, k_a, logdet, hm_a


def joseph_ratio(
    innovation_cov: FloatArray, r: FloatArray, mask: BoolArray | None = None
) -> FloatArray:
    """Return ``trace(S) / lambda_min(R)`` with both scaled to ``R``'s unit diagonal.

    The measure of the Joseph update's lost digits (:data:`JOSEPH_MAX_RATIO`). Rescaling
    the measured components by powers of 2 changes no bit of a Kalman update, so the measure
    must not depend on their units either: a radar's metres and radians, or positions and
    speeds, are no ill-conditioning; only ``S`` large against ``R`` or ``R`` nearly singular
    as a correlation is. ``innovation_cov`` (..., m, m) and ``r`` (..., m, m) broadcast
    (``R``'s eigenvalues are computed on ``r`` as given: once when it is shared); components
    where ``mask`` (..., m) is False are left out of the trace (the eigenvalue over all
    components is the smaller one: conservative).
    """
    scale, r_min = joseph_scaling(r)
    s_scaled = np.diagonal(innovation_cov, axis1=-2, axis2=-1) * scale
    if mask is not None:
        s_scaled = np.where(mask, s_scaled, 0.0)
    return np.asarray(s_scaled.sum(axis=-1) / r_min)


def joseph_scaling(r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return ``1 / diag(R)`` (..., m) and ``R``'s smallest eigenvalue at unit diagonal (...).

    :func:`joseph_ratio` is ``sum_a S_aa / R_aa`` over the latter.
    """
    scale = 1.0 / np.diagonal(r, axis1=-2, axis2=-1)
    root = np.sqrt(scale)
    return scale, np.linalg.eigvalsh(r * root[..., :, None] * root[..., None, :])[..., 0]


def exceeds_joseph_limit(innovation_cov: FloatArray, r: FloatArray) -> bool:
    """Whether some :func:`joseph_ratio` exceeds :data:`JOSEPH_MAX_RATIO`.

    ``innovation_cov`` (..., m, m) and ``r`` (..., m, m) broadcast over their batch axes.
    """
    return bool(np.any(joseph_ratio(innovation_cov, r) > JOSEPH_MAX_RATIO))


def _innovation_stats(
    nu: FloatArray, s: FloatArray, logdet: FloatArray, n_obs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    nis = np.einsum("...i,...i->...", nu, np.linalg.solve(s, nu[..., None])[..., 0])
    loglik = np.where(n_obs > 0, -0.5 * (logdet + nis + n_obs * LOG_2PI), 0.0)
    return nis, loglik


def update(
    state: GaussianState,
    measurement: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    form: UpdateForm = "auto",
    measurement_noise_mean: ArrayLike | None = None,
) -> tuple[GaussianState, StepInfo]:
    """Condition a Gaussian state on a linear measurement ``z = H x + v``.

    Parameters
    ----------
    state : GaussianState
        Prior, mean (..., n).
    measurement : array_like, shape (..., m)
        ``z``; entries under a False mask are ignored (may be NaN).
    measurement_matrix : array_like, shape (m, n) or (..., m, n)
        ``H``.
    measurement_cov : array_like, shape (m, m) or (..., m, m)
        ``R`` (for a noise ``D eta`` pass ``D S_eta D^T``), symmetric positive definite.
    mask : array_like of bool, shape (..., m) or (...), optional
        True where a component was measured (default: all).
    form : {"auto", "joseph", "standard", "sqrt"}
        Covariance update: Joseph, the textbook ``(I - K H) P``, or the square-root (array)
        form from ``state.factor`` or a factor of ``state.cov`` (PSD by construction; the
        posterior carries its factor). ``"auto"``: the square root for a state that carries a
        factor, else Joseph unless ``trace(S)`` exceeds :data:`JOSEPH_MAX_RATIO` times the
        smallest eigenvalue of ``R`` or ``S`` is not positive definite, then the square root
        (the criterion of :func:`adaptrack.kalman_filter`).
    measurement_noise_mean : array_like, shape (m,), optional
        Known mean of the measurement noise, removed from the innovation.

    Returns
    -------
    (GaussianState, StepInfo)
        The posterior and the innovation statistics computed from the prior.
    """
    state = as_gaussian_state(state, "state")
    z, h, r, mk, offset = _measurement_inputs(
        state.dim, measurement, measurement_matrix, measurement_cov, mask, measurement_noise_mean
    )
    form = _check_form(form)
    if not _square_root(form, state):
        done = _plain_update(state, z, h, r, mk, form, offset)
        if done is not None:
            return done
    return _sqrt_posterior(state.mean, _factor_of(state), state.time, z, h, r, mk, offset)


def _square_root(form: UpdateForm, state: GaussianState) -> bool:
    """Whether a step takes the square-root form from the start.

    Asked for, or ``"auto"`` on a state that carries a factor (a square-root sequence
    continues as one).
    """
    return form == "sqrt" or (form == "auto" and state.factor is not None)


def _factor_of(state: GaussianState) -> FloatArray:
    """Return the state's factor, or one of its covariance (checked positive semi-definite)."""
    if state.factor is not None:
        return state.factor
    check_symmetric_pd(state.cov, "state.cov", semidefinite=True)
    return lower_factor(state.cov)


def _measurement_inputs(
    dim: int,
    measurement: ArrayLike,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    mask: ArrayLike | None,
    measurement_noise_mean: ArrayLike | None,
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray, FloatArray | None]:
    """Validate one step's measurement arguments against a state of ``dim`` components."""
    z = as_float_array(measurement, "measurement", min_ndim=1, allow_nan=True)
    h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
    r = as_float_array(measurement_cov, "measurement_cov", min_ndim=2)
    if h.shape[-1] != dim:
        raise ValueError(
            f"measurement_matrix must have shape (..., m, {dim}) to match the state; got {h.shape}"
        )
    m = h.shape[-2]
    if z.shape[-1] != m:
        raise ValueError(
            f"measurement must have shape (..., {m}) to match measurement_matrix; got {z.shape}"
        )
    if r.shape[-2:] != (m, m):
        raise ValueError(f"measurement_cov must have shape (..., {m}, {m}); got {r.shape}")
    check_symmetric_pd(r, "measurement_cov")
    mk = _component_mask(mask, z.shape, "mask")
    if np.any(np.isnan(z) & mk):
        idx = tuple(int(i) for i in np.argwhere(np.isnan(z) & mk)[0])
        raise ValueError(f"measurement is NaN at index {idx} where mask says it was measured")
    offset = None
    if measurement_noise_mean is not None:
        offset = as_float_array(measurement_noise_mean, "measurement_noise_mean", min_ndim=1)
        if offset.shape != (m,):
            raise ValueError(f"measurement_noise_mean must have shape ({m},); got {offset.shape}")
    return z, h, r, mk, offset


def _plain_update(
    prior: GaussianState,
    z: FloatArray,
    h: FloatArray,
    r: FloatArray,
    mask: BoolArray,
    form: UpdateForm,
    offset: FloatArray | None,
) -> tuple[GaussianState, StepInfo] | None:
    """Joseph or standard update; None where ``"auto"`` wants the square-root form instead."""
    try:
        post, info = _update(prior, z, h, r, mask, "joseph" if form == "auto" else form, offset)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(symmetrize(h @ prior.cov @ mT(h) + r))
        indefinite = eig[..., 0] < -1e-9 * np.abs(eig).max(axis=-1)
        if form == "auto" and not np.any(indefinite):
            return None  # lost to rounding: the square root keeps it
        bad = indefinite if form == "auto" else eig[..., 0] <= 0
        idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
        raise CovarianceError(
            f"innovation covariance is not positive definite at batch index "
            f"{idx}; is state.cov positive semi-definite?"
        ) from None
    if form == "auto" and exceeds_joseph_limit(info.innovation_cov, r):
        return None
    return post, info


def _sqrt_posterior(
    mean: FloatArray,
    factor: FloatArray,
    time: ArrayLike,
    z: FloatArray,
    h: FloatArray,
    r: FloatArray,
    mask: BoolArray,
    offset: FloatArray | None,
) -> tuple[GaussianState, StepInfo]:
    """Square-root update of a prior given by its mean and covariance factor.

    The posterior carries its factor.
    """
    new_mean, new_factor, info = sqrt_update(mean, factor, z, h, r, mask, offset)
    time_arr = np.broadcast_to(np.asarray(time, dtype=np.float64), new_mean.shape[:-1])
    shape = new_mean.shape + new_mean.shape[-1:]
    cov = np.broadcast_to(covariance(new_factor), shape)
    new_factor = np.broadcast_to(new_factor, shape)
    post = _trusted(GaussianState, mean=new_mean, cov=cov, time=time_arr, factor=new_factor)
    return post, info


def _update(
    state: GaussianState,
    z: FloatArray,
    h: FloatArray,
    r: FloatArray,
    mask: BoolArray,
    form: str,
    offset: FloatArray | None = None,
) -> tuple[GaussianState, StepInfo]:
    """Trusted update kernel (inputs validated by the caller)."""
    full = bool(mask.all())
    hm, rm = masked_model(h, r, None if full else mask)
    zm = np.where(mask, z, 0.0)
    if offset is not None:
        zm = zm - np.where(mask, offset, 0.0)
    nu = zm - matvec(hm, state.mean)
    k, s, logdet = _gain(state.cov, hm, rm)
    cov = _covariance_update(state.cov, k, hm, rm, form)
    mean = state.mean + matvec(k, nu)
    n_obs = np.broadcast_to(mask.sum(axis=-1).astype(np.float64), mean.shape[:-1])
    nis, loglik = _innovation_stats(nu, s, logdet, n_obs)
    full_cov = np.broadcast_to(cov, mean.shape + mean.shape[-1:])
    post = _trusted(GaussianState, mean=mean, cov=full_cov, time=state.time)
    info = _trusted(
        StepInfo,
        innovation=nu,
        innovation_cov=s,
        nis=nis,
        log_likelihood=loglik,
        gain=k,
        n_observed=n_obs,
    )
    return post, info


def _check_form(form: str) -> UpdateForm:
    forms: tuple[UpdateForm, ...] = ("auto", "joseph", "standard", "sqrt")
    for f in forms:
        if form == f:
            return f
    raise ValueError(f"form must be 'auto', 'joseph', 'standard' or 'sqrt'; got {form!r}")


def _component_mask(mask: ArrayLike | None, shape: tuple[int, ...], name: str) -> BoolArray:
    """Broadcast a whole-vector (...) or per-component (..., m) boolean mask to ``shape``."""
    if mask is None:
        return np.ones(shape, dtype=bool)
    mk = np.asarray(mask)
    if mk.dtype != np.bool_:
        raise TypeError(f"{name} must be boolean (True = measured); got dtype {mk.dtype}")
    if mk.shape == shape[:-1]:
        mk = mk[..., None]
    try:
        return np.broadcast_to(mk, shape)
    except ValueError:
        raise ValueError(
            f"{name} must have shape {shape[:-1]} (whole measurements) or {shape} "
            f"(per component); got {mk.shape}"
        ) from None


def kalman_step(
    state: GaussianState,
    measurement: ArrayLike,
    model: MotionModel,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    *,
    time: ArrayLike,
    mask: ArrayLike | None = None,
    method: Method = "expm",
    noise: Noise = "white",
    order: int = 2,
    form: UpdateForm = "auto",
) -> tuple[GaussianState, StepInfo]:
    """One online step: predict ``state`` to ``time`` with ``model``, then update.

    The online counterpart of :func:`adaptrack.kalman_filter`: feeding a sequence step by step
    gives the same numbers as the sequence API. ``time`` equal to ``state.time`` makes the step
    update-only (``Phi = I``, ``Qd = 0``).

    Parameters
    ----------
    state : GaussianState
        Current belief, mean (..., n).
    measurement : array_like, shape (..., m)
        Measurement at ``time``.
    model : MotionModel
        Continuous motion model.
    measurement_matrix, measurement_cov : array_like
        ``H`` (m, n) and ``R`` (m, m) or batched.
    time : array_like, shape (...)
        Measurement time [s], >= ``state.time``.
    mask : array_like of bool, optional
        As in :func:`update`.
    method, noise, order : see :func:`adaptrack.discretize`.
    form : {"auto", "joseph", "standard", "sqrt"}
        As in :func:`update`; the square-root form predicts and updates a factor of the
        covariance (``tria([Phi S, S_q])``, then the update's pre-array) and returns it in
        the state, so the next step continues from it.

    Returns
    -------
    (GaussianState, StepInfo)
    """
    state = as_gaussian_state(state, "state")
    model = as_motion_model(model)
    measurement_matrix = named_measurement_matrix(measurement_matrix, model)
    z, h, r, mk, _ = _measurement_inputs(
        state.dim, measurement, measurement_matrix, measurement_cov, mask, None
    )
    form = _check_form(form)
    t = as_float_array(time, "time")
    check_finite(t, "time")
    dt = np.broadcast_to(t, state.batch_shape) - state.time
    if np.any(dt < 0):
        idx = tuple(int(i) for i in np.argwhere(dt < 0)[0]) if dt.ndim else ()
        raise ValueError(f"time must not precede state.time; dt = {dt[idx]} at batch index {idx}")
    phi, qd, u = discretize_with_input(model, dt, method, noise=noise, order=order)
    times = np.broadcast_to(t, state.batch_shape)
    if not _square_root(form, state):
        prior = predict(state, phi, qd, time=times, control=u)
        done = _plain_update(prior, z, h, r, mk, form, None)
        if done is not None:
            return done
    control = np.zeros(state.dim) if u is None else u
    mean, factor = sqrt_predict(state.mean, _factor_of(state), phi, lower_factor(qd), control)
    return _sqrt_posterior(mean, factor, times, z, h, r, mk, None)


__all__ = [
    "JOSEPH_MAX_RATIO",
    "CovarianceError",
    "exceeds_joseph_limit",
    "joseph_ratio",
    "joseph_scaling",
    "kalman_step",
    "predict",
    "update",
]
