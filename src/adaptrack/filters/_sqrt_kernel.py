"""Compiled (numba) square-root Kalman filter over (N tracks, T steps).

The NumPy reference is :mod:`adaptrack.filters.square_root` (QR of the pre-arrays); this
kernel triangularises the same pre-arrays with Householder reflections from the right and
returns what :func:`adaptrack.filters._kernels.kalman_kernel` returns.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._kernel_linalg import cholesky_into
from ._kernels import filter_outputs, start_track

_LOG_2PI = math.log(2.0 * math.pi)


@numba.njit(cache=True, inline="always")
def lower_triangularize(a, rows, cols):  # type: ignore[no-untyped-def]
    """In place: ``a[:rows, :cols] -> [L, 0]`` with ``L L^T`` unchanged (Householder, right).

    The columns are first sorted by decreasing norm, as in
    :func:`adaptrack.filters.square_root.triangularize` (row-wise accuracy on badly scaled
    pre-arrays).
    """
    norms = np.empty(cols)
    for c in range(cols):
        acc = 0.0
        for r in range(rows):
            acc += a[r, c] * a[r, c]
        norms[c] = acc
    for c in range(cols - 1):  # selection: the largest remaining column to position c
        big = c
        for k in range(c + 1, cols):
            if norms[k] > norms[big]:
                big = k
        if big != c:
            norms[c], norms[big] = norms[big], norms[c]
            for r in range(rows):
                a[r, c], a[r, big] = a[r, big], a[r, c]
    for i in range(rows):
        tail = 0.0
        for c in range(i + 1, cols):
            tail += a[i, c] * a[i, c]
        if tail == 0.0:
            continue
        norm = math.sqrt(a[i, i] * a[i, i] + tail)
        alpha = -norm if a[i, i] >= 0.0 else norm
        v0 = a[i, i] - alpha
        vv = v0 * v0 + tail
        for j in range(i + 1, rows):
            acc = a[j, i] * v0
            for c in range(i + 1, cols):
                acc += a[j, c] * a[i, c]
            f = 2.0 * acc / vv
            a[j, i] -= f * v0
            for c in range(i + 1, cols):
                a[j, c] -= f * a[i, c]
        a[i, i] = alpha
        for c in range(i + 1, cols):
            a[i, c] = 0.0


@numba.njit(cache=True, inline="always")
def outer_into(f, out, k):  # type: ignore[no-untyped-def]
    """``out = F F^T`` of the leading (k, k) block of ``f`` (exactly symmetric)."""
    for a in range(k):
        for b in range(a + 1):
            acc = 0.0
            for c in range(k):
                acc += f[a, c] * f[b, c]
            out[a, b] = acc
            out[b, a] = acc


@numba.njit(cache=True)
def lower_factor_into(a, out, c):  # type: ignore[no-untyped-def]
    """``out`` = a factor ``L L^T = A`` of symmetric PSD ``a`` (k, k); ``c`` is (k, k) scratch.

    The compiled :func:`adaptrack.filters.square_root.lower_factor`: Cholesky of ``A`` scaled to
    unit diagonal, its eigen-based factor where that is not positive definite.
    """
    k = a.shape[0]
    d = np.empty(k)
    for i in range(k):
        d[i] = math.sqrt(max(a[i, i], 0.0))
    for i in range(k):
        for j in range(k):
            c[i, j] = a[i, j] / ((d[i] if d[i] > 0.0 else 1.0) * (d[j] if d[j] > 0.0 else 1.0))
    if not cholesky_into(c, out):
        vals, vecs = np.linalg.eigh(0.5 * (c + c.T))
        for i in range(k):
            for j in range(k):
                out[i, j] = vecs[i, j] * math.sqrt(max(vals[j], 0.0))
    else:
        for i in range(k):
            for j in range(i + 1, k):
                out[i, j] = 0.0
    for i in range(k):
        for j in range(k):
            out[i, j] *= d[i]


@numba.njit(cache=True)
def sqrt_step(x, fac, ph, sqk, uk, zk, on, h, rk, off, xp, pre1, pre2, rm, sr, nu, w, kt):  # type: ignore[no-untyped-def]
    """One predict + update in square-root form, in place on ``x`` (n,) and ``fac`` (n, n).

    ``ph``, ``sqk`` (a factor of ``Qd``), ``uk``: the step's transition; ``zk``, ``on`` (m,) the
    measurement and its present components; ``rk`` (m, m). Leaves the predicted mean in ``xp``,
    the predicted factor in ``pre1[:, :n]``, ``Ss`` (``S = Ss Ss^T``) in ``pre2[:m, :m]``, the
    innovation in ``nu`` and the gain in ``kt`` (n, m). Returns ``(ok, nis, logdet, n_obs)``;
    not ok (nothing changed) if the masked ``R`` is not positive definite.
    """
    n = fac.shape[0]
    m = zk.shape[0]
    nobs = 0.0
    for a in range(m):
        nobs += 1.0 if on[a] else 0.0
        for b in range(m):
            if on[a] and on[b]:
                rm[a, b] = rk[a, b]
            else:
                rm[a, b] = 1.0 if a == b else 0.0
    if not cholesky_into(rm, sr):
        return False, 0.0, 0.0, nobs
    # predict: [Phi S, Sq] -> [S-, 0]
    for a in range(n):
        acc = uk[a]
        for b in range(n):
            acc += ph[a, b] * x[b]
        xp[a] = acc
        for b in range(n):
            acc = 0.0
            for c in range(n):
                acc += ph[a, c] * fac[c, b]
            pre1[a, b] = acc
            pre1[a, n + b] = sqk[a, b]
    lower_triangularize(pre1, n, 2 * n)
    # update pre-array [[Sr, Hm S-], [0, S-]]
    for a in range(m + n):
        for b in range(m + n):
            pre2[a, b] = 0.0
    for a in range(m):
        acc = 0.0
        for b in range(n):
            acc += h[a, b] * xp[b]
        nu[a] = (zk[a] - off[a] - acc) if on[a] else 0.0
        for b in range(a + 1):
            pre2[a, b] = sr[a, b]
        if on[a]:
            for b in range(n):
                acc = 0.0
                for c in range(n):
                    acc += h[a, c] * pre1[c, b]
                pre2[a, m + b] = acc
    for a in range(n):
        for b in range(n):
            pre2[m + a, m + b] = pre1[a, b]
    lower_triangularize(pre2, m + n, m + n)
    # w = Ss^-1 nu; x+ = x- + Kb w; K^T = Ss^-T Kb^T
    logdet = 0.0
    nis = 0.0
    for a in range(m):
        acc = nu[a]
        for c in range(a):
            acc -= pre2[a, c] * w[c]
        w[a] = acc / pre2[a, a]
        nis += w[a] * w[a]
        logdet += 2.0 * math.log(abs(pre2[a, a]))
    for a in range(n):
        acc = xp[a]
        for c in range(m):
            acc += pre2[m + a, c] * w[c]
        x[a] = acc
        for b in range(n):
            fac[a, b] = pre2[m + a, m + b]
    for a in range(n):
        for b in range(m - 1, -1, -1):
            acc = pre2[m + a, b]
            for c in range(b + 1, m):
                acc -= pre2[c, b] * kt[a, c]
            kt[a, b] = acc / pre2[b, b]
    return True, nis, logdet, nobs


@numba.njit(cache=True)
def sqrt_kernel(x0, s0, phi, sq, u, z, mask, h, r, off):  # type: ignore[no-untyped-def]
    """Filter every track of the batch in square-root form.

    Shapes: x0 (N|1, n), s0 (N|1, n, n) a factor of the prior covariance, phi (N|1, T, n, n),
    sq (N|1, T, n, n) factors of ``Qd``, u (N|1, T, n), z (N, T, m), mask (N, T, m), h (m, n),
    r (N|1, T|1, m, m), off (m,). Raises ValueError if a masked ``R`` is not positive definite.
    Returns what :func:`adaptrack.filters._kernels.kalman_kernel` returns, then the filtered
    covariances' factors (N, T, n, n).
    """
    n_tr, n_st, m = z.shape
    n = h.shape[1]
    pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o = filter_outputs(n_tr, n_st, n, m)
    ff = np.empty((n_tr, n_st, n, n))
    x = np.empty(n)
    xp = np.empty(n)
    fac = np.empty((n, n))
    pre1 = np.empty((n, 2 * n))
    pre2 = np.empty((m + n, m + n))
    rm = np.empty((m, m))
    sr = np.empty((m, m))
    nu = np.empty(m)
    w = np.empty(m)
    for i in range(n_tr):
        ip, ir, iu = start_track(i, x0, s0, phi, r, u, x, fac)
        for k in range(n_st):
            ok, nis, logdet, nobs = sqrt_step(
                x, fac, phi[ip, k], sq[ip, k], u[iu, k], z[i, k], mask[i, k], h,
                r[ir, min(k, r.shape[1] - 1)], off, xp, pre1, pre2, rm, sr, nu, w, k_o[i, k],
            )  # fmt: skip
            if not ok:
                raise ValueError("measurement covariance is not positive definite")
            outer_into(pre1, pc[i, k], n)
            outer_into(fac, fc[i, k], n)
            ff[i, k] = fac
            outer_into(pre2, s_o[i, k], m)
            for a in range(n):
                pm[i, k, a] = xp[a]
                fm[i, k, a] = x[a]
            for a in range(m):
                nu_o[i, k, a] = nu[a]
            nis_o[i, k] = nis
            ll_o[i, k] = -0.5 * (logdet + nis + nobs * _LOG_2PI) if nobs > 0 else 0.0
            nobs_o[i, k] = nobs
    return pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o, ff
