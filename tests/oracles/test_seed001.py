"""Spec section B (seed 001: models M1, M2) and 0.3 oracles: checks C1.1 - C1.16."""

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import quad_vec
from scipy.linalg import expm

import adaptrack as at
from adaptrack.models import (
    ConstantVelocity,
    InverseDynamics,
    ShapingFilter,
    discretize,
    discretize_with_input,
    singer_accel_std,
)
from adaptrack.models._layout import Block
from adaptrack.models.discretize import _discretize_block

from .reference import m1_mp, m2_closed, relerr, relerr_el, van_loan_mp

LAMS = [0.01, 0.03, 0.05, 0.7]
DTS = [0.2, 0.5, 2.0, 6.0]


def m1_f(k):
    return np.array([[0, 1.0], [0, -k]])


def m2_f(k, a):
    return np.array([[0, 1.0, 0], [0, -k, k], [0, 0, -a]])


def gamma_of(model, dt, method="expm"):
    """Gamma of the model's noise input, through the block discretiser (one axis)."""
    (b,), _ = model.blocks()
    return _discretize_block(b, np.asarray(dt, float), method, "white", 2)[2][..., 0]


@pytest.mark.parametrize("method", ["expm", "analytic"])
def test_c1_1_to_c1_3_m1_closed_forms(method):
    for lam in LAMS:
        k = math.sqrt(lam)
        for dt in DTS:
            model = InverseDynamics(lambda_per_s2=lam, accel_psd=1.7)
            phi, qd = discretize(model, dt, method)
            r = math.exp(-k * dt)
            assert relerr(phi, [[1, (1 - r) / k], [0, r]]) < 1e-12  # (77)
            assert relerr(phi, expm(m1_f(k) * dt)) < 1e-12
            gam_src = np.array([dt - (1 - r) / k, 1 - r])  # (78), input G1 = [0, k]
            assert relerr(gamma_of(model, dt, method) * k, gam_src) < 1e-10
            quad = quad_vec(
                lambda s, k=k, lam=lam: (
                    expm(m1_f(k) * s)
                    @ np.array([[0.0], [k]])
                    @ np.array([[0.0, k]])
                    @ expm(m1_f(k) * s).T
                    * (1.7 / lam)
                ),
                0.0,
                dt,
                epsabs=1e-14,
                epsrel=1e-12,
            )[0]
            g = 1.7 / lam
            closed = g * np.array(
                [
                    [dt - (1 - r) * (3 - r) / (2 * k), (1 - r) ** 2 / 2],
                    [(1 - r) ** 2 / 2, k * (1 - r**2) / 2],
                ]
            )
            assert relerr_el(qd, quad) < 1e-7
            assert relerr_el(qd, closed) < 1e-7
            # both parameterisations: gamma fixed (seed) and q_a (default)
            _, qd_g = discretize(InverseDynamics.from_intensity(lam, 1.7 / lam), dt, method)
            np.testing.assert_allclose(qd_g, qd, rtol=1e-14)


def test_c1_4_c1_5_m1_taylor_second_order():
    dt, k, s = sp.symbols("dt k s", positive=True)
    f1 = sp.Matrix([[0, 1], [0, -k]])
    g1 = sp.Matrix([0, k])
    t1 = sp.eye(2) + f1 * dt + f1**2 * dt**2 / 2
    ts = sp.eye(2) + f1 * s + f1**2 * s**2 / 2
    gt = (ts * g1).applyfunc(lambda e: sp.integrate(e, (s, 0, dt)))
    pub_phi = sp.Matrix([[1, dt - k * dt**2 / 2], [0, 1 - k * dt + k**2 * dt**2 / 2]])
    pub_gam = sp.Matrix(
        [k * dt**2 / 2 - k**2 * dt**3 / 6, k * dt - k**2 * dt**2 / 2 + k**3 * dt**3 / 6]
    )
    assert sp.simplify(t1 - pub_phi) == sp.zeros(2, 2)
    assert sp.simplify(gt - pub_gam) == sp.zeros(2, 1)
    # the library's taylor(2) is (82)
    kk = math.sqrt(0.03)
    model = InverseDynamics(lambda_per_s2=0.03, accel_psd=1.0)
    for h in (0.05, 0.3):
        phi, _ = discretize(model, h, "taylor", order=2)
        np.testing.assert_allclose(
            phi, [[1, h - kk * h**2 / 2], [0, 1 - kk * h + kk**2 * h**2 / 2]], rtol=1e-14
        )
        np.testing.assert_allclose(
            gamma_of(model, h, "taylor") * kk,
            [kk * h**2 / 2 - kk**2 * h**3 / 6, kk * h - kk**2 * h**2 / 2 + kk**3 * h**3 / 6],
            rtol=1e-14,
        )
    ep, eg = [], []
    for h in (0.8, 0.4, 0.2):
        ep.append(
            np.max(np.abs(discretize(model, h, "taylor", order=2)[0] - discretize(model, h)[0]))
        )
        eg.append(np.max(np.abs(gamma_of(model, h, "taylor") - gamma_of(model, h))))
    assert 7 < ep[1] / ep[2] < 9
    assert 14 < eg[1] / eg[2] < 18


@pytest.mark.parametrize("method", ["expm", "analytic"])
def test_c1_6_c1_7_m2_closed_forms(method):
    for lam, al in [(0.01, 0.2), (0.05, 1.0), (0.7, 0.05), (0.04, 0.2)]:  # last: alpha == k
        k = math.sqrt(lam)
        model = ShapingFilter(lambda_per_s2=lam, alpha_per_s=al, shaping_std=1.0)
        for h in DTS:
            phi, gam = m2_closed(h, k, al)
            got_phi, _ = discretize(model, h, method)
            got_gam = gamma_of(model, h, method)
            assert relerr(got_phi, expm(m2_f(k, al) * h)) < 1e-12
            assert relerr(got_phi, phi) < 1e-9
            assert relerr(got_gam, gam) < 1e-9
            assert got_gam[1] == pytest.approx(got_phi[0, 2], rel=1e-12)


def test_c1_6b_m2_near_confluence_and_long_steps():
    k = 0.5
    for kdt in (0.2, 5.0):
        dt = kdt / k
        # exactly confluent: closed confluent formulas
        model = ShapingFilter(lambda_per_s2=k**2, alpha_per_s=k, shaping_std=1.0)
        phi, gam = m2_closed(dt, k, k)
        for method in ("expm", "analytic"):
            assert relerr(discretize(model, dt, method)[0], phi) < 1e-13
            assert relerr(gamma_of(model, dt, method), gam) < 1e-13
        # 1 % away: closed forms accurate to 1e-8 there
        al = k * 1.01
        model = ShapingFilter(lambda_per_s2=k**2, alpha_per_s=al, shaping_std=1.0)
        phi, gam = m2_closed(dt, k, al)
        for method in ("expm", "analytic"):
            assert relerr(discretize(model, dt, method)[0], phi) < 1e-8
    # a long step with the recipe equals high precision
    model = ShapingFilter(lambda_per_s2=1.0, alpha_per_s=1.0 + 1e-12, shaping_std=1.0)
    p_ref, q_ref = van_loan_mp(
        m2_f(1.0, 1.0 + 1e-12), np.array([[0.0], [0], [1]]), 2 * (1.0 + 1e-12), 5.0
    )
    for method in ("expm", "analytic"):
        phi, qd = discretize(model, 5.0, method)
        assert relerr(phi, p_ref) < 1e-13
        assert relerr(qd, q_ref) < 1e-13


def test_c1_8_m2_taylor_second_order():
    dt, k, a, s = sp.symbols("dt k alpha s", positive=True)
    f2 = sp.Matrix([[0, 1, 0], [0, -k, k], [0, 0, -a]])
    g2 = sp.Matrix([0, 0, 1])
    t2 = sp.eye(3) + f2 * dt + f2**2 * dt**2 / 2
    t2s = sp.eye(3) + f2 * s + f2**2 * s**2 / 2
    gt2 = (t2s * g2).applyfunc(lambda e: sp.integrate(e, (s, 0, dt)))
    pub2 = sp.Matrix(
        [
            [1, dt - k * dt**2 / 2, k * dt**2 / 2],
            [0, 1 - k * dt + k**2 * dt**2 / 2, k * dt - (k**2 + a * k) * dt**2 / 2],
            [0, 0, 1 - a * dt + a**2 * dt**2 / 2],
        ]
    )
    pubg2 = sp.Matrix(
        [
            k * dt**3 / 6,
            k * dt**2 / 2 - (k**2 + a * k) * dt**3 / 6,
            dt - a * dt**2 / 2 + a**2 * dt**3 / 6,
        ]
    )
    assert sp.simplify(t2 - pub2) == sp.zeros(3, 3)
    assert sp.simplify(gt2 - pubg2) == sp.zeros(3, 1)
    kk, al = math.sqrt(0.03), 0.5
    model = ShapingFilter(lambda_per_s2=0.03, alpha_per_s=al, shaping_std=1.0)
    h = 0.1
    np.testing.assert_allclose(
        discretize(model, h, "taylor", order=2)[0],
        np.array(pub2.subs({dt: h, k: kk, a: al}), dtype=float),
        rtol=1e-14,
    )
    np.testing.assert_allclose(
        gamma_of(model, h, "taylor"),
        np.array(pubg2.subs({dt: h, k: kk, a: al}), dtype=float)[:, 0],
        rtol=1e-14,
    )
    ep = [
        np.max(np.abs(discretize(model, hh, "taylor", order=2)[0] - discretize(model, hh)[0]))
        for hh in (0.4, 0.2)
    ]
    assert 7 < ep[0] / ep[1] < 9


def test_c1_9_m1_piecewise_vs_white_ratios():
    model = InverseDynamics(lambda_per_s2=0.03, accel_psd=0.03)
    h = 1e-3
    _, q_pw = discretize(model, h, noise="piecewise")
    _, q_ex = discretize(model, h)
    ratio = q_pw / q_ex
    np.testing.assert_allclose(ratio, [[0.75, 1], [1, 1]], atol=1e-3)
    # the source's piecewise form (gamma/dt) Gamma1 Gamma1^T = (q_a/dt) Gamma_a Gamma_a^T, with
    # Gamma_a from high precision ((78) itself cancels in float64 at this step)
    _, g_ref, _ = m1_mp(h, math.sqrt(0.03), 0.03)
    np.testing.assert_allclose(q_pw, (0.03 / h) * (g_ref @ g_ref.T), rtol=1e-13)


def test_c1_9b_m2_piecewise_vs_white_ratios():
    model = ShapingFilter(lambda_per_s2=0.03, alpha_per_s=0.5, shaping_std=1.0)
    h = 1e-4
    ratio = discretize(model, h, noise="piecewise")[1] / discretize(model, h)[1]
    np.testing.assert_allclose(ratio, [[5 / 9, 2 / 3, 1], [2 / 3, 3 / 4, 1], [1, 1, 1]], atol=2e-3)


def test_c1_10_shaping_filter_stationary_variance():
    amax, pmax, p0 = 6.0, 0.1, 0.5
    sm2 = amax**2 / 3 * (1 + 4 * pmax - p0)
    model = ShapingFilter(lambda_per_s2=0.04, alpha_per_s=0.3, shaping_std=math.sqrt(sm2))
    phi, qd = discretize(model, 0.1)
    assert phi[2, 2] ** 2 * sm2 + qd[2, 2] == pytest.approx(sm2, rel=1e-10)


def test_c1_10b_singer_rule_and_shaping_std():
    assert singer_accel_std(9.0, 0.05, 0.5) == pytest.approx(9.0 * math.sqrt(0.7 / 3), rel=1e-15)
    assert round(singer_accel_std(9.0, 0.05, 0.5), 2) == 4.35  # spec B.4
    m = ShapingFilter.from_singer_rule(0.04, 1 / 3, 9.0, 0.05, 0.5)
    assert m.shaping_std[0] == pytest.approx(singer_accel_std(9.0, 0.05, 0.5) / 0.2)
    # the acceleration input k xi then has RMS sigma_a
    accel_rms = math.sqrt(m.lambda_per_s2[0]) * m.shaping_std[0]
    assert accel_rms == pytest.approx(9.0 * math.sqrt(0.7 / 3))


def test_c1_11_lambda_to_zero_gamma_fixed_is_noise_free_cv():
    model = InverseDynamics.from_intensity(1e-14, 1.0)
    phi, qd = discretize(model, 0.5)
    np.testing.assert_allclose(phi, [[1, 0.5], [0, 1]], atol=1e-6)
    assert np.max(np.abs(qd)) < 1e-12


def test_c1_11b_lambda_zero_qa_fixed_is_cv():
    for method in ("expm", "analytic", "taylor"):
        for dt in (0.05, 1.0, 30.0):
            m1 = discretize(InverseDynamics(lambda_per_s2=0.0, accel_psd=2.5), dt, method, order=4)
            cv = discretize(ConstantVelocity(accel_psd=2.5), dt, "analytic")
            np.testing.assert_allclose(m1.transition, cv.transition, rtol=1e-14)
            np.testing.assert_allclose(m1.process_cov, cv.process_cov, rtol=1e-13)
    # continuity: tiny lambda is close to CV
    tiny = discretize(InverseDynamics(lambda_per_s2=1e-12, accel_psd=2.5), 1.0, "analytic")
    np.testing.assert_allclose(
        tiny.process_cov, discretize(ConstantVelocity(accel_psd=2.5), 1.0).process_cov, rtol=1e-5
    )


def test_c1_12_taylor_orders():
    for dt in (0.1, 2.0):
        np.testing.assert_allclose(
            discretize(ConstantVelocity(accel_psd=1.3), dt, "taylor", order=0).process_cov,
            1.3 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]),
            rtol=1e-14,
        )
    model = InverseDynamics(lambda_per_s2=0.09, accel_psd=1.0)
    ref = discretize(model, 0.05, "analytic").process_cov
    errs = [
        relerr_el(discretize(model, 0.05, "taylor", order=p).process_cov, ref) for p in (0, 2, 6)
    ]
    assert 5e-3 < errs[0] < 5e-2
    assert 1e-7 < errs[1] < 1e-6
    assert errs[2] < 1e-14


def test_c1_13_m1_analytic_elementwise():
    k, qa = 0.5, 1.3
    for y in np.concatenate([np.geomspace(1e-9, 1e3, 40), [0.999, 1.0, 1.001]]):
        dt = y / k
        p_ref, g_ref, q_ref = m1_mp(dt, k, qa)
        model = InverseDynamics(lambda_per_s2=k**2, accel_psd=qa)
        phi, qd = discretize(model, dt, "analytic")
        assert relerr_el(phi, p_ref) < 1e-14
        assert relerr_el(qd, q_ref) < 1e-14
        assert relerr_el(gamma_of(model, dt, "analytic"), g_ref[:, 0]) < 1e-14
    phi0, qd0 = discretize(InverseDynamics(lambda_per_s2=0.3, accel_psd=1.0), 0.0, "analytic")
    np.testing.assert_array_equal(phi0, np.eye(2))
    assert not np.any(qd0)


def test_c1_14_two_point_differencing_covariance(rng):
    dt, s1 = 0.1, 0.7
    z = rng.normal(size=(200000, 2)) * s1
    v = (z[:, 1] - z[:, 0]) / dt
    emp = np.cov(np.stack([z[:, 1], v]), bias=True)
    want = s1**2 * np.array([[1, 1 / dt], [1 / dt, 2 / dt**2]])
    # sample covariance of 2e5 draws: relative sd ~ sqrt(2/2e5) = 0.3 %, 5 sigma = 1.6 %
    np.testing.assert_allclose(emp, want, rtol=0.016)


@pytest.mark.parametrize("method", ["expm", "analytic"])
def test_c1_15_dt_zero_and_composition(method):
    models = [
        InverseDynamics(lambda_per_s2=0.05, accel_psd=1.0),
        ShapingFilter(lambda_per_s2=0.05, alpha_per_s=0.4, shaping_std=2.0),
        at.models.Singer(time_constant_s=3.0, accel_std_mps2=1.0),
    ]
    for model in models:
        for noise in ("white", "piecewise"):
            phi0, qd0 = discretize(model, 0.0, method, noise=noise)
            np.testing.assert_array_equal(phi0, np.eye(model.state_dim))
            assert not np.any(qd0)
        a, b = 0.37, 1.21
        pa, qa = discretize(model, a, method)
        pb, qb = discretize(model, b, method)
        pab, qab = discretize(model, a + b, method)
        assert relerr(pb @ pa, pab) < 1e-13
        assert relerr(pb @ qa @ pb.T + qb, qab) < 1e-13
    # piecewise noise does not compose (missing by ~30 % in the spec's example)
    m = InverseDynamics(lambda_per_s2=0.05, accel_psd=1.0)
    pa, qa = discretize(m, 0.5, method, noise="piecewise")
    pb, qb = discretize(m, 0.5, method, noise="piecewise")
    _, qab = discretize(m, 1.0, method, noise="piecewise")
    assert relerr(pb @ qa @ pb.T + qb, qab) > 0.05


def test_c1_16_m2_analytic_elementwise():
    for lam, al in ((0.04, 0.2), (0.05, 1.0), (0.01, 0.1)):
        model = ShapingFilter(lambda_per_s2=lam, alpha_per_s=al, shaping_std=1.5)
        for dt in np.geomspace(1e-4, 40.0, 12):
            p_ref, q_ref = van_loan_mp(
                m2_f(math.sqrt(lam), al), np.array([[0.0], [0], [1]]), 2 * al * 1.5**2, dt
            )
            phi, qd = discretize(model, dt, "analytic")
            assert relerr_el(phi, p_ref, floor=1e-300) < 1e-13
            assert relerr_el(qd, q_ref) < 1e-13
            # expm is accurate normwise
            _, qd_e = discretize(model, dt, "expm")
            assert relerr(qd_e, q_ref) < 1e-14


def test_multi_axis_is_block_diagonal_in_state_order():
    model = ShapingFilter(
        lambda_per_s2=[0.01, 0.05], alpha_per_s=[0.2, 1.0], shaping_std=[1.0, 2.0], n_axes=2
    )
    assert model.state_names == ("x", "y", "vx", "vy", "xi_x", "xi_y")
    phi, qd, _ = discretize_with_input(model, 0.3)
    for axis, (lam, al, sm) in enumerate([(0.01, 0.2, 1.0), (0.05, 1.0, 2.0)]):
        p1, q1 = discretize(ShapingFilter(lambda_per_s2=lam, alpha_per_s=al, shaping_std=sm), 0.3)
        idx = [axis, 2 + axis, 4 + axis]
        np.testing.assert_array_equal(phi[np.ix_(idx, idx)], p1)
        np.testing.assert_array_equal(qd[np.ix_(idx, idx)], q1)
    other = [1, 3, 5]
    assert not np.any(phi[np.ix_([0, 2, 4], other)])


def test_block_helper_rejects_nothing_silently():
    # a generic LinearSDE uses the recipe for "analytic"; it must match expm
    f = np.array([[0.0, 1.0], [-2.0, -0.3]])
    sde = at.models.LinearSDE(f, [[0.0], [1.0]], [[0.8]], ("p", "v"))
    for dt in (0.01, 3.0, 50.0):
        a = discretize(sde, dt, "analytic")
        e = discretize(sde, dt, "expm")
        assert relerr(a.transition, e.transition) < 1e-13
        assert relerr(a.process_cov, e.process_cov) < 1e-13
    assert isinstance(sde.blocks()[0][0], Block)
