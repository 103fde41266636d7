"""Radar triple nodes (spec D.2): fit weights, unwrapping, the honest sandwich covariance."""

import math

import numpy as np
import pytest

from adaptrack.smoothers.batch_ls import fit_polynomial
from adaptrack.smoothers.triple_nodes import radar_triple_nodes, rate_fit_weights

SIG = {"range_std_m": 30.0, "azimuth_std_rad": math.radians(0.08),
       "elevation_std_rad": math.radians(0.08)}  # fmt: skip


def polar_of(p):
    """(range, azimuth, elevation) of ENU positions (n, 3), written out here (oracle)."""
    horiz = np.hypot(p[:, 0], p[:, 1])
    return np.linalg.norm(p, axis=1), np.arctan2(p[:, 0], p[:, 1]), np.arctan2(p[:, 2], horiz)


def trajectory(t):
    """A turning aircraft 20-30 km out: positions and velocities (n, 3) in closed form."""
    w = 0.02  # rad/s
    p = np.stack([20e3 + 3000 * np.sin(w * t), 15e3 + 3000 * np.cos(w * t), 3000 + 5 * t], -1)
    v = np.stack([60 * np.cos(w * t), -60 * np.sin(w * t), np.full_like(t, 5.0)], -1)
    return p, v


def test_centred_quadratic_fit_weights_give_the_published_correlations():
    t = np.arange(21.0)
    idx, w1, w2 = rate_fit_weights(t, 10, 7, 2, 1.0)
    assert idx.tolist() == list(range(7, 14))
    assert w2[3] / np.linalg.norm(w2) == pytest.approx(-4 / math.sqrt(84), abs=1e-12)
    assert abs(w1[3]) < 1e-12  # corr(eps_i, eps'_i) = 0 for a centred fit
    idx_b, w1b, _ = rate_fit_weights(t, 11, 7, 2, 1.0)
    shared = np.intersect1d(idx, idx_b)
    c11 = sum(w1[idx.tolist().index(k)] * w1b[idx_b.tolist().index(k)] for k in shared)
    assert c11 / (w1 @ w1) == pytest.approx(16 / 28, abs=1e-12)
    idx_edge, _, _ = rate_fit_weights(t, 0, 7, 2, 1.0)
    assert idx_edge.tolist() == list(range(7))  # one-sided at the record's start


def test_noise_free_nodes_are_the_trajectory():
    t = np.arange(0.0, 40.0, 1.0)
    p, v = trajectory(t)
    r, az, el = polar_of(p)
    nodes = radar_triple_nodes(t, r, az, el, **SIG)
    np.testing.assert_allclose(nodes.values[:, :3], p, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(nodes.values[3:-3, 3:6], v[3:-3], atol=0.05)  # quadratic fits


def test_azimuth_crossing_the_cut_is_unwrapped_before_the_fit():
    """A target passing due south: the azimuth jumps from +pi to -pi between samples."""
    t = np.arange(-10.0, 11.0)
    p = np.stack([40.0 * t, np.full_like(t, -2000.0), np.full_like(t, 300.0)], -1)
    r, az, el = polar_of(p)
    assert np.ptp(az) > math.pi
    nodes = radar_triple_nodes(t, r, az, el, **SIG)
    # one-sided fits at the ends miss by 0.1 m/s; wrapped samples would give ~1e4 m/s
    np.testing.assert_allclose(nodes.values[:, 3:5], [[40.0, 0.0]] * t.size, atol=0.2)
    assert np.all(np.abs(nodes.values[:, 0] - p[:, 0]) < 1e-6)


@pytest.mark.statistical
def test_sandwich_covariance_matches_monte_carlo_and_the_naive_one_under_reports():
    """Spec C3.12: std of the fitted position and velocity at the window centre over 1000
    runs (weights fixed at the noise-free nodes', as the spec's check) against the sandwich
    (within 8 %: a std ratio from 1000 runs has a standard error of 2.2 %) and against inv(N)
    with the nodes taken as independent (under by more than 10 %)."""
    t = np.arange(0.0, 25.0, 1.0)
    p, _ = trajectory(t)
    r, az, el = polar_of(p)
    clean = radar_triple_nodes(t, r, az, el, **SIG)
    sel = np.arange(5, 20)  # a window of 15 nodes, away from the one-sided edges
    rows = np.sort(np.concatenate([3 * sel + d for d in range(3)]))
    tc = np.array([t[12]])
    weight = clean.weight_cov(sel)

    def fit(nodes, full_cov=None):
        times, orders, values, covs = nodes.as_nodes()
        return fit_polynomial(
            times[rows], orders[rows], values[rows], covs[rows], degree=2, center_s=tc[0],
            weight_cov=weight, full_cov=full_cov,
        )  # fmt: skip

    sd_honest = np.sqrt(np.diag(fit(clean, clean.covariance(sel)).evaluate(tc).cov[0]))[:6]
    sd_naive = np.sqrt(np.diag(fit(clean).evaluate(tc).cov[0]))[:6]
    rng = np.random.default_rng(3)
    est = []
    for _ in range(1000):
        noisy = radar_triple_nodes(
            t, r + rng.normal(0, SIG["range_std_m"], t.size),
            az + rng.normal(0, SIG["azimuth_std_rad"], t.size),
            el + rng.normal(0, SIG["elevation_std_rad"], t.size), **SIG,
        )  # fmt: skip
        est.append(fit(noisy).evaluate(tc).mean[0, :6])
    sd_mc = np.std(np.array(est), axis=0)
    assert np.all(np.abs(sd_mc / sd_honest - 1) < 0.08), sd_mc / sd_honest
    assert np.all(sd_mc[:3] / sd_naive[:3] > 1.10), sd_mc / sd_naive


def test_measured_range_rate_is_used_and_tightens_the_velocity():
    t = np.arange(0.0, 30.0, 1.0)
    p, v = trajectory(t)
    r, az, el = polar_of(p)
    rate = np.einsum("ij,ij->i", p, v) / r
    derived = radar_triple_nodes(t, r, az, el, **SIG)
    measured = radar_triple_nodes(t, r, az, el, range_rate=rate, range_rate_std_mps=0.3, **SIG)
    u = p / r[:, None]  # the line of sight: its velocity variance falls
    var_d = np.einsum("ni,nij,nj->n", u, derived.node_cov[:, 3:6, 3:6], u)
    var_m = np.einsum("ni,nij,nj->n", u, measured.node_cov[:, 3:6, 3:6], u)
    assert np.all(var_m < 0.5 * var_d)
    np.testing.assert_allclose(np.einsum("ij,ij->i", measured.values[:, 3:6], u), rate, rtol=1e-9)


def test_bad_records_are_named():
    t = np.arange(10.0)
    p, _ = trajectory(t)
    r, az, el = polar_of(p)
    high = el.copy()
    high[4] = math.radians(87.0)
    with pytest.raises(ValueError, match=r"node 4 \(t = 4.0 s\): elevation 87.0 deg"):
        radar_triple_nodes(t, r, az, high, **SIG)
    with pytest.raises(ValueError, match="window must be odd"):
        radar_triple_nodes(t, r, az, el, window=6, **SIG)
    with pytest.raises(ValueError, match="shorter than"):
        radar_triple_nodes(t[:5], r[:5], az[:5], el[:5], **SIG)
    with pytest.raises(ValueError, match="needs its sigma"):
        radar_triple_nodes(t, r, az, el, range_rate=r * 0, **SIG)
    with pytest.raises(ValueError, match="strictly increasing"):
        radar_triple_nodes(t[::-1], r, az, el, **SIG)


def test_fit_polynomial_weight_cov_is_checked():
    t = np.arange(0.0, 12.0, 1.0)
    p, _ = trajectory(t)
    r, az, el = polar_of(p)
    times, orders, values, covs = radar_triple_nodes(t, r, az, el, **SIG).as_nodes()
    k = times.size
    with pytest.raises(ValueError, match=r"weight_cov must have shape \(108, 108\)"):
        fit_polynomial(times, orders, values, covs, weight_cov=np.eye(3 * k - 3))
    with pytest.raises(ValueError, match="weight_cov"):
        fit_polynomial(times, orders, values, covs, weight_cov=-np.eye(3 * k))
    with pytest.raises(ValueError, match="weights='full' and joint=True"):
        fit_polynomial(times, orders, values, covs, weight_cov=np.eye(3 * k), joint=False)
