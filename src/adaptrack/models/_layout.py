"""Block structure of motion models: per-axis blocks and their placement in the state vector.

A model is a set of independent blocks (one per axis for the kinematic models, one for a
generic :class:`~adaptrack.models.LinearSDE`). Each block is a continuous linear SDE
``dx = F x dt + G dbeta + B u dt`` with ``E[dbeta dbeta^T] = Qc dt`` and a known constant
input ``u``. ``order`` maps the concatenated block states to the model's state order.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray

# closed_form(dt) -> (Phi, Qd_white, Gamma of [G B]),
# shapes (..., d, d), (..., d, d), (..., d, w + c)
ClosedForm = Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]]


@dataclass(frozen=True, eq=False)
class Block:
    """One independent block of a motion model (see module docstring)."""

    drift: FloatArray
    noise_input: FloatArray
    noise_psd: FloatArray
    control_input: FloatArray
    control: FloatArray
    closed_form: ClosedForm | None = None
    source_form: ClosedForm | None = None

    @property
    def dim(self) -> int:
        """Block state size d."""
        return int(self.drift.shape[0])


def interleave_order(n_axes: int, n_derivs: int) -> np.ndarray:
    """Model index of each concatenated per-axis state.

    Per-axis blocks list (position, velocity, ...) of axis 0, then of axis 1, ...; the model
    lists all positions, then all velocities, ... (CONVENTIONS 3). Returns ``order`` with
    ``model_index = order[block_index]``.
    """
    return np.array([i * n_axes + a for a in range(n_axes) for i in range(n_derivs)])


def assemble(blocks: list[FloatArray], order: np.ndarray, square: bool) -> FloatArray:
    """Place per-block arrays block-diagonally and permute to the model's state order.

    ``blocks[b]`` has shape (..., d_b, d_b) if ``square`` else (..., d_b, k_b) (then the
    columns are concatenated without permutation).
    """
    lead = np.broadcast_shapes(*(b.shape[:-2] for b in blocks))
    n = sum(b.shape[-2] for b in blocks)
    k = n if square else sum(b.shape[-1] for b in blocks)
    out = np.zeros(lead + (n, k))
    r = c = 0
    for b in blocks:
        d, w = b.shape[-2:]
        out[..., r : r + d, c : c + w] = b
        r += d
        c += w
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)
    if square:
        return out[..., inv, :][..., :, inv]
    return out[..., inv, :]


__all__ = ["Block", "ClosedForm", "assemble", "interleave_order"]
