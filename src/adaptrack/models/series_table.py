"""Exact discretisation as matrix polynomials in the step, for compiled per-step use.

For ``h <= h_max`` the white-noise discretisation of ``dx = F x dt + G dbeta + b dt`` is

``Phi(h) = sum_i A_i h^i`` with ``A_i = F^i / i!``,
``Qd(h) = sum_m C_m h^(m+1)`` with ``C_m = sum_{i+j=m} F^i G Qc G^T (F^T)^j / (i! j! (m+1))``
and the known-input offset ``u(h) = sum_i F^i b h^(i+1) / (i+1)!``,

the Taylor recipe of spec 0.3.3 grouped by power of ``h``, truncated where the remaining terms
are below ``1e-17`` of the leading one at ``x = norm1(F) h_max = 0.5`` (16 terms for ``Phi``,
19 for ``Qd``, for every parameter value; finite and exact for nilpotent ``F`` such as
constant velocity or acceleration). Longer steps use ``h = dt / 2^s <= h_max`` and ``s``
doublings (spec 0.3.1). A kernel evaluates a step with
:func:`adaptrack.filters._kernels.series_transition_into` (Horner, about 0.1 us for four
states) instead of reading tabulated ``Phi``/``Qd`` per step, which is what irregular
(jittered) sampling otherwise costs: one matrix exponential per distinct step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._typing import FloatArray
from ._layout import assemble
from .continuous import MotionModel

_SUBSTEP_NORM = 0.5
_TAIL = 1e-17


class SeriesTable(NamedTuple):
    """Coefficients of ``Phi``, ``Qd / h`` and ``u / h``, and the longest direct step.

    ``phi_coef`` (p, n, n), ``qd_coef`` (q, n, n), ``offset_coef`` (p or 0, n) (none without a
    known input), ``h_max`` [s].
    """

    phi_coef: FloatArray
    qd_coef: FloatArray
    offset_coef: FloatArray
    h_max: float


def series_table(
    drift: FloatArray,
    noise_cov_rate: FloatArray,
    max_dt: float = math.inf,
    input_drift: FloatArray | None = None,
) -> SeriesTable:
    """Table of ``dx = F x dt + dbeta + b dt``, ``E[dbeta dbeta^T] = W dt`` (``W = G Qc G^T``).

    ``input_drift``: the constant ``b = B u`` (n,) of a known input, if any.
    ``max_dt`` [s] is the longest step the caller expects; the table covers
    ``min(max_dt, 0.5 / norm1(F))`` without doublings (any step with them).
    """
    f = np.asarray(drift, dtype=float)
    w = np.asarray(noise_cov_rate, dtype=float)
    if not max_dt > 0:
        raise ValueError(f"max_dt must be > 0; got {max_dt!r}")
    n = f.shape[0]
    powers = [np.eye(n)]
    for _ in range(n):  # F is nilpotent iff F^n = 0: then the series is finite and exact
        powers.append(powers[-1] @ f)
    if not np.any(powers[n]):
        powers = [a for a in powers if np.any(a)]
        h_max, p, q = math.inf, len(powers), 2 * len(powers) - 1
    else:
        norm1 = float(np.abs(f).sum(axis=0).max())
        h_max = min(float(max_dt), _SUBSTEP_NORM / norm1)
        # as many terms as the largest step allows (norm1 h_max <= 0.5), whatever the model's
        # parameters: tables of one model structure share one shape (and generated kernel)
        p = _terms(_SUBSTEP_NORM)
        q = _terms(2.0 * _SUBSTEP_NORM)
        while len(powers) < q:
            powers.append(powers[-1] @ f)
    k = len(powers)
    stack = np.stack(powers)
    fact = np.array([math.factorial(i) for i in range(k)], dtype=float)
    phi_coef = stack[:p] / fact[:p, None, None]
    # pair (i, j): F^i W (F^T)^j / (i! j!), summed over i + j = m, divided by m + 1
    scaled = stack / fact[:, None, None]
    pairs = (scaled @ w)[:, None] @ np.swapaxes(scaled, -1, -2)[None]
    by_degree = np.zeros((2 * k - 1, n, n))
    np.add.at(by_degree, np.add.outer(np.arange(k), np.arange(k)), pairs)
    qd_coef = by_degree[:q] / np.arange(1, q + 1)[:, None, None]
    qd_coef = 0.5 * (qd_coef + np.swapaxes(qd_coef, -1, -2))
    if input_drift is None or not np.any(input_drift):
        offset_coef = np.zeros((0, f.shape[0]))
    else:
        b = np.asarray(input_drift, dtype=float)
        offset_coef = np.stack([powers[i] @ b / math.factorial(i + 1) for i in range(p)])
    return SeriesTable(phi_coef, np.ascontiguousarray(qd_coef), offset_coef, h_max)


def shortened(table: SeriesTable) -> SeriesTable:
    """Drop the terms below ``1e-17`` of the leading one at the table's own ``h_max``.

    A table for short steps (``max_dt`` well below ``0.5 / norm1(F)``) needs fewer terms
    than the shared shape carries; the values are unchanged to rounding.
    """
    if math.isinf(table.h_max) or table.phi_coef.shape[0] < 2:
        return table
    x = float(np.abs(table.phi_coef[1]).sum(axis=0).max()) * table.h_max
    p = min(_terms(x), table.phi_coef.shape[0])
    q = min(_terms(2.0 * x), table.qd_coef.shape[0])
    return SeriesTable(
        table.phi_coef[:p], np.ascontiguousarray(table.qd_coef[:q]), table.offset_coef[:p],
        table.h_max,
    )  # fmt: skip


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
    """Table of a motion model, optionally followed by random-walk states.

    ``extra_random_walk_psd``: PSD [unit^2/s] of each appended random-walk state (e.g. the
    lateral offset of the road-constrained tracker).
    """
    blocks, order = model.blocks()
    k = model.state_dim
    n = k + len(extra_random_walk_psd)
    f, w, b = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n)
    f[:k, :k] = assemble([blk.drift for blk in blocks], order, square=True)
    w[:k, :k] = assemble(
        [blk.noise_input @ blk.noise_psd @ blk.noise_input.T for blk in blocks], order, True
    )
    w[k:, k:] = np.diag(extra_random_walk_psd)
    b[:k] = assemble([(blk.control_input @ blk.control)[:, None] for blk in blocks], order, False)[
        :, 0
    ]
    return series_table(f, w, max_dt, b)


__all__ = ["SeriesTable", "model_series_table", "series_table", "shortened"]
