"""Global nearest-neighbour assignment and clustering of detections."""

from __future__ import annotations

import numba
import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .._typing import FloatArray

_FORBIDDEN = 1e18


def gnn_assign(cost: FloatArray, miss_cost: FloatArray | float) -> tuple[np.ndarray, np.ndarray]:
    """Globally cheapest one-to-one assignment of tracks (rows) to detections (columns).

    ``cost`` (T, D) is ``inf`` outside the gate; leaving track ``t`` unassigned costs
    ``miss_cost[t]`` (e.g. the gate threshold), so that a pair is chosen only if that is
    cheaper than leaving both out. Solved exactly with
    :func:`scipy.optimize.linear_sum_assignment` on the matrix augmented with one
    "unassigned" column per track. Returns the assigned track and detection indices.
    """
    c = np.asarray(cost, dtype=float)
    n_t, n_d = c.shape
    if n_t == 0 or n_d == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    miss = np.broadcast_to(np.asarray(miss_cost, dtype=float), (n_t,))
    aug = np.full((n_t, n_d + n_t), _FORBIDDEN)
    aug[:, :n_d] = np.where(np.isfinite(c), c, _FORBIDDEN)
    aug[np.arange(n_t), n_d + np.arange(n_t)] = miss
    rows, cols = linear_sum_assignment(aug)
    real = (cols < n_d) & (aug[rows, cols] < _FORBIDDEN)
    return rows[real], cols[real]


def cluster_points(points: FloatArray, radius_m: float) -> np.ndarray:
    """Labels (N,) of the connected groups of points closer than ``radius_m`` (single link)."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    n = p.shape[0]
    if n == 0:
        return np.zeros(0, dtype=int)
    pairs = cKDTree(p).query_pairs(radius_m, output_type="ndarray")
    if len(pairs) == 0:  # every point alone (the usual case of a scan's left-overs)
        return np.arange(n)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


@numba.njit(cache=True)
def cluster_labels(gx, gy, radius):  # type: ignore[no-untyped-def]
    """Labels of the groups of points within ``radius`` of each other (single link).

    Compiled, for a few dozen points (all pairs); groups are numbered in the order of their
    first point, as :func:`cluster_points` (the k-d tree version for many points). Returns
    the labels (N,) and the number of groups.
    """
    n = gx.size
    parent = np.arange(n)
    r2 = radius * radius
    for a in range(n):
        for b in range(a + 1, n):
            if (gx[a] - gx[b]) ** 2 + (gy[a] - gy[b]) ** 2 <= r2:
                ra, rb = a, b
                while parent[ra] != ra:
                    ra = parent[ra]
                while parent[rb] != rb:
                    rb = parent[rb]
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    labels = np.full(n, -1, dtype=np.int64)
    count = 0
    for a in range(n):
        r = a
        while parent[r] != r:
            r = parent[r]
        if labels[r] < 0:
            labels[r] = count
            count += 1
        labels[a] = labels[r]
    return labels, count


__all__ = ["cluster_labels", "cluster_points", "gnn_assign"]
