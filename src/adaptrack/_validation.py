"""Validation helpers for the public boundary.

Every message names the argument, what was expected and what was received, and, where
an array is involved, the index of the first offending entry.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from ._typing import ArrayLike, FloatArray


def _fmt_shape(shape: tuple[Any, ...]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _first_index(bad: np.ndarray) -> tuple[int, ...]:
    idx = np.argwhere(bad)[0]
    return tuple(int(i) for i in idx)


def as_float_array(
    value: ArrayLike, name: str, *, min_ndim: int = 0, allow_nan: bool = False
) -> FloatArray:
    """Convert to a float64 array, rejecting non-numeric input, too few axes and NaN/inf.

    Parameters
    ----------
    value : array_like
        Input values.
    name : str
        Argument name used in error messages.
    min_ndim : int
        Minimum number of axes.
    allow_nan : bool
        If True, NaN is accepted (inf never is).

    Returns
    -------
    ndarray
        float64 array (a copy only where a conversion was needed).
    """
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be numeric array_like; got {type(value).__name__}")
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as exc:  # ragged nested sequences
        raise TypeError(f"{name} must be a rectangular numeric array_like; {exc}") from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.bool_)
    ):
        raise TypeError(f"{name} must be numeric; got dtype {arr.dtype}")
    if np.iscomplexobj(arr):
        raise TypeError(f"{name} must be real; got dtype {arr.dtype}")
    arr = np.asarray(arr, dtype=np.float64)
    if arr.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} axes; got shape {arr.shape}")
    check_finite(arr, name, allow_nan=allow_nan)
    return arr


def check_finite(arr: np.ndarray, name: str, *, allow_nan: bool = False) -> None:
    """Raise ValueError naming the first index holding NaN or inf."""
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if np.any(bad):
        idx = _first_index(bad)
        raise ValueError(
            f"{name} must be finite; got {arr[idx]} at index {idx if arr.ndim != 1 else idx[0]}"
        )


def check_shape(
    arr: np.ndarray, expected: tuple[int, ...], name: str, *, against: str | None = None
) -> None:
    """Raise ValueError unless ``arr.shape == expected``."""
    if arr.shape != expected:
        ref = f" to match {against}" if against else ""
        raise ValueError(f"{name} must have shape {_fmt_shape(expected)}{ref}; got {arr.shape}")


def check_square(arr: np.ndarray, name: str) -> int:
    """Check that the last two axes are square; return their size."""
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must have shape (..., n, n); got {arr.shape}")
    return int(arr.shape[-1])


def check_positive_scalar(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float after checking it is a finite positive (or >= 0) real."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number; got {type(value).__name__}")
    v = float(value)
    ok = v >= 0.0 if allow_zero else v > 0.0
    if not np.isfinite(v) or not ok:
        need = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {need}; got {v}")
    return v


def broadcast_shape(**shapes: tuple[int, ...]) -> tuple[int, ...]:
    """Return the common shape of named array shapes; a ValueError names every one."""
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        listed = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ValueError(f"{listed} must broadcast to one shape") from None


def broadcast_as(a: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    """Return ``a`` broadcast to ``shape``; a ValueError names ``name`` and both shapes."""
    try:
        return np.broadcast_to(a, shape)
    except ValueError:
        raise ValueError(f"{name} must broadcast to shape {shape}; got {np.shape(a)}") from None


def check_symmetric_pd(
    cov: np.ndarray, name: str, *, semidefinite: bool = False, rtol: float = 1e-9
) -> None:
    """Check symmetry (relative to scale) and positive (semi)definiteness over leading axes.

    Raises
    ------
    ValueError
        Naming the batch index of the first offending matrix.
    """
    n = check_square(cov, name)
    if n == 0:
        return
    scale = np.max(np.abs(cov), axis=(-2, -1), keepdims=True)
    asym = np.abs(cov - np.swapaxes(cov, -1, -2)) > rtol * np.maximum(scale, np.finfo(float).tiny)
    if np.any(asym):
        idx = _first_index(np.any(asym, axis=(-2, -1))) if cov.ndim > 2 else ()
        raise ValueError(f"{name} must be symmetric; not symmetric at batch index {idx}")
    if semidefinite:
        eig = np.linalg.eigvalsh(cov)
        tol = -rtol * np.maximum(scale[..., 0], np.finfo(float).tiny)
        bad = np.any(eig < tol, axis=-1)
    else:
        bad = _cholesky_fails(cov)
    if np.any(bad):
        idx = _first_index(np.atleast_1d(bad)) if cov.ndim > 2 else ()
        kind = "positive semi-definite" if semidefinite else "positive definite"
        raise ValueError(f"{name} must be {kind}; not at batch index {idx}")


def _cholesky_fails(cov: np.ndarray) -> np.ndarray:
    """Boolean (batch shape) telling which matrices are not positive definite."""
    flat = cov.reshape((-1,) + cov.shape[-2:])
    try:
        np.linalg.cholesky(flat)
        return np.zeros(cov.shape[:-2], dtype=bool)
    except np.linalg.LinAlgError:
        bad = np.zeros(len(flat), dtype=np.bool_)
        for i, c in enumerate(flat):  # only on the error path, to find the offending index
            try:
                np.linalg.cholesky(c)
                bad[i] = False
            except np.linalg.LinAlgError:
                bad[i] = True
        return bad.reshape(cov.shape[:-2])


def check_times(times: np.ndarray, name: str) -> None:
    """Check that times are strictly increasing along the last axis (sorted, no duplicates)."""
    if times.shape[-1] < 2:
        return
    d = np.diff(times, axis=-1)
    bad = d <= 0
    if np.any(bad):
        idx = _first_index(bad)
        k = idx[-1] + 1
        where = f"track {idx[0]}, step {k}" if times.ndim > 1 else f"step {k}"
        what = "duplicate" if d[idx] == 0 else "unsorted"
        raise ValueError(
            f"{name} must be strictly increasing along the time axis; {what} time at {where}: "
            f"{times[idx[:-1] + (k,)]} after {times[idx]}"
        )


def frozen(arr: np.ndarray) -> np.ndarray:
    """Return a read-only float64 array, copying unless it is already a read-only float64 array."""
    if arr.dtype == np.float64 and not arr.flags.writeable:
        return arr
    out = np.array(arr, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out


__all__ = [
    "as_float_array",
    "check_finite",
    "check_positive_scalar",
    "check_shape",
    "check_square",
    "check_symmetric_pd",
    "check_times",
    "frozen",
]
