"""Compiled (numba) kernel of the RTS smoother.

The NumPy version in ``rts.py`` is the reference; tests check agreement to 1e-10 relative.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def rts_kernel(fm, fc, pm, pc, phi):  # type: ignore[no-untyped-def]
    """Smooth every track: fm (N, T, n), fc/pc (N, T, n, n), pm (N, T, n), phi (N|1, T, n, n).

    ``C_k = P_k|k Phi_{k+1}^T P_{k+1|k}^-1`` (Cholesky solve), then the RTS recursion.
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
            # Cholesky of P_{k+1|k}
            for a in range(n):
                for q in range(a + 1):
                    acc = pc[i, k + 1, a, q]
                    for r in range(q):
                        acc -= lo[a, r] * lo[q, r]
                    if a == q:
                        if acc <= 0.0:
                            raise ValueError("predicted covariance is not positive definite")
                        lo[a, a] = math.sqrt(acc)
                    else:
                        lo[a, q] = acc / lo[q, q]
            # B = Phi P_k|k  (n x n); solve P_{k+1|k} C^T = B for C^T column by column
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        acc += phi[ip, k + 1, a, r] * fc[i, k, r, q]
                    b[a, q] = acc
            for col in range(n):
                for a in range(n):
                    acc = b[a, col]
                    for r in range(a):
                        acc -= lo[a, r] * d[r, col]
                    d[a, col] = acc / lo[a, a]
                for a in range(n - 1, -1, -1):
                    acc = d[a, col]
                    for r in range(a + 1, n):
                        acc -= lo[r, a] * d[r, col]
                    d[a, col] = acc / lo[a, a]
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
            # covariances: P_k|T = P_k|k + C (P_{k+1|T} - P_{k+1|k}) C^T
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        acc += c[a, r] * (sc[i, k + 1, r, q] - pc[i, k + 1, r, q])
                    e[a, q] = acc
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        acc += e[a, r] * c[q, r]
                    sc[i, k, a, q] = fc[i, k, a, q] + acc
            for a in range(n):
                for q in range(a + 1, n):
                    v = 0.5 * (sc[i, k, a, q] + sc[i, k, q, a])
                    sc[i, k, a, q] = v
                    sc[i, k, q, a] = v
    return sm, sc
