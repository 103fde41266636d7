"""Spec section A (seed 000) and 0.3 oracles: checks C0.1 - C0.15."""

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import quad_vec
from scipy.linalg import expm

import adaptrack as at
from adaptrack.models import Singer, discretize
from adaptrack.models.discretize import control_offset

from .reference import PI, relerr, relerr_el, singer_closed_float, singer_mp, to_seed

CASES = [(0.1, 5.0, 0.7), (1.0, 2.0, 1.3), (3.0, 0.7, 0.4), (0.05, 30.0, 2.0)]


def a000(tau):
    return np.array([[-1.0 / tau, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])


def seed_disc(dt, tau, sw, method="expm"):
    phi, qd = discretize(Singer(time_constant_s=tau, accel_std_mps2=sw), dt, method)
    return to_seed(phi), to_seed(qd)


@pytest.mark.parametrize("method", ["expm", "analytic"])
def test_c0_1_exact_phi_is_expm(method):
    for dt, tau, sw in CASES:
        phi, _ = seed_disc(dt, tau, sw, method)
        rho = math.exp(-dt / tau)
        closed = np.array(
            [[rho, 0, 0], [tau * (1 - rho), 1, 0], [tau * dt - tau**2 * (1 - rho), dt, 1]]
        )
        assert relerr(phi, expm(a000(tau) * dt)) < 1e-13
        assert relerr(phi, closed) < 1e-13


def test_c0_2_exact_qd_closed_form_vs_quadrature():
    for dt, tau, sw in [(1.0, 5.0, 0.7), (1.0, 2.0, 1.3), (3.0, 0.7, 0.4), (6.0, 30.0, 2.0)]:
        qc = 2 * sw**2 / tau
        g = np.array([[1.0], [0], [0]])
        gg = g @ g.T
        quad = quad_vec(
            lambda s, tau=tau, qc=qc, gg=gg: expm(a000(tau) * s) @ gg @ expm(a000(tau) * s).T * qc,
            0.0,
            dt,
            epsabs=1e-14,
            epsrel=1e-12,
        )[0]
        closed = singer_closed_float(dt, tau, sw)
        for method in ("expm", "analytic"):
            _, qd = seed_disc(dt, tau, sw, method)
            assert relerr_el(qd, closed) < 1e-9
        assert relerr_el(closed, quad) < 1e-9


def test_c0_2b_small_step_series_and_closed_form_cancellation():
    dt, tau, sw = 0.003, 30.0, 2.0
    qc = 2 * sw**2 / tau
    _, qd = seed_disc(dt, tau, sw)
    series = qc * np.array(
        [
            [dt, dt**2 / 2, dt**3 / 6],
            [dt**2 / 2, dt**3 / 3, dt**4 / 8],
            [dt**3 / 6, dt**4 / 8, dt**5 / 20],
        ]
    )
    assert relerr_el(qd, series) < 3 * dt / tau
    # the printed closed form loses accuracy here; the library does not use it for dt/tau < 1
    assert relerr_el(singer_closed_float(dt, tau, sw), qd) > 1e-6


def test_c0_2c_long_steps_exact_where_single_exponential_fails():
    tau, sw = 1.0, 0.7
    for x in (10.0, 20.0, 30.0, 1000.0):
        p_ref, q_ref, _ = singer_mp(x * tau, tau, sw)
        phi, qd = seed_disc(x * tau, tau, sw, "expm")
        assert relerr_el(qd, q_ref) < 1e-14
        assert relerr_el(phi, p_ref) < 1e-14
    # normwise accuracy over dt/tau in [1e-6, 1e3]
    for tau_ in (1.0, 4.0):
        for x in np.geomspace(1e-6, 1e3, 28):
            _, q_ref, _ = singer_mp(x * tau_, tau_, sw)
            _, qd = seed_disc(x * tau_, tau_, sw, "expm")
            assert relerr(qd, q_ref) < 5e-15
            if x >= 0.5:
                assert relerr_el(qd, q_ref) < 1e-14


def test_c0_2c_long_step_input_gain():
    tau = 1.0
    model = Singer(time_constant_s=tau, accel_std_mps2=0.7, mean_accel_mps2=1.0)
    for x in (10.0, 30.0, 1000.0):
        _, _, gam_ref = singer_mp(x * tau, tau, 0.7)
        u = control_offset(model, x * tau)
        # the known-mean input is B = e_w / tau, so its offset is Gamma / tau
        assert relerr_el(to_seed(u), gam_ref[:, 0] / tau) < 1e-14


def test_c0_3_qd_ww_in_both_forms():
    for dt, tau, sw in CASES:
        want = sw**2 * (1 - math.exp(-2 * dt / tau))
        for method in ("expm", "analytic", "source"):
            _, qd = seed_disc(dt, tau, sw, method)
            assert abs(qd[0, 0] - want) < 1e-14


def test_c0_4_source_phi_is_euler_order_dt2():
    tau = 4.0
    errs = []
    for dt in (0.4, 0.2, 0.1):
        src, _ = seed_disc(dt, tau, 1.0, "source")
        ex, _ = seed_disc(dt, tau, 1.0, "expm")
        errs.append(np.max(np.abs(src - ex)))
        rho = math.exp(-dt / tau)
        np.testing.assert_array_equal(src, [[rho, 0, 0], [dt, 1, 0], [0, dt, 1]])
    assert 3.5 < errs[0] / errs[1] < 4.5 and 3.5 < errs[1] / errs[2] < 4.5


def test_c0_4_source_qd():
    dt, tau, sw = 0.3, 2.0, 1.1
    _, qd = seed_disc(dt, tau, sw, "source")
    np.testing.assert_array_equal(qd, np.diag([sw**2 * (1 - math.exp(-dt / tau) ** 2), 0, 0]))


def test_c0_5_semigroup_exact_yes_source_no():
    tau, a, b = 4.0, 0.3, 0.5
    pa, pb, pab = (seed_disc(d, tau, 1.0)[0] for d in (a, b, a + b))
    assert relerr(pa @ pb, pab) < 1e-13
    sa, sb, sab = (seed_disc(d, tau, 1.0, "source")[0] for d in (a, b, a + b))
    assert np.max(np.abs(sa @ sb - sab)) > 1e-3


def test_c0_6_printed_observability_matrices_and_ranks():
    dt, c2, c3, rho = sp.symbols("dt c2 c3 rho", positive=True)
    ph = sp.Matrix([[rho, 0, 0], [dt, 1, 0], [0, dt, 1]])
    cr, cv = sp.Matrix([[0, 0, c3]]), sp.Matrix([[0, c2, 0]])
    nr = sp.Matrix.hstack(cr.T, ph.T * cr.T, (ph.T) ** 2 * cr.T)
    nv = sp.Matrix.hstack(cv.T, ph.T * cv.T, (ph.T) ** 2 * cv.T)
    assert sp.simplify(
        nr - sp.Matrix([[0, 0, c3 * dt**2], [0, c3 * dt, 2 * c3 * dt], [c3, c3, c3]])
    ) == sp.zeros(3, 3)
    assert sp.simplify(
        nv - sp.Matrix([[0, c2 * dt, c2 * dt * (rho + 1)], [c2, c2, c2], [0, 0, 0]])
    ) == sp.zeros(3, 3)
    assert sp.factor(nr.det()) == -(c3**3) * dt**3
    # numerically, through the library, with the source transition (seed order)
    for dt_, tau in ((0.1, 5.0), (1e-3, 30.0), (2.0, 0.7)):
        src, _ = discretize(Singer(time_constant_s=tau), dt_, "source")
        o_range = at.observability_matrix(src, [[1.0, 0.0, 0.0]])
        o_speed = at.observability_matrix(src, [[0.0, 1.0, 0.0]])
        assert at.observability_rank(o_range) == 3
        assert at.observability_rank(o_speed) == 2
        # seed N = (O_seed)^T with O_seed = O P (P the order permutation), so N = P O^T
        r_ = math.exp(-dt_ / tau)
        n_pub = np.array([[0, 0, dt_**2], [0, dt_, 2 * dt_], [1, 1, 1]])
        np.testing.assert_allclose(PI @ o_range.T, n_pub, rtol=1e-12, atol=1e-15)
        n_pub_v = np.array([[0, dt_, dt_ * (r_ + 1)], [1, 1, 1], [0, 0, 0]])
        np.testing.assert_allclose(PI @ o_speed.T, n_pub_v, rtol=1e-12, atol=1e-15)


def test_c0_7_exact_phi_and_irregular_steps_ranks():
    for dt, tau, _ in CASES:
        phi, _ = discretize(Singer(time_constant_s=tau), dt)
        assert at.is_observable(phi, [[1.0, 0, 0]])
        assert at.observability_rank(at.observability_matrix(phi, [[0, 1.0, 0]])) == 2
    for method in ("source", "expm"):
        phis, _ = discretize(Singer(time_constant_s=2.0), np.array([0.13, 0.71]), method)
        assert at.observability_rank(at.observability_matrix(phis, [[1.0, 0, 0]])) == 3
        assert at.observability_rank(at.observability_matrix(phis, [[0, 1.0, 0]])) == 2
        assert not at.is_observable(phis, [[0, 1.0, 0]])
        # the unobservable direction is distance
        d = at.unobservable_directions(at.observability_matrix(phis, [[0, 1.0, 0]]))
        np.testing.assert_allclose(np.abs(d[:, 0]), [1, 0, 0], atol=1e-12)


def test_c0_8_acceleration_stays_stationary():
    for dt, tau, sw in CASES:
        phi, qd = seed_disc(dt, tau, sw)
        assert abs((phi @ np.diag([sw**2, 0, 0]) @ phi.T + qd)[0, 0] - sw**2) < 1e-12


def test_c0_11_mean_acceleration_input():
    for dt, tau, _ in CASES:
        # b(dt) = (1/tau) int_0^dt expm(A s) e_w ds; the printed closed form cancels for small
        # dt/tau, so compare with quadrature and with the high-precision Gamma / tau
        bq = quad_vec(
            lambda s, tau=tau: expm(a000(tau) * s)[:, 0] / tau, 0.0, dt, epsabs=1e-16, epsrel=1e-13
        )[0]
        _, _, gam = singer_mp(dt, tau, 1.0)
        for method in ("expm", "analytic"):
            u = to_seed(
                control_offset(Singer(time_constant_s=tau, mean_accel_mps2=1.7), dt, method)
            )
            assert relerr(u, 1.7 * bq) < 1e-10
            assert relerr_el(u, 1.7 * gam[:, 0] / tau) < 1e-13
        rho = math.exp(-dt / tau)
        if dt / tau >= 0.1:  # the printed closed form where it is accurate
            b = np.array([1 - rho, dt - tau * (1 - rho), dt**2 / 2 - tau * dt + tau**2 * (1 - rho)])
            assert relerr(u, 1.7 * b) < 1e-12


def test_c0_12_information_form_equals_joseph(rng):
    a = rng.normal(size=(3, 3))
    m = a @ a.T + np.eye(3)
    c = rng.normal(size=(2, 3))
    r = np.diag([0.5, 2.0])
    prior = at.GaussianState(np.zeros(3), m, 0.0)
    post_j, _ = at.update(prior, np.zeros(2), c, r, form="joseph")
    post_s, _ = at.update(prior, np.zeros(2), c, r, form="standard")
    info_form = m - m @ c.T @ np.linalg.solve(c @ m @ c.T + r, c @ m)
    assert relerr(post_j.cov, info_form) < 1e-12
    assert relerr(post_s.cov, info_form) < 1e-12


def test_c0_13_phi_functions():
    import mpmath as mp

    from adaptrack.models._phi import phi

    zs = -np.concatenate([[0.0, 2.0, np.nextafter(2.0, 3.0)], np.geomspace(1e-10, 2000.0, 60)])
    for j in range(1, 6):
        got = phi(j, zs)
        for z, g in zip(zs, got):
            zz = mp.mpf(z)
            with mp.workdps(60):
                if abs(zz) < 1:
                    ref = mp.fsum(zz**i / mp.factorial(i + j) for i in range(80))
                else:
                    ref = (mp.e**zz - mp.fsum(zz**i / mp.factorial(i) for i in range(j))) / zz**j
            assert abs(g - float(ref)) / abs(float(ref)) < 3e-15


def test_c0_14_singer_analytic_elementwise():
    tau, sw = 2.0, 1.3
    for x in np.concatenate([np.geomspace(1e-9, 1e3, 40), [0.999, 1.0, 1.001]]):
        p_ref, q_ref, g_ref = singer_mp(x * tau, tau, sw)
        phi, qd = seed_disc(x * tau, tau, sw, "analytic")
        u = to_seed(
            control_offset(
                Singer(time_constant_s=tau, accel_std_mps2=sw, mean_accel_mps2=tau),
                x * tau,
                "analytic",
            )
        )
        assert relerr_el(phi, p_ref) < 1e-14
        assert relerr_el(qd, q_ref) < 1e-14
        assert relerr_el(u, g_ref[:, 0]) < 1e-14
    phi0, qd0 = seed_disc(0.0, tau, sw, "analytic")
    np.testing.assert_array_equal(phi0, np.eye(3))
    assert not np.any(qd0)


def test_c0_15_adaptrack_order_is_permutation():
    tau, sw, dt = 3.0, 0.8, 0.7
    model = Singer(time_constant_s=tau, accel_std_mps2=sw)
    phi_c, qd_c = discretize(model, dt)
    # discretise the seed-order model directly (generic SDE) and permute
    seed_model = at.models.LinearSDE(
        a000(tau), [[1.0], [0.0], [0.0]], [[2 * sw**2 / tau]], ("w", "v", "r")
    )
    phi_s, qd_s = discretize(seed_model, dt)
    assert relerr(phi_c, PI @ phi_s @ PI.T) < 1e-14
    assert relerr(qd_c, PI @ qd_s @ PI.T) < 1e-14
    np.testing.assert_array_equal(at.models.seed000_permutation(), PI)
    assert at.observability_rank(at.observability_matrix(phi_c, [[1.0, 0, 0]])) == 3
    assert at.observability_rank(at.observability_matrix(phi_c, [[0, 1.0, 0]])) == 2
