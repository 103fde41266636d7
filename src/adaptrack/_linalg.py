"""Small batched linear-algebra helpers (no explicit inverses)."""

from __future__ import annotations

import numpy as np

from ._typing import FloatArray


def symmetrize(a: FloatArray) -> FloatArray:
    """Return ``(A + A^T) / 2`` over the last two axes."""
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def mT(a: FloatArray) -> FloatArray:
    """Transpose the last two axes (batched ``.T``)."""
    return np.swapaxes(a, -1, -2)


def matvec(a: FloatArray, x: FloatArray) -> FloatArray:
    """Batched matrix-vector product ``A x`` over leading axes.

    A single matrix ``a`` (n, n) is applied as ``x @ a^T`` (one BLAS call for all vectors).
    """
    if a.ndim == 2:
        return x @ a.T
    return np.einsum("...ij,...j->...i", a, x)


def solve_vec(a: FloatArray, b: FloatArray) -> FloatArray:
    """Solve ``A x = b`` for batched vectors ``b`` (..., n)."""
    return np.linalg.solve(a, b[..., None])[..., 0]


def psd_sqrt(a: FloatArray) -> FloatArray:
    """Return a factor ``L`` with ``L L^T = A`` for symmetric PSD ``A`` (batched, eigen-based)."""
    w, v = np.linalg.eigh(symmetrize(a))
    return v * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


__all__ = ["mT", "matvec", "psd_sqrt", "solve_vec", "symmetrize"]
