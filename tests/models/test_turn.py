"""The coordinated-turn model against an independent integration of its equations of motion."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from adaptrack.models import CoordinatedTurn, NonlinearMotionModel

# turn rates [rad/s] on both sides of the series branch (|w dt| < 1e-3 with dt = 2 s)
TURN_RATES = [0.0, 1e-9, -3e-4, 4.9e-4, 5.1e-4, -0.05, 0.3, np.pi / 2]


def integrated(x0, dt, n_axes):
    """State after ``dt`` by integrating dp/dt = v, dv/dt = w x v (horizontal), w constant."""
    k = n_axes

    def rhs(_t, s):
        d = np.zeros_like(s)
        d[:k] = s[k : 2 * k]
        w = s[-1]
        d[k], d[k + 1] = -w * s[k + 1], w * s[k]
        return d

    return solve_ivp(rhs, (0.0, dt), x0, rtol=1e-12, atol=1e-10, method="DOP853").y[:, -1]


@pytest.mark.parametrize("w", TURN_RATES)
@pytest.mark.parametrize("n_axes", [2, 3])
def test_propagation_equals_the_integrated_motion(w, n_axes):
    ct = CoordinatedTurn(n_axes=n_axes)
    x0 = np.array([100.0, -50.0, 30.0, -12.0, w]) if n_axes == 2 else np.array(
        [100.0, -50.0, 800.0, 30.0, -12.0, 4.0, w]
    )  # fmt: skip
    got, _ = ct.propagate(x0, np.array(2.0))
    np.testing.assert_allclose(got, integrated(x0, 2.0, n_axes), rtol=1e-9, atol=1e-7)
    speed = np.hypot(*got[n_axes : n_axes + 2])
    assert speed == pytest.approx(np.hypot(30.0, -12.0), rel=1e-12)  # a turn keeps the speed


@pytest.mark.parametrize("w", TURN_RATES)
def test_jacobian_equals_central_differences(w):
    ct = CoordinatedTurn(n_axes=3)
    x0 = np.array([100.0, -50.0, 800.0, 30.0, -12.0, 4.0, w])
    _, jac = ct.propagate(x0, np.array(2.0))
    num = np.empty((7, 7))
    for i in range(7):
        h = 1e-6 * max(1.0, abs(x0[i]))
        step = np.zeros(7)
        step[i] = h
        num[:, i] = (ct.propagate(x0 + step, 2.0)[0] - ct.propagate(x0 - step, 2.0)[0]) / (2 * h)
    np.testing.assert_allclose(jac, num, rtol=1e-6, atol=1e-6)


def test_batches_and_zero_steps():
    ct = CoordinatedTurn(accel_psd=0.3, turn_psd=1e-4)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 3, 5)) * [100, 100, 20, 20, 0.1]
    dt = rng.uniform(0.0, 3.0, size=(4, 3))
    dt[0, 0] = 0.0
    out, jac = ct.propagate(x, dt)
    for i in range(4):
        for j in range(3):
            one, one_jac = ct.propagate(x[i, j], dt[i, j])
            np.testing.assert_allclose(out[i, j], one, rtol=1e-14)
            np.testing.assert_allclose(jac[i, j], one_jac, rtol=1e-14)
    np.testing.assert_array_equal(out[0, 0], x[0, 0])
    np.testing.assert_array_equal(jac[0, 0], np.eye(5))
    q = ct.process_cov(dt)
    assert q.shape == (4, 3, 5, 5)
    assert np.all(np.linalg.eigvalsh(q[1:]) > 0)
    np.testing.assert_array_equal(q[0, 0], 0.0)


def test_equals_stone_soup_constant_turn():
    from datetime import timedelta

    from stonesoup.models.transition.nonlinear import ConstantTurn
    from stonesoup.types.state import State

    order = [0, 2, 1, 3, 4]  # ours (x, y, vx, vy, w) -> Stone Soup (x, vx, y, vy, w)
    ct = CoordinatedTurn(accel_psd=0.7, turn_psd=2e-4)
    ss = ConstantTurn(linear_noise_coeffs=np.array([0.7, 0.7]), turn_noise_coeff=2e-4)
    for w in (0.08, -0.3, 0.0):
        x0 = np.array([100.0, -50.0, 30.0, -12.0, w])
        got, _ = ct.propagate(x0, np.array(1.7))
        theirs = ss.function(State(x0[order].reshape(-1, 1)), time_interval=timedelta(seconds=1.7))
        # Stone Soup puts eps in place of a zero turn rate
        np.testing.assert_allclose(
            got[order], np.asarray(theirs, float).ravel(), rtol=1e-12, atol=1e-12
        )
    q_ss = ss.covar(time_interval=timedelta(seconds=1.7))
    np.testing.assert_allclose(
        ct.process_cov(np.array(1.7))[np.ix_(order, order)], q_ss, rtol=1e-14
    )


def test_is_a_nonlinear_motion_model_and_checks_its_parameters():
    assert isinstance(CoordinatedTurn(), NonlinearMotionModel)
    assert CoordinatedTurn(n_axes=3).state_names == ("x", "y", "z", "vx", "vy", "vz", "omega")
    for bad in ({"n_axes": 1}, {"n_axes": True}, {"accel_psd": -1.0}, {"turn_psd": np.nan}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            CoordinatedTurn(**bad)
