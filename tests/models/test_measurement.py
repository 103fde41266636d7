"""Measurement models against independent computations (pymap3d, numerical derivatives)."""

import numpy as np
import pymap3d
import pytest

from adaptrack.models import (
    FunctionMeasurement,
    GeodeticMeasurement,
    PositionMeasurement,
    RadarMeasurement,
)
from adaptrack.models.measurement import residual, state_indices, weighted_mean


def central_jacobian(f, s, rel=1e-6):
    """Central differences of f at s (k,), angle jumps unwrapped: (m, k)."""
    cols = []
    for i in range(s.size):
        h = rel * max(1.0, abs(s[i]))
        up, down = s.copy(), s.copy()
        up[i] += h
        down[i] -= h
        d = f(up) - f(down)
        d = (d + np.pi) % (2 * np.pi) - np.pi if np.all(np.abs(d) < 1) else d
        cols.append(d / (2 * h))
    return np.stack(cols, -1)


@pytest.fixture
def rng():
    return np.random.default_rng(20261127)


def test_3d_radar_matches_pymap3d_azimuth_elevation_range(rng):
    sensor = np.array([120.0, -40.0, 15.0])
    heading = 0.3
    radar = RadarMeasurement(
        noise_cov=[1.0, 1e-6, 1e-6], components=("range", "azimuth", "elevation"),
        n_axes=3, sensor_position=sensor, heading=heading,
    )  # fmt: skip
    p = rng.uniform([-5e4, -5e4, 0.0], [5e4, 5e4, 1e4], size=(50, 3))
    z = radar.predict(p)
    az, el, rng_m = pymap3d.enu2aer(*(p - sensor).T, deg=False)
    np.testing.assert_allclose(z[:, 0], rng_m, rtol=1e-12)
    np.testing.assert_allclose(np.cos(z[:, 1] - (az - heading)), 1.0, atol=1e-12)
    np.testing.assert_allclose(z[:, 2], el, atol=1e-12)
    assert np.all(np.abs(z[:, 1]) <= np.pi)


def test_range_rate_is_the_time_derivative_of_range(rng):
    """Range-rate against the numerical derivative of the range along the relative motion."""
    sensor, sensor_v = np.array([10.0, 20.0, 5.0]), np.array([3.0, -1.0, 0.0])
    radar = RadarMeasurement(
        noise_cov=[1.0, 0.01], components=("range", "range_rate"), n_axes=3,
        sensor_position=sensor, sensor_velocity=sensor_v,
    )  # fmt: skip
    for _ in range(20):
        p, v = rng.normal(0, 3000, 3), rng.normal(0, 80, 3)
        dt = 1e-4
        r_up = np.linalg.norm(p + v * dt - (sensor + sensor_v * dt))
        r_dn = np.linalg.norm(p - v * dt - (sensor - sensor_v * dt))
        z = radar.predict(np.concatenate([p, v]))
        assert z[1] == pytest.approx((r_up - r_dn) / (2 * dt), rel=1e-7, abs=1e-9)


@pytest.mark.parametrize(
    ("components", "n_axes"),
    [
        (("range", "azimuth"), 2),
        (("range", "azimuth", "range_rate"), 2),
        (("azimuth",), 2),
        (("range", "azimuth", "elevation", "range_rate"), 3),
        (("elevation", "range_rate"), 3),
    ],
)
def test_radar_jacobian_matches_central_differences(rng, components, n_axes):
    radar = RadarMeasurement(
        noise_cov=np.ones(len(components)), components=components, n_axes=n_axes,
        sensor_position=rng.normal(0, 50, n_axes), sensor_velocity=rng.normal(0, 5, n_axes),
        heading=1.1,
    )  # fmt: skip
    for _ in range(10):
        s = np.concatenate([rng.normal(0, 2000, n_axes), rng.normal(0, 50, n_axes)])[
            : len(radar.reads)
        ]
        jac = radar.jacobian(s)
        num = central_jacobian(radar.predict, s)
        np.testing.assert_allclose(jac, num, rtol=2e-6, atol=1e-9)


def test_batched_radar_jacobian_equals_one_by_one(rng):
    radar = RadarMeasurement(
        noise_cov=[1, 1, 1, 1], components=("range", "azimuth", "elevation", "range_rate"),
        n_axes=3,
    )  # fmt: skip
    s = rng.normal(0, 1000, (4, 3, 6))
    whole = radar.jacobian(s)
    for i in np.ndindex(4, 3):
        np.testing.assert_array_equal(whole[i], radar.jacobian(s[i]))


def test_geodetic_model_matches_pymap3d_and_its_jacobian_the_differences(rng):
    origin = (np.radians(51.03), np.radians(13.73), 120.0)
    gnss = GeodeticMeasurement.from_metres(origin, horizontal_std_m=2.0, vertical_std_m=4.0)
    enu = rng.uniform([-2e4, -2e4, -100.0], [2e4, 2e4, 3000.0], size=(20, 3))
    z = gnss.predict(enu)
    lat, lon, h = pymap3d.enu2geodetic(*enu.T, *origin, deg=False)
    np.testing.assert_allclose(z[:, 0], lat, atol=1e-11)
    np.testing.assert_allclose(z[:, 1], lon, atol=1e-11)
    np.testing.assert_allclose(z[:, 2], h, atol=1e-5)
    for p in enu[:5]:
        num = central_jacobian(gnss.predict, p, rel=1e-4)  # steps of metres: no rounding
        jac = gnss.jacobian(p)
        row_scale = np.abs(num).max(axis=1, keepdims=True)  # rad/m for lat, lon; m/m for h
        assert np.all(np.abs(jac - num) <= 1e-6 * row_scale)
    # 2 m on the ground at the origin
    sig = np.sqrt(np.diag(gnss.noise_cov))
    jac = gnss.jacobian(np.zeros(3))
    assert sig[0] / jac[0, 1] == pytest.approx(2.0, rel=1e-9)
    assert sig[1] / jac[1, 0] == pytest.approx(2.0, rel=1e-9)


def test_residual_wraps_angles_and_mean_is_circular():
    radar = RadarMeasurement(noise_cov=[1.0, 1e-6])
    d = residual(radar, np.array([100.0, np.pi - 0.01]), np.array([90.0, -np.pi + 0.01]))
    np.testing.assert_allclose(d, [10.0, -0.02], atol=1e-12)
    pts = np.array([[10.0, np.pi - 0.1], [20.0, -np.pi + 0.1]])
    mean = weighted_mean(radar, pts, np.array([0.5, 0.5]))
    assert mean[0] == pytest.approx(15.0)
    assert abs(abs(mean[1]) - np.pi) < 1e-12


def test_function_measurement_differences_agree_with_the_analytic_radar(rng):
    radar = RadarMeasurement(noise_cov=[1.0, 1e-6, 0.1], components=("range", "azimuth",
                             "range_rate"))  # fmt: skip
    user = FunctionMeasurement(
        function=radar.predict, reads=radar.reads, names=radar.names,
        noise_cov=radar.noise_cov, angular=radar.angular,
    )  # fmt: skip
    s = np.concatenate([rng.normal(0, 3000, (5, 2)), rng.normal(0, 30, (5, 2))], -1)
    np.testing.assert_allclose(user.jacobian(s), radar.jacobian(s), rtol=1e-6, atol=1e-10)


def test_position_measurement_is_the_identity():
    pos = PositionMeasurement(noise_cov=[1.0, 4.0])
    s = np.array([[3.0, 4.0]])
    np.testing.assert_array_equal(pos.predict(s), s)
    np.testing.assert_array_equal(pos.jacobian(s), np.eye(2)[None])
    assert pos.names == ("x_m", "y_m")


def test_bad_measurement_models_are_named():
    with pytest.raises(ValueError, match="subset of"):
        RadarMeasurement(noise_cov=[1, 1], components=("azimuth", "range"))
    with pytest.raises(ValueError, match="no elevation"):
        RadarMeasurement(noise_cov=[1, 1], components=("range", "elevation"))
    with pytest.raises(ValueError, match="sensor_position must have shape"):
        RadarMeasurement(noise_cov=[1, 1], sensor_position=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="noise_cov"):
        RadarMeasurement(noise_cov=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="noise_cov"):
        PositionMeasurement(noise_cov=[1.0, -1.0])
    with pytest.raises(ValueError, match="origin"):
        GeodeticMeasurement(noise_cov=[1e-14, 1e-14, 1.0], origin=(51.0, 13.0, 0.0))
    with pytest.raises(ValueError, match="vertical axis"):
        RadarMeasurement(noise_cov=[1, 1]).predict(np.zeros(2))
    user = FunctionMeasurement(lambda s: s[..., :1], reads=("x", "y"), names=("a", "b"),
                               noise_cov=[1.0, 1.0])  # fmt: skip
    with pytest.raises(ValueError, match="returned shape"):
        user.predict(np.zeros(2))
    with pytest.raises(ValueError, match=r"reads state\(s\) \['vx', 'vy'\]"):
        state_indices(RadarMeasurement([1, 1, 1], ("range", "azimuth", "range_rate")), ("x", "y"))
