"""The ``backend=`` choice between the NumPy reference code and the compiled kernels."""

from __future__ import annotations

from typing import Literal

Backend = Literal["auto", "numpy", "numba"]
COMPILED_MIN_TRACK_STEPS = 20_000  # below this "auto" keeps the NumPy path (no compile wait)
SHARED_MIN_TRACKS = 64  # from this many tracks sharing one covariance it is computed once


def use_compiled(
    backend: str, track_steps: int, *, threshold: int = COMPILED_MIN_TRACK_STEPS
) -> bool:
    """Whether to run the compiled kernel: ``"numba"``, or ``"auto"`` from ``threshold`` on.

    Raises
    ------
    ValueError
        If ``backend`` is not ``"auto"``, ``"numpy"`` or ``"numba"``.
    """
    if backend not in ("auto", "numpy", "numba"):
        raise ValueError(f"backend must be 'auto', 'numpy' or 'numba'; got {backend!r}")
    return backend == "numba" or (backend == "auto" and track_steps >= threshold)
