"""Compiled (numba) kernel of the linear Kalman filter over (N tracks, T steps).

The NumPy implementation in :mod:`adaptrack.filters.run` is the readable reference; this
kernel computes the same quantities with explicit loops (Joseph or standard covariance update,
masked components, per-track or shared transitions and measurement covariances) and agrees with
it to rounding (tests: <= 1e-10 relative). Leading dimensions of size 1 broadcast.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from .._kernel_linalg import cholesky_into, cholesky_solve_into, matmul_into
from ._codegen import GENERATED_MAX_STATES

_LOG_2PI = math.log(2.0 * math.pi)


@numba.njit(cache=True, inline="always")
def predict_into(x, p, phi, qd, u, xp, pp, tmp):  # type: ignore[no-untyped-def]
    """``xp = Phi x + u``, ``pp = Phi P Phi^T + Qd`` (symmetrised); ``tmp`` (n, n) scratch."""
    n = x.shape[0]
    for a in range(n):
        acc = 0.0
        for b in range(n):
            acc += phi[a, b] * x[b]
        xp[a] = acc + u[a]
    matmul_into(phi, p, tmp)
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for c in range(n):
                acc += tmp[a, c] * phi[b, c]
            pp[a, b] = acc + qd[a, b]
    for a in range(n):
        for b in range(a + 1, n):
            v = 0.5 * (pp[a, b] + pp[b, a])
            pp[a, b] = v
            pp[b, a] = v


@numba.njit(cache=True, inline="always")
def update_into(xp, pp, nu, h, r, joseph, x, p, hp, s, lo, kt, w, ikh, tmp):  # type: ignore[no-untyped-def]
    """Posterior ``x``, ``p`` of the prior ``xp``, ``pp`` given innovation ``nu`` (m,).

    ``h`` (m, n), ``r`` (m, m); Joseph or standard covariance form; the rest are scratch and
    hold ``H P``, ``S``, its Cholesky factor and the transposed gain afterwards. Returns
    ``(ok, nis, log det S)``; ``ok`` is False (``x``, ``p`` untouched) if S is not PD.
    """
    n = xp.shape[0]
    m = nu.shape[0]
    for a in range(m):
        for b in range(n):
            acc = 0.0
            for c in range(n):
                acc += h[a, c] * pp[c, b]
            hp[a, b] = acc
    for a in range(m):
        for b in range(m):
            acc = 0.0
            for c in range(n):
                acc += hp[a, c] * h[b, c]
            s[a, b] = acc + r[a, b]
    for a in range(m):
        for b in range(a + 1, m):
            v = 0.5 * (s[a, b] + s[b, a])
            s[a, b] = v
            s[b, a] = v
    # Cholesky S = L L^T; K^T = S^-1 (H P)
    if not cholesky_into(s, lo):
        return False, 0.0, 0.0
    logdet = 0.0
    for a in range(m):
        logdet += 2.0 * math.log(lo[a, a])
    cholesky_solve_into(lo, hp, kt)
    # NIS = nu^T S^-1 nu
    for a in range(m):
        acc = nu[a]
        for c in range(a):
            acc -= lo[a, c] * w[c]
        w[a] = acc / lo[a, a]
    nis = 0.0
    for a in range(m):
        nis += w[a] * w[a]
    for a in range(n):
        acc = 0.0
        for b in range(m):
            acc += kt[b, a] * nu[b]
        x[a] = xp[a] + acc
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for c in range(m):
                acc += kt[c, a] * h[c, b]
            ikh[a, b] = (1.0 if a == b else 0.0) - acc
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for c in range(n):
                acc += ikh[a, c] * pp[c, b]
            tmp[a, b] = acc
    if joseph:
        for a in range(n):
            for b in range(n):
                acc = 0.0
                for c in range(n):
                    acc += tmp[a, c] * ikh[b, c]
                krk = 0.0
                for c in range(m):
                    for d in range(m):
                        krk += kt[c, a] * r[c, d] * kt[d, b]
                p[a, b] = acc + krk
    else:
        for a in range(n):
            for b in range(n):
                p[a, b] = tmp[a, b]
    for a in range(n):
        for b in range(a + 1, n):
            v = 0.5 * (p[a, b] + p[b, a])
            p[a, b] = v
            p[b, a] = v
    return True, nis, logdet


@numba.njit(cache=True, inline="always")
def kf_step(  # type: ignore[no-untyped-def]
    x, p, phi, qd, u, z, mask, h, r, off, joseph, xp, pp, tmp, hm, rm, hp, s, lo, kt, nu, w, ikh
):
    """One predict + update in place: ``x``, ``p`` (n), (n, n) become the filtered moments.

    ``phi``, ``qd`` (n, n), ``u`` (n,), ``z``, ``mask``, ``off`` (m,), ``h`` (m, n), ``r``
    (m, m); the rest are scratch buffers that hold the predicted moments (``xp``, ``pp``),
    innovation ``nu``, its covariance ``s`` and the transposed gain ``kt`` afterwards.
    Returns ``(ok, nis, log det S, observed components)``; ``ok`` is False (and ``x``, ``p``
    untouched) when ``S`` is not positive definite.
    """
    predict_into(x, p, phi, qd, u, xp, pp, tmp)
    return masked_update_into(
        xp, pp, z, mask, h, r, off, joseph, x, p, tmp, hm, rm, hp, s, lo, kt, nu, w, ikh
    )


@numba.njit(cache=True, inline="always")
def masked_update_into(  # type: ignore[no-untyped-def]
    xp, pp, z, mask, h, r, off, joseph, x, p, tmp, hm, rm, hp, s, lo, kt, nu, w, ikh
):
    """Update the prior ``xp``, ``pp`` as :func:`kf_step` does, into ``x``, ``p``.

    Missing components (``mask`` False) carry no information. Returns ``(ok, nis, log det S,
    observed components)``.
    """
    n = xp.shape[0]
    m = z.shape[0]
    # masked measurement model and innovation
    nobs = 0.0
    for a in range(m):
        on = mask[a]
        nobs += 1.0 if on else 0.0
        for b in range(n):
            hm[a, b] = h[a, b] if on else 0.0
        for b in range(m):
            if on and mask[b]:
                rm[a, b] = r[a, b]
            else:
                rm[a, b] = 1.0 if a == b and not on else 0.0
    for a in range(m):
        acc = 0.0
        for b in range(n):
            acc += hm[a, b] * xp[b]
        nu[a] = (z[a] - off[a] - acc) if mask[a] else -acc
    ok, nis, logdet = update_into(xp, pp, nu, hm, rm, joseph, x, p, hp, s, lo, kt, w, ikh, tmp)
    return ok, nis, logdet, nobs


@numba.njit(cache=True)
def filter_outputs(n_tr, n_st, n, m):  # type: ignore[no-untyped-def]
    """Empty outputs of a filter kernel, in its return order.

    Predicted and filtered means (N, T, n) and covariances (N, T, n, n), innovations (N, T, m),
    their covariances (N, T, m, m), NIS and log-likelihood (N, T), gains (N, T, n, m) and the
    observed-component counts (N, T).
    """
    return (
        np.empty((n_tr, n_st, n)),
        np.empty((n_tr, n_st, n, n)),
        np.empty((n_tr, n_st, n)),
        np.empty((n_tr, n_st, n, n)),
        np.empty((n_tr, n_st, m)),
        np.empty((n_tr, n_st, m, m)),
        np.empty((n_tr, n_st)),
        np.empty((n_tr, n_st)),
        np.empty((n_tr, n_st, n, m)),
        np.empty((n_tr, n_st)),
    )


@numba.njit(cache=True, inline="always")
def start_track(i, x0, m0, phi, r, u, x, mat):  # type: ignore[no-untyped-def]
    """Load track ``i``'s prior mean into ``x`` and its matrix (covariance or factor) into ``mat``.

    Returns the rows of ``phi``, ``r``, ``u`` the track uses (a shared first axis has one).
    """
    ix = min(i, x0.shape[0] - 1)
    for a in range(x.shape[0]):
        x[a] = x0[ix, a]
        for b in range(x.shape[0]):
            mat[a, b] = m0[ix, a, b]
    return min(i, phi.shape[0] - 1), min(i, r.shape[0] - 1), min(i, u.shape[0] - 1)


@numba.njit(cache=True, fastmath=False)
def kalman_kernel(x0, p0, phi, qd, u, z, mask, h, r, off, joseph):  # type: ignore[no-untyped-def]
    """Filter every track of the batch.

    Shapes: x0 (N|1, n), p0 (N|1, n, n), phi/qd (N|1, T, n, n), u (N|1, T, n), z (N, T, m),
    mask (N, T, m), h (m, n), r (N|1, T|1, m, m), off (m,).
    """
    n_tr, n_st, m = z.shape
    n = h.shape[1]
    pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o = filter_outputs(n_tr, n_st, n, m)
    x = np.empty(n)
    xp = np.empty(n)
    p = np.empty((n, n))
    pp = np.empty((n, n))
    tmp = np.empty((n, n))
    hm = np.empty((m, n))
    rm = np.empty((m, m))
    hp = np.empty((m, n))
    s = np.empty((m, m))
    lo = np.empty((m, m))
    kt = np.empty((m, n))
    nu = np.empty(m)
    w = np.empty(m)
    ikh = np.empty((n, n))
    for i in range(n_tr):
        ip, ir, iu = start_track(i, x0, p0, phi, r, u, x, p)
        for k in range(n_st):
            kr = min(k, r.shape[1] - 1)
            ok, nis, logdet, nobs = kf_step(
                x,
                p,
                phi[ip, k],
                qd[ip, k],
                u[iu, k],
                z[i, k],
                mask[i, k],
                h,
                r[ir, kr],
                off,
                joseph,
                xp,
                pp,
                tmp,
                hm,
                rm,
                hp,
                s,
                lo,
                kt,
                nu,
                w,
                ikh,
            )
            if not ok:
                raise ValueError("innovation covariance is not positive definite")
            store_step(pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o, i, k, xp, pp, x, p, kt,
                       nu, s, nis, logdet, nobs)  # fmt: skip
    return pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o


@numba.njit(cache=True, inline="always")
def store_step(  # type: ignore[no-untyped-def]
    pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o, i, k, xp, pp, x, p, kt, nu, s, nis,
    logdet, nobs,
):  # fmt: skip
    """Write step ``k`` of track ``i`` into the arrays of :func:`filter_outputs` (in its order).

    Moments, innovation, ``S``, NIS, log-likelihood, the gain (from ``kt`` = K^T) and the
    observed-component count.
    """
    n, m = x.shape[0], nu.shape[0]
    for a in range(n):
        pm[i, k, a] = xp[a]
        fm[i, k, a] = x[a]
        for b in range(n):
            pc[i, k, a, b] = pp[a, b]
            fc[i, k, a, b] = p[a, b]
        for b in range(m):
            k_o[i, k, a, b] = kt[b, a]
    for a in range(m):
        nu_o[i, k, a] = nu[a]
        for b in range(m):
            s_o[i, k, a, b] = s[a, b]
    nis_o[i, k] = nis
    ll_o[i, k] = -0.5 * (logdet + nis + nobs * _LOG_2PI) if nobs > 0 else 0.0
    nobs_o[i, k] = nobs


def run_kernels(x0, p0, phi, qd, u, z, mask, h, r, off, joseph):  # type: ignore[no-untyped-def]
    """Filter with the fastest compiled kernel for the case (arguments of :func:`kalman_kernel`).

    Joseph form, every component present and one ``R`` run straight-line code generated for
    the (n, m) at hand (:func:`adaptrack.filters._codegen.sequence_kernel`; n <= 6, larger
    straight-line code compiles too slowly); anything else the
    generic kernel. Raises ValueError if an innovation covariance is not positive definite.
    """
    c = np.ascontiguousarray
    n_tr, n_steps, m = z.shape
    n = h.shape[1]
    if joseph and r.shape[:2] == (1, 1) and n <= GENERATED_MAX_STATES and bool(mask.all()):
        from ._codegen import sequence_kernel

        out = tuple(
            np.empty((n_tr, n_steps) + tail)
            for tail in ((n,), (n, n), (n,), (n, n), (m,), (m, m), (), (), (n, m))
        )
        status = np.zeros(n_tr, dtype=np.int64)
        sequence_kernel(n, m)(
            c(x0), c(p0), c(phi), c(qd), c(u), c(z), c(h), c(r[0, 0]), c(off), *out, status
        )
        if status.any():
            raise ValueError("innovation covariance is not positive definite")
        return (*out, np.full((n_tr, n_steps), float(m)))
    return kalman_kernel(
        c(x0), c(p0), c(phi), c(qd), c(u), c(z), c(mask), c(h), c(r), c(off), joseph
    )


@numba.njit(cache=True, parallel=True)
def affine_forward(a, b, kg, obs, z, x0, out):  # type: ignore[no-untyped-def]
    """Run the shared-gain forward recursion with generic loops (any n, m)."""
    n_tr, n_st, m = z.shape
    n = a.shape[1]
    for i in prange(n_tr):
        x = x0[i].copy()
        y = np.empty(n)
        for k in range(n_st):
            for r in range(n):
                acc = b[k, r]
                for c in range(n):
                    acc += a[k, r, c] * x[c]
                for c in range(m):
                    if obs[k, c]:
                        acc += kg[k, r, c] * z[i, k, c]
                y[r] = acc
            for r in range(n):
                x[r] = y[r]
                out[i, k, r] = y[r]
    return out


@numba.njit(cache=True, parallel=True)
def affine_backward(d, cg, e, out):  # type: ignore[no-untyped-def]
    """Run the shared-gain RTS recursion with generic loops, in place."""
    n_tr, n_st, n = out.shape
    for i in prange(n_tr):
        s = out[i, n_st - 1].copy()
        y = np.empty(n)
        for k in range(n_st - 2, -1, -1):
            for r in range(n):
                acc = e[k, r]
                for c in range(n):
                    acc += d[k, r, c] * out[i, k, c] + cg[k, r, c] * s[c]
                y[r] = acc
            for r in range(n):
                s[r] = y[r]
                out[i, k, r] = y[r]
    return out


@numba.njit(cache=True, inline="always")
def _series_substep(dt, h_max):  # type: ignore[no-untyped-def]
    """``(h, s)``: the step ``h = dt / 2^s <= h_max`` a series table evaluates directly."""
    h, s = dt, 0
    while h > h_max:
        h *= 0.5
        s += 1
    return h, s


@numba.njit(cache=True, inline="always")
def _series_doublings(s, phi, qd, u, with_offset, tmp):  # type: ignore[no-untyped-def]
    """Double the step ``s`` times in place (``tmp`` (n, n) scratch).

    ``Qd(2h) = Phi Qd Phi^T + Qd``, ``u(2h) = Phi u + u``, ``Phi(2h) = Phi Phi``.
    """
    n = phi.shape[0]
    for _ in range(s):
        matmul_into(phi, qd, tmp)
        for a in range(n):
            for b in range(a, n):
                acc = qd[a, b]
                for c in range(n):
                    acc += tmp[a, c] * phi[b, c]
                qd[a, b] = acc
                qd[b, a] = acc
        if with_offset:
            for a in range(n):
                acc = u[a]
                for c in range(n):
                    acc += phi[a, c] * u[c]
                tmp[a, 0] = acc
            for a in range(n):
                u[a] = tmp[a, 0]
        matmul_into(phi, phi, tmp)
        phi[:, :] = tmp


@numba.njit(cache=True, inline="always")
def series_transition_into(dt, phi_coef, qd_coef, off_coef, h_max, phi, qd, u, tmp):  # type: ignore[no-untyped-def]
    """``Phi(dt)``, ``Qd(dt)``, ``u(dt)`` of a :class:`~adaptrack.models.series_table.SeriesTable`.

    Horner in ``h = dt / 2^s <= h_max``, then ``s`` doublings; ``u`` is zero without offset
    coefficients; ``tmp`` (n, n) scratch.
    """
    n = phi.shape[0]
    h, s = _series_substep(dt, h_max)
    top = phi_coef.shape[0] - 1
    for a in range(n):
        for b in range(n):
            acc = phi_coef[top, a, b]
            for i in range(top - 1, -1, -1):
                acc = acc * h + phi_coef[i, a, b]
            phi[a, b] = acc
    top = qd_coef.shape[0] - 1
    for a in range(n):
        for b in range(a, n):
            acc = qd_coef[top, a, b]
            for i in range(top - 1, -1, -1):
                acc = acc * h + qd_coef[i, a, b]
            qd[a, b] = acc * h
            qd[b, a] = acc * h
    top = off_coef.shape[0] - 1
    for a in range(n):
        acc = 0.0
        for i in range(top, -1, -1):
            acc = acc * h + off_coef[i, a]
        u[a] = acc * h
    _series_doublings(s, phi, qd, u, top >= 0, tmp)


@numba.njit(cache=True, inline="always")
def _horner_steps(coef, h, acc):  # type: ignore[no-untyped-def]
    """``acc[j] = sum_i coef[i] h[j]^i`` for every step ``j``: Horner, the steps side by side.

    The operations of the single-step evaluation, in its order (0 without coefficients).
    """
    top = coef.shape[0] - 1
    for j in range(acc.size):
        acc[j] = coef[top] if top >= 0 else 0.0
    for i in range(top - 1, -1, -1):
        c = coef[i]
        for j in range(acc.size):
            acc[j] = acc[j] * h[j] + c


SERIES_CHUNK = 4096  # steps evaluated side by side by ``series_transitions``


@numba.njit(cache=True, parallel=True)
def series_transitions(dt, phi_coef, qd_coef, off_coef, h_max):  # type: ignore[no-untyped-def]
    """``Phi``, ``Qd``, ``u`` of every step length in ``dt`` (K,) from a series table.

    The values of :func:`series_transition_into`, step by step; each coefficient's Horner
    update runs over a chunk of steps at once (independent chains, vectorised).
    """
    n = phi_coef.shape[1]
    k_all = dt.size
    phi, qd = np.empty((k_all, n, n)), np.empty((k_all, n, n))
    u = np.empty((k_all, n))
    with_offset = off_coef.shape[0] > 0
    for c in prange((k_all + SERIES_CHUNK - 1) // SERIES_CHUNK):
        lo = c * SERIES_CHUNK
        m = min(SERIES_CHUNK, k_all - lo)
        h = np.empty(m)
        s = np.empty(m, np.int64)
        for j in range(m):
            h[j], s[j] = _series_substep(dt[lo + j], h_max)
        acc = np.empty(m)
        for a in range(n):
            for b in range(n):
                _horner_steps(phi_coef[:, a, b], h, acc)
                for j in range(m):
                    phi[lo + j, a, b] = acc[j]
            for b in range(a, n):
                _horner_steps(qd_coef[:, a, b], h, acc)
                for j in range(m):
                    qd[lo + j, a, b] = acc[j] * h[j]
                    qd[lo + j, b, a] = acc[j] * h[j]
            _horner_steps(off_coef[:, a], h, acc)
            for j in range(m):
                u[lo + j, a] = acc[j] * h[j]
        tmp = np.empty((n, n))
        for j in range(m):
            if s[j]:
                _series_doublings(s[j], phi[lo + j], qd[lo + j], u[lo + j], with_offset, tmp)
    return phi, qd, u


@numba.njit(cache=True)
def series_bank_row(bank, row, dt, phi_coef, qd_coef, off_coef, h_max):  # type: ignore[no-untyped-def]
    """Write ``[dt, Phi, Qd, u]`` of step ``dt`` (from a series table) into ``bank[row]``."""
    n = phi_coef.shape[1]
    phi, qd, tmp = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    u = np.empty(n)
    series_transition_into(dt, phi_coef, qd_coef, off_coef, h_max, phi, qd, u, tmp)
    bank[row, 0] = dt
    for a in range(n):
        for b in range(n):
            bank[row, 1 + a * n + b] = phi[a, b]
            bank[row, 1 + n * n + a * n + b] = qd[a, b]
        bank[row, 1 + 2 * n * n + a] = u[a]
