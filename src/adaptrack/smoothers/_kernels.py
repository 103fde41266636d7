"""Compiled (numba) kernel of the RTS smoother.

The NumPy version in ``rts.py`` is the reference; tests check agreement to 1e-10 relative.
"""

from __future__ import annotations

import numba
import numpy as np

from .._kernel_linalg import cholesky_into, cholesky_solve_into


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
            if not cholesky_into(pc[i, k + 1], lo):
                raise ValueError("predicted covariance is not positive definite")
            # B = Phi P_k|k  (n x n); solve P_{k+1|k} C^T = B for C^T column by column
            for a in range(n):
                for q in range(n):
                    acc = 0.0
                    for r in range(n):
                        acc += phi[ip, k + 1, a, r] * fc[i, k, r, q]
                    b[a, q] = acc
            cholesky_solve_into(lo, b, d)
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
