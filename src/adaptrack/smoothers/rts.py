"""Rauch-Tung-Striebel fixed-interval smoother over a :class:`~adaptrack.types.FilterResult`.

Uses only the stored predicted/filtered moments and transitions (models are never re-run):
``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1``,
``x_k|T = x_k|k + C_k (x_{k+1|T} - x_{k+1|k})``,
``P_k|T = P_k|k + C_k (P_{k+1|T} - P_{k+1|k}) C_k^T``.

The square-root form carries a factor ``S_k|T`` (Sarkka, *Bayesian Filtering and Smoothing*,
2013, sec. 8.2 form): with ``S_f S_f^T = P_k|k`` and ``S_q S_q^T = Qd``::

    [ Phi S_f  S_q ]                [ X11  0   ]    X11 X11^T = P_k+1|k
    [ S_f      0   ]  triangularise [ X21  X22 ]    C = X21 X11^-1 (pseudo-inverse if singular)

    S_k|T = tria([X22, X21 - C X11, C S_k+1|T])

(``X21 - C X11`` is zero unless the prediction is singular), so ``P_k|T`` is PSD by
construction and no difference of covariances is formed.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .._backend import SHARED_MIN_TRACKS, Backend, use_compiled
from .._linalg import matvec, mT, symmetrize
from .._typing import FloatArray
from ..filters.kalman import JOSEPH_MAX_RATIO
from ..filters.run import worst_joseph_ratio
from ..filters.square_root import covariance, lower_factor, triangularize
from ..types import FilterResult, GaussianState, _trusted

SmootherForm = Literal["auto", "standard", "joseph", "sqrt"]
FORMS = ("standard", "joseph", "sqrt")  # the compiled kernel's form codes 0, 1, 2


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


def gain_from_factors(x11: FloatArray, x21: FloatArray) -> FloatArray:
    """``C = X21 X11^-1`` of lower-triangular ``X11``; ``X21 pinv(X11)`` where it is singular.

    Singular means an exactly zero diagonal entry (a known component with no process noise);
    ``X21 pinv(X11) = P_k|k Phi^T pinv(P_k+1|k)`` there, the smoother gain of that case.
    """
    singular = np.any(np.diagonal(x11, axis1=-2, axis2=-1) == 0.0, axis=-1)
    eye = np.eye(x11.shape[-1])
    safe = np.where(singular[..., None, None], eye, x11)
    c = mT(np.linalg.solve(mT(safe), mT(x21)))
    if np.any(singular):
        c = np.where(singular[..., None, None], x21 @ np.linalg.pinv(x11), c)
    return c


def sqrt_smoother_step(
    sf: FloatArray, sq: FloatArray, phi: FloatArray, ss_next: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Gain ``C_k`` and smoothed factor ``S_k|T``.

    From the lower factors ``sf`` of ``P_k|k``, ``sq`` of ``Qd`` and ``ss_next`` of ``P_k+1|T``.
    """
    n = sf.shape[-1]
    batch = np.broadcast_shapes(sf.shape[:-2], sq.shape[:-2], phi.shape[:-2])
    pre = np.zeros(batch + (2 * n, 2 * n))
    pre[..., :n, :n] = phi @ sf
    pre[..., :n, n:] = sq
    pre[..., n:, :n] = sf
    post = triangularize(pre)
    x11, x21, x22 = post[..., :n, :n], post[..., n:, :n], post[..., n:, n:]
    c = gain_from_factors(x11, x21)
    s = triangularize(np.concatenate([x22, x21 - c @ x11, c @ ss_next], axis=-1))
    return c, s


def rts_smooth(
    result: FilterResult, *, form: SmootherForm = "auto", backend: Backend = "auto"
) -> GaussianState:
    """Smooth a Kalman filter result (fixed interval, all tracks at once).

    Parameters
    ----------
    result : FilterResult
        Output of :func:`adaptrack.kalman_filter`, shapes (..., T, n).
    form : {"auto", "standard", "joseph", "sqrt"}
        Covariance recursion: the textbook difference form; the Joseph form, a sum of
        positive semi-definite terms that stays PSD where the difference cancels (after long
        gaps or very precise measurements); or the square-root form, which carries factors of
        the covariances and solves for the gain with a factor of ``P_k+1|k`` (half the
        condition number). ``"auto"``: square-root where the filter's own problem is
        ill-conditioned (the criterion of :func:`adaptrack.kalman_filter`'s ``"auto"``), else
        the difference form.
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
    if form not in ("auto",) + FORMS:
        raise ValueError(f"form must be 'auto', 'standard', 'joseph' or 'sqrt'; got {form!r}")
    if form == "auto":
        form = "sqrt" if worst_joseph_ratio(result) > JOSEPH_MAX_RATIO else "standard"
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
        return _rts_compiled(result, form)
    pf, pp, phi, qd = shared or (filt.cov, pred.cov, result.transition, result.process_cov)
    cov_tail = () if shared else (slice(None),) * b
    tail = (slice(None),) * b
    sm = np.array(filt.mean)
    sc = np.array(pf)
    if form == "sqrt":  # the filter's factors where it carried them
        factor = filt.factor if not shared or filt.factor is None else _shared(filt.factor, b)
        sf = lower_factor(pf) if factor is None else factor
        sq = lower_factor(qd)
        ss = sf[cov_tail + (-1,)]
    for k in range(n_steps - 2, -1, -1):
        i, j = cov_tail + (k,), cov_tail + (k + 1,)
        if form == "sqrt":
            c, ss = sqrt_smoother_step(sf[i], sq[j], phi[j], ss)
            sc[i] = covariance(ss)
        else:
            c = smoother_gains(pf[i], pp[j], phi[j])
            sc[i] = _smoothed_cov(pf[i], c, sc[j], pp[j], phi[j], qd[j], form == "joseph")
        sm[tail + (k,)] = filt.mean[tail + (k,)] + matvec(
            c, sm[tail + (k + 1,)] - pred.mean[tail + (k + 1,)]
        )
    cov = np.broadcast_to(sc, filt.cov.shape) if shared else sc
    sm.flags.writeable = False
    if cov.flags.writeable:
        cov.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=cov, time=filt.time)


def _rts_compiled(result: FilterResult, form: str) -> GaussianState:
    """Run the RTS recursion through the compiled kernel (``qd`` as factors in square-root form)."""
    from ._kernels import rts_kernel

    pred, filt = result.predicted, result.filtered
    n = filt.dim
    n_steps = filt.mean.shape[-2]
    lead = filt.mean.shape[:-2]
    flat = (-1, n_steps)
    qd = lower_factor(result.process_cov) if form == "sqrt" else result.process_cov
    ff = np.zeros((0, 0, n, n))  # none: the kernel factors the filtered covariances
    if form == "sqrt" and filt.factor is not None:
        ff = filt.factor.reshape(flat + (n, n))
    c = np.ascontiguousarray
    sm, sc = rts_kernel(
        c(filt.mean.reshape(flat + (n,))),
        c(filt.cov.reshape(flat + (n, n))),
        c(ff),
        c(pred.mean.reshape(flat + (n,))),
        c(pred.cov.reshape(flat + (n, n))),
        c(result.transition.reshape(flat + (n, n))),
        c(qd.reshape(flat + (n, n))),
        FORMS.index(form),
    )
    sm = sm.reshape(lead + (n_steps, n))
    sc = sc.reshape(lead + (n_steps, n, n))
    sm.flags.writeable = False
    sc.flags.writeable = False
    return _trusted(GaussianState, mean=sm, cov=sc, time=filt.time)


__all__ = ["rts_smooth"]
