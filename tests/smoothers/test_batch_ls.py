"""Multi-node LSQ polynomial smoother: spec D.8 oracles (C3.8-C3.11, C3.14, C3.15)."""

import numpy as np
import pytest

from adaptrack.smoothers.batch_ls import fit_polynomial, smooth_polynomial

COEF = np.array([[5.0, -2.0, 0.3], [1.0, 0.5, -0.1], [-3.0, 0.0, 0.05]])  # per axis, low first


def truth(t, order):
    out = []
    for c in COEF:
        poly = np.polynomial.Polynomial(c)
        out.append((poly.deriv(order) if order else poly)(t))
    return np.stack(out, -1)


def nodes(rng, n=15, noise=0.0, with_derivs=True):
    t = np.sort(rng.uniform(0, 30, n))
    times, orders, values, covs = (
        [t],
        [np.zeros(n, int)],
        [truth(t, 0)],
        [np.broadcast_to(np.diag([4.0, 4.0, 9.0]), (n, 3, 3))],
    )
    if with_derivs:
        for d, var in ((1, 0.25), (2, 0.04)):
            td = t + 0.37 * d
            times.append(td)
            orders.append(np.full(n, d))
            values.append(truth(td, d))
            covs.append(np.broadcast_to(var * np.eye(3), (n, 3, 3)))
    t, o, y, r = (np.concatenate(x) for x in (times, orders, values, covs))
    if noise:
        y = y + noise * rng.standard_normal(y.shape) * np.sqrt(np.diagonal(r, axis1=1, axis2=2))
    return t, o, y, r


def test_c3_8_exact_on_polynomials(rng):
    t, o, y, r = nodes(rng)
    fit = fit_polynomial(t, o, y, r, degree=2)
    est = fit.evaluate([3.0, 17.5])
    for d in range(3):
        np.testing.assert_allclose(
            est.mean[:, 3 * d : 3 * d + 3], truth(np.array([3.0, 17.5]), d), rtol=1e-10, atol=1e-10
        )


def test_c3_9_c3_14_scale_invariance_of_full_and_diagonal_weights(rng):
    t, o, y, r = nodes(rng, noise=1.0)
    for weights in ("full", "diagonal"):
        a = fit_polynomial(t, o, y, r, weights=weights, scale_s=0.5).evaluate([10.0])
        b = fit_polynomial(t, o, y, r, weights=weights, scale_s=7.0).evaluate([10.0])
        np.testing.assert_allclose(a.mean, b.mean, rtol=1e-9)
        np.testing.assert_allclose(a.cov, b.cov, rtol=1e-8, atol=1e-10 * np.abs(a.cov).max())
    # the literal reading of the source depends on T0
    a = fit_polynomial(t, o, y, r, weights="diagonal_unscaled", scale_s=0.5).evaluate([10.0])
    b = fit_polynomial(t, o, y, r, weights="diagonal_unscaled", scale_s=7.0).evaluate([10.0])
    assert np.max(np.abs(a.mean - b.mean)) > 1e-6


def test_c3_10_basis_invariance(rng):
    t, o, y, r = nodes(rng, noise=1.0)
    a = fit_polynomial(t, o, y, r, degree=3).evaluate([4.0, 20.0])
    b = fit_polynomial(t, o, y, r, degree=3, basis="legendre").evaluate([4.0, 20.0])
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-7, atol=1e-12)


def test_c3_11_redundancy_never_increases_the_covariance(rng):
    t, o, y, r = nodes(rng)
    pos_only = o == 0
    basis = {"center_s": 15.0, "scale_s": 1.0}  # same coefficient basis for both fits
    d_pos = fit_polynomial(t[pos_only], o[pos_only], y[pos_only], r[pos_only], **basis).coef_cov
    d_all = fit_polynomial(t, o, y, r, **basis).coef_cov
    assert np.linalg.eigvalsh(d_pos - d_all).min() >= -1e-12 * np.abs(d_pos).max()
    # sandwich with non-optimal (diagonal) weights is never better than the optimal weights
    rr = r.copy()
    rr[o == 0, 0, 1] = rr[o == 0, 1, 0] = 1.5  # correlated position axes
    d_opt = fit_polynomial(t, o, y, rr, **basis).coef_cov
    d_diag = fit_polynomial(t, o, y, rr, weights="diagonal", **basis).coef_cov
    assert np.linalg.eigvalsh(d_diag - d_opt).min() >= -1e-10 * np.abs(d_opt).max()


def test_zero_derivative_weight_limit_is_an_ordinary_fit(rng):
    t, o, y, r = nodes(rng, noise=1.0)
    rr = r.copy()
    rr[o > 0] *= 1e12
    fit = fit_polynomial(t, o, y, rr, joint=False, center_s=0.0, scale_s=1.0)
    pos = o == 0
    w = 1 / np.sqrt(r[pos, 0, 0])
    ref = np.polynomial.polynomial.polyfit(t[pos], y[pos, 0], 2, w=w)
    np.testing.assert_allclose(fit.coef[0], ref, rtol=1e-5, atol=1e-6)


@pytest.mark.statistical
def test_reported_covariance_and_variance_factor_match_monte_carlo():
    rng = np.random.default_rng(7)
    t, o, y0, r = nodes(np.random.default_rng(8))
    sd = np.sqrt(np.diagonal(r, axis1=1, axis2=2))
    ests, s0 = [], []
    for _ in range(2000):
        fit = fit_polynomial(t, o, y0 + rng.standard_normal(y0.shape) * sd, r)
        ests.append(fit.evaluate([12.0]).mean[0])
        s0.append(fit.residual_var_factor)
    cov = fit.evaluate([12.0]).cov[0]
    emp = np.std(np.array(ests), axis=0)
    # sampling sd of a standard deviation from 2000 draws: 1.6 %; 5 sigma = 8 %
    np.testing.assert_allclose(emp, np.sqrt(np.diag(cov)), rtol=0.08)
    # E[s0^2] = 1 with independent nodes and correct weights (dof = 3 * 45 - 9)
    assert abs(np.mean(s0) - 1.0) < 5 * np.sqrt(2 / (3 * 45 - 9) / 2000)


def test_sliding_window_and_errors(rng):
    t, o, y, r = nodes(rng, n=40)
    est = smooth_polynomial(t, o, y, r, [5.0, 15.0], window_s=8.0)
    np.testing.assert_allclose(
        est.mean[:, :3], truth(np.array([5.0, 15.0]), 0), rtol=1e-9, atol=1e-9
    )
    far = smooth_polynomial(t, o, y, r, [500.0], window_s=2.0, insufficient="nan")
    assert np.all(np.isnan(far.mean))
    with pytest.raises(ValueError, match="window at t = 500.0 s: too few nodes"):
        smooth_polynomial(t, o, y, r, [500.0], window_s=2.0)
    with pytest.raises(ValueError, match="too few nodes for a degree-2 polynomial"):
        fit_polynomial(t[:2], o[:2], y[:2], r[:2])
    with pytest.raises(ValueError, match="singular normal equations"):
        fit_polynomial(np.full(3, 1.0), np.zeros(3, int), y[:3], r[:3])
    with pytest.raises(ValueError, match="orders must be integers 0"):
        fit_polynomial(t, o + 3, y, r)
    with pytest.raises(ValueError, match="covs must be positive definite"):
        fit_polynomial(t, o, y, -r)
