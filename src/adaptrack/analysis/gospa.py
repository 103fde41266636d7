"""GOSPA metric (alpha = 2) with its parts, and track-identity metrics over time.

Identity metrics: identity switches and fragmentation.

GOSPA (Rahmathullah, Garcia-Fernandez, Svensson 2017) between truth X and estimates Y with
cut-off ``c`` and order ``p``: the p-th root of the smallest, over assignments of pairs closer
than ``c``, of the sum of ``d^p`` over assigned pairs plus ``c^p / 2`` per unassigned truth
(missed) and per unassigned estimate (false). The parts are given in the same p-th power units
and sum to ``gospa^p``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .._typing import FloatArray


@dataclass(frozen=True)
class Gospa:
    """GOSPA distance and its parts (``localisation + missed + false == distance ** p``)."""

    distance: float
    localisation: float
    missed: float
    false: float
    n_missed: int
    n_false: int
    pairs: tuple[tuple[int, int], ...]  # (truth index, estimate index) assigned


def gospa(truth: FloatArray, estimates: FloatArray, c: float, p: float = 2.0) -> Gospa:
    """GOSPA (alpha = 2) between point sets ``truth`` (n, k) and ``estimates`` (m, k)."""
    if not (c > 0 and p >= 1):
        raise ValueError(f"need c > 0 and p >= 1; got c={c}, p={p}")
    x = np.asarray(truth, dtype=float).reshape(len(truth), -1) if len(truth) else np.zeros((0, 1))
    y = (
        np.asarray(estimates, dtype=float).reshape(len(estimates), -1)
        if len(estimates)
        else np.zeros((0, x.shape[1]))
    )
    n, m = x.shape[0], y.shape[0]
    pairs: list[tuple[int, int]] = []
    loc = 0.0
    if n and m:
        d = np.linalg.norm(x[:, None, :] - y[None, :, :], axis=-1)
        cost = np.minimum(d, c) ** p
        rows, cols = linear_sum_assignment(cost)
        for i, j in zip(rows, cols, strict=True):
            if d[i, j] < c:
                pairs.append((int(i), int(j)))
                loc += float(d[i, j] ** p)
    half = c**p / 2.0
    n_miss, n_false = n - len(pairs), m - len(pairs)
    total = loc + half * (n_miss + n_false)
    return Gospa(
        total ** (1.0 / p), loc, half * n_miss, half * n_false, n_miss, n_false, tuple(pairs)
    )


@dataclass(frozen=True)
class IdentityCounts:
    """Identity switches and fragmentations over a sequence of epochs.

    A switch: a truth's track changes; a fragmentation: its track resumes after a gap.
    """

    switches: int
    fragmentations: int


def identity_counts(assignments: list[dict[int, int]]) -> IdentityCounts:
    """Count switches and fragmentations from per-epoch ``{truth id: track id}`` maps."""
    last: dict[int, int] = {}
    assigned_prev: set[int] = set()
    switches = frags = 0
    for epoch in assignments:
        for truth_id, track_id in epoch.items():
            if truth_id in last and last[truth_id] != track_id:
                switches += 1
            if truth_id in last and truth_id not in assigned_prev:
                frags += 1
            last[truth_id] = track_id
        assigned_prev = set(epoch)
    return IdentityCounts(switches, frags)


__all__ = ["Gospa", "IdentityCounts", "gospa", "identity_counts"]
