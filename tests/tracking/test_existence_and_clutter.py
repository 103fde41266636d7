"""Track existence (IPDA) against Bayes' rule by enumeration; the clutter map against counts."""

import numpy as np
import pytest

from adaptrack.tracking.clutter_map import ClutterMap
from adaptrack.tracking.existence import after_hit, after_miss, at_birth, survive


def test_a_miss_follows_bayes_rule():
    r, pd = 0.7, 0.9
    joint_exists = r * (1 - pd)
    assert after_miss(r, pd) == pytest.approx(joint_exists / (joint_exists + (1 - r)))


def test_a_hit_follows_bayes_rule_with_the_clutter_alternative():
    r, pd, g, lam = 0.2, 0.8, 0.05, 0.01
    # exists: detected (density g) or missed while the hit is clutter (density lam)
    exists = r * (pd * g + (1 - pd) * lam)
    absent = (1 - r) * lam
    assert after_hit(r, pd, g / lam) == pytest.approx(exists / (exists + absent))


def test_a_run_of_scans_is_the_product_of_its_odds():
    r, pd, ratio = 0.01, 0.95, 40.0
    rr = r
    for hit in (True, False, True, True, False):
        rr = after_hit(rr, pd, ratio) if hit else after_miss(rr, pd)
    odds = r / (1 - r) * (1 - pd + pd * ratio) ** 3 * (1 - pd) ** 2 / 1.0
    # a miss multiplies the odds by (1 - pd) / 1 and a hit by (1 - pd + pd ratio)
    assert rr / (1 - rr) == pytest.approx(odds)


def test_survival_and_birth():
    assert survive(0.8, 10.0, 100.0) == pytest.approx(0.8 * np.exp(-0.1))
    assert at_birth(1e-6, 3e-6) == pytest.approx(0.25)
    assert after_miss(0.5, 0.0) == pytest.approx(0.5)  # an unseen track learns nothing


def test_the_clutter_map_learns_the_rate_where_clutter_falls():
    rng = np.random.default_rng(3)
    cmap = ClutterMap(prior_density=1e-4, cell_m=10.0, memory_scans=1e9, prior_scans=10.0)
    rate = 0.5  # per scan in the cell [0, 10) x [0, 10)
    for _ in range(4000):
        n = rng.poisson(rate)
        cmap.end_scan(rng.uniform(0.0, 10.0, (n, 2)))
    got = cmap.density(np.array([[5.0, 5.0], [55.0, 5.0]]))
    assert got[0] == pytest.approx(rate / 100.0, rel=0.05)  # Poisson sd of the count: 1.4 %
    assert got[1] == pytest.approx(1e-4 * 10 / (4000 + 10), rel=1e-9)  # the prior's weight


def test_the_clutter_map_forgets():
    cmap = ClutterMap(prior_density=1e-6, cell_m=1.0, memory_scans=100.0, prior_scans=1.0)
    for _ in range(1000):
        cmap.end_scan(np.array([[0.5, 0.5]]))
    busy = cmap.density(np.array([[0.5, 0.5]]))[0]
    assert busy == pytest.approx(1.0, rel=0.02)
    for _ in range(1000):
        cmap.end_scan(np.zeros((0, 2)))
    assert cmap.density(np.array([[0.5, 0.5]]))[0] < 1e-3 * busy


def test_a_clutter_map_rejects_bad_settings():
    with pytest.raises(ValueError, match="cell_m"):
        ClutterMap(prior_density=1e-5, cell_m=0.0)
    with pytest.raises(ValueError, match="prior_density"):
        ClutterMap(prior_density=float("nan"))


def test_the_count_ratio_is_negative_binomial_over_geometric():
    from scipy.stats import geom, nbinom

    from adaptrack.tracking.existence import count_ratio

    rate, shape, clutter_mean = 30.0, 2.0, 1.2
    n = np.arange(1, 60)
    p_nb = shape / (shape + rate)
    want = nbinom.pmf(n, shape, p_nb) / (1 - nbinom.pmf(0, shape, p_nb))
    want /= geom.pmf(n, 1 / clutter_mean)
    assert count_ratio(n, rate, shape, clutter_mean) == pytest.approx(want, rel=1e-9)
    # a lone detection of a body that gives tens is clutter-like; of an object list, not
    assert count_ratio(1, 30.0, 2.0, 1.2) < 0.01
    assert 0.3 < count_ratio(1, 1.0, 2.0, 1.2) < 1.0
