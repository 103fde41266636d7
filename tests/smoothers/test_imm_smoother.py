"""IMM smoother: one model is RTS (linear or extended); against the exact (enumerated)
posterior; Monte Carlo with linear models and with the coordinated turn."""

import itertools

import numpy as np
import pytest

import adaptrack as at
from adaptrack.filters.imm import imm_filter
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    PositionMeasurement,
    RadarMeasurement,
)
from adaptrack.smoothers.imm_smoother import imm_smooth


def test_one_model_is_the_rts_smoother(rng):
    t = np.cumsum(rng.uniform(0.2, 1.5, (3, 30)), axis=1)
    z = rng.normal(size=(3, 30, 1)) * 2 + (4 * t)[..., None]
    model = ConstantAcceleration(jerk_psd=0.3)
    prior = at.GaussianState([0.0, 4.0, 0.0], np.diag([100.0, 10.0, 1.0]), 0.0)
    res = imm_filter(t, z, [model], ("x",), [[4.0]], [prior], [[1.0]], [1.0], form="joseph")
    ours = imm_smooth(res, [model], [[1.0]])
    ref = at.rts_smooth(at.kalman_filter(t, z, model, ["x"], [[4.0]], prior, form="joseph"))
    np.testing.assert_allclose(ours.smoothed.mean, ref.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours.smoothed.cov, ref.cov, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(ours.mode_probabilities, 1.0)


def exact_switching_posterior(t, z, models, r, prior, pi, mu0):
    """Enumerate every mode sequence: each is a linear Gaussian model (KF + RTS); weight by
    its likelihood and prior. Returns the posterior mean (T, 2) and mode marginals (T, M)."""
    n = len(t)
    means, weights, modes = [], [], []
    for seq in itertools.product(range(len(models)), repeat=n):
        x, p = np.array(prior.mean), np.array(prior.cov)
        log_w = np.log(mu0[seq[0]]) + sum(np.log(pi[a, b]) for a, b in itertools.pairwise(seq))
        xs, ps, xp_l, pp_l, phis = [], [], [], [], []
        for k in range(n):
            if k:
                phi, qd = at.discretize(models[seq[k]], t[k] - t[k - 1])
                x, p = phi @ x, phi @ p @ phi.T + qd
                phis.append(phi)
            xp_l.append(x)
            pp_l.append(p)
            s = p[0, 0] + r
            nu = z[k] - x[0]
            log_w += -0.5 * (np.log(2 * np.pi * s) + nu**2 / s)
            gain = p[:, 0] / s
            x, p = x + gain * nu, p - np.outer(gain, p[0])
            xs.append(x)
            ps.append(p)
        sm = [xs[-1]]
        for k in range(n - 2, -1, -1):
            g = ps[k] @ phis[k].T @ np.linalg.inv(pp_l[k + 1])
            sm.insert(0, xs[k] + g @ (sm[0] - xp_l[k + 1]))
        means.append(np.array(sm))
        weights.append(log_w)
        modes.append(seq)
    w = np.exp(np.array(weights) - max(weights))
    w /= w.sum()
    mean = np.einsum("s,stn->tn", w, np.array(means))
    marg = np.stack([(w[:, None] * (np.array(modes) == j)).sum(0) for j in range(len(models))], -1)
    return mean, marg


@pytest.mark.parametrize("q_quiet", [0.5, 0.01])
def test_close_to_the_exact_posterior_of_a_small_switching_system(q_quiet):
    """Two CV models (quiet, agile), 9 steps: 512 mode sequences enumerated. The smoother is
    an approximation. With q 0.5 / 5 it stays within 0.1 posterior sigma of the exact mean
    and 0.1 of the exact mode marginals (measured 0.03 and 0.04; Kim's approximation alone:
    0.20 and 0.22); with a nearly deterministic quiet model (q 0.01) it is still closer to
    the exact mean than the IMM filter (measured: total error 2.2 against 4.7)."""
    t = np.arange(9.0)
    z = np.array([0.0, 1.1, 1.9, 3.2, 6.0, 10.1, 15.2, 19.8, 25.1])
    models = [ConstantVelocity(accel_psd=q_quiet), ConstantVelocity(accel_psd=5.0)]
    pi, mu0 = np.array([[0.9, 0.1], [0.2, 0.8]]), np.array([0.7, 0.3])
    prior = at.GaussianState([0.0, 1.0], np.diag([1.0, 1.0]), 0.0)
    res = imm_filter(t, z[:, None], models, ("x",), [[0.25]], [prior, prior], pi, mu0,
                     form="joseph")  # fmt: skip
    sm = imm_smooth(res, models, pi)
    exact_mean, exact_modes = exact_switching_posterior(t, z, models, 0.25, prior, pi, mu0)
    error = np.abs(sm.smoothed.mean - exact_mean)
    assert error.sum() < 0.6 * np.abs(res.filtered.mean - exact_mean).sum()
    if q_quiet == 0.5:
        assert np.all(error < 0.1 * np.sqrt(sm.smoothed.cov[:, [0, 1], [0, 1]]))
        assert np.all(np.abs(sm.mode_probabilities - exact_modes) < 0.1)


@pytest.mark.statistical
def test_smoothing_cv_and_ca_beats_the_filter_on_manoeuvres():
    """CV (2 states) + CA (3): smoothed position and velocity errors below the filter's over
    40 manoeuvring runs (the mean of the paired differences more than 3 standard errors).
    Measured: position MSE 11.2 -> 4.2 m^2, velocity 3.0 -> 1.1 (m/s)^2; a single CA's RTS
    smoother reaches 4.7 m^2 in position."""
    rng = np.random.default_rng(7)
    n = 120
    t = np.cumsum(rng.uniform(0.5, 1.5, (40, n)), axis=1)
    acc = np.zeros((40, n))
    for run in range(40):
        for s in rng.choice(n - 15, 2, replace=False):
            acc[run, s : s + 10] = rng.normal(0, 3)
    dt = np.diff(t, prepend=0.0, axis=1)
    v = 20 + np.cumsum(acc * dt, axis=1)
    x = np.cumsum(v * dt, axis=1)
    z = x + rng.normal(0, 5, x.shape)
    models = [ConstantVelocity(0.05), ConstantAcceleration(1.0)]
    priors = [at.GaussianState(np.c_[z[:, 0], np.full(40, 20.0)], np.broadcast_to(
                  np.diag([25.0, 100.0]), (40, 2, 2)), t[:, 0]),
              at.GaussianState(np.c_[z[:, 0], np.full(40, 20.0), np.zeros(40)], np.broadcast_to(
                  np.diag([25.0, 100.0, 9.0]), (40, 3, 3)), t[:, 0])]  # fmt: skip
    rates = [[-0.05, 0.05], [0.1, -0.1]]
    res = imm_filter(t, z[..., None], models, ("x",), [[25.0]], priors, initial_probs=[0.5, 0.5],
                     switching_rates=rates)  # fmt: skip
    sm = imm_smooth(res, models, switching_rates=rates)
    for axis, truth in ((0, x), (1, v)):
        e_f = np.mean((res.filtered.mean[..., axis] - truth) ** 2, axis=1)
        e_s = np.mean((sm.smoothed.mean[..., axis] - truth) ** 2, axis=1)
        d = e_f - e_s
        assert d.mean() > 3 * d.std(ddof=1) / np.sqrt(d.size), (axis, e_f.mean(), e_s.mean())


def test_bad_arguments_are_named(rng):
    t = np.arange(5.0)
    z = rng.normal(size=(5, 1))
    models = [ConstantVelocity(1.0), ConstantAcceleration(1.0)]
    priors = [at.GaussianState([0.0, 0.0], np.eye(2), 0.0),
              at.GaussianState([0.0, 0.0, 0.0], np.eye(3), 0.0)]  # fmt: skip
    pi = [[0.9, 0.1], [0.1, 0.9]]
    res = imm_filter(t, z, models, ("x",), [[1.0]], priors, pi, [0.5, 0.5])
    with pytest.raises(ValueError, match="the filter's models"):
        imm_smooth(res, models[::-1], pi)
    with pytest.raises(ValueError, match="give one of"):
        imm_smooth(res, models)
    with pytest.raises(TypeError, match="IMMResult"):
        imm_smooth(res.filtered, models, pi)
    with pytest.raises(ValueError, match="the filter's models"):
        imm_smooth(res, [models[0], CoordinatedTurn()], pi)
    with pytest.raises(TypeError, match=r"models\[1\]"):
        imm_smooth(res, [models[0], "ca"], pi)


RADAR = RadarMeasurement(noise_cov=np.diag([25.0, 1e-6]))


def test_one_turn_model_is_the_extended_rts_smoother(rng):
    """A coordinated turn alone, radar plots over irregular steps: the IMM smoother equals
    the extended RTS smoother of the EKF (both linearise at each filtered estimate)."""
    t = np.cumsum(rng.uniform(0.5, 1.5, (3, 40)), axis=1)
    heading = 0.3 + 0.03 * t
    pos = np.stack([3000.0 + 500 * np.sin(heading), 4000.0 + 500 * np.cos(heading)], -1)
    z = RADAR.predict(pos) + rng.normal(size=(3, 40, 2)) * [5.0, 1e-3]
    ct = CoordinatedTurn(0.2, 1e-4)
    prior = at.GaussianState([3100.0, 4450.0, 14.0, -4.0, 0.0],
                             np.diag([400.0, 400.0, 100.0, 100.0, 1e-3]), 0.0)  # fmt: skip
    imm = imm_filter(t, z, [ct], RADAR, None, [prior], initial_probs=[1.0],
                     switching_rates=[[0.0]])  # fmt: skip
    ours = imm_smooth(imm, [ct], switching_rates=[[0.0]])
    ref = at.rts_smooth(at.ekf_filter(t, z, ct, RADAR, prior))
    np.testing.assert_allclose(ours.smoothed.mean, ref.mean, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(ours.smoothed.cov, ref.cov, rtol=1e-7, atol=1e-9)


def _turning_flights(rng, n_tracks, n_steps):
    """Straight legs and turns of 2-4 deg/s either way at 80 m/s: truth integrated over 0.1 s
    (independent of the turn model), radar plots every 1-2 s."""
    fine = 0.1
    t = np.cumsum(rng.uniform(1.0, 2.0, (n_tracks, n_steps)), axis=1)
    grid = np.arange(0.0, t.max() + fine, fine)
    rate = np.zeros((n_tracks, grid.size))
    for run in range(n_tracks):
        for start in rng.uniform(0.0, grid[-1] - 40.0, 3):
            turn = (grid >= start) & (grid < start + 30.0)
            rate[run, turn] = np.deg2rad(rng.uniform(2.0, 4.0)) * rng.choice([-1.0, 1.0])
    heading = 0.5 + np.cumsum(rate, axis=1) * fine
    vel = 80.0 * np.stack([np.sin(heading), np.cos(heading)], -1)
    fine_pos = np.array([3000.0, 4000.0]) + np.cumsum(vel, axis=1) * fine
    k = np.rint(t / fine).astype(int)
    rows = np.arange(n_tracks)[:, None]
    pos, v = fine_pos[rows, k], vel[rows, k]
    z = RADAR.predict(pos) + rng.normal(size=(n_tracks, n_steps, 2)) * [5.0, 1e-3]
    return t, z, pos, v


@pytest.mark.statistical
@pytest.mark.parametrize("slow", [False, True])
def test_smoothing_cv_and_ct_on_turning_flights(slow):
    """CV (4 states) + CT (5) over 30 flights with three turns each, paired per flight.

    Switching about as often as the turns (0.02 / 0.05 per s): smoothed position and
    velocity errors below the filter's by more than 3 standard errors. Switching rarely
    (0.002 / 0.005 per s): the CT mode holds; weighed by Kim's approximation alone, the
    smoothed position error is that of the CT model's own extended RTS within 3 standard
    errors (measured 28.6 and 29.0 m^2); with the correction (the default) it is not above
    the filter's (measured 57.3 against 67.8 m^2: the linearised predictions misweigh the
    pairs here, where Kim's approximation does well)."""
    rng = np.random.default_rng(11)
    n, steps = 30, 120
    t, z, pos, vel = _turning_flights(rng, n, steps)
    cv, ct = ConstantVelocity(0.05, n_axes=2), CoordinatedTurn(0.05, 1e-4)
    start = np.c_[pos[:, 0], vel[:, 0]] + rng.normal(size=(n, 4)) * 10.0
    cov = np.diag([100.0, 100.0, 100.0, 100.0])
    priors = [at.GaussianState(start, np.broadcast_to(cov, (n, 4, 4)), 0.0),
              at.GaussianState(np.c_[start, np.zeros(n)], np.broadcast_to(
                  np.diag([100.0, 100.0, 100.0, 100.0, 1e-3]), (n, 5, 5)), 0.0)]  # fmt: skip
    rates = [[-0.002, 0.002], [0.005, -0.005]] if slow else [[-0.02, 0.02], [0.05, -0.05]]
    res = imm_filter(t, z, [cv, ct], RADAR, None, priors, initial_probs=[0.5, 0.5],
                     switching_rates=rates)  # fmt: skip
    sm = imm_smooth(res, [cv, ct], switching_rates=rates)

    def mse(mean, cols, truth):
        return np.sum((mean[..., cols] - truth) ** 2, -1).mean(-1)

    if slow:
        kim = imm_smooth(res, [cv, ct], switching_rates=rates, pair_weights="kim")
        alone = at.rts_smooth(at.ekf_filter(t, z, ct, RADAR, priors[1]))
        d = mse(kim.smoothed.mean, [0, 1], pos) - mse(alone.mean, [0, 1], pos)
        assert abs(d.mean()) < 3 * d.std(ddof=1) / np.sqrt(n), d.mean()
        d = mse(res.filtered.mean, [0, 1], pos) - mse(sm.smoothed.mean, [0, 1], pos)
        assert d.mean() > -3 * d.std(ddof=1) / np.sqrt(n), d.mean()
        return
    kim = imm_smooth(res, [cv, ct], switching_rates=rates, pair_weights="kim")
    for smoothed in (sm, kim):  # corrected (the default) and Kim's
        for cols, truth in (([0, 1], pos), ([2, 3], vel)):
            e_f = mse(res.filtered.mean, cols, truth)
            e_s = mse(smoothed.smoothed.mean, cols, truth)
            d = e_f - e_s
            assert d.mean() > 3 * d.std(ddof=1) / np.sqrt(d.size), (cols, e_f.mean(), e_s.mean())


@pytest.mark.statistical
def test_a_winding_road_needs_the_correction_to_kims_weights():
    """A near-constant-velocity mode beside a coordinated turn, 12 cars on winding roads seen
    by 10 Hz positions (2 m noise), truth integrated at 0.01 s (independent of the models).
    The modes' likelihoods hardly differ over 0.1 s, so each keeps about half the
    probability: weighed by Kim's approximation alone, the CV mode's backward pass straightens
    the road and the smoothed position is worse than the filter's (measured MSE 8.8 against
    1.5 m^2); with the correction (the default) it is far better (0.37 m^2). Both by more
    than 3 standard errors over the cars."""
    rng = np.random.default_rng(3)
    n, steps, fine = 12, 600, 0.01
    t = np.arange(steps) * 0.1
    grid = np.arange(0.0, t[-1] + fine, fine)
    pos = np.empty((n, steps, 2))
    for car in range(n):
        rate = 0.12 * np.sin(2 * np.pi * grid / rng.uniform(15, 30) + rng.uniform(0, 6))
        heading = np.cumsum(rate) * fine
        speed = 15.0 + 3.0 * np.sin(grid / 7.0)
        vel = speed[:, None] * np.stack([np.sin(heading), np.cos(heading)], -1)
        pos[car] = (np.cumsum(vel, axis=0) * fine)[np.rint(t / fine).astype(int)]
    z = pos + rng.normal(size=pos.shape) * 2.0
    cv, ct = ConstantVelocity((0.006, 0.006), n_axes=2), CoordinatedTurn(5.0, 1e-7)
    sensor = PositionMeasurement([4.0, 4.0], ("x", "y"))
    priors = [
        at.GaussianState(np.c_[z[:, 0], np.zeros((n, 2))],
                         np.broadcast_to(np.diag([4.0, 4.0, 225.0, 225.0]), (n, 4, 4)), 0.0),
        at.GaussianState(np.c_[z[:, 0], np.zeros((n, 3))],
                         np.broadcast_to(np.diag([4.0, 4.0, 225.0, 225.0, 0.09]), (n, 5, 5)), 0.0),
    ]  # fmt: skip
    rates = [[-0.19, 0.19], [0.19, -0.19]]
    res = imm_filter(t, z, [cv, ct], sensor, None, priors, initial_probs=[0.5, 0.5],
                     switching_rates=rates)  # fmt: skip

    def mse(mean):
        return np.sum((mean[:, 10:, :2] - pos[:, 10:]) ** 2, -1).mean(-1)

    e_f = mse(res.filtered.mean)
    e_c = mse(imm_smooth(res, [cv, ct], switching_rates=rates).smoothed.mean)
    e_k = mse(imm_smooth(res, [cv, ct], switching_rates=rates, pair_weights="kim").smoothed.mean)
    for d in (e_f - e_c, e_k - e_f):
        assert d.mean() > 3 * d.std(ddof=1) / np.sqrt(n), (e_f.mean(), e_c.mean(), e_k.mean())
    with pytest.raises(ValueError, match="pair_weights"):
        imm_smooth(res, [cv, ct], switching_rates=rates, pair_weights="exact")


def test_a_recorded_drive_with_all_but_certain_modes_smooths_to_finite_estimates():
    """The Dresden car's GNSS fixes (``docs/data``; receiver-smoothed, noise of centimetres)
    under an IMM of CV and the coordinated turn fitted to them: the smoothed probability of
    CV at one step is exactly 0, and the pair corrections of the step before differ by
    e^2500, beyond the float range. The backward weights are taken in log space, so the
    smoother gives finite estimates and probabilities summing to 1 (it gave NaN)."""
    from pathlib import Path

    from adaptrack.io.position_log import read_position_log
    from adaptrack.tuning.log_fit import _run, _switching, motion_models

    car = Path(__file__).parents[2] / "docs" / "data" / "ground_10hz_car_dresden_20140326.csv"
    log = read_position_log(car, "gnss")
    values = {"q_horizontal": 1.11, "q_vertical": 0.078, "q_ct_horizontal": 849.0,
              "q_ct_vertical": 65.4, "switch_rate": 0.406, "q_turn": 9.16e-4,
              "r_horizontal": 1.42e-3, "r_vertical": 1.95e-5}  # fmt: skip
    run = _run(log, "cv+ct", values)
    out = imm_smooth(run, motion_models("cv+ct", values, 3), switching_rates=_switching(values))
    assert np.all(np.isfinite(out.smoothed.mean)) and np.all(np.isfinite(out.smoothed.cov))
    assert np.allclose(out.mode_probabilities.sum(axis=-1), 1.0)
    assert np.any(out.mode_probabilities == 0.0)  # the case: a mode ruled out exactly
    err = np.linalg.norm(out.smoothed.mean[:, :2] - log.enu[:, :2], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.2  # near the centimetre fixes, not astray
