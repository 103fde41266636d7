"""Seeded Monte Carlo: a matched Singer filter is consistent and its RMSE equals its own
predicted covariance (the PCRLB for a linear-Gaussian model)."""

import numpy as np
import pytest
from scipy.stats import chi2

import adaptrack as at
from adaptrack.analysis.metrics import nees
from adaptrack.models import Singer
from adaptrack.simulation import simulate_linear_measurements, simulate_linear_trajectory

pytestmark = pytest.mark.statistical


def test_matched_singer_filter_is_consistent_and_efficient():
    rng = np.random.default_rng(20261122)  # fixed; the test passes for most seeds
    n_runs, n_steps = 500, 300
    model = Singer(time_constant_s=4.0, accel_std_mps2=2.0)
    times = np.cumsum(rng.uniform(0.05, 0.25, n_steps))  # irregular sampling
    m0 = np.array([0.0, 10.0, 0.0])
    p0 = np.diag([25.0, 4.0, 4.0])
    truth = simulate_linear_trajectory(model, times, m0, p0, n_runs=n_runs, rng=rng)
    h, r = np.array([[1.0, 0.0, 0.0]]), np.array([[1.0]])
    z = simulate_linear_measurements(truth, h, r, rng=rng)
    res = at.kalman_filter(times, z, model, h, r, at.GaussianState(m0, p0, times[0]))
    err = res.filtered.mean - truth
    e = nees(err, res.filtered.cov)  # (n_runs, T), each chi2(3)
    anees = e.mean(axis=0)  # n_runs * anees ~ chi2(3 n_runs)
    lo, hi = chi2.ppf([5e-4, 1 - 5e-4], 3 * n_runs) / n_runs  # each step outside w.p. 1e-3
    inside = np.mean((anees > lo) & (anees < hi))
    # expected 0.3 of 300 steps outside; 2 % = 6 steps outside is a false failure of < 1e-4
    # even allowing for the positive correlation of neighbouring steps
    assert inside >= 0.98, f"{inside:.3f} of steps inside [{lo:.3f}, {hi:.3f}]"
    # RMSE per state vs the filter's predicted RMS (its own covariance = PCRLB here), over all
    # runs and steps; the relative standard error of the RMSE is below 1 % (>= 12,000
    # effectively independent squared errors), so 3 % is a > 3-sigma tolerance
    rmse = np.sqrt(np.mean(err**2, axis=(0, 1)))
    predicted = np.sqrt(np.mean(np.diagonal(res.filtered.cov, axis1=-2, axis2=-1), axis=(0, 1)))
    np.testing.assert_allclose(rmse, predicted, rtol=0.03)
    # innovations: NIS averages inside their chi2(1) band as well
    nis = res.info.nis.mean(axis=0)
    lo1, hi1 = chi2.ppf([5e-4, 1 - 5e-4], n_runs) / n_runs
    assert np.mean((nis > lo1) & (nis < hi1)) >= 0.98
