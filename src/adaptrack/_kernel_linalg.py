"""Small dense linear algebra for the compiled (numba) kernels: Cholesky factor and solves.

Explicit loops into caller-owned buffers, so the kernels allocate nothing per step.
"""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def cholesky_into(s, lo):  # type: ignore[no-untyped-def]
    """Write the lower Cholesky factor of SPD ``s`` (k, k) into ``lo``; False if not PD."""
    k = s.shape[0]
    for a in range(k):
        for b in range(a + 1):
            acc = s[a, b]
            for c in range(b):
                acc -= lo[a, c] * lo[b, c]
            if a == b:
                if acc <= 0.0:
                    return False
                lo[a, a] = math.sqrt(acc)
            else:
                lo[a, b] = acc / lo[b, b]
    return True


@numba.njit(cache=True, inline="always")
def cholesky_solve_into(lo, rhs, out):  # type: ignore[no-untyped-def]
    """Solve ``(L L^T) X = rhs`` column by column into ``out`` (k, p); ``out`` may be ``rhs``."""
    k = lo.shape[0]
    for col in range(rhs.shape[1]):
        for a in range(k):
            acc = rhs[a, col]
            for c in range(a):
                acc -= lo[a, c] * out[c, col]
            out[a, col] = acc / lo[a, a]
        for a in range(k - 1, -1, -1):
            acc = out[a, col]
            for c in range(a + 1, k):
                acc -= lo[c, a] * out[c, col]
            out[a, col] = acc / lo[a, a]


@numba.njit(cache=True, inline="always")
def matmul_into(a, b, out):  # type: ignore[no-untyped-def]
    """``out = a @ b`` for small matrices (``out`` distinct from ``a`` and ``b``)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            acc = 0.0
            for c in range(a.shape[1]):
                acc += a[i, c] * b[c, j]
            out[i, j] = acc
