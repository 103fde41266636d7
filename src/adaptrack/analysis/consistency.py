"""Consistency of a filter on recorded data, without truth: its innovations' statistics.

A filter whose model and noise are right has innovations ``nu_k`` with covariance ``S_k`` that
are independent from step to step: each NIS ``nu^T S^-1 nu`` is chi-square with the observed
components' degrees of freedom, and the innovations whitened by ``S^-1/2`` are uncorrelated
in time. :func:`innovation_consistency` tests both with chi-square and normal bands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..types import FilterResult


@dataclass(frozen=True)
class Consistency:
    """Innovation statistics of one filter run against their bands at ``level``.

    ``mean_nis`` over ``n_updates`` updates against ``mean_nis_band`` (``sum NIS ~ chi2(sum
    dof)``); ``outside`` the fraction of single NIS outside their own two-sided ``level``
    interval against ``outside_band`` (binomial); ``lag1`` the lag-one autocorrelation of the
    whitened innovations against ``+-lag1_limit`` (normal). ``dof`` the mean observed
    components per update.
    """

    n_updates: int
    dof: float
    mean_nis: float
    mean_nis_band: tuple[float, float]
    outside: float
    outside_band: tuple[float, float]
    lag1: float
    lag1_limit: float
    level: float

    @property
    def verdict(self) -> str:
        """``consistent``, or what is off first: the covariance or the whiteness."""
        lo, hi = self.mean_nis_band
        if self.mean_nis > hi:
            return "overconfident: innovations larger than the filter's covariance says"
        if self.mean_nis < lo:
            return "underconfident: innovations smaller than the filter's covariance says"
        if abs(self.lag1) > self.lag1_limit:
            return "innovations correlated in time: the motion model or the noise is off"
        if not self.outside_band[0] <= self.outside <= self.outside_band[1]:
            return "NIS spread unlike chi-square: heavy tails or mixed noise levels"
        return "consistent"


def innovation_consistency(result: FilterResult, level: float = 0.95) -> Consistency:
    """Test the innovations of a one-track filter run (``kalman_filter``'s result).

    Updates without an observed component are left out. Raises ValueError for a batch of
    tracks (pass one track: ``result`` of a 1-D time axis) or fewer than 3 updates.
    """
    from scipy.stats import binom, chi2, norm  # here: scipy.stats takes 0.3 s to import

    info = result.info
    if info.nis.ndim != 1:
        raise ValueError(f"one track expected (nis of shape (T,)); got {info.nis.shape}")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1); got {level}")
    used = info.n_observed > 0
    n = int(used.sum())
    if n < 3:
        raise ValueError(f"at least 3 updates with a measurement are needed; got {n}")
    nis = info.nis[used]
    dof = info.n_observed[used].astype(float)
    tail = (1 - level) / 2
    total = float(dof.sum())
    band = chi2.ppf([tail, 1 - tail], total) / n
    lo, hi = chi2.ppf(tail, dof), chi2.ppf(1 - tail, dof)
    outside = float(np.mean((nis < lo) | (nis > hi)))
    out_band = binom.ppf([tail, 1 - tail], n, 1 - level) / n
    white = _whitened(info.innovation[used], info.innovation_cov[used], result.mask[used])
    a, b = white[:-1], white[1:]
    lag1 = float(np.sum(a * b) / math.sqrt(np.sum(a * a) * np.sum(b * b)))
    return Consistency(
        n_updates=n,
        dof=total / n,
        mean_nis=float(nis.mean()),
        mean_nis_band=(float(band[0]), float(band[1])),
        outside=outside,
        outside_band=(float(out_band[0]), float(out_band[1])),
        lag1=lag1,
        lag1_limit=float(norm.ppf(1 - tail) / math.sqrt(max(white.size - 1, 1))),
        level=level,
    )


def _whitened(nu: np.ndarray, s: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Return the first observed component of each update over its standard deviation."""
    first = np.argmax(mask, axis=-1)
    rows = np.arange(nu.shape[0])
    return nu[rows, first] / np.sqrt(s[rows, first, first])


__all__ = ["Consistency", "innovation_consistency"]
