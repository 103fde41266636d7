"""Track existence as a probability: the IPDA recursion (Musicki, Evans and Stankovic, 1994).

A track's existence probability ``r`` is the probability that a real object stands behind it.
Between scans it survives with ``survival``; a scan that could have detected it (detection
probability ``pd``) either brings a measurement ``z`` or nothing:

- miss: ``r' = r (1 - pd) / (1 - r pd)``;
- hit: ``r' = r (1 - pd + pd g / lambda) / (1 - r pd + r pd g / lambda)``, with ``g`` the
  track's predicted density of ``z`` and ``lambda`` the clutter density at ``z`` (same units:
  per unit volume of the measurement space per scan). The gate's own probability is taken as 1.

A new track opened on a measurement nothing explains starts at
``birth / (birth + clutter)``: the share of the measurement density at that point that new
objects make. Vectorised over tracks (axis 0).
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def survive(existence: FloatArray, dt_s: FloatArray, lifetime_s: float) -> FloatArray:
    """Existence after ``dt_s`` [s] for objects of mean lifetime ``lifetime_s`` [s] (exponential)."""
    return np.asarray(existence, float) * np.exp(-np.asarray(dt_s, float) / lifetime_s)


def after_miss(existence: FloatArray, detection_probability: FloatArray) -> FloatArray:
    """Existence after a scan that could have detected the track (``pd``) but did not."""
    r = np.asarray(existence, float)
    pd = np.asarray(detection_probability, float)
    return r * (1.0 - pd) / (1.0 - r * pd)


def after_hit(
    existence: FloatArray, detection_probability: FloatArray, likelihood_ratio: FloatArray
) -> FloatArray:
    """Existence after a measurement of likelihood ratio ``g / lambda`` (module docstring)."""
    r = np.asarray(existence, float)
    pd = np.asarray(detection_probability, float)
    gain = 1.0 - pd + pd * np.asarray(likelihood_ratio, float)
    return r * gain / (1.0 - r + r * gain)


def at_birth(birth_density: FloatArray, clutter_density: FloatArray) -> FloatArray:
    """Existence of a track opened where new objects and clutter have these densities."""
    b = np.asarray(birth_density, float)
    return b / (b + np.asarray(clutter_density, float))


__all__ = ["after_hit", "after_miss", "at_birth", "survive"]
