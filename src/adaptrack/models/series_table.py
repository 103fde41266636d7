"""Exact discretisation as matrix polynomials in the step, for compiled per-step use.

For ``h <= h_max`` the white-noise discretisation of ``dx = F x dt + G dbeta`` is

``Phi(h) = sum_i A_i h^i`` with ``A_i = F^i / i!`` and
``Qd(h) = sum_m C_m h^(m+1)`` with ``C_m = sum_{i+j=m} F^i G Qc G^T (F^T)^j / (i! j! (m+1))``,

the Taylor recipe of spec 0.3.3 grouped by power of ``h``, truncated where the remaining terms
are below ``1e-17`` of the leading one (``x = norm1(F) h_max <= 0.5``: at most 17 terms for
``Phi``, 21 for ``Qd``; finite and exact for nilpotent ``F`` such as constant velocity or
acceleration). Longer steps use ``h = dt / 2^s <= h_max`` and ``s`` doublings (spec 0.3.1). A
kernel evaluates a step with :func:`adaptrack.filters._kernels.series_transition_into` (Horner,
about 0.1 us for four states) instead of reading tabulated ``Phi``/``Qd`` per step, which is what
irregular (jittered) sampling otherwise costs: one matrix exponential per distinct step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import block_diag

from .._typing import FloatArray
from .continuous import MotionModel, drift_matrix, noise_input_matrix, noise_psd

_SUBSTEP_NORM = 0.5
_TAIL = 1e-17
_MAX_TERMS = 40


class SeriesTable(NamedTuple):
    """Coefficients ``A`` (p, n, n) of ``Phi`` and ``C`` (q, n, n) of ``Qd / h``; ``h_max`` [s]."""

    phi_coef: FloatArray
    qd_coef: FloatArray
    h_max: float


def series_table(
    drift: FloatArray, noise_cov_rate: FloatArray, max_dt: float = math.inf
) -> SeriesTable:
    """Table of ``dx = F x dt + dbeta`` with ``E[dbeta dbeta^T] = W dt`` (``W = G Qc G^T``).

    ``max_dt`` [s] is the longest step the caller expects; the table covers
    ``min(max_dt, 0.5 / norm1(F))`` without doublings (any step with them).
    """
    f = np.asarray(drift, dtype=float)
    w = np.asarray(noise_cov_rate, dtype=float)
    if not max_dt > 0:
        raise ValueError(f"max_dt must be > 0; got {max_dt!r}")
    powers = [np.eye(f.shape[0])]
    while len(powers) <= _MAX_TERMS and np.any(powers[-1]):
        powers.append(powers[-1] @ f)
    nilpotent = not np.any(powers[-1])  # the series is finite and exact for every step
    if nilpotent:
        powers.pop()
        h_max, p, q = math.inf, len(powers), 2 * len(powers) - 1
    else:
        norm1 = float(np.abs(f).sum(axis=0).max())
        h_max = min(float(max_dt), _SUBSTEP_NORM / norm1)
        p = _terms(norm1 * h_max)
        q = _terms(2.0 * norm1 * h_max)
    phi_coef = np.stack([powers[i] / math.factorial(i) for i in range(p)])
    qd_coef = np.zeros((q,) + f.shape)
    for m in range(q):
        for i in range(max(0, m - len(powers) + 1), min(m, len(powers) - 1) + 1):
            j = m - i
            qd_coef[m] += (
                powers[i] @ w @ powers[j].T / (math.factorial(i) * math.factorial(j) * (m + 1))
            )
    qd_coef = 0.5 * (qd_coef + np.swapaxes(qd_coef, -1, -2))
    return SeriesTable(phi_coef, np.ascontiguousarray(qd_coef), h_max)


def _terms(x: float) -> int:
    """Count the terms ``x^i / i!`` (``x <= 1``) before the first below ``1e-17``."""
    term, i = 1.0, 0
    while term > _TAIL:
        i += 1
        term *= x / i
    return i


def model_series_table(
    model: MotionModel, max_dt: float = math.inf, extra_random_walk_psd: tuple[float, ...] = ()
) -> SeriesTable:
    """Table of a motion model (no known input), optionally followed by random-walk states.

    ``extra_random_walk_psd``: PSD [unit^2/s] of each appended random-walk state (e.g. the
    lateral offset of the road-constrained tracker).
    """
    blocks, _ = model.blocks()
    if any(np.any(b.control) for b in blocks):
        raise ValueError("series tables cover models without a known input (mean acceleration)")
    g = noise_input_matrix(model)
    extra = len(extra_random_walk_psd)
    f = block_diag(drift_matrix(model), np.zeros((extra, extra)))
    w = block_diag(g @ noise_psd(model) @ g.T, np.diag(extra_random_walk_psd))
    return series_table(f, w, max_dt)


__all__ = ["SeriesTable", "model_series_table", "series_table"]
