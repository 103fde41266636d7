"""Observability of linear discrete systems (spec A.7).

The observability matrix stacks ``H, H Phi_1, H Phi_2 Phi_1, ...`` (rows). Seed 000 prints
its transpose, ``N = [H^T, Phi^T H^T, (Phi^T)^2 H^T]``. The rank test equilibrates the
columns first (a non-singular diagonal scaling, which leaves the rank unchanged): the columns
of kinematic observability matrices differ by powers of ``dt``, and an unscaled SVD threshold
would call a well-observable system unobservable at small steps.
"""

from __future__ import annotations

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_square


def observability_matrix(
    transition: ArrayLike, measurement_matrix: ArrayLike, n_steps: int | None = None
) -> FloatArray:
    """Observability matrix of ``(Phi, H)``.

    Parameters
    ----------
    transition : array_like, shape (n, n) or (K, n, n)
        A constant transition, or the transitions ``Phi_1 .. Phi_K`` of irregular steps.
    measurement_matrix : array_like, shape (m, n)
        ``H``.
    n_steps : int, optional
        Number of blocks for a constant transition (default n).

    Returns
    -------
    ndarray, shape (m * (K + 1), n)
        ``[H; H Phi_1; H Phi_2 Phi_1; ...]`` (for a constant ``Phi``: ``H Phi^k``).

    Examples
    --------
    >>> phi = np.array([[1.0, 0.1, 0.005], [0.0, 1.0, 0.1], [0.0, 0.0, 1.0]])
    >>> observability_rank(observability_matrix(phi, [[0.0, 1.0, 0.0]]))
    2
    """
    phi = as_float_array(transition, "transition", min_ndim=2)
    n = check_square(phi, "transition")
    h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
    if h.ndim != 2 or h.shape[1] != n:
        raise ValueError(
            f"measurement_matrix must have shape (m, {n}) to match transition; got {h.shape}"
        )
    if phi.ndim == 2:
        k = n - 1 if n_steps is None else int(n_steps)
        phis = np.broadcast_to(phi, (k, n, n))
    elif phi.ndim == 3:
        if n_steps is not None:
            raise ValueError("n_steps applies to a constant transition only")
        phis = phi
    else:
        raise ValueError(f"transition must have shape (n, n) or (K, n, n); got {phi.shape}")
    rows = [h]
    acc = np.eye(n)
    for p in phis:
        acc = p @ acc
        rows.append(h @ acc)
    return np.vstack(rows)


def observability_rank(obs_matrix: ArrayLike, rtol: float | None = None) -> int:
    """Numerical rank of an observability matrix, after column equilibration.

    Singular values below ``rtol * s_max`` count as zero (default ``max(shape) * eps``).
    Zero columns (states that never reach the output) are left unscaled.
    """
    o = as_float_array(obs_matrix, "obs_matrix", min_ndim=2)
    norms = np.linalg.norm(o, axis=0)
    scaled = o / np.where(norms > 0, norms, 1.0)
    s = np.linalg.svd(scaled, compute_uv=False)
    if s.size == 0 or s[0] == 0:
        return 0
    tol = (max(o.shape) * np.finfo(float).eps if rtol is None else rtol) * s[0]
    return int(np.sum(s > tol))


def unobservable_directions(obs_matrix: ArrayLike, rtol: float | None = None) -> FloatArray:
    """Orthonormal basis (n, n - rank) of the unobservable subspace (null space)."""
    o = as_float_array(obs_matrix, "obs_matrix", min_ndim=2)
    rank = observability_rank(o, rtol)
    norms = np.linalg.norm(o, axis=0)
    d = np.where(norms > 0, norms, 1.0)
    _, _, vt = np.linalg.svd(o / d, full_matrices=True)
    null_scaled = vt[rank:].T
    null = null_scaled / d[:, None]  # map back: o @ (v / d) = (o / d) @ v = 0
    q, _ = np.linalg.qr(null)
    return q


def is_observable(
    transition: ArrayLike, measurement_matrix: ArrayLike, rtol: float | None = None
) -> bool:
    """Tell whether ``(Phi, H)`` (constant or a sequence of transitions) is fully observable.

    Examples
    --------
    >>> from adaptrack.models import Singer, discretize
    >>> phi, _ = discretize(Singer(time_constant_s=5.0, accel_std_mps2=1.0), 0.1)
    >>> is_observable(phi, [[1.0, 0.0, 0.0]]), is_observable(phi, [[0.0, 1.0, 0.0]])
    (True, False)
    """
    o = observability_matrix(transition, measurement_matrix)
    return observability_rank(o, rtol) == o.shape[1]


__all__ = ["is_observable", "observability_matrix", "observability_rank", "unobservable_directions"]
