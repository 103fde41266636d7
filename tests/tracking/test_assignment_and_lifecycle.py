"""Generic tracking layer: gating, GNN assignment, clustering and the track life cycle, on
hand-made cases with a known answer (and brute force where the answer is a minimum)."""

import itertools

import numpy as np
import pytest
from scipy.stats import chi2

from adaptrack.tracking import (
    LifecycleRules,
    TrackBook,
    assignment_by_components,
    cluster_points,
    gate_threshold,
    gnn_assign,
    mahalanobis_squared,
)


def brute_force_assignment(cost, miss):
    """Cheapest partial one-to-one assignment by enumeration (oracle)."""
    n_t, n_d = cost.shape
    best, best_pairs = np.inf, None
    for k in range(min(n_t, n_d) + 1):
        for rows in itertools.combinations(range(n_t), k):
            for cols in itertools.permutations(range(n_d), k):
                c = sum(cost[r, d] for r, d in zip(rows, cols, strict=True))
                c += sum(miss[r] for r in range(n_t) if r not in rows)
                if c < best:
                    best, best_pairs = c, set(zip(rows, cols, strict=True))
    return best, best_pairs


def test_gnn_prefers_the_global_optimum_over_greedy():
    # greedy would give track 0 detection 0 (cost 1) and leave track 1 with cost 9
    cost = np.array([[1.0, 2.0], [1.5, 9.0]])
    rows, cols = gnn_assign(cost, 20.0)
    assert set(zip(rows.tolist(), cols.tolist())) == {(0, 1), (1, 0)}


def test_gnn_leaves_out_pairs_dearer_than_the_miss_cost_and_gated_ones():
    cost = np.array([[np.inf, 3.0], [12.0, np.inf]])
    rows, cols = gnn_assign(cost, 10.0)
    assert list(zip(rows.tolist(), cols.tolist())) == [(0, 1)]
    rows, cols = gnn_assign(np.full((2, 3), np.inf), 10.0)
    assert rows.size == 0 and cols.size == 0
    assert gnn_assign(np.zeros((0, 4)), 1.0)[0].size == 0


@pytest.mark.parametrize("seed", range(20))
def test_gnn_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n_t, n_d = rng.integers(1, 5), rng.integers(1, 5)
    cost = rng.uniform(0, 15, (n_t, n_d))
    cost[rng.uniform(size=cost.shape) < 0.3] = np.inf
    miss = rng.uniform(3, 12, n_t)
    rows, cols = gnn_assign(cost, miss)
    got = cost[rows, cols].sum() + sum(miss[r] for r in range(n_t) if r not in rows)
    best, _ = brute_force_assignment(cost, miss)
    assert got == pytest.approx(best)


@pytest.mark.parametrize("seed", range(40))
def test_assignment_by_components_matches_brute_force_and_scipy(seed):
    """Several conflicts in one scan, each solved on its own: the same cheapest total as the
    brute force over the whole matrix, and the same pairs as SciPy's (the optimum is unique
    for continuous random costs)."""
    rng = np.random.default_rng(seed)
    n_t, n_d = rng.integers(1, 6), rng.integers(1, 6)
    cost = rng.uniform(0, 15, (n_t, n_d))
    cost[rng.uniform(size=cost.shape) < 0.5] = np.inf  # gated out; components form
    gate = 10.0
    solved, rows, cols = assignment_by_components(cost, gate, 4096)
    assert solved
    got = cost[rows, cols].sum() + gate * (n_t - rows.size)
    best, _ = brute_force_assignment(np.where(cost <= gate, cost, np.inf), np.full(n_t, gate))
    assert got == pytest.approx(best)
    ref_rows, ref_cols = gnn_assign(np.where(cost <= gate, cost, np.inf), gate)
    assert rows.tolist() == ref_rows.tolist() and cols.tolist() == ref_cols.tolist()


def test_assignment_by_components_on_a_hand_made_scan():
    """Tracks 0 and 1 share detection 0 (greedy would give it to 0, the global optimum to 1);
    track 2 alone has detections 2 and 3 (takes the nearer); track 3 has none in its gate.
    A component with more choices than allowed is left to the caller."""
    inf = np.inf
    cost = np.array([
        [1.0, 2.0, inf, inf],
        [1.5, inf, inf, inf],
        [inf, inf, 4.0, 3.0],
        [inf, inf, inf, 12.0],
    ])  # fmt: skip
    solved, rows, cols = assignment_by_components(cost, 10.0, 4096)
    assert solved
    assert list(zip(rows.tolist(), cols.tolist(), strict=True)) == [(0, 1), (1, 0), (2, 3)]
    solved, rows, cols = assignment_by_components(cost, 10.0, 5)  # 3 x 2 choices: too many
    assert not solved and rows.size == 0
    cost[1, 0] = np.nan  # a NaN cost is no pair, as in gnn_assign: track 0 takes detection 0
    solved, rows, cols = assignment_by_components(cost, 10.0, 4096)
    pairs = list(zip(rows.tolist(), cols.tolist(), strict=True))
    assert solved and pairs == [(0, 0), (2, 3)]
    reference = gnn_assign(cost, 10.0)
    assert list(zip(*(a.tolist() for a in reference), strict=True)) == pairs


def test_mahalanobis_and_gate():
    s = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    r = np.array([[[2.0, 0.0], [0.0, 3.0], [2.0, 1.0]]])
    np.testing.assert_allclose(mahalanobis_squared(r, s), [[1.0, 9.0, 2.0]])
    assert gate_threshold(3, 0.99) == pytest.approx(chi2.ppf(0.99, 3))
    with pytest.raises(ValueError, match="not positive definite"):
        mahalanobis_squared(r, np.array([[[1.0, 2.0], [2.0, 1.0]]]))
    with pytest.raises(ValueError, match="probability"):
        gate_threshold(3, 1.0)


def test_clusters_are_single_link_groups():
    pts = np.array([[0, 0], [1.5, 0], [3.0, 0], [10, 0], [10, 1], [30, 30]])
    labels = cluster_points(pts, 2.0)
    groups = {frozenset(np.flatnonzero(labels == g)) for g in np.unique(labels)}
    assert groups == {frozenset({0, 1, 2}), frozenset({3, 4}), frozenset({5})}
    assert cluster_points(np.zeros((0, 2)), 1.0).size == 0


def test_m_of_n_confirmation_coasting_and_stable_ids():
    book = TrackBook(LifecycleRules(confirm_hits=3, confirm_window=4, tentative_misses=2,
                                    max_coast_s=1.0, max_coast_stopped_s=10.0,
                                    max_coast_hidden_s=5.0))  # fmt: skip
    ids = book.add(2, 0.0)
    assert ids.tolist() == [1, 2]
    rows = np.arange(2)
    assert book.record(rows, np.array([True, False]), 0.1).tolist() == []
    assert book.record(rows, np.array([True, False]), 0.2).tolist() == [0]  # 3 hits of 4
    none = np.zeros(2, bool)
    assert book.expired(0.2, none, none).tolist() == [1]  # two misses in a row
    book.remove(np.array([1]))
    assert book.ids.tolist() == [1]
    assert book.add(1, 0.3).tolist() == [3]  # ids are never reused
    # a confirmed track is kept while it coasts less than its limit
    rows = np.arange(2)
    for t in (0.5, 0.9, 1.1):
        book.record(rows, np.array([False, True]), t)
    assert book.expired(1.1, none, none).tolist() == []
    assert book.expired(1.3, none, none).tolist() == [0]
    first = np.array([True, False])
    assert book.expired(1.3, first, none).tolist() == []  # stopped: longer limit
    assert book.expired(1.3, none, first).tolist() == []  # hidden: longer limit
    assert book.expired(5.1, none, first).tolist() == [1]  # 4.9 s hidden: kept
    assert book.expired(5.3, none, first).tolist() == [0, 1]  # 5.1 s hidden: deleted
    assert book.expired(5.3, first, none).tolist() == [1]


def test_confirmation_waits_until_the_track_is_ready():
    book = TrackBook(LifecycleRules(confirm_hits=2, confirm_window=3))
    book.add(2, 0.0)
    rows = np.arange(2)
    hits = np.array([True, True])
    assert book.record(rows, hits, 0.1, np.array([True, False])).tolist() == [0]
    assert book.record(rows, hits, 0.2, np.array([True, False])).tolist() == []
    assert book.record(rows, hits, 0.3, np.array([True, True])).tolist() == [1]


def test_an_unconfirmed_track_dies_of_age_and_a_lost_one_of_its_sigma():
    book = TrackBook(LifecycleRules(max_tentative_s=2.0, max_position_std_m=8.0))
    book.add(2, 0.0)
    rows = np.arange(2)
    none = np.zeros(2, bool)
    for t in np.arange(1, 20) / 10:  # both seen every scan; only the second is ever ready
        book.record(rows, np.array([True, True]), t, np.array([False, True]))
    assert book.confirmed.tolist() == [False, True]
    assert book.expired(1.95, none, none).tolist() == []
    assert book.expired(2.05, none, none).tolist() == [0]  # not confirmed within 2 s
    sigma = np.array([1.0, 9.0])
    assert book.expired(1.95, none, none, sigma).tolist() == [1]  # lost: 9 m > 8 m
    assert book.expired(1.95, np.array([False, True]), none, sigma).tolist() == []  # stopped
    assert book.expired(1.95, none, none, np.array([1.0, 7.9])).tolist() == []


def test_a_stopped_track_missed_in_a_row_has_left_when_standstills_are_detectable():
    book = TrackBook(LifecycleRules(confirm_hits=1, confirm_window=1, max_stopped_misses=3))
    book.add(2, 0.0)
    rows = np.arange(2)
    book.record(rows, np.array([True, True]), 0.1)
    stopped, none = np.array([True, True]), np.zeros(2, bool)
    for t in (0.2, 0.3):  # the first missed twice, the second seen
        book.record(rows, np.array([False, True]), t)
    assert book.expired(0.3, stopped, none).tolist() == []
    book.record(rows, np.array([False, True]), 0.4)  # third miss in a row: it has left
    assert book.expired(0.4, stopped, none).tolist() == [0]
    assert book.expired(0.4, none, none).tolist() == []  # moving: the coasting time decides
    assert book.expired(0.4, stopped, none, stopped_detectable=False).tolist() == []


@pytest.mark.parametrize(
    ("field", "value"),
    [("max_tentative_s", 0.0), ("max_coast_s", -1.0), ("max_coast_stopped_s", float("nan")),
     ("max_coast_hidden_s", 0.0), ("max_position_std_m", -5.0), ("tentative_misses", 0),
     ("max_stopped_misses", 0)],
)  # fmt: skip
def test_life_cycle_limits_must_be_positive(field, value):
    with pytest.raises(ValueError, match=f"{field} must be"):
        LifecycleRules(**{field: value})
    LifecycleRules(max_position_std_m=float("inf"))  # no limit is allowed
