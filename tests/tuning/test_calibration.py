"""Sensor calibration by maximum likelihood: a clock offset between sources, radar biases."""

import math

import numpy as np
import pytest

from adaptrack.tuning.calibration import fit_clock_offset, fit_radar_bias
from tests.cv_truth import cv_states

DT, N, Q, SIGMA_P, SIGMA_V = 0.1, 600, 2.0, 0.5, 0.2


def two_sources(seed, offset_s, n=N, sigma_p=SIGMA_P, sigma_v=SIGMA_V):
    """A planar constant-velocity truth (its own closed form), fixes stamped ``offset_s`` late;
    ``n`` fixes at 10 Hz with noise ``sigma_p`` [m], velocities with ``sigma_v`` [m/s]."""
    rng = np.random.default_rng(seed)
    states = cv_states(rng, [[0.0, 8.0], [0.0, 3.0]], DT, Q, n)
    t = DT * np.arange(n)
    pos = states[:, :, 0] + rng.normal(0, sigma_p, (n, 2))
    vel = states[:, :, 1] + rng.normal(0, sigma_v, (n, 2))
    return t + offset_s, pos, t, vel


@pytest.mark.statistical
@pytest.mark.parametrize(("seed", "offset_s"), [(1, 0.1), (2, -0.05)])
def test_the_offset_is_recovered_within_its_standard_error(seed, offset_s):
    """Within 3 standard errors (two-sided 0.3 % each if the errors are honest), as are the
    noise levels and the motion PSD; the offset's standard error is tens of milliseconds or
    less on 60 s at 10 Hz."""
    fit = fit_clock_offset(*two_sources(seed, offset_s))
    assert fit.converged, fit.message
    truth = {"offset_s": offset_s, "accel_psd": Q, "position_var": SIGMA_P**2,
             "velocity_var": SIGMA_V**2}  # fmt: skip
    for name, value in truth.items():
        assert abs(fit.value(name) - value) < 3 * fit.std_error(name), (name, fit.value(name))
    assert fit.std_error("offset_s") < 0.03
    lo, hi = fit.interval("offset_s")
    assert lo < offset_s < hi and hi - lo == pytest.approx(
        2 * 1.96 * fit.std_error("offset_s"), rel=1e-4
    )


@pytest.mark.statistical
@pytest.mark.parametrize("seed", [7, 8])
def test_a_120_ms_receiver_latency_is_recovered_within_10_ms(seed):
    """GNSS fixes (0.5 m noise, 10 Hz, 10 minutes) stamped 120 ms late against an INS's
    velocities (0.05 m/s): the latency within 10 ms (the issue's bound), which is more than 4
    of its standard errors (about 2.3 ms here; four seeds gave errors of 1-5 ms), and within
    3 of them."""
    fit = fit_clock_offset(*two_sources(seed, 0.12, n=6000, sigma_p=0.5, sigma_v=0.05))
    assert fit.converged, fit.message
    error = fit.value("offset_s") - 0.12
    assert fit.std_error("offset_s") < 0.003
    assert abs(error) < 0.010 and abs(error) < 3 * fit.std_error("offset_s"), error


def test_bad_input():
    t = np.arange(5.0)
    with pytest.raises(ValueError, match="must match their times"):
        fit_clock_offset(t, np.zeros((4, 2)), t, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="at least 3"):
        fit_clock_offset(t[:2], np.zeros((2, 1)), t, np.zeros((5, 1)))


def test_nan_and_unsorted_times_are_refused():
    t = np.arange(5.0)
    p = np.zeros((5, 2))
    with pytest.raises(ValueError, match="positions"):
        fit_clock_offset(t, np.where(t[:, None] == 2, np.nan, p), t, p)
    with pytest.raises(ValueError, match="velocity_times"):
        fit_clock_offset(t, p, t[::-1], p)


AZIMUTH_BIAS = math.radians(0.3)


def radar_and_reference(seed, n=1200, q=0.1, range_bias=1.0, azimuth_bias=AZIMUTH_BIAS):
    """A test vehicle driving past a radar at (0, -40) m: truth of a planar constant-velocity
    process on a 25 ms grid (its own closed form); reference fixes (0.5 m) at 10 Hz, radar
    range (0.3 m) and azimuth (0.15 deg, clockwise from north) at 20 Hz on other times, with
    their biases."""
    rng = np.random.default_rng(seed)
    fine, m = 0.025, n * 4
    truth = cv_states(rng, [[-400.0, 7.0], [30.0, 0.0]], fine, q, m)[:, :, 0]
    t = fine * np.arange(m)
    ref, rad = np.arange(0, m, 4), np.arange(1, m, 2)
    site = np.array([0.0, -40.0])
    d = truth[rad] - site
    ranges = np.hypot(d[:, 0], d[:, 1]) + range_bias + rng.normal(0, 0.3, rad.size)
    azimuths = np.arctan2(d[:, 0], d[:, 1]) + azimuth_bias + rng.normal(0, 2.618e-3, rad.size)
    return t[ref], truth[ref] + rng.normal(0, 0.5, (ref.size, 2)), t[rad], ranges, azimuths, site


@pytest.mark.statistical
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_radar_range_and_azimuth_biases_are_recovered_within_their_standard_errors(seed):
    """A 0.3 deg azimuth bias and a 1 m range bias, with the noise variances and the PSD, each
    within 3 standard errors (two minutes of a vehicle passing at 70-500 m); the azimuth
    bias's standard error is below 0.01 deg, so 0.3 deg is resolved thirty times over."""
    fit = fit_radar_bias(*radar_and_reference(seed))
    assert fit.converged, fit.message
    truth = {"range_bias_m": 1.0, "azimuth_bias_rad": math.radians(0.3), "accel_psd": 0.1,
             "reference_var": 0.25, "range_var": 0.09, "azimuth_var": 2.618e-3**2}  # fmt: skip
    for name, value in truth.items():
        assert abs(fit.value(name) - value) < 3 * fit.std_error(name), (name, fit.value(name))
    assert fit.std_error("azimuth_bias_rad") < math.radians(0.01)


def test_radar_bias_likelihood_equals_filterpys_ekf_on_the_same_rows():
    """The EKF behind ``fit_radar_bias`` against FilterPy's ``ExtendedKalmanFilter`` given the
    same transitions, Jacobians, noise and wrapped azimuth residual: the summed
    log-likelihood of 200 mixed rows to 1e-9 relative."""
    from filterpy.kalman import ExtendedKalmanFilter

    from adaptrack.tuning.calibration import _radar_reference_loglik

    tr, zr, tm, rng_m, az, site = radar_and_reference(4, n=60)
    t = np.concatenate([tr, tm])
    order = np.argsort(t, kind="stable")
    z = np.concatenate([zr, np.stack([rng_m, az], -1)])[order]
    radar = np.concatenate([np.zeros(tr.size, bool), np.ones(tm.size, bool)])[order]
    t = t[order]
    b_r, b_a, q, v_ref, v_r, v_a, v_speed = 0.7, 0.004, 0.2, 0.3, 0.1, 1e-5, 2500.0
    ours = _radar_reference_loglik(
        t, z, radar, site[0], site[1], zr[0, 0], zr[0, 1], b_r, b_a, q, v_ref, v_r, v_a, v_speed
    )
    ekf = ExtendedKalmanFilter(dim_x=4, dim_z=2)
    ekf.x = np.array([zr[0, 0], zr[0, 1], 0.0, 0.0])
    ekf.P = np.diag([v_ref, v_ref, v_speed, v_speed])

    def polar(x):
        dx, dy = x[0] - site[0], x[1] - site[1]
        return np.array([np.hypot(dx, dy) + b_r, np.arctan2(dx, dy) + b_a])

    def polar_jacobian(x):
        dx, dy = x[0] - site[0], x[1] - site[1]
        r2 = dx * dx + dy * dy
        return np.array([[dx / np.sqrt(r2), dy / np.sqrt(r2), 0, 0], [dy / r2, -dx / r2, 0, 0]])

    def wrapped(a, b):
        y = a - b
        y[1] = (y[1] + np.pi) % (2 * np.pi) - np.pi
        return y

    total, prev = 0.0, t[0]
    for k in range(t.size):
        dt = t[k] - prev
        prev = t[k]
        if dt > 0:
            ekf.F = np.eye(4) + np.diag([dt, dt], 2)
            g = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
            ekf.Q = np.kron(g, np.eye(2))
            ekf.predict()
        if radar[k]:
            ekf.update(z[k], polar_jacobian, polar, R=np.diag([v_r, v_a]), residual=wrapped)
        else:
            ekf.update(z[k], lambda x: np.eye(2, 4), lambda x: x[:2], R=v_ref * np.eye(2))
        total += ekf.log_likelihood
    assert ours == pytest.approx(total, rel=1e-9)


def test_radar_bias_bad_input_is_named():
    t = np.arange(5.0)
    with pytest.raises(ValueError, match="reference_positions must be"):
        fit_radar_bias(t, np.zeros((5, 3)), t, t, t, [0.0, 0.0])
    with pytest.raises(ValueError, match="radar_position"):
        fit_radar_bias(t, np.zeros((5, 2)), t, t, t, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="radar_times"):
        fit_radar_bias(t, np.zeros((5, 2)), t[::-1], t, t, [0.0, 0.0])
    with pytest.raises(ValueError, match="ranges_m"):
        fit_radar_bias(t, np.zeros((5, 2)), t, np.where(t == 2, np.nan, t), t, [0.0, 0.0])
