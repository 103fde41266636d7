"""Angle wrapping, in one place: NumPy (:func:`wrap`) and compiled (:func:`wrapped`) forms.

Both return the floored remainder ``(a + half) % (2 half) - half``, in ``[-half, half)``:
azimuths with ``half = pi``, a folding radar's radial speeds with ``half`` its folding speed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._typing import ArrayLike, FloatArray


def wrap(a: ArrayLike, half: float = math.pi) -> FloatArray:
    """Return ``(a + half) % (2 half) - half``: ``a`` wrapped to ``[-half, half)`` (floored)."""
    return (np.asarray(a, dtype=float) + half) % (2 * half) - half


@numba.njit(cache=True, inline="always")
def wrapped(a, half):  # type: ignore[no-untyped-def]
    """Return ``(a + half) % (2 half) - half`` (floored remainder, as Python and NumPy).

    Within one turn either side the remainder is a subtraction or an addition, as Python's
    (``fmod`` returns its argument, or its difference from the modulus exactly, there): the
    same value to the last bit without the library call. Further out it is taken.
    """
    r = a + half
    m = 2.0 * half
    if 0.0 <= r < m:
        return r - half
    if m <= r < 2.0 * m:
        return (r - m) - half
    if -m <= r < 0.0:
        return (r + m) - half
    return r % m - half


__all__ = ["wrap", "wrapped"]
