"""Differential-Taylor transform (C3.4)."""

import math

import numpy as np

from adaptrack.coords.radar import polar_kinematics_to_enu
from adaptrack.coords.taylor_transform import (
    dt_derivative,
    dt_product,
    dt_sin_cos,
    radar_spectra_to_enu,
)


def test_product_is_polynomial_multiplication():
    u, v = np.array([1.0, 2.0, 3.0, 0.0]), np.array([0.5, -1.0, 0.0, 0.0])
    np.testing.assert_allclose(dt_product(u, v), np.polynomial.polynomial.polymul(u, v)[:4])


def test_sin_cos_spectra_are_taylor_coefficients():
    u = np.array([0.4, 0.3, -0.2, 0.1, 0.0, 0.0])  # u(t) = 0.4 + 0.3 t - 0.2 t^2 + 0.1 t^3
    s, c = dt_sin_cos(u)
    # compare with the Taylor coefficients of sin(u(t)) from finite differences of high order
    t = np.linspace(-0.05, 0.05, 11)
    fit = np.polynomial.polynomial.polyfit(t, np.sin(np.polyval(u[::-1], t)), 5)
    np.testing.assert_allclose(s[:4], fit[:4], rtol=1e-4, atol=1e-6)
    assert s[0] == math.sin(0.4) and c[0] == math.cos(0.4)
    np.testing.assert_allclose(dt_derivative(u, 2.0), [0.15, -0.2, 0.15, 0.0, 0.0])


def test_c3_4_radar_spectra_reproduce_stage_one():
    a = np.array([20000.0, 0.3, 0.1, -150.0, 0.002, 0.0005, 2.0, 1e-5, -2e-6])
    for h in (1.0, 4.8):
        spec = radar_spectra_to_enu(
            [a[0], h * a[3], h**2 * a[6] / 2],
            [a[1], h * a[4], h**2 * a[7] / 2],
            [a[2], h * a[5], h**2 * a[8] / 2],
        )
        k = polar_kinematics_to_enu(a)
        np.testing.assert_allclose(spec[:, 0], k[:3], rtol=1e-13)
        np.testing.assert_allclose(spec[:, 1], h * k[3:6], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(spec[:, 2], h**2 * k[6:9] / 2, rtol=1e-10, atol=1e-12)
