"""Seed 000 reduced model and dead reckoning: checks C0.9 and C0.10."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import Singer, discretize


@pytest.mark.parametrize("method", ["source", "expm"])
def test_c0_9_c0_10_reduced_filter_and_dead_reckoning(rng, method):
    tau, sw, sv = 3.0, 0.8, 0.3
    model = Singer(time_constant_s=tau, accel_std_mps2=sw)
    t = np.cumsum(rng.uniform(0.05, 0.5, 60))
    y = rng.normal(10, 1, 60)
    prior = at.GaussianState(mean=[10.0, 0.0], cov=np.diag([4.0, sw**2]), time=t[0])
    dr = at.dead_reckoning_filter(t, y, model, sv**2, prior, initial_distance_m=0.0, method=method)
    # C0.9: the 3-state speed-only filter's (v, w) block equals the reduced filter
    full = at.kalman_filter(
        t,
        y[:, None],
        model,
        [[0.0, 1.0, 0.0]],
        [[sv**2]],
        at.GaussianState([0.0, 10.0, 0.0], np.diag([0.0, 4.0, sw**2]), t[0]),
        method=method,
    )
    np.testing.assert_allclose(dr.filtered.mean, full.filtered.mean[:, 1:], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(
        dr.filtered.cov, full.filtered.cov[:, 1:, 1:], rtol=1e-10, atol=1e-12
    )
    # C0.10: dead reckoning == 3-state filter with the distance-row gain forced to zero
    x = np.array([0.0, 10.0, 0.0])
    p = np.diag([0.0, 4.0, sw**2])
    c = np.array([[0.0, 1.0, 0.0]])
    for k in range(t.size):
        if k:
            phi, qd = discretize(model, t[k] - t[k - 1], method)
            x, p = phi @ x, phi @ p @ phi.T + qd
        s = c @ p @ c.T + sv**2
        gain = p @ c.T / s
        gain[0] = 0.0
        ikc = np.eye(3) - gain @ c
        x = x + gain[:, 0] * (y[k] - x[1])
        p = ikc @ p @ ikc.T + gain @ gain.T * sv**2
        assert dr.distance_m[k] == pytest.approx(x[0], rel=1e-10, abs=1e-10)
        assert dr.distance_var_m2[k] == pytest.approx(p[0, 0], rel=1e-10, abs=1e-14)
    # the distance variance grows without bound (distance is unobservable from speed)
    assert dr.distance_var_m2[-1] > dr.distance_var_m2[10] > 0


def test_source_dead_reckoning_is_equation_18(rng):
    model = Singer(time_constant_s=2.0, accel_std_mps2=0.5)
    t = np.cumsum(rng.uniform(0.1, 0.3, 20))
    y = rng.normal(5, 0.2, 20)
    prior = at.GaussianState(mean=[5.0, 0.0], cov=np.diag([1.0, 0.25]), time=t[0])
    dr = at.dead_reckoning_filter(
        t, y, model, 0.04, prior, initial_distance_m=100.0, method="source"
    )
    r = 100.0
    for k in range(1, t.size):
        r = r + dr.filtered.mean[k - 1, 0] * (t[k] - t[k - 1])  # (18)
        assert dr.distance_m[k] == pytest.approx(r, rel=1e-13)


def test_dead_reckoning_batch_equals_loop(rng):
    model = Singer(time_constant_s=2.0, accel_std_mps2=0.5)
    t = np.cumsum(rng.uniform(0.1, 0.3, (3, 15)), axis=1)
    y = rng.normal(5, 0.2, (3, 15))
    prior = at.GaussianState(mean=[5.0, 0.0], cov=np.diag([1.0, 0.25]), time=0.0)
    dr = at.dead_reckoning_filter(
        t, y, model, 0.04, prior, initial_distance_m=[1.0, 2.0, 3.0], initial_distance_var_m2=0.5
    )
    for i in range(3):
        one = at.dead_reckoning_filter(
            t[i],
            y[i],
            model,
            0.04,
            prior,
            initial_distance_m=[1.0, 2.0, 3.0][i],
            initial_distance_var_m2=0.5,
        )
        np.testing.assert_allclose(dr.distance_m[i], one.distance_m, rtol=1e-13)
        np.testing.assert_allclose(dr.distance_var_m2[i], one.distance_var_m2, rtol=1e-13)


def test_dead_reckoning_bad_input():
    model = Singer(time_constant_s=2.0, accel_std_mps2=0.5)
    prior = at.GaussianState(mean=[5.0, 0.0], cov=np.eye(2), time=0.0)
    with pytest.raises(TypeError, match="one-axis adaptrack.models.Singer"):
        at.dead_reckoning_filter([0.0, 1.0], [1.0, 1.0], at.models.ConstantVelocity(), 1.0, prior)
    with pytest.raises(ValueError, match="speed_var must be finite and > 0"):
        at.dead_reckoning_filter([0.0, 1.0], [1.0, 1.0], model, 0.0, prior)
    with pytest.raises(ValueError, match="duplicate time at step 1"):
        at.dead_reckoning_filter([0.0, 0.0], [1.0, 1.0], model, 1.0, prior)
    with pytest.raises(ValueError, match=r"speeds must have shape \(2,\)"):
        at.dead_reckoning_filter([0.0, 1.0], [1.0, 1.0, 2.0], model, 1.0, prior)
    with pytest.raises(ValueError, match="speeds must be finite"):
        at.dead_reckoning_filter([0.0, 1.0], [1.0, np.nan], model, 1.0, prior)
