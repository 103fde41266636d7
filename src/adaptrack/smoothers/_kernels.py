"""Compiled (numba) kernel of the RTS smoother.

The NumPy version in ``rts.py`` is the reference; tests check agreement to 1e-10 relative
(and, on ill-conditioned problems, both against a 60-digit reference).
"""

from __future__ import annotations

import numba
import numpy as np

from .._kernel_linalg import cholesky_into, cholesky_solve_into, matmul_into
from ..filters._sqrt_kernel import lower_factor_into, lower_triangularize, outer_into


@numba.njit(cache=True)
def sqrt_smoother_step(sf, sq, ph, ss, pre, pre2, x11, c):  # type: ignore[no-untyped-def]
    """Gain ``c`` and, in place, the smoothed factor ``ss`` (n, n) of one square-root step.

    ``sf``, ``sq`` factors of ``P_k|k`` and ``Qd``; ``pre`` (2n, 2n), ``pre2`` (n, 3n) and
    ``x11`` (n, n) are scratch. The compiled :func:`adaptrack.smoothers.rts.sqrt_smoother_step`.
    """
    n = sf.shape[0]
    pre[:, :] = 0.0
    matmul_into(ph, sf, x11)
    pre[:n, :n] = x11
    pre[:n, n:] = sq
    pre[n:, :n] = sf
    lower_triangularize(pre, 2 * n, 2 * n)
    x11[:, :] = pre[:n, :n]
    singular = False
    for j in range(n):
        singular = singular or x11[j, j] == 0.0
    if singular:  # a known component without process noise: X21 pinv(X11)
        c[:, :] = np.ascontiguousarray(pre[n:, :n]) @ np.linalg.pinv(x11)
    else:  # C X11 = X21, X11 lower triangular: back substitution along each row of C
        for a in range(n):
            for j in range(n - 1, -1, -1):
                acc = pre[n + a, j]
                for q in range(j + 1, n):
                    acc -= c[a, q] * x11[q, j]
                c[a, j] = acc / x11[j, j]
    for a in range(n):  # pre2 = [X22, X21 - C X11, C S_k+1|T]
        for q in range(n):
            pre2[a, q] = pre[n + a, n + q]
            acc = pre[n + a, q]
            acc2 = 0.0
            for r in range(n):
                acc -= c[a, r] * x11[r, q]
                acc2 += c[a, r] * ss[r, q]
            pre2[a, n + q] = acc
            pre2[a, 2 * n + q] = acc2
    lower_triangularize(pre2, n, 3 * n)
    ss[:, :] = pre2[:, :n]


@numba.njit(cache=True)
def rts_kernel(fm, fc, ff, pm, pc, phi, qd, form):  # type: ignore[no-untyped-def]
    """Smooth every track: fm (N, T, n), fc/pc (N, T, n, n), pm (N, T, n), phi/qd (N|1, T, n, n).

    ``ff`` (N, T, n, n): the filtered covariances' factors of a square-root filter run (used in
    square-root form; empty: factor ``fc``).

    ``form`` indexes ``rts.FORMS``. Difference and Joseph forms: ``C_k = P_k|k Phi_{k+1}^T
    P_{k+1|k}^-1`` (Cholesky solve; the pseudo-inverse where the prediction is singular), then
    the RTS recursion. Square-root form: ``qd`` holds factors of ``Qd`` and each step is
    :func:`sqrt_smoother_step`.
    """
    n_tr, n_st, n = fm.shape
    joseph = form == 1
    sm = fm.copy()
    sc = fc.copy()
    lo = np.empty((n, n))
    b = np.empty((n, n))
    c = np.empty((n, n))
    d = np.empty((n, n))
    e = np.empty((n, n))
    dx = np.empty(n)
    ss = np.empty((n, n))
    pre = np.empty((2 * n, 2 * n))
    pre2 = np.empty((n, 3 * n))
    for i in range(n_tr):
        ip = min(i, phi.shape[0] - 1)
        if form == 2 and n_st > 1:
            if ff.shape[0]:
                ss[:, :] = ff[i, n_st - 1]
            else:
                lower_factor_into(fc[i, n_st - 1], ss, lo)
        for k in range(n_st - 2, -1, -1):
            if form == 2:
                if ff.shape[0]:
                    d[:, :] = ff[i, k]
                else:
                    lower_factor_into(fc[i, k], d, lo)
                sqrt_smoother_step(d, qd[ip, k + 1], phi[ip, k + 1], ss, pre, pre2, b, c)
            else:
                # B = Phi P_k|k  (n x n); solve P_{k+1|k} C^T = B for C^T column by column
                matmul_into(phi[ip, k + 1], fc[i, k], b)
                if cholesky_into(pc[i, k + 1], lo):
                    cholesky_solve_into(lo, b, d)
                else:  # singular prediction: a known component without process noise
                    d[:, :] = np.linalg.pinv(pc[i, k + 1]) @ b
                for a in range(n):  # C = D^T
                    for q in range(n):
                        c[a, q] = d[q, a]
            # means
            for a in range(n):
                dx[a] = sm[i, k + 1, a] - pm[i, k + 1, a]
            for a in range(n):
                acc = 0.0
                for q in range(n):
                    acc += c[a, q] * dx[q]
                sm[i, k, a] = fm[i, k, a] + acc
            if form == 2:
                outer_into(ss, sc[i, k], n)
                continue
            # covariances: P_k|T = P_k|k + C (P_{k+1|T} - P_{k+1|k}) C^T, or in Joseph form
            # (I - C Phi) P_k|k (I - C Phi)^T + C (Qd + P_{k+1|T}) C^T
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        if joseph:
                            acc += c[a, r] * (sc[i, k + 1, r, q] + qd[ip, k + 1, r, q])
                        else:
                            acc += c[a, r] * (sc[i, k + 1, r, q] - pc[i, k + 1, r, q])
                    e[a, q] = acc
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        acc += e[a, r] * c[q, r]
                    sc[i, k, a, q] = acc if joseph else fc[i, k, a, q] + acc
            if joseph:  # + (I - C Phi) P_k|k (I - C Phi)^T; b = I - C Phi, e = b P_k|k
                for a in range(n):
                    for q in range(n):
                        acc = 1.0 if a == q else 0.0
                        for r in range(n):
                            acc -= c[a, r] * phi[ip, k + 1, r, q]
                        b[a, q] = acc
                matmul_into(b, fc[i, k], e)
                for a in range(n):
                    for q in range(n):
                        acc = 0.0
                        for r in range(n):
                            acc += e[a, r] * b[q, r]
                        sc[i, k, a, q] += acc
            for a in range(n):
                for q in range(a + 1, n):
                    v = 0.5 * (sc[i, k, a, q] + sc[i, k, q, a])
                    sc[i, k, a, q] = v
                    sc[i, k, q, a] = v
    return sm, sc
