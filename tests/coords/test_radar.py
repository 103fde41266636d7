"""Radar polar <-> ENU, rates, Jacobians and covariance propagation (C3.3, C3.5, C3.6)."""

import numpy as np
import pymap3d as pm
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adaptrack.coords import (
    enu_to_polar,
    enu_to_polar_rates,
    polar_kinematics_jacobian,
    polar_kinematics_to_enu,
    polar_to_enu,
    polar_to_enu_cov,
)
from adaptrack.coords.radar import wrap_to_pi

A = np.array([20000.0, 0.3, 0.1, -150.0, 0.002, 0.0005, 2.0, 1e-5, -2e-6])


def path(t):
    """Radar coordinates as quadratics of time; returns (r, eps, beta) (..., 3)."""
    return np.stack(
        [
            A[0] + A[3] * t + A[6] * t**2 / 2,
            A[1] + A[4] * t + A[7] * t**2 / 2,
            A[2] + A[5] * t + A[8] * t**2 / 2,
        ],
        -1,
    )


def test_c3_3_kinematics_are_derivatives_of_r_u():
    h = 1e-2
    p = polar_to_enu(path(np.array([-h, 0.0, h])))
    out = polar_kinematics_to_enu(A)
    np.testing.assert_allclose(out[:3], p[1], rtol=1e-12)
    np.testing.assert_allclose(out[3:6], (p[2] - p[0]) / (2 * h), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(out[6:], (p[2] - 2 * p[1] + p[0]) / h**2, rtol=1e-4, atol=1e-4)


def test_c3_5_jacobian_equals_finite_differences():
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = A * (1 + 0.3 * rng.normal(size=9))
        jac = polar_kinematics_jacobian(a)
        num = np.empty((9, 9))
        for i in range(9):
            step = 1e-6 * max(1.0, abs(a[i]))
            e = np.zeros(9)
            e[i] = step
            num[:, i] = (polar_kinematics_to_enu(a + e) - polar_kinematics_to_enu(a - e)) / (
                2 * step
            )
        np.testing.assert_allclose(jac, num, rtol=1e-6, atol=1e-7 * np.abs(jac).max())


@pytest.mark.statistical
def test_c3_6_propagated_covariance_matches_monte_carlo():
    rng = np.random.default_rng(1)
    sig = np.array([30.0, np.radians(0.08), np.radians(0.1)])
    truth = np.array([40000.0, 1.0, 0.05])
    draws = truth + rng.standard_normal((200000, 3)) * sig
    emp = np.cov(polar_to_enu(draws).T)
    lin = polar_to_enu_cov(truth, np.diag(sig**2))
    # standard deviations agree within 1 % (sampling sd of a std over 2e5 draws: 0.16 %)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(lin)), rtol=0.01)


@pytest.mark.crosscheck
def test_enu_to_polar_against_pymap3d():
    rng = np.random.default_rng(2)
    enu = rng.normal(size=(100, 3)) * [3e4, 3e4, 3e3]
    mine = enu_to_polar(enu)
    az, el, rng_m = pm.enu2aer(*enu.T.copy(), deg=False)
    np.testing.assert_allclose(mine[:, 0], rng_m, rtol=1e-12)
    np.testing.assert_allclose(mine[:, 1], wrap_to_pi(az), atol=1e-12)
    np.testing.assert_allclose(mine[:, 2], el, atol=1e-12)
    assert np.all((mine[:, 1] >= -np.pi) & (mine[:, 1] < np.pi))


@given(st.floats(1.0, 1e6), st.floats(-np.pi, np.pi - 1e-9), st.floats(-1.5, 1.5))
def test_polar_round_trip(r, az, el):
    back = enu_to_polar(polar_to_enu([r, az, el]))
    np.testing.assert_allclose(back, [r, az, el], rtol=1e-9, atol=1e-9)


def test_rates_are_derivatives_of_the_polar_coordinates():
    p = np.array([1.2e4, -3e3, 800.0])
    v = np.array([-150.0, 40.0, 5.0])
    h = 1e-3
    num = (enu_to_polar(p + v * h) - enu_to_polar(p - v * h)) / (2 * h)
    np.testing.assert_allclose(enu_to_polar_rates(p, v), num, rtol=1e-6)


def test_sensor_position_raises():
    with pytest.raises(ValueError, match="coincides with the sensor"):
        enu_to_polar([0.0, 0.0, 0.0])


@pytest.mark.statistical
def test_eq13_chain_covariance_matches_monte_carlo_in_ecef():
    from adaptrack.coords import enu_to_ecef_rotation, polar_kinematics_cov_to_ecef

    rng = np.random.default_rng(4)
    lat, lon = 0.8, 0.15
    sig = np.array([30.0, 1.4e-3, 1.7e-3, 0.5, 1e-4, 1e-4, 0.2, 1e-5, 1e-5])
    cov = polar_kinematics_cov_to_ecef(A, np.diag(sig**2), lat, lon)
    draws = A + rng.standard_normal((100000, 9)) * sig
    rot = np.kron(np.eye(3), enu_to_ecef_rotation(lat, lon))
    emp = np.cov((polar_kinematics_to_enu(draws) @ rot.T).T)
    # linearised standard deviations within 3 % of Monte Carlo (spec D.5; sampling sd 0.2 %)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(cov)), rtol=0.03)
