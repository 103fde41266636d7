"""Linear-measurement helpers shared by every filter form (plain, Joseph, square root)."""

from __future__ import annotations

import numpy as np

from .._typing import BoolArray, FloatArray

LOG_2PI = float(np.log(2.0 * np.pi))


def masked_model(
    h: FloatArray, r: FloatArray, mask: BoolArray | None
) -> tuple[FloatArray, FloatArray]:
    """Zero the rows of H and decouple the entries of R of missing components.

    A missing component gets a zero row of ``H`` and a unit variance uncorrelated with the
    rest, so it carries no information; ``mask`` None: every component present.
    """
    if mask is None:
        return h, r
    m = mask.astype(np.float64)
    hm = h * m[..., :, None]
    both = m[..., :, None] * m[..., None, :]
    rm = r * both + np.eye(r.shape[-1]) * (1.0 - m)[..., None, :]
    return hm, rm
