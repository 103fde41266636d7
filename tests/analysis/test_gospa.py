"""GOSPA against a brute-force oracle on small cases, and identity counts on known sequences."""

import itertools

import numpy as np
import pytest

from adaptrack.analysis.gospa import gospa, identity_counts


def gospa_brute_force(x, y, c, p):
    """Definition: minimum over partial assignments of the cut-off cost (oracle)."""
    n, m = len(x), len(y)
    best = np.inf
    for k in range(min(n, m) + 1):
        for rows in itertools.combinations(range(n), k):
            for cols in itertools.permutations(range(m), k):
                d = [np.linalg.norm(x[i] - y[j]) for i, j in zip(rows, cols, strict=True)]
                if any(v >= c for v in d):
                    continue
                cost = sum(v**p for v in d) + c**p / 2 * (n - k + m - k)
                best = min(best, cost)
    return best ** (1 / p)


@pytest.mark.parametrize("seed", range(25))
def test_gospa_matches_the_definition(seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 10, (rng.integers(0, 5), 2))
    y = rng.uniform(0, 10, (rng.integers(0, 5), 2))
    c, p = rng.uniform(1, 6), rng.choice([1.0, 2.0])
    res = gospa(x, y, c, p)
    assert res.distance == pytest.approx(gospa_brute_force(x, y, c, p), rel=1e-12)
    assert res.localisation + res.missed + res.false == pytest.approx(res.distance**p)
    assert res.n_missed == len(x) - len(res.pairs) and res.n_false == len(y) - len(res.pairs)


def test_gospa_hand_case():
    # one pair 1 m apart, one missed truth, two false estimates; c = 5, p = 2
    res = gospa(np.array([[0, 0], [10, 0]]), np.array([[1, 0], [30, 0], [31, 0]]), 5.0)
    assert (res.localisation, res.missed, res.false) == (1.0, 12.5, 25.0)
    assert res.distance == pytest.approx(np.sqrt(38.5))
    assert gospa(np.zeros((0, 2)), np.zeros((0, 2)), 5.0).distance == 0.0


def test_identity_switches_and_fragmentation():
    seq = [{1: 10}, {1: 10}, {1: 11}, {}, {1: 11}, {1: 11, 2: 20}, {2: 21}]
    counts = identity_counts(seq)
    assert counts.switches == 2  # 1: 10 -> 11, 2: 20 -> 21
    assert counts.fragmentations == 1  # 1 resumes after a gap
