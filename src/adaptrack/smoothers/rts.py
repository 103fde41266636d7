"""Rauch-Tung-Striebel fixed-interval smoother over a :class:`~adaptrack.types.FilterResult`.

Uses only the stored predicted/filtered moments and transitions (models are never re-run):
``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1``,
``x_k|T = x_k|k + C_k (x_{k+1|T} - x_{k+1|k})``,
``P_k|T = P_k|k + C_k (P_{k+1|T} - P_{k+1|k}) C_k^T``.
"""

from __future__ import annotations

import numpy as np

from .._backend import SHARED_MIN_TRACKS, Backend, use_compiled
from .._linalg import matvec, mT, symmetrize
from .._typing import FloatArray
from ..types import FilterResult, GaussianState, _trusted


def _shared(a: FloatArray, batch_ndim: int) -> FloatArray | None:
    """Return the unbatched array if ``a`` repeats one array over its batch axes (zero strides)."""
    if batch_ndim and all(s == 0 for s in a.strides[:batch_ndim]):
        return a[(0,) * batch_ndim]
    return None


def _gains(pf: FloatArray, pp_next: FloatArray, phi_next: FloatArray) -> FloatArray:
    return mT(np.linalg.solve(pp_next, phi_next @ pf))


def rts_smooth(result: FilterResult, *, backend: Backend = "auto") -> GaussianState:
    """Smooth a Kalman filter result (fixed interval, all tracks at once).

    Parameters
    ----------
    result : FilterResult
        Output of :func:`adaptrack.kalman_filter`, shapes (..., T, n).
    backend : {"auto", "numpy", "numba"}
        NumPy reference or the compiled kernel (same results to rounding); ``"auto"`` uses the
        kernel from 20,000 track-steps on unless 64 or more tracks share their covariances.

    Returns
    -------
    GaussianState
        Smoothed means (..., T, n) and covariances (..., T, n, n) at the filter's times.

    Examples
    --------
    >>> import numpy as np
    >>> import adaptrack as at
    >>> t = np.arange(4.0)
    >>> prior = at.GaussianState(mean=[0.0, 0.0], cov=10.0 * np.eye(2), time=0.0)
    >>> res = at.kalman_filter(t, t[:, None], at.models.ConstantVelocity(accel_psd=0.1),
    ...                        [[1.0, 0.0]], [[0.5]], prior)
    >>> at.rts_smooth(res).mean.shape
    (4, 2)
    """
    if not isinstance(result, FilterResult):
        raise TypeError(f"result must be a FilterResult; got {type(result).__name__}")
    pred, filt = result.predicted, result.filtered
    b = pred.mean.ndim - 2
    n_steps = pred.mean.shape[-2]
    sh = [_shared(a, b) for a in (filt.cov, pred.cov, result.transition)]
    shared = [a for a in sh if a is not None]
    if len(shared) < 3:
        shared = []
    n_tracks = filt.mean.size // (filt.dim * n_steps)
    if use_compiled(backend, filt.mean.size // filt.dim) and (
        backend == "numba" or not (shared and n_tracks >= SHARED_MIN_TRACKS)
    ):
        return _rts_compiled(result)
    sm = np.array(filt.mean)
    sc = np.array(shared[0]) if shared else np.array(filt.cov)
    tail = (slice(None),) * b
    for k in range(n_steps - 2, -1, -1):
        if shared:
            pf, pp, phi = shared
            c = _gains(pf[k], pp[k + 1], phi[k + 1])
            sc[k] = symmetrize(pf[k] + c @ (sc[k + 1] - pp[k + 1]) @ c.T)
        else:
            i, j = tail + (k,), tail + (k + 1,)
            c = _gains(filt.cov[i], pred.cov[j], result.transition[j])
            sc[i] = symmetrize(filt.cov[i] + c @ (sc[j] - pred.cov[j]) @ mT(c))
        i, j = tail + (k,), tail + (k + 1,)
        sm[i] = filt.mean[i] + matvec(c, sm[j] - pred.mean[j])
    cov = np.broadcast_to(sc, filt.cov.shape) if shared else sc
    sm.flags.writeable = False
    if cov.flags.writeable:
        cov.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=cov, time=filt.time)


def _rts_compiled(result: FilterResult) -> GaussianState:
    """Run the RTS recursion through the compiled kernel."""
    from ._kernels import rts_kernel

    pred, filt = result.predicted, result.filtered
    n = filt.dim
    n_steps = filt.mean.shape[-2]
    lead = filt.mean.shape[:-2]
    flat = (-1, n_steps)
    c = np.ascontiguousarray
    sm, sc = rts_kernel(
        c(filt.mean.reshape(flat + (n,))),
        c(filt.cov.reshape(flat + (n, n))),
        c(pred.mean.reshape(flat + (n,))),
        c(pred.cov.reshape(flat + (n, n))),
        c(result.transition.reshape(flat + (n, n))),
    )
    sm = sm.reshape(lead + (n_steps, n))
    sc = sc.reshape(lead + (n_steps, n, n))
    sm.flags.writeable = False
    sc.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=sc, time=filt.time)


__all__ = ["rts_smooth"]
