"""Rauch-Tung-Striebel fixed-interval smoother over a :class:`~adaptrack.types.FilterResult`.

Uses only the stored predicted/filtered moments and transitions (models are never re-run):
``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1``,
``x_k|T = x_k|k + C_k (x_{k+1|T} - x_{k+1|k})``,
``P_k|T = P_k|k + C_k (P_{k+1|T} - P_{k+1|k}) C_k^T``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .._backend import SHARED_MIN_TRACKS, Backend, use_compiled
from .._linalg import matvec, mT, symmetrize
from .._typing import FloatArray
from ..filters.run import joseph_loses_digits
from ..types import FilterResult, GaussianState, _trusted

SmootherForm = Literal["auto", "standard", "joseph"]


def _shared(a: FloatArray, batch_ndim: int) -> FloatArray | None:
    """Return the unbatched array if ``a`` repeats one array over its batch axes (zero strides)."""
    if batch_ndim and all(s == 0 for s in a.strides[:batch_ndim]):
        return a[(0,) * batch_ndim]
    return None


def smoother_gains(pf: FloatArray, pp_next: FloatArray, phi_next: FloatArray) -> FloatArray:
    """``C = P_k|k Phi^T P_{k+1|k}^-1``; the pseudo-inverse where ``P_{k+1|k}`` is singular.

    A singular prediction (a known component and no process noise) is legitimate: its range
    holds that of ``Phi P_k|k``, so the pseudo-inverse gives the smoother gain.
    """
    try:
        return mT(np.linalg.solve(pp_next, phi_next @ pf))
    except np.linalg.LinAlgError:
        return mT(np.linalg.pinv(pp_next, hermitian=True) @ (phi_next @ pf))


def _smoothed_cov(
    pf: FloatArray,
    c: FloatArray,
    sc_next: FloatArray,
    pp_next: FloatArray,
    phi_next: FloatArray,
    qd_next: FloatArray,
    joseph: bool,
) -> FloatArray:
    """Return ``P_k|T`` in difference or Joseph form.

    ``P_k|k + C (P_{k+1|T} - P_{k+1|k}) C^T``, or
    ``(I - C Phi) P_k|k (I - C Phi)^T + C (Qd + P_{k+1|T}) C^T`` (a sum of PSD terms).
    """
    if not joseph:
        return symmetrize(pf + c @ (sc_next - pp_next) @ mT(c))
    a = np.eye(pf.shape[-1]) - c @ phi_next
    return symmetrize(a @ pf @ mT(a) + c @ (qd_next + sc_next) @ mT(c))


def rts_smooth(
    result: FilterResult, *, form: SmootherForm = "auto", backend: Backend = "auto"
) -> GaussianState:
    """Smooth a Kalman filter result (fixed interval, all tracks at once).

    Parameters
    ----------
    result : FilterResult
        Output of :func:`adaptrack.kalman_filter`, shapes (..., T, n).
    form : {"auto", "standard", "joseph"}
        Covariance recursion: the textbook difference form, or the Joseph form, a sum of
        positive semi-definite terms that stays PSD where the difference cancels (after long
        gaps or very precise measurements); ``"auto"``: Joseph where the filter's own problem
        is ill-conditioned (the criterion of :func:`adaptrack.kalman_filter`'s ``"auto"``).
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
    if form not in ("auto", "standard", "joseph"):
        raise ValueError(f"form must be 'auto', 'standard' or 'joseph'; got {form!r}")
    joseph = form == "joseph" or (form == "auto" and joseph_loses_digits(result))
    pred, filt = result.predicted, result.filtered
    b = pred.mean.ndim - 2
    n_steps = pred.mean.shape[-2]
    sh = [_shared(a, b) for a in (filt.cov, pred.cov, result.transition, result.process_cov)]
    shared = [a for a in sh if a is not None]
    if len(shared) < 4:
        shared = []
    n_tracks = filt.mean.size // (filt.dim * n_steps)
    if use_compiled(backend, filt.mean.size // filt.dim) and (
        backend == "numba" or not (shared and n_tracks >= SHARED_MIN_TRACKS)
    ):
        return _rts_compiled(result, joseph)
    sm = np.array(filt.mean)
    sc = np.array(shared[0]) if shared else np.array(filt.cov)
    tail = (slice(None),) * b
    for k in range(n_steps - 2, -1, -1):
        i, j = tail + (k,), tail + (k + 1,)
        if shared:
            pf, pp, phi, qd = shared
            c = smoother_gains(pf[k], pp[k + 1], phi[k + 1])
            sc[k] = _smoothed_cov(pf[k], c, sc[k + 1], pp[k + 1], phi[k + 1], qd[k + 1], joseph)
        else:
            c = smoother_gains(filt.cov[i], pred.cov[j], result.transition[j])
            sc[i] = _smoothed_cov(
                filt.cov[i],
                c,
                sc[j],
                pred.cov[j],
                result.transition[j],
                result.process_cov[j],
                joseph,
            )
        sm[i] = filt.mean[i] + matvec(c, sm[j] - pred.mean[j])
    cov = np.broadcast_to(sc, filt.cov.shape) if shared else sc
    sm.flags.writeable = False
    if cov.flags.writeable:
        cov.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=cov, time=filt.time)


def _rts_compiled(result: FilterResult, joseph: bool) -> GaussianState:
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
        c(result.process_cov.reshape(flat + (n, n))),
        joseph,
    )
    sm = sm.reshape(lead + (n_steps, n))
    sc = sc.reshape(lead + (n_steps, n, n))
    sm.flags.writeable = False
    sc.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=sc, time=filt.time)


__all__ = ["rts_smooth"]
