"""Compiled (numba) kernel of the RTS smoother.

The NumPy version in ``rts.py`` is the reference; tests check agreement to 1e-10 relative.
"""

from __future__ import annotations

import numba
import numpy as np

from .._kernel_linalg import cholesky_into, cholesky_solve_into, matmul_into


@numba.njit(cache=True)
def rts_kernel(fm, fc, pm, pc, phi, qd, joseph):  # type: ignore[no-untyped-def]
    """Smooth every track: fm (N, T, n), fc/pc (N, T, n, n), pm (N, T, n), phi/qd (N|1, T, n, n).

    ``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1`` (Cholesky solve; the pseudo-inverse where the
    prediction is singular), then the RTS recursion in difference or Joseph form.
    """
    n_tr, n_st, n = fm.shape
    sm = fm.copy()
    sc = fc.copy()
    lo = np.empty((n, n))
    b = np.empty((n, n))
    c = np.empty((n, n))
    d = np.empty((n, n))
    e = np.empty((n, n))
    dx = np.empty(n)
    for i in range(n_tr):
        ip = min(i, phi.shape[0] - 1)
        for k in range(n_st - 2, -1, -1):
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
