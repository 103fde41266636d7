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


@numba.njit(cache=True)
def assignment_by_components(cost, miss_cost, max_choices):  # type: ignore[no-untyped-def]
    """:func:`gnn_assign` for one ``miss_cost`` (e.g. the gate), solved per connected component.

    Tracks (rows) and detections (columns) joined by a pair of cost at most ``miss_cost`` form
    components that do not interact; each is solved exactly on its own by trying every
    one-to-one choice of its tracks (a gated detection or none), when there are at most
    ``max_choices`` of them (the product over its tracks of one plus their gated detections).
    A cost above ``miss_cost``, ``inf`` or NaN is no pair (as :func:`gnn_assign` takes them).
    Compiled, for the few tracks and detections a scan's conflicts involve. Returns
    ``(solved, tracks, detections)``, the pairs in track order; ``solved`` is False (no pairs)
    when a component has more choices: the caller solves the whole with :func:`gnn_assign`.
    """
    n_t, n_d = cost.shape
    parent = np.arange(n_t + n_d)  # tracks, then detections
    for i in range(n_t):
        for j in range(n_d):
            if cost[i, j] <= miss_cost:
                a, b = _root(parent, i), _root(parent, n_t + j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    track_of = np.full(n_t, -1, np.int64)  # each track's detection
    members = np.zeros(n_t, np.int64)
    options = np.zeros((n_t, n_d), np.int64)
    n_options = np.zeros(n_t, np.int64)
    done = np.zeros(n_t, np.bool_)
    for first in range(n_t):
        if done[first]:
            continue
        root = _root(parent, first)
        m, choices = 0, 1
        for i in range(first, n_t):
            if not done[i] and _root(parent, i) == root:
                done[i] = True
                members[m] = i
                m += 1
                n_options[i] = 0
                for j in range(n_d):
                    if cost[i, j] <= miss_cost:
                        options[i, n_options[i]] = j
                        n_options[i] += 1
                choices = min(choices * (1 + n_options[i]), max_choices + 1)
        if choices > max_choices:
            return False, np.zeros(0, np.int64), np.zeros(0, np.int64)
        if m == 1:  # one track: its nearest gated detection, if any
            i = members[0]
            for k in range(n_options[i]):
                j = options[i, k]
                if track_of[i] < 0 or cost[i, j] < cost[i, track_of[i]]:
                    track_of[i] = j
            continue
        _best_choice(cost, miss_cost, members[:m], options, n_options, track_of, n_d)
    tracks = np.flatnonzero(track_of >= 0)
    return True, tracks, track_of[tracks]


@numba.njit(cache=True)
def _root(parent, a):  # type: ignore[no-untyped-def]
    """Return the root of ``a`` in a union-find forest (halving the path)."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(cache=True)
def _best_choice(cost, miss_cost, members, options, n_options, track_of, n_d):  # type: ignore[no-untyped-def]
    """Write the cheapest one-to-one choice of the ``members`` tracks into ``track_of``.

    Every combination of options (digit ``n_options[i]``: no detection, cost ``miss_cost``)
    is counted through like an odometer; one that uses a detection twice is skipped. The
    first cheapest wins a tie.
    """
    m = members.size
    digit = np.zeros(m, np.int64)
    used = np.zeros(n_d, np.bool_)
    best = np.inf
    best_digit = np.zeros(m, np.int64)
    while True:
        total, ok = 0.0, True
        used[:] = False
        for k in range(m):
            i = members[k]
            if digit[k] == n_options[i]:
                total += miss_cost
            else:
                j = options[i, digit[k]]
                ok &= not used[j]
                used[j] = True
                total += cost[i, j]
        if ok and total < best:
            best = total
            best_digit[:] = digit
        k = 0
        while k < m:  # next combination
            digit[k] += 1
            if digit[k] <= n_options[members[k]]:
                break
            digit[k] = 0
            k += 1
        if k == m:
            break
    for k in range(m):
        i = members[k]
        track_of[i] = options[i, best_digit[k]] if best_digit[k] < n_options[i] else -1


__all__ = ["assignment_by_components", "cluster_labels", "cluster_points", "gnn_assign"]
