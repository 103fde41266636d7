"""Fleet-scale filtering and smoothing of tracks that share their gain.

When all tracks share the model, the measurement times, the prior covariance, ``R`` and the
missing-data pattern (a fleet post-processed on a common clock, a Monte-Carlo batch), the
covariance recursion and the gains are the same for every track: they are computed once, and
each track's mean follows the affine recursion

``x_k = A_k x_{k-1} + b_k + K_k z_k``,  ``A_k = (I - K_k H_k) Phi_k``,
``b_k = (I - K_k H_k) u_k - K_k mu_k``

(``H_k`` with the rows of missing components zeroed, ``mu`` the measurement-noise mean), and its
RTS-smoothed mean ``s_k = (I - C_k Phi_{k+1}) x_k + C_k s_{k+1} - C_k u_{k+1}`` with
``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1``. Only the means are stored per track (the covariances
once), optionally into a caller's buffer: the fast path for millions of tracks. The same
numbers as :func:`adaptrack.kalman_filter` / :func:`adaptrack.rts_smooth` to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._backend import Backend, use_compiled
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array
from ..models.continuous import MotionModel, as_motion_model, named_measurement_matrix
from ..models.discretize import Method, Noise
from ..smoothers.rts import rts_smooth, smoother_gains
from ..types import GaussianState, as_gaussian_state
from .run import FilterForm, kalman_filter, measurement_matrix_for


@dataclass(frozen=True, eq=False)
class SharedGainResult:
    """Per-track means and the covariances all tracks share.

    ``mean`` (N, T, n): filtered, or smoothed when ``smoothed``; ``cov`` (T, n, n) the matching
    covariance of every track; ``time`` (T,) [s].
    """

    time: FloatArray
    mean: FloatArray
    cov: FloatArray
    smoothed: bool


def shared_gain_filter(
    times: ArrayLike,
    measurements: ArrayLike,
    model: MotionModel,
    measurement_matrix: ArrayLike,
    measurement_cov: ArrayLike,
    initial: GaussianState,
    *,
    mask: ArrayLike | None = None,
    smooth: bool = False,
    out: FloatArray | None = None,
    method: Method = "expm",
    noise: Noise = "white",
    order: int = 2,
    form: FilterForm = "auto",
    measurement_noise_mean: ArrayLike | None = None,
    backend: Backend = "auto",
) -> SharedGainResult:
    """Filter (and optionally smooth) N tracks that share times, prior covariance, R and mask.

    Parameters
    ----------
    times : array_like, shape (T,)
        Measurement times [s] of every track, strictly increasing.
    measurements : array_like, shape (N, T, m)
        ``z``; float64 C-contiguous input is used without a copy.
    model, measurement_matrix, measurement_cov
        Continuous motion model, ``H`` (m, n) and ``R`` (m, m) as in
        :func:`adaptrack.kalman_filter`.
    initial : GaussianState
        Prior at ``initial.time`` (<= ``times[0]``): mean (n,) or (N, n) and one covariance
        (n, n), or (N, n, n) equal for every track (e.g. ``np.broadcast_to``).
    mask : array_like of bool, shape (T,) or (T, m), optional
        The missing-data pattern shared by all tracks (True: present); missing values are
        ignored and may be NaN.
    smooth : bool
        Return RTS-smoothed means (computed in place over the filtered ones).
    out : ndarray, shape (N, T, n), optional
        Float64 C-contiguous buffer for the means (reuse it across calls to save allocation;
        its content is undefined after an error).
    method, noise, order, form, measurement_noise_mean
        As in :func:`adaptrack.kalman_filter`.
    backend : {"auto", "numpy", "numba"}
        ``"numba"``: kernels generated for the (n, m) at hand; ``"numpy"``: the readable
        reference; ``"auto"``: numba from 20,000 track-steps on.

    Returns
    -------
    SharedGainResult

    Raises
    ------
    ValueError
        For bad shapes, non-finite present measurements (naming track, step and component),
        unsorted times, covariances that are not positive definite, or an unusable ``out``.
    FloatingPointError
        If finite input overflows the means.
    """
    model = as_motion_model(model)
    measurement_matrix = named_measurement_matrix(measurement_matrix, model)
    initial = as_gaussian_state(initial, "initial")
    n = model.state_dim
    t = as_float_array(times, "times", min_ndim=1)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"times must have shape (T,) with T >= 1; got {t.shape}")
    z = as_float_array(measurements, "measurements", allow_nan=True)
    if z.ndim != 3 or z.shape[1] != t.size:
        raise ValueError(
            f"times (T,) and measurements (N, T, m) must agree; got times {t.shape} and "
            f"measurements {z.shape}"
        )
    n_tracks, n_steps, m = z.shape
    cov0 = _shared_prior_cov(initial, n_tracks, n)
    t_init = np.asarray(initial.time, dtype=np.float64)
    if t_init.size == 0 or np.any(t_init != t_init.flat[0]):
        raise ValueError("initial.time must be one time shared by all tracks")
    measurement_matrix_for(measurement_matrix, m, n)  # before the mask: it names m's source
    present = _shared_mask(mask, n_steps, m)
    _check_finite(z, present)
    out = _output(out, (n_tracks, n_steps, n))
    compiled = use_compiled(backend, n_tracks * n_steps)
    # The covariances and gains do not depend on the measurements: one track of the filter
    # gives them, validated as kalman_filter validates (and in square-root form where needed).
    one = kalman_filter(
        t, np.zeros((n_steps, m)), model, measurement_matrix, measurement_cov,
        GaussianState(np.zeros(n), cov0, t_init.flat[0]), mask=present, method=method,
        noise=noise, order=order, form=form, measurement_noise_mean=measurement_noise_mean,
        backend="numba" if compiled else "numpy",
    )  # fmt: skip
    phi, u, h = one.transition, one.control, one.measurement_matrix
    fc, kg = one.filtered.cov, one.info.gain
    hm = h * present[..., None]
    ikh = np.eye(n) - kg @ hm
    a = ikh @ phi
    b = np.einsum("kij,kj->ki", ikh, u)
    if measurement_noise_mean is not None:
        mu = np.broadcast_to(as_float_array(measurement_noise_mean, "measurement_noise_mean"), (m,))
        b = b - np.einsum("kij,kj->ki", kg, np.where(present, mu, 0.0))
    x0 = np.ascontiguousarray(np.broadcast_to(initial.mean, (n_tracks, n)))
    if compiled:
        from ._codegen import GENERATED_MAX_STATES, forward_kernel
        from ._kernels import affine_forward

        forward = forward_kernel(n, m) if n <= GENERATED_MAX_STATES else affine_forward
        contiguous = np.ascontiguousarray
        forward(a, contiguous(b), contiguous(kg), present, contiguous(z), x0, out)
    else:
        _forward_numpy(a, b, kg, present, z, x0, out)
    if not np.isfinite(out[:, -1]).all():  # finite input overflowed
        raise FloatingPointError("the filtered means overflowed; check the scale of the input")
    if not smooth:
        return SharedGainResult(t, out, fc, smoothed=False)
    c = np.ascontiguousarray(smoother_gains(fc[:-1], one.predicted.cov[1:], phi[1:]))
    d = np.eye(n) - c @ phi[1:]
    e = np.ascontiguousarray(-np.einsum("kij,kj->ki", c, u[1:]))
    ps = rts_smooth(one, backend="numba" if compiled else "numpy").cov
    if compiled:
        from ._codegen import GENERATED_MAX_STATES, backward_kernel
        from ._kernels import affine_backward

        backward = backward_kernel(n) if n <= GENERATED_MAX_STATES else affine_backward
        backward(d, c, e, out)
    else:
        _backward_numpy(d, c, e, out)
    return SharedGainResult(t, out, ps, smoothed=True)


def _shared_prior_cov(initial: GaussianState, n_tracks: int, n: int) -> FloatArray:
    """Return the prior covariance shared by all tracks (``initial.cov`` (n, n) or equal)."""
    if initial.mean.shape not in ((n,), (n_tracks, n)):
        raise ValueError(
            f"initial.mean must have shape ({n},) or ({n_tracks}, {n}); got {initial.mean.shape}"
        )
    cov = initial.cov
    if cov.ndim == 3:
        if not np.array_equal(cov, np.broadcast_to(cov[0], cov.shape)):
            i = int(np.flatnonzero(np.any(cov != cov[0], axis=(1, 2)))[0])
            raise ValueError(
                f"initial.cov must be the same for every track (shared gain); track {i} "
                "differs from track 0 (use kalman_filter for per-track covariances)"
            )
        cov = cov[0]
    return cov


def _shared_mask(mask: ArrayLike | None, n_steps: int, m: int) -> np.ndarray:
    if mask is None:
        return np.ones((n_steps, m), dtype=np.bool_)
    mk = np.asarray(mask)
    if mk.dtype != np.bool_:
        raise ValueError(f"mask must be boolean; got dtype {mk.dtype}")
    if mk.shape == (n_steps,):
        mk = np.repeat(mk[:, None], m, axis=1)
    if mk.shape != (n_steps, m):
        raise ValueError(
            f"mask must have shape ({n_steps},) or ({n_steps}, {m}) (one pattern shared by "
            f"all tracks); got {mk.shape}"
        )
    return np.ascontiguousarray(mk)


def _check_finite(z: FloatArray, present: np.ndarray) -> None:
    """Name the first present measurement that is NaN or infinite."""
    bad = ~np.isfinite(z) & present
    if bad.any():
        i, k, c = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"measurements is {z[i, k, c]} at track {i}, step {k}, component {c} where the "
            "mask marks it present"
        )


def _output(out: FloatArray | None, shape: tuple[int, int, int]) -> FloatArray:
    if out is None:
        return np.empty(shape)
    if (
        not isinstance(out, np.ndarray)
        or out.shape != shape
        or out.dtype != np.float64
        or not out.flags.c_contiguous
        or not out.flags.writeable
    ):
        raise ValueError(
            f"out must be a writeable float64 C-contiguous array of shape {shape}; got "
            f"{getattr(out, 'shape', type(out).__name__)}"
        )
    return out


def _forward_numpy(
    a: FloatArray,
    b: FloatArray,
    kg: FloatArray,
    present: np.ndarray,
    z: FloatArray,
    x0: FloatArray,
    out: FloatArray,
) -> None:
    """Run the affine filter recursion (reference), all tracks at once per step."""
    x = x0
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite input is named afterwards
        for k in range(z.shape[1]):
            zk = np.where(present[k], z[:, k], 0.0)
            x = x @ a[k].T + b[k] + zk @ kg[k].T
            out[:, k] = x


def _backward_numpy(d: FloatArray, c: FloatArray, e: FloatArray, out: FloatArray) -> None:
    """Run the affine RTS recursion (reference) in place over the filtered means."""
    s = out[:, -1]
    for k in range(out.shape[1] - 2, -1, -1):
        s = out[:, k] @ d[k].T + s @ c[k].T + e[k]
        out[:, k] = s


__all__ = ["SharedGainResult", "shared_gain_filter"]
