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
objects make.

An extended object gives a number of detections per scan: with a gamma-distributed rate of
mean ``rate`` and shape ``shape`` (the scan-to-scan fluctuation of its radar cross-section)
the count is negative binomial, while a clutter group holds one detection, rarely more
(geometric of mean ``clutter_mean``). :func:`count_ratio` is the ratio of the two for a
count ``n >= 1``, a factor of the likelihood ratio of a hit: a lone detection where an object
gives tens (a multipath ghost beside a body seen by a point-cloud radar) is clutter-like, and
for an object list (one detection per object) the count tells nothing. Vectorised over
tracks (axis 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import gammaln

from .._typing import FloatArray


def survive(existence: ArrayLike, dt_s: ArrayLike, lifetime_s: float) -> FloatArray:
    """Return the existence after ``dt_s`` [s] for a mean lifetime ``lifetime_s`` [s]."""
    return np.asarray(existence, float) * np.exp(-np.asarray(dt_s, float) / lifetime_s)


def after_miss(existence: ArrayLike, detection_probability: ArrayLike) -> FloatArray:
    """Existence after a scan that could have detected the track (``pd``) but did not."""
    r = np.asarray(existence, float)
    pd = np.asarray(detection_probability, float)
    return r * (1.0 - pd) / (1.0 - r * pd)


def after_hit(
    existence: ArrayLike, detection_probability: ArrayLike, likelihood_ratio: FloatArray
) -> FloatArray:
    """Existence after a measurement of likelihood ratio ``g / lambda`` (module docstring)."""
    r = np.asarray(existence, float)
    pd = np.asarray(detection_probability, float)
    gain = 1.0 - pd + pd * np.asarray(likelihood_ratio, float)
    with np.errstate(divide="ignore"):
        return r / (r + (1.0 - r) / gain)  # an infinite ratio gives 1


def at_birth(birth_density: ArrayLike, clutter_density: ArrayLike) -> FloatArray:
    """Existence of a track opened where new objects and clutter have these densities."""
    b = np.asarray(birth_density, float)
    return b / (b + np.asarray(clutter_density, float))


def count_ratio(
    count: ArrayLike, rate: ArrayLike, shape: float, clutter_mean: ArrayLike
) -> FloatArray:
    """Likelihood ratio object / clutter of ``count`` >= 1 detections in one group.

    Object: negative binomial of mean ``rate`` and ``shape``, given at least one detection;
    clutter: geometric on 1, 2, ... of mean ``clutter_mean`` (>= 1).
    """
    n = np.asarray(count, float)
    mu = np.maximum(np.asarray(rate, float), 1e-9)
    k = float(shape)
    log_nb = (gammaln(n + k) - gammaln(k) - gammaln(n + 1) + k * np.log(k / (k + mu))
              + n * np.log(mu / (k + mu)))  # fmt: skip
    log_zero = k * np.log(k / (k + mu))
    log_object = log_nb - np.log1p(-np.exp(log_zero))
    q = 1.0 - 1.0 / np.maximum(np.asarray(clutter_mean, float), 1.0 + 1e-9)
    log_clutter = np.log1p(-q) + (n - 1) * np.log(q)
    return np.exp(np.minimum(log_object - log_clutter, 700.0))


__all__ = ["after_hit", "after_miss", "at_birth", "count_ratio", "survive"]
