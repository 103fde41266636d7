"""Array type aliases used in annotations (shapes are documented in docstrings)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

# float64 in practice; typed as floating[Any] because NumPy's stubs type linalg results so
FloatArray = npt.NDArray[np.floating[Any]]
BoolArray = npt.NDArray[np.bool_]
ArrayLike = npt.ArrayLike
AnyArray = npt.NDArray[Any]

__all__ = ["AnyArray", "ArrayLike", "BoolArray", "FloatArray"]
