"""Kalman filter over measurement sequences, for one track or a batch of tracks.

Loops over time steps only; every track of the batch is processed at once. Irregular
sampling (per-track times) is the norm: the transition is discretised for every step's
``dt``. When all tracks share their times, prior covariance, measurement covariance and
missing-data pattern, the covariance recursion is identical for every track; it is then
computed once and shared (the result holds broadcast views), which is exact and fast.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal, TypeVar

import numpy as np

from .._backend import SHARED_MIN_TRACKS, Backend, use_compiled
from .._linalg import matvec
from .._typing import AnyArray, ArrayLike, BoolArray, FloatArray
from .._validation import (
    as_float_array,
    check_symmetric_pd,
    check_times,
)
from ..models.continuous import MotionModel, as_motion_model, named_measurement_matrix
from ..models.discretize import Method, Noise, discretize_with_input
from ..models.turn import NonlinearMotionModel
from ..types import FilterResult, GaussianState, StepInfo, _trusted, as_gaussian_state
from ._measurement import masked_model
from .kalman import (
    JOSEPH_MAX_RATIO,
    CovarianceError,
    _component_mask,
    _innovation_stats,
    _update,
    covariance_recursion,
    exceeds_joseph_limit,
    joseph_ratio,
    predict,
)
from .square_root import covariance, lower_factor, sqrt_predict, sqrt_update

SERIES_MIN_STEPS = 256  # from this many distinct step lengths, series tables
NanPolicy = Literal["raise", "missing"]
FilterForm = Literal["auto", "joseph", "standard", "sqrt"]
_Result = TypeVar("_Result")


def kalman_filter(
    times: ArrayLike,
    measurements: ArrayLike,
    model: MotionModel,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    initial: GaussianState,
    *,
    mask: ArrayLike | None = None,
    nan_policy: NanPolicy = "raise",
    method: Method = "expm",
    noise: Noise = "white",
    order: int = 2,
    form: FilterForm = "auto",
    measurement_noise_mean: ArrayLike | None = None,
    backend: Backend = "auto",
) -> FilterResult:
    """Run a linear Kalman filter over one track or a batch of tracks.

    Parameters
    ----------
    times : array_like, shape (T,) or (N, T)
        Measurement times [s], strictly increasing per track; a 1-D array is shared by all
        tracks.
    measurements : array_like, shape (T, m) or (N, T, m)
        Measurements ``z``.
    model : MotionModel
        Continuous-time motion model, discretised for every step (``method``, ``noise``,
        ``order`` as in :func:`adaptrack.discretize`).
    measurement_matrix : array_like, shape (m, n), or sequence of str
        ``H``, or the names of the measured state components (``["x", "y"]``: see
        :func:`adaptrack.models.measurement_matrix`; FilterPy's layout differs, see
        :func:`adaptrack.models.filterpy_order`).
    measurement_cov : array_like, shape (m, m), (N, m, m) or (..., T, m, m)
        ``R``: shared, per track, or per step; symmetric positive definite.
    initial : GaussianState
        Prior at ``initial.time`` (scalar or per track), applied to the first measurement;
        its covariance must be symmetric positive semi-definite (a zero variance is a known
        component):
        when ``initial.time`` equals the first measurement time, step 0 is update-only
        (spec 0.2); an earlier time is predicted forward first.
    mask : array_like of bool, shape (..., T) or (..., T, m), optional
        True where a measurement (component) is present. Missing entries are predicted
        through; their values are ignored and may be NaN.
    nan_policy : {"raise", "missing"}
        What a NaN in a measurement that the mask calls present means: an error (default)
        or a missing component. Nothing is ever dropped silently.
    method, noise, order
        Discretisation options.
    form : {"auto", "joseph", "standard", "sqrt"}
        Covariance form: Joseph or standard update of ``P``, or the square-root (array) filter
        that carries a factor of ``P`` (:mod:`adaptrack.filters.square_root`): symmetric PSD
        by construction and accurate on ill-conditioned problems (long gaps, tiny noise,
        condition numbers to 1e12), at 2-5 times the cost. ``"auto"``: Joseph, rerun in
        square-root form where Joseph would lose more than 8 digits (an innovation
        covariance above 1e8 times the smallest measurement variance) or loses definiteness.
    measurement_noise_mean : array_like, shape (m,), optional
        Known mean of the measurement noise, removed from every innovation.
    backend : {"auto", "numpy", "numba"}
        ``"numpy"``: the readable reference implementation; ``"numba"``: the compiled kernel
        (same results to rounding, <= 1e-10 relative); ``"auto"``: the kernel from
        20,000 track-steps on, NumPy below (then the online :func:`kalman_step` reproduces the
        result bit for bit) and for batches of 64 or more tracks that share one covariance
        recursion (the exact shared path computes it once; see also
        :func:`adaptrack.shared_gain_filter`).

    Returns
    -------
    FilterResult
        Predicted and filtered moments (..., T, n), the transitions used, innovations, NIS
        and log-likelihood per step.

    Raises
    ------
    ValueError
        For bad shapes, non-finite values, unsorted or duplicate times, an initial time after
        the first measurement, or covariances that are not positive definite (naming the
        argument, step and track).

    Examples
    --------
    >>> import numpy as np
    >>> from adaptrack.models import ConstantVelocity
    >>> t = np.arange(5.0)
    >>> z = (2.0 * t)[:, None]
    >>> prior = GaussianState(mean=[0.0, 0.0], cov=100.0 * np.eye(2), time=0.0)
    >>> res = kalman_filter(t, z, ConstantVelocity(accel_psd=0.01), [[1.0, 0.0]], [[1.0]], prior)
    >>> res.filtered.mean.shape
    (5, 2)
    """
    model = as_motion_model(model)
    measurement_matrix = named_measurement_matrix(measurement_matrix, model)
    initial = as_gaussian_state(initial, "initial")
    if form not in ("auto", "joseph", "standard", "sqrt"):
        raise ValueError(f"form must be 'auto', 'joseph', 'standard' or 'sqrt'; got {form!r}")
    if nan_policy not in ("raise", "missing"):
        raise ValueError(f"nan_policy must be 'raise' or 'missing'; got {nan_policy!r}")
    n = model.state_dim
    t, z = check_sequence(times, measurements)
    batch, n_steps, m = z.shape[:-2], z.shape[-2], z.shape[-1]
    h = measurement_matrix_for(measurement_matrix, m, n)
    r, r_per_step = check_measurement_cov(measurement_cov, batch, n_steps, m)
    check_initial(initial, model, t, batch)
    if measurement_noise_mean is not None:
        mu = as_float_array(measurement_noise_mean, "measurement_noise_mean")
        if mu.shape not in ((), (m,)):
            raise ValueError(f"measurement_noise_mean must have shape ({m},); got {mu.shape}")
    mk = present_mask(mask, z, nan_policy)
    batch = z.shape[:-2]
    n_tracks = int(np.prod(batch, dtype=int))
    compiled = use_compiled(backend, z.size // max(m, 1)) and (
        backend == "numba"
        or not (n_tracks >= SHARED_MIN_TRACKS and _covariance_shared(t, initial, r, mk))
    )
    problem = _Problem(
        t,
        z,
        model,
        h,
        r,
        r_per_step,
        initial,
        mk,
        method,
        noise,
        order,
        "joseph" if form == "auto" else form,
        measurement_noise_mean,
    )
    if form != "auto":
        return _solve(problem, compiled)

    def joseph() -> tuple[FilterResult, float]:
        result = _solve(problem, compiled)
        return result, worst_joseph_ratio(result)

    return auto_form(joseph, lambda: _solve(replace(problem, form="sqrt"), compiled), r)


def check_sequence(times: ArrayLike, measurements: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate times (T,) or (N, T) and measurements (T, m) or (N, T, m) of a filter run."""
    t = as_float_array(times, "times", min_ndim=1)
    if t.ndim > 2:
        raise ValueError(f"times must have shape (T,) or (N, T); got {t.shape}")
    z = as_float_array(measurements, "measurements", min_ndim=2, allow_nan=True)
    if z.ndim > 3:
        raise ValueError(f"measurements must have shape (T, m) or (N, T, m); got {z.shape}")
    batch = z.shape[:-2]
    n_steps = z.shape[-2]
    if t.shape not in ((n_steps,), batch + (n_steps,)):
        raise ValueError(
            f"times must have shape ({n_steps},) or {batch + (n_steps,)} to match "
            f"measurements {z.shape}; got {t.shape}"
        )
    if n_steps == 0:
        raise ValueError("measurements must hold at least one time step; got T = 0")
    check_times(t, "times")
    return t, z


def check_measurement_cov(
    value: ArrayLike, batch: tuple[int, ...], n_steps: int, m: int
) -> tuple[FloatArray, bool]:
    """Validate ``R``: shared (m, m), per track or per step; return it and whether per step."""
    r = as_float_array(value, "measurement_cov", min_ndim=2)
    r_per_step = r.shape == batch + (n_steps, m, m) and r.shape != (m, m)
    if r.shape not in ((m, m), batch + (m, m), batch + (n_steps, m, m)):
        raise ValueError(
            f"measurement_cov must have shape ({m}, {m}), {batch + (m, m)} or "
            f"{batch + (n_steps, m, m)}; got {r.shape}"
        )
    check_symmetric_pd(r, "measurement_cov")
    return r, r_per_step


def check_initial(
    initial: GaussianState, model: MotionModel | NonlinearMotionModel, t: FloatArray,
    batch: tuple[int, ...],
) -> None:  # fmt: skip
    """Check the prior's size, batch shape, covariance and time against the run."""
    n = model.state_dim
    if initial.dim != n:
        raise ValueError(
            f"initial.mean must have shape (..., {n}) to match the model "
            f"{model.state_names}; got {initial.mean.shape}"
        )
    if initial.batch_shape not in ((), batch):
        raise ValueError(
            f"initial must have batch shape () or {batch} to match measurements; "
            f"got {initial.batch_shape}"
        )
    check_symmetric_pd(initial.cov, "initial.cov", semidefinite=True)
    t0 = t[..., 0]
    late = np.broadcast_to(initial.time, batch) > np.broadcast_to(t0, batch)
    if np.any(late):
        idx = tuple(int(i) for i in np.argwhere(late)[0]) if batch else ()
        raise ValueError(
            f"initial.time must not be after the first measurement time; track "
            f"{idx}: {np.broadcast_to(initial.time, batch)[idx]} > "
            f"{np.broadcast_to(t0, batch)[idx]}"
        )


def present_mask(mask: ArrayLike | None, z: FloatArray, nan_policy: NanPolicy) -> BoolArray:
    """Return the components to use (..., T, m): ``mask``, with NaN an error or missing."""
    batch = z.shape[:-2]
    mk = np.array(_component_mask(mask, z.shape, "mask"))
    nan = np.isnan(z) & mk
    if np.any(nan):
        if nan_policy == "raise":
            idx = tuple(int(i) for i in np.argwhere(nan)[0])
            where = (
                f"track {idx[0]}, step {idx[1]}, component {idx[2]}"
                if batch
                else f"step {idx[0]}, component {idx[1]}"
            )
            raise ValueError(
                f"measurements is NaN at {where} where it is marked present; pass "
                "mask=... or nan_policy='missing' to treat NaN as missing"
            )
        mk = mk & ~nan
    return mk


def auto_form(
    joseph: Callable[[], tuple[_Result, float]], sqrt: Callable[[], _Result], r: FloatArray
) -> _Result:
    """Apply the ``form="auto"`` rule of every batch path: Joseph unless the root is needed.

    ``joseph()`` runs the Joseph form and returns its result and worst
    :func:`~adaptrack.filters.kalman.joseph_ratio`; ``sqrt()`` runs the square-root form.
    The square root is taken where
    ``R`` alone already exceeds the limit (then every step would), where Joseph loses
    definiteness (``CovarianceError``), or where its worst ratio exceeds
    :data:`JOSEPH_MAX_RATIO`.
    """
    if exceeds_joseph_limit(r, r):  # S >= R: every step would exceed the Joseph limit
        return sqrt()
    try:
        result, worst = joseph()
    except CovarianceError:
        return sqrt()
    return result if worst <= JOSEPH_MAX_RATIO else sqrt()


# The Joseph update forms I - K H = R S^-1 (in the measured directions) by cancellation, so
# P+ and the gain carry a relative error of about eps * lambda_max(S) / lambda_min(R); the
# mean's error in posterior sigmas grows as the 3/2 power of that ratio. Above 1e8 (8 digits
# of 16 lost, means off by ~1e-4 sigma) the square-root form is used instead.
def measurement_matrix_for(measurement_matrix: ArrayLike, m: int, n: int) -> FloatArray:
    """``measurement_matrix`` as a float (m, n) array, or a ValueError naming both sizes."""
    h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
    if h.shape != (m, n):
        raise ValueError(
            f"measurement_matrix must have shape ({m}, {n}) to match measurements "
            f"(m = {m}) and model (n = {n}); got {h.shape}"
        )
    return h


def worst_joseph_ratio(result: FilterResult) -> float:
    """Return the largest :func:`~adaptrack.filters.kalman.joseph_ratio` of a run's steps.

    Over the observed components of each step (any filter's :class:`FilterResult`).
    """
    r = result.measurement_cov
    s = result.info.innovation_cov
    if 2 < r.ndim < s.ndim:  # one R per track: the same at every step
        r = r[..., None, :, :]
    return float(np.max(joseph_ratio(s, r, result.mask), initial=0.0))


def _solve(problem: _Problem, compiled: bool) -> FilterResult:
    """Run a validated problem through the compiled kernel or the NumPy reference."""
    if compiled:
        try:
            return _run_compiled(problem)
        except ValueError:
            pass  # a covariance stopped being positive definite: the reference path names it
    return _run(problem)


@dataclass(frozen=True)
class _Problem:
    """A validated filtering problem: the arguments of :func:`kalman_filter` after checks."""

    t: FloatArray
    z: FloatArray
    model: MotionModel
    h: FloatArray
    r: FloatArray
    r_per_step: bool
    initial: GaussianState
    mask: BoolArray
    method: Method
    noise: Noise
    order: int
    form: str
    offset: ArrayLike | None


def _covariance_shared(
    t: FloatArray, initial: GaussianState, r: FloatArray, mask: BoolArray
) -> bool:
    """Whether every track has the same covariance recursion (times, prior, R and mask)."""
    n_steps, m = mask.shape[-2:]
    t_init = np.asarray(initial.time)
    return (
        t.ndim == 1
        and initial.cov.ndim == 2
        and r.ndim == 2
        and bool(np.all(t_init == t_init.flat[0]))
        and bool(np.all(mask == mask.reshape(-1, n_steps, m)[0]))
    )


def _run_compiled(p: _Problem) -> FilterResult:
    """Run the same filter through the compiled kernel (:mod:`adaptrack.filters._kernels`)."""
    from ._kernels import run_kernels

    t, z, model, h, r, initial, mask = p.t, p.z, p.model, p.h, p.r, p.initial, p.mask
    method, noise, order, r_per_step = p.method, p.noise, p.order, p.r_per_step

    batch = z.shape[:-2]
    n_steps, m = z.shape[-2:]
    n = model.state_dim
    n_tr = int(np.prod(batch, dtype=int))
    t_init = np.broadcast_to(initial.time, batch)
    if t.ndim == 1 and bool(np.all(t_init == t_init.flat[0])):
        phi, qd, u = _transitions(model, t, t_init.flat[0], method, noise, order)
        phi, qd, u = phi[None], qd[None], u[None]
    else:
        phi, qd, u = _transitions(
            model, np.broadcast_to(t, batch + (n_steps,)), t_init, method, noise, order
        )
        phi, qd, u = (a.reshape((n_tr, n_steps) + a.shape[len(batch) + 1 :]) for a in (phi, qd, u))
    if r.shape == (m, m):
        r4 = r[None, None]
    elif r_per_step:
        r4 = r.reshape(n_tr, n_steps, m, m)
    else:
        r4 = r.reshape(n_tr, 1, m, m)
    x0 = initial.mean.reshape(-1, n)
    p0 = initial.cov.reshape(-1, n, n)
    off = (
        np.zeros(m)
        if p.offset is None
        else np.broadcast_to(as_float_array(p.offset, "measurement_noise_mean"), (m,))
    )
    zk, mk = z.reshape(n_tr, n_steps, m), mask.reshape(n_tr, n_steps, m)
    if p.form == "sqrt":
        from ._sqrt_kernel import sqrt_kernel

        c = np.ascontiguousarray
        out = sqrt_kernel(
            c(x0),
            c(lower_factor(p0)),
            c(phi),
            c(lower_factor(qd)),
            c(u),
            c(zk),
            c(mk),
            h,
            c(r4),
            off,
        )
        ff = out[-1].reshape(batch + out[-1].shape[1:])
        out = out[:-1]
    else:
        out = run_kernels(x0, p0, phi, qd, u, zk, mk, h, r4, off, p.form == "joseph")
        ff = None
    pm, pc, fm, fc, nu, s_a, nis, ll, k_a, nobs = (a.reshape(batch + a.shape[1:]) for a in out)
    tb = np.broadcast_to(t, batch + (n_steps,))

    def expand(x: FloatArray) -> FloatArray:
        """(1 | N, T, ...) -> batch + (T, ...), broadcasting a shared first axis."""
        tail = batch + x.shape[1:]
        return np.broadcast_to(x[0], tail) if x.shape[0] == 1 else x.reshape(tail)

    return _result(
        tb,
        pm,
        pc,
        fm,
        fc,
        expand(phi),
        expand(qd),
        expand(u),
        nu,
        s_a,
        nis,
        ll,
        k_a,
        nobs,
        mask,
        h,
        np.broadcast_to(r, batch + ((n_steps,) if r_per_step else ()) + (m, m)),
        factor=ff,
    )


def _transitions(
    model: MotionModel, t: FloatArray, t_init: FloatArray, method: Method, noise: Noise, order: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Phi, Qd and control offsets per step (entry k maps step k-1 -> k)."""
    prev = np.concatenate([np.broadcast_to(t_init, t.shape[:-1])[..., None], t[..., :-1]], axis=-1)
    return step_transitions(model, t - prev, method, noise, order)


def _distinct_at_least(values: FloatArray, count: int) -> bool:
    """Whether ``values`` hold at least ``count`` distinct numbers.

    An evenly strided sample of 16 ``count`` values decides when it has enough; only
    otherwise are all values sorted (millions of jittered steps need no full sort).
    """
    flat = values.reshape(-1)
    if flat.size < count:
        return False
    sample = flat[:: max(1, flat.size // (16 * count))]
    return np.unique(sample).size >= count or np.unique(flat).size >= count


def step_transitions(
    model: MotionModel, dt: FloatArray, method: Method, noise: Noise, order: int = 2
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Phi, Qd and control offsets for every step length in ``dt`` (any shape).

    Each distinct step is discretised once, unless there are at least
    :data:`SERIES_MIN_STEPS` distinct ones (jittered sampling: every step length new): then
    the exact white-noise discretisation (``expm``, ``analytic`` or ``auto``) is evaluated for
    every step by the model's series table, compiled (:mod:`adaptrack.models.series_table`:
    exact to rounding), not by one matrix exponential per distinct step.
    """
    exact = method in ("expm", "analytic", "auto") and noise == "white"
    if exact and _distinct_at_least(dt, SERIES_MIN_STEPS):
        from ..models.series_table import model_series_table, shortened
        from ._kernels import series_transitions

        if np.any(dt < 0):
            return discretize_with_input(model, dt, method, noise=noise, order=order)  # names it
        table = shortened(model_series_table(model, float(dt.max(initial=0.0))))
        parts = series_transitions(
            np.ascontiguousarray(dt).reshape(-1), table.phi_coef, table.qd_coef,
            table.offset_coef, table.h_max,
        )  # fmt: skip
        return tuple(a.reshape(dt.shape + a.shape[1:]) for a in parts)
    return discretize_with_input(model, dt, method, noise=noise, order=order)


def _run(p: _Problem) -> FilterResult:
    """Run the NumPy reference filter (shared-covariance path when every track shares it)."""
    t, z, model, h, r, initial, mask = p.t, p.z, p.model, p.h, p.r, p.initial, p.mask
    method, noise, order, form, offset = p.method, p.noise, p.order, p.form, p.offset
    batch = z.shape[:-2]
    n_steps = z.shape[-2]
    t_init = np.broadcast_to(initial.time, batch)
    times_shared = t.ndim == 1 and bool(np.all(t_init == t_init.flat[0]))
    if times_shared:
        phi, qd, u = _transitions(model, t, t_init.flat[0], method, noise, order)
    else:
        phi, qd, u = _transitions(
            model, np.broadcast_to(t, batch + (n_steps,)), t_init, method, noise, order
        )
    off = None if offset is None else as_float_array(offset, "measurement_noise_mean", min_ndim=1)
    if form != "sqrt" and times_shared and _covariance_shared(t, initial, r, mask):
        return _run_shared(t, z, h, r, initial, mask, phi, qd, u, form, off)
    return _run_per_track(t, z, h, r, p.r_per_step, initial, mask, phi, qd, u, form, off)


def _alloc(batch: tuple[int, ...], n_steps: int, *tail: int) -> FloatArray:
    return np.empty(batch + (n_steps,) + tail)


def _step_view(a: FloatArray, k: int, batch_ndim: int) -> FloatArray:
    return a[(slice(None),) * batch_ndim + (k,)]


def _raise_not_pd(what: str, k: int, tracks: list[int] | None) -> None:
    where = f"step {k}" + (f", tracks {tracks[:10]}" if tracks else "")
    raise CovarianceError(
        f"{what} is not positive definite at {where}; check the model, "
        "measurement_cov and the prior"
    )


class _Recorder:
    """Per-step outputs of a filter run over batch + (T,), turned into a FilterResult."""

    def __init__(
        self, batch: tuple[int, ...], n_steps: int, n: int, m: int, factors: bool = False
    ) -> None:
        self.pm, self.pc = _alloc(batch, n_steps, n), _alloc(batch, n_steps, n, n)
        self.fm, self.fc = _alloc(batch, n_steps, n), _alloc(batch, n_steps, n, n)
        self.ff = _alloc(batch, n_steps, n, n) if factors else None  # filtered factors
        self.nu, self.s = _alloc(batch, n_steps, m), _alloc(batch, n_steps, m, m)
        self.nis, self.ll = _alloc(batch, n_steps), _alloc(batch, n_steps)
        self.nobs, self.k = _alloc(batch, n_steps), _alloc(batch, n_steps, n, m)

    def store(
        self,
        sv: tuple[slice | int, ...],
        pm: FloatArray,
        pc: FloatArray,
        fm: FloatArray,
        fc: FloatArray,
        info: StepInfo,
        factor: FloatArray | None = None,
    ) -> None:
        """Keep step ``sv``'s predicted and filtered moments (and factor) and its StepInfo."""
        self.pm[sv], self.pc[sv], self.fm[sv], self.fc[sv] = pm, pc, fm, fc
        if self.ff is not None:
            self.ff[sv] = factor
        self.nu[sv], self.s[sv], self.nis[sv] = info.innovation, info.innovation_cov, info.nis
        self.ll[sv], self.nobs[sv], self.k[sv] = info.log_likelihood, info.n_observed, info.gain

    def result(
        self,
        t: FloatArray,
        phi: FloatArray,
        qd: FloatArray,
        u: FloatArray,
        mask: BoolArray,
        h: FloatArray,
        r: FloatArray,
    ) -> FilterResult:
        """Return the FilterResult of the recorded steps and the run's inputs."""
        return _result(
            t,
            self.pm,
            self.pc,
            self.fm,
            self.fc,
            phi,
            qd,
            u,
            self.nu,
            self.s,
            self.nis,
            self.ll,
            self.k,
            self.nobs,
            mask,
            h,
            r,
            factor=self.ff,
        )


def _run_per_track(
    t: FloatArray,
    z: FloatArray,
    h: FloatArray,
    r: FloatArray,
    r_per_step: bool,
    initial: GaussianState,
    mask: BoolArray,
    phi: FloatArray,
    qd: FloatArray,
    u: FloatArray,
    form: str,
    off: FloatArray | None,
) -> FilterResult:
    """Run the filter with a covariance recursion per track (Joseph/standard or square root).

    Square-root form: :mod:`adaptrack.filters.square_root`, the factors of ``Qd`` taken once.
    """
    batch = z.shape[:-2]
    n_steps, m = z.shape[-2:]
    n = phi.shape[-1]
    tb, phi_b, qd_b, u_b = _per_track(batch, t, phi, qd, u)
    sqrt = form == "sqrt"
    sq_b = np.broadcast_to(lower_factor(qd), batch + (n_steps, n, n)) if sqrt else qd_b
    out = _Recorder(batch, n_steps, n, m, factors=sqrt)
    x = np.broadcast_to(initial.mean, batch + (n,))
    carried = np.broadcast_to(lower_factor(initial.cov) if sqrt else initial.cov, batch + (n, n))
    for k in range(n_steps):
        sv = (slice(None),) * len(batch) + (k,)
        rk = r[sv] if r_per_step else r
        if sqrt:
            xp, sp = sqrt_predict(x, carried, phi_b[sv], sq_b[sv], u_b[sv])
            x, carried, info = sqrt_update(xp, sp, z[sv], h, rk, mask[sv], off)
            out.store(sv, xp, covariance(sp), x, covariance(carried), info, carried)
            continue
        state = _trusted(GaussianState, mean=x, cov=carried, time=tb[sv])
        prior = predict(state, phi_b[sv], qd_b[sv], time=tb[sv], control=u_b[sv])
        try:
            post, info = _update(prior, z[sv], h, rk, mask[sv], form, off)
        except np.linalg.LinAlgError:
            _raise_not_pd("innovation covariance", k, _bad_tracks(prior.cov, h, rk, mask[sv]))
        x, carried = post.mean, post.cov
        out.store(sv, prior.mean, prior.cov, x, carried, info)
    r_b = np.broadcast_to(r, batch + ((n_steps,) if r_per_step else ()) + (m, m))
    return out.result(tb, phi_b, qd_b, u_b, mask, h, r_b)


def _per_track(
    batch: tuple[int, ...], t: FloatArray, phi: FloatArray, qd: FloatArray, u: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Broadcast times, transitions, process covariances and controls to ``batch + (T, ...)``."""
    n_steps, n = t.shape[-1], phi.shape[-1]
    return (
        np.broadcast_to(t, batch + (n_steps,)),
        np.broadcast_to(phi, batch + (n_steps, n, n)),
        np.broadcast_to(qd, batch + (n_steps, n, n)),
        np.broadcast_to(u, batch + (n_steps, n)),
    )


def _bad_tracks(cov: FloatArray, h: FloatArray, r: FloatArray, mask: BoolArray) -> list[int] | None:
    if cov.ndim < 3:
        return None
    hm, rm = masked_model(h, r, mask)
    s = hm @ cov @ np.swapaxes(hm, -1, -2) + rm
    return [int(i) for i in np.flatnonzero(np.linalg.eigvalsh(s).min(axis=-1) <= 0)]


def _run_shared(
    t: FloatArray,
    z: FloatArray,
    h: FloatArray,
    r: FloatArray,
    initial: GaussianState,
    mask: BoolArray,
    phi: FloatArray,
    qd: FloatArray,
    u: FloatArray,
    form: str,
    off: FloatArray | None,
) -> FilterResult:
    """All tracks share the covariance recursion: compute it once, batch only the means."""
    batch = z.shape[:-2]
    b = len(batch)
    n_steps, m = z.shape[-2:]
    n = phi.shape[-1]
    mask0 = mask.reshape(-1, n_steps, m)[0]
    pc, fc, s_a, k_a, logdet, hm_a = covariance_recursion(phi, qd, h, r, mask0, initial.cov, form)
    # means, all tracks at once (same arithmetic as the general path)
    pm, fm = _alloc(batch, n_steps, n), _alloc(batch, n_steps, n)
    nu_a = _alloc(batch, n_steps, m)
    x = np.broadcast_to(initial.mean, batch + (n,))
    zm = np.where(mask, z, 0.0)
    if off is not None:
        zm = zm - np.where(mask, off, 0.0)
    for k in range(n_steps):
        sv = (slice(None),) * b + (k,)
        xp = matvec(phi[k], x) + u[k]
        nu = zm[sv] - matvec(hm_a[k], xp)
        x = xp + matvec(k_a[k], nu)
        pm[sv], fm[sv], nu_a[sv] = xp, x, nu
    n_obs = np.broadcast_to(mask0.sum(axis=-1).astype(np.float64), batch + (n_steps,))
    nis, ll = _innovation_stats(nu_a, s_a, logdet, n_obs)
    full_shape = batch + (n_steps,)

    def bc(a: FloatArray) -> FloatArray:
        return np.broadcast_to(a, full_shape + a.shape[1:])

    return _result(
        np.broadcast_to(t, full_shape),
        pm,
        bc(pc),
        fm,
        bc(fc),
        bc(phi),
        bc(qd),
        bc(u),
        nu_a,
        bc(s_a),
        nis,
        ll,
        bc(k_a),
        n_obs,
        mask,
        h,
        np.broadcast_to(r, full_shape[:-1] + (m, m)),
    )


def _ro(a: AnyArray) -> AnyArray:
    if a.flags.writeable:
        a.flags.writeable = False
    return a


def _result(
    t: FloatArray,
    pm: FloatArray,
    pc: FloatArray,
    fm: FloatArray,
    fc: FloatArray,
    phi: FloatArray,
    qd: FloatArray,
    u: FloatArray,
    nu: FloatArray,
    s: FloatArray,
    nis: FloatArray,
    ll: FloatArray,
    k: FloatArray,
    n_obs: FloatArray,
    mask: BoolArray,
    h: FloatArray,
    r: FloatArray,
    factor: FloatArray | None = None,
) -> FilterResult:
    """Assemble a FilterResult (arrays made read-only).

    ``factor``: the filtered covariances' factors of a square-root run, carried by
    ``filtered`` for the smoother.
    """
    t = _ro(np.array(t, dtype=np.float64)) if t.flags.writeable else t
    predicted = _trusted(GaussianState, mean=_ro(pm), cov=_ro(pc), time=t)
    filtered = _trusted(
        GaussianState, mean=_ro(fm), cov=_ro(fc), time=t,
        factor=None if factor is None else _ro(factor),
    )  # fmt: skip
    info = _trusted(
        StepInfo,
        innovation=_ro(nu),
        innovation_cov=_ro(s),
        nis=_ro(nis),
        log_likelihood=_ro(ll),
        gain=_ro(k),
        n_observed=_ro(np.asarray(n_obs)),
    )
    return _trusted(
        FilterResult,
        predicted=predicted,
        filtered=filtered,
        transition=_ro(phi),
        process_cov=_ro(qd),
        control=_ro(u),
        info=info,
        mask=_ro(mask),
        measurement_matrix=_ro(np.array(h)),
        measurement_cov=_ro(r),
    )


__all__ = ["kalman_filter"]
