"""The ``backend=`` choice between the NumPy reference code and the compiled kernels."""

from __future__ import annotations

import os
from pathlib import Path
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


def kernels_cached(
    kernel: str = "radar_kernel.detections_kernel", package: str = "crossing"
) -> bool:
    """Whether numba's on-disk cache holds ``kernel`` (else a first run compiles).

    ``kernel`` is ``module.function`` in the subpackage ``package`` of :mod:`adaptrack`; its
    cache index is looked for where numba keeps it: under ``NUMBA_CACHE_DIR`` if set, else
    next to the package.
    """
    where = os.environ.get("NUMBA_CACHE_DIR")
    root = Path(where) if where else Path(__file__).parent / package
    return next(root.rglob(f"{kernel}-*.nbi"), None) is not None
