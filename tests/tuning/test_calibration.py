"""Clock offset between a position and a velocity source, by maximum likelihood."""

import numpy as np
import pytest

from adaptrack.tuning.calibration import fit_clock_offset

DT, N, Q, SIGMA_P, SIGMA_V = 0.1, 600, 2.0, 0.5, 0.2


def two_sources(seed, offset_s, n=N, sigma_p=SIGMA_P, sigma_v=SIGMA_V):
    """A planar constant-velocity truth (its own closed form), fixes stamped ``offset_s`` late;
    ``n`` fixes at 10 Hz with noise ``sigma_p`` [m], velocities with ``sigma_v`` [m/s]."""
    rng = np.random.default_rng(seed)
    phi = np.array([[1.0, DT], [0.0, 1.0]])
    chol = np.linalg.cholesky(Q * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]]))
    s, states = np.array([[0.0, 8.0], [0.0, 3.0]]), np.zeros((n, 2, 2))
    for k in range(n):
        for a in range(2):
            s[a] = phi @ s[a] + chol @ rng.standard_normal(2)
        states[k] = s
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
