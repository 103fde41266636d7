"""Row selection over the scene tracker's track table (compiled)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def rows_where(mask, value):  # type: ignore[no-untyped-def]
    """Return the rows whose ``mask`` (bool array) is ``value``: one array, no temporaries."""
    rows = np.empty(mask.size, np.int64)
    k = 0
    for i in range(mask.size):
        if mask[i] == value:
            rows[k] = i
            k += 1
    return rows[:k]


@numba.njit(cache=True, inline="always")
def rows_and_not(a, b):  # type: ignore[no-untyped-def]
    """Return the rows with ``a`` and not ``b`` (bool arrays): one array, no temporaries."""
    rows = np.empty(a.size, np.int64)
    k = 0
    for i in range(a.size):
        if a[i] and not b[i]:
            rows[k] = i
            k += 1
    return rows[:k]
