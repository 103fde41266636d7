"""A borrowed view is the array's memory with its shape and strides, writable, without ownership."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from adaptrack._borrowed import borrowed, keep_alive


@numba.njit(cache=True)
def _write_through(a):  # type: ignore[no-untyped-def]
    """Write through a borrowed view and a row of it; return its sums, shape and strides."""
    view = borrowed(a)
    view[1, 1] = 5.0
    row = view[2]
    row[0] = 7.0
    return view.sum(), view[1:3].sum(), view.shape, view.strides


@pytest.mark.parametrize("columns", [slice(None), slice(None, None, 2)])
def test_a_borrowed_view_writes_through_and_keeps_shape_and_strides(columns) -> None:
    """On a contiguous array and on a slice of every other column (not contiguous)."""
    base = np.arange(30.0).reshape(5, 6)
    a = base[:, columns]
    expected = a.copy()
    expected[1, 1], expected[2, 0] = 5.0, 7.0
    total, part, shape, strides = _write_through(a)
    np.testing.assert_array_equal(a, expected)
    assert total == expected.sum() and part == expected[1:3].sum()
    assert shape == a.shape and strides == a.strides
    untouched = np.ones(6, bool)
    untouched[columns] = False  # the columns between a slice's are left as they were
    np.testing.assert_array_equal(base[:, untouched], np.arange(30.0).reshape(5, 6)[:, untouched])


@numba.njit(cache=True)
def _write_after_allocating(n):  # type: ignore[no-untyped-def]
    """Borrow a local array, allocate another, write through the view; return both sums."""
    own = np.zeros(n)
    view = borrowed(own)
    other = np.zeros(n)  # would take the memory of ``own`` if ``own`` were freed by now
    view[:] = 1.0
    total = other.sum()
    keep_alive(own)
    return total, view.sum()


def test_keep_alive_keeps_a_borrowed_local_array_until_its_call() -> None:
    """Without it numba frees ``own`` after its last use, and the writes would land elsewhere."""
    for n in (8, 1000, 100_000):
        assert _write_after_allocating(n) == (0.0, float(n))
