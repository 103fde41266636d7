"""A borrowed view is the array's memory with its shape and strides, writable, without ownership;
a stack array is zeroed scratch memory of its kernel's frame."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from adaptrack._borrowed import borrowed, on_stack


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


N = 4


@numba.njit(cache=True, inline="always")
def _pair(m):  # type: ignore[no-untyped-def]
    return on_stack((m, N)), on_stack(m)


@numba.njit(cache=True)
def _stack_rounds(rounds):  # type: ignore[no-untyped-def]
    """Fill two stack arrays each round; return what each round found before writing."""
    found = np.zeros((rounds, 2))
    for k in range(rounds):
        a, b = _pair(3)
        found[k, 0], found[k, 1] = a.sum(), b.sum()
        a[:, :] = k + 1.0
        b[:] = -(k + 1.0)
    a, b = _pair(3)
    return found, a.shape, a.strides, b.shape, a.sum() + b.sum()


def test_stack_arrays_are_zeroed_at_each_call_and_do_not_overlap() -> None:
    """Shapes from literals (through an inlined helper), C strides, zero at every call although
    the same frame memory is reused each round, and writes to one leave the other alone."""
    found, a_shape, a_strides, b_shape, last = _stack_rounds(5)
    np.testing.assert_array_equal(found, np.zeros((5, 2)))
    assert a_shape == (3, N) and a_strides == (N * 8, 8) and b_shape == (3,)
    assert last == 0.0


@numba.njit(cache=True)
def _written_apart():  # type: ignore[no-untyped-def]
    a, b, c = on_stack(5), on_stack((2, 3)), on_stack(5)
    a[:] = 1.0
    b[:, :] = 2.0
    c[:] = 3.0
    return a.sum(), b.sum(), c.sum()


def test_stack_arrays_of_one_frame_are_distinct() -> None:
    assert _written_apart() == (5.0, 12.0, 15.0)


def test_a_shape_not_known_when_compiling_is_a_typing_error() -> None:
    @numba.njit
    def runtime_shape(n):  # type: ignore[no-untyped-def]
        return on_stack(n).sum()

    with pytest.raises(numba.core.errors.TypingError):
        runtime_shape(3)
