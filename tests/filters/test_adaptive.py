"""Seed 002 adaptive Kalman filter: oracles C2.1, C2.4, C2.8, C2.9, reductions, C5.3."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.filters.adaptive import binomial_difference, innovation_adaptive_filter
from adaptrack.models import ConstantVelocity

T = 0.1


def table1(n_runs, seed=1):
    t = T * np.arange(701)
    x = np.zeros(t.size)
    xi, vi = 0.0, 200.0
    for i, ti in enumerate(t):
        x[i] = xi
        a, j = (
            (-20.0, 0.0)
            if 20 <= ti < 30 - 1e-9
            else ((2.0 * (ti - 50), 2.0) if 50 <= ti < 70 - 1e-9 else (0.0, 0.0))
        )
        xi += vi * T + a * T**2 / 2 + j * T**3 / 6
        vi += a * T + j * T**2 / 2
    z = x + 5.0 * np.random.default_rng(seed).standard_normal((n_runs, t.size))
    return t, x, z


def interval_rmse(est, x, t):
    out = []
    for a, b in ((0, 20), (20, 30), (30, 50), (50, 70)):
        sel = (t >= a) & ((t < b - 1e-9) if b < 70 else (t <= b + 1e-9))
        out.append(float(np.sqrt(np.mean((est[:, sel] - x[sel]) ** 2))))
    return np.round(out, 2)


def test_c2_1_binomial_coefficients_and_printed_k2_form():
    c = binomial_difference(3)
    np.testing.assert_array_equal(c, [1, -3, 3, -1])
    # (17) with N = 3: -C^T sum c_i Ht_i = C^T [3 Ht_1 - 3 Ht_2 + Ht_3]
    np.testing.assert_array_equal(-c[1:], [3, -3, 1])
    # -(1/T) F^T sum c_i (Ht_i - Ht_{i+1}) = (1/T) F^T [3 Ht_1 - 6 Ht_2 + 4 Ht_3 - Ht_4]
    coef = np.zeros(5)
    for i in range(1, 4):
        coef[i] -= c[i]
        coef[i + 1] += c[i]
    np.testing.assert_array_equal(coef[1:], [3, -6, 4, -1])


def test_c2_4_difference_annihilates_quadratics():
    c = binomial_difference(3)
    t = T * np.arange(10)
    quad = 3.0 + 2.0 * t - 0.7 * t**2
    d = np.convolve(quad, c, mode="valid")
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    cubic = t**3 / 6  # jerk 1 m/s^3: Delta^3 = 6 a3 T^3 = T^3
    np.testing.assert_allclose(np.convolve(cubic, c, mode="valid"), T**3, rtol=1e-9)


@pytest.mark.parametrize("ident", ["published", "mehra"])
def test_c2_8_equivariance_to_position_and_velocity_offsets(ident):
    t, _x, z = table1(20, seed=5)
    base = innovation_adaptive_filter(
        t, z[..., None], measurement_var=25.0, dwna_accel_var=22.0, identification=ident
    ).filtered.mean
    for x0, v0 in ((1e4, 0.0), (-3e3, -250.0)):
        shifted = innovation_adaptive_filter(
            t,
            (z + x0 + v0 * t)[..., None],
            measurement_var=25.0,
            dwna_accel_var=22.0,
            identification=ident,
        ).filtered.mean
        np.testing.assert_allclose(
            shifted[..., 0] - base[..., 0], np.broadcast_to(x0 + v0 * t, base.shape[:2]), atol=1e-7
        )
        np.testing.assert_allclose(
            shifted[:, 1:, 1] - base[:, 1:, 1], np.full((20, 700), v0), atol=1e-7
        )


@pytest.mark.parametrize("ident", ["published", "mehra"])
def test_c2_9_adaptation_frozen_is_the_nominal_kalman_filter(ident):
    t, _x, z = table1(10)
    res = innovation_adaptive_filter(
        t,
        z[..., None],
        measurement_var=25.0,
        dwna_accel_var=22.0,
        identification=ident,
        adapt=False,
    )
    assert not res.identified.any()
    # the same model through the library's Kalman filter, from the two-point prior at t_1
    p1 = 25.0 * np.array([[1, 1 / T], [1 / T, 2 / T**2]])
    prior = at.GaussianState(
        np.stack([z[:, 1], (z[:, 1] - z[:, 0]) / T], -1), np.broadcast_to(p1, (10, 2, 2)), t[1]
    )
    kf = at.kalman_filter(
        t[2:],
        z[:, 2:, None],
        ConstantVelocity(accel_psd=22.0 * T),
        [[1.0, 0.0]],
        [[25.0]],
        prior,
        noise="piecewise",
    )
    np.testing.assert_allclose(res.filtered.mean[:, 2:], kf.filtered.mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(res.filtered.cov[:, 2:], kf.filtered.cov, rtol=1e-9)


def test_three_axes_equal_three_single_axis_runs():
    t, _, z = table1(4)
    rng = np.random.default_rng(2)
    z3 = np.stack([z, z[::-1] + 100.0, rng.normal(size=z.shape) * 5], axis=-1)
    res3 = innovation_adaptive_filter(
        t, z3, measurement_var=[25.0, 25.0, 30.0], dwna_accel_var=22.0
    )
    assert res3.filtered.mean.shape == (4, 701, 6)
    for a, r0 in enumerate((25.0, 25.0, 30.0)):
        one = innovation_adaptive_filter(
            t, z3[..., a : a + 1], measurement_var=r0, dwna_accel_var=22.0
        )
        np.testing.assert_array_equal(res3.filtered.mean[..., [a, 3 + a]], one.filtered.mean)
        np.testing.assert_array_equal(res3.identified[..., a], one.identified[..., 0])


def test_missing_measurements_predict_through():
    t, _, z = table1(3)
    mask = np.ones((3, 701), dtype=bool)
    mask[:, 300:310] = False
    zz = z.copy()
    zz[~mask] = np.nan
    res = innovation_adaptive_filter(
        t, zz[..., None], measurement_var=25.0, dwna_accel_var=22.0, mask=mask
    )
    m = res.filtered.mean
    np.testing.assert_allclose(m[:, 300, 0], m[:, 299, 0] + T * m[:, 299, 1])
    assert not res.identified[:, 300:310].any()
    assert np.all(np.isfinite(m[:, 2:]))


@pytest.mark.statistical
def test_c5_3_reference_numbers():
    """Spec 5.3 reference numbers (spec_checks --table1), reproduced to the printed digits."""
    t, x, z = table1(200, seed=1)
    pub = innovation_adaptive_filter(t, z[..., None], measurement_var=25.0, dwna_accel_var=22.0)
    np.testing.assert_array_equal(
        interval_rmse(pub.filtered.mean[..., 0], x, t), [6.57, 8.20, 6.94, 7.68]
    )
    assert round(100 * pub.fallback_fraction) == 13
    meh = innovation_adaptive_filter(
        t, z[..., None], measurement_var=25.0, dwna_accel_var=22.0, identification="mehra"
    )
    np.testing.assert_array_equal(
        interval_rmse(meh.filtered.mean[..., 0], x, t), [1.90, 6.00, 2.78, 3.17]
    )
    assert round(100 * (1 - meh.fallback_fraction)) == 67
    win = innovation_adaptive_filter(
        t, z[..., None], measurement_var=25.0, dwna_accel_var=22.0, averaging="window"
    )
    np.testing.assert_array_equal(
        interval_rmse(win.filtered.mean[..., 0], x, t), [6.93, 8.94, 6.96, 8.82]
    )
    frozen = innovation_adaptive_filter(
        t, z[..., None], measurement_var=25.0, dwna_accel_var=22.0, adapt=False
    )
    np.testing.assert_array_equal(
        interval_rmse(frozen.filtered.mean[..., 0], x, t), [1.81, 17.96, 5.00, 20.61]
    )


def test_bad_input():
    t, _, z = table1(2)
    zz = z[..., None]
    with pytest.raises(ValueError, match="uniformly spaced"):
        tt = t.copy()
        tt[5] += 0.01
        innovation_adaptive_filter(tt, zz, measurement_var=25.0, dwna_accel_var=22.0)
    with pytest.raises(ValueError, match="exactly one of dwna_accel_var and nominal_process_cov"):
        innovation_adaptive_filter(t, zz, measurement_var=25.0)
    with pytest.raises(ValueError, match="measurement_var must be > 0"):
        innovation_adaptive_filter(t, zz, measurement_var=0.0, dwna_accel_var=22.0)
    with pytest.raises(ValueError, match="first two epochs must be measured"):
        mask = np.ones((2, 701), dtype=bool)
        mask[0, 1] = False
        innovation_adaptive_filter(t, zz, measurement_var=25.0, dwna_accel_var=22.0, mask=mask)
    with pytest.raises(ValueError, match="identification must be 'published' or 'mehra'"):
        innovation_adaptive_filter(
            t, zz, measurement_var=25.0, dwna_accel_var=22.0, identification="sage-husa"
        )
    with pytest.raises(ValueError, match="NaN at index"):
        bad = zz.copy()
        bad[0, 7, 0] = np.nan
        innovation_adaptive_filter(t, bad, measurement_var=25.0, dwna_accel_var=22.0)


@pytest.mark.parametrize(
    ("averaging", "adapt", "n_steps"),
    [("ewma", True, 600), ("ewma", False, 600), ("window", True, 150), ("window", False, 600)],
)
def test_compiled_published_filter_equals_the_numpy_reference(averaging, adapt, n_steps):
    """Same numbers to rounding, same gain decisions. (The sliding-window form feeds rounding
    differences back through the identified gain and they grow over hundreds of steps, as
    between any two builds of NumPy, hence its shorter horizon.)"""
    rng = np.random.default_rng(0)
    t = 0.1 * np.arange(n_steps)
    shape = (40, n_steps, 2)
    z = 0.01 * np.cumsum(np.cumsum(0.5 * rng.normal(size=shape), axis=1), axis=1)
    z += 2.0 * rng.normal(size=shape)
    mask = rng.random(shape[:2]) > 0.05
    mask[:, :2] = True
    z[~mask] = np.nan
    kw = {"measurement_var": 4.0, "dwna_accel_var": 1.0, "mask": mask, "memory": 20}
    kw |= {"averaging": averaging, "adapt": adapt}
    ref = innovation_adaptive_filter(t, z, backend="numpy", **kw)
    got = innovation_adaptive_filter(t, z, backend="numba", **kw)
    a, b = ref.filtered.mean, got.filtered.mean
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    scale = np.nanmax(np.abs(a), axis=-2, keepdims=True)  # per track and component
    assert np.nanmax(np.abs(a - b) / scale) <= 1e-10
    ca, cb = ref.filtered.cov, got.filtered.cov
    assert np.nanmax(np.abs(ca - cb)) <= 1e-10 * np.nanmax(np.abs(ca))
    np.testing.assert_array_equal(ref.identified, got.identified)
    assert ref.fallback_fraction == got.fallback_fraction
    assert (ref.identified.mean() > 0.5) == adapt
    with pytest.raises(ValueError, match="backend must be"):
        innovation_adaptive_filter(t, z, backend="gpu", **kw)
