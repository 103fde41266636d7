"""EKF, UKF, IMM and RTS with the coordinated-turn model.

Oracles: with the turn rate known to be zero the model is the constant-velocity one, so every
filter must equal the linear Kalman filter; a one-model IMM is its filter; the consistency of
the EKF and UKF is checked by NEES over seeded Monte Carlo runs; Stone Soup on identical inputs
in tests/crosscheck/test_turn_peers.py.
"""

import numpy as np
import pytest
from scipy import stats

import adaptrack as at
from adaptrack.filters.imm import imm_filter
from adaptrack.models import (
    ConstantVelocity,
    CoordinatedTurn,
    PositionMeasurement,
    RadarMeasurement,
)
from adaptrack.types import GaussianState

RADAR = RadarMeasurement(noise_cov=np.diag([25.0, 1e-6]))


def turning_problem(seed, n_tracks=1, n_steps=60, psd=(0.2, 1e-5)):
    """Truth drawn from the discrete CT model itself, planar radar plots, irregular steps."""
    rng = np.random.default_rng(seed)
    ct = CoordinatedTurn(*psd)
    t = np.cumsum(rng.uniform(0.5, 1.5, (n_tracks, n_steps)), axis=-1)
    x = np.empty((n_tracks, n_steps, 5))
    state = np.broadcast_to([3000.0, 4000.0, 40.0, -20.0, 0.04], (n_tracks, 5)).copy()
    prev = np.zeros(n_tracks)
    for k in range(n_steps):
        dt = t[:, k] - prev
        state = ct.propagate(state, dt)[0]
        q = ct.process_cov(dt)
        state = state + np.einsum(
            "nij,nj->ni", np.linalg.cholesky(q), rng.normal(size=(n_tracks, 5))
        )
        x[:, k], prev = state, t[:, k]
    z = RADAR.predict(x[..., :2]) + rng.normal(size=(n_tracks, n_steps, 2)) * [5.0, 1e-3]
    cov0 = np.diag([100.0, 100.0, 25.0, 25.0, 0.02**2])
    mean0 = np.array([3000.0, 4000.0, 40.0, -20.0, 0.04]) + rng.normal(
        size=(n_tracks, 5)
    ) * np.sqrt(np.diag(cov0))
    return ct, t, x, z, GaussianState(mean0, np.broadcast_to(cov0, (n_tracks, 5, 5)), 0.0)


@pytest.mark.parametrize("run", [at.ekf_filter, at.ukf_filter])
def test_with_a_known_zero_turn_rate_it_is_the_constant_velocity_filter(run):
    """Turn rate 0 with zero variance and no turn noise: the CV Kalman filter and smoother."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.2, 2.0, 40))
    z = np.c_[10.0 * t, 3.0 * t] + rng.normal(size=(40, 2)) * 3.0
    cov = np.diag([25.0, 25.0, 100.0, 100.0, 0.0])
    ct = CoordinatedTurn(accel_psd=0.4, turn_psd=0.0)
    ours = run(
        t, z, ct, PositionMeasurement(9.0 * np.eye(2)), GaussianState([0, 0, 5, 5, 0.0], cov, 0.0)
    )
    cv = at.kalman_filter(t, z, ConstantVelocity(0.4, n_axes=2), ["x", "y"], 9.0 * np.eye(2),
                          GaussianState([0, 0, 5, 5.0], cov[:4, :4], 0.0))  # fmt: skip
    np.testing.assert_allclose(ours.filtered.mean[:, :4], cv.filtered.mean, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ours.filtered.cov[:, :4, :4], cv.filtered.cov, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours.log_likelihood, cv.log_likelihood, rtol=1e-10)
    smoothed, reference = at.rts_smooth(ours), at.rts_smooth(cv)
    np.testing.assert_allclose(smoothed.mean[:, :4], reference.mean, rtol=1e-9, atol=1e-8)


@pytest.mark.parametrize("run", [at.ekf_filter, at.ukf_filter])
def test_filters_are_consistent_on_turning_targets(run):
    """Average NEES of 200 runs inside the two-sided 99.9 % chi-square band at each of the
    last 20 steps (Bonferroni over the steps: a false failure below 2 %)."""
    ct, t, x, z, prior = turning_problem(77, n_tracks=200)
    res = run(t, z, ct, RADAR, prior)
    err = res.filtered.mean - x
    nees = np.einsum(
        "...i,...i->...", err, np.linalg.solve(res.filtered.cov, err[..., None])[..., 0]
    )
    total = nees[:, -20:].sum(axis=0)
    alpha = 1e-3 / 20
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], 200 * 5)
    assert np.all((total > lo) & (total < hi)), (total.min(), total.max(), lo, hi)


@pytest.mark.parametrize("run", [at.ekf_filter, at.ukf_filter])
def test_smoothing_a_turn_lowers_the_error(run):
    """RTS over the stored (statistical) linearisations: position MSE lower than filtered,
    over 100 runs (paired, the improvement many standard errors away from zero)."""
    ct, t, x, z, prior = turning_problem(78, n_tracks=100)
    res = run(t, z, ct, RADAR, prior)
    sm = at.rts_smooth(res)
    e_f = np.sum((res.filtered.mean[..., :2] - x[..., :2]) ** 2, -1).mean(-1)
    e_s = np.sum((sm.mean[..., :2] - x[..., :2]) ** 2, -1).mean(-1)
    d = e_f - e_s
    assert d.mean() > 5 * d.std(ddof=1) / np.sqrt(d.size), (e_f.mean(), e_s.mean())


@pytest.mark.parametrize("mode", ["ekf", "ukf"])
def test_a_one_model_imm_is_its_filter(mode):
    ct, t, _x, z, prior = turning_problem(79, n_tracks=3, n_steps=30)
    single = (at.ekf_filter if mode == "ekf" else at.ukf_filter)(t, z, ct, RADAR, prior)
    imm = imm_filter(t, z, [ct], RADAR, None, [prior], initial_probs=[1.0],
                     switching_rates=[[0.0]], nonlinear=mode)  # fmt: skip
    np.testing.assert_allclose(imm.filtered.mean, single.filtered.mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(imm.log_likelihood.sum(-1), single.log_likelihood, rtol=1e-10)


def test_imm_of_straight_and_turning_models_finds_the_turn():
    """CV + CT on straight flight then a 3 deg/s turn (truth: 1 s chords along the path): the
    CT model's probability rises in the turn, and its position error beats CV alone."""
    rng = np.random.default_rng(80)
    t = np.arange(1.0, 121.0)
    w = np.where((t > 60) & (t <= 90), np.deg2rad(3.0), 0.0)
    heading = np.pi / 2 - np.cumsum(w)  # from the x axis
    speed = 80.0
    vel = speed * np.c_[np.cos(heading), np.sin(heading)]
    pos = np.array([2000.0, 5000.0]) + np.cumsum(vel, axis=0)  # 1 s chords of the turn
    z = RADAR.predict(pos) + rng.normal(size=(120, 2)) * [5.0, 1e-3]
    cv = ConstantVelocity(0.05, n_axes=2)
    ct = CoordinatedTurn(0.05, 1e-4)
    p_cv = GaussianState(np.r_[pos[0], vel[0]], np.diag([100, 100, 100, 100.0]), 0.0)
    p_ct = GaussianState(np.r_[pos[0], vel[0], 0.0], np.diag([100, 100, 100, 100.0, 1e-3]), 0.0)
    imm = imm_filter(t, z, [cv, ct], RADAR, None, [p_cv, p_ct], initial_probs=[0.5, 0.5],
                     switching_rates=[[-0.02, 0.02], [0.02, -0.02]])  # fmt: skip
    alone = at.ekf_filter(t, z, cv, RADAR, p_cv)
    turn = (t > 70) & (t <= 90)
    assert imm.mode_probabilities[turn, 1].mean() > 0.8
    e_imm = np.sum((imm.filtered.mean[turn, :2] - pos[turn]) ** 2, -1).mean()
    e_cv = np.sum((alone.filtered.mean[turn, :2] - pos[turn]) ** 2, -1).mean()
    assert e_imm < 0.5 * e_cv, (e_imm, e_cv)


def test_a_turn_model_imm_in_square_root_form_is_the_square_root_ekf():
    """A one-model IMM of the coordinated turn with a linear measurement (the IMM's own
    linear update, in factor form after the EKF's factor-form prediction) gives
    ``ekf_filter(form="sqrt")`` to rounding; a prior of the wrong batch shape is refused."""
    ct, t, _x, z, prior = turning_problem(81, n_steps=40)
    one = GaussianState(prior.mean[0], prior.cov[0], 0.0)
    xs = np.cumsum(np.random.default_rng(81).normal(10.0, 1.0, 40))[:, None]
    imm = imm_filter(t[0], xs, [ct], ["x"], [[25.0]], [one], initial_probs=[1.0],
                     switching_rates=[[0.0]], form="sqrt")  # fmt: skip
    ekf = at.ekf_filter(t[0], xs, ct, PositionMeasurement([[25.0]], ("x",)), one, form="sqrt")
    sigma = np.sqrt(np.diagonal(ekf.filtered.cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(imm.filtered.mean - ekf.filtered.mean) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(imm.filtered.cov - ekf.filtered.cov) / scale) < 1e-8
    with pytest.raises(ValueError, match=r"initial\[0\] must have batch shape \(\) or \(\)"):
        imm_filter(t[0], z[0, :, :1], [ct], ["x"], [[25.0]], [prior], initial_probs=[1.0],
                   switching_rates=[[0.0]])  # fmt: skip


@pytest.mark.parametrize("sensor", ["radar", "position"])
def test_compiled_imm_with_a_turn_model_equals_numpy(sensor):
    """CV + CT in the IMM kernel (EKF prediction of the turn) against the NumPy IMM: a 3-D
    radar with range-rate, or positions; per-track irregular times, missing components."""
    rng = np.random.default_rng(82)
    radar = RadarMeasurement(np.diag([25.0, 1e-6, 4e-6, 0.25]),
                             ("range", "azimuth", "elevation", "range_rate"), n_axes=3,
                             sensor_position=[50.0, -20.0, 10.0], heading=0.3)  # fmt: skip
    measure = (
        radar if sensor == "radar" else PositionMeasurement(np.full(3, 100.0), ("x", "y", "z"))
    )
    t = np.cumsum(rng.uniform(0.5, 1.5, (3, 60)), -1)
    x0, v = np.array([6000.0, -9000.0, 3000.0]), np.array([-150.0, 60.0, 5.0])
    full = np.concatenate([x0 + t[..., None] * v, np.broadcast_to(v, (3, 60, 3))], -1)
    z = measure.predict(full[..., : len(measure.reads)])
    z = z + rng.normal(size=z.shape) * np.sqrt(np.diag(measure.noise_cov))
    mask = rng.uniform(size=z.shape) > 0.1
    models = [ConstantVelocity(0.5, n_axes=3), CoordinatedTurn(0.5, 1e-4, 0.1, n_axes=3)]
    p_cv = GaussianState(np.r_[x0, v] + 10, np.diag([400.0] * 3 + [100.0] * 3), 0.0)
    p_ct = GaussianState(
        np.r_[x0 + 10, v + 10, 0.01], np.diag([400.0] * 3 + [100.0] * 3 + [1e-3]), 0.0
    )
    kw = dict(initial_probs=[0.5, 0.5], switching_rates=[[-0.1, 0.1], [0.1, -0.1]], mask=mask)
    ref = imm_filter(t, z, models, measure, None, [p_cv, p_ct], backend="numpy", **kw)
    got = imm_filter(t, z, models, measure, None, [p_cv, p_ct], backend="numba", **kw)
    np.testing.assert_allclose(got.filtered.mean, ref.filtered.mean, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(got.filtered.cov, ref.filtered.cov, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(
        got.components[1].mean, ref.components[1].mean, rtol=1e-10, atol=1e-8
    )
    np.testing.assert_allclose(got.log_likelihood, ref.log_likelihood, rtol=1e-10, atol=1e-9)
