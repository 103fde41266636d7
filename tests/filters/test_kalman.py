"""Kalman filter: sequence API, online step, batching, missing data, likelihood, oracles."""

import math

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.stats import multivariate_normal

import adaptrack as at
from adaptrack.models import ConstantVelocity, Singer, discretize

H3 = np.array([[1.0, 0.0, 0.0]])
SINGER = Singer(time_constant_s=5.0, accel_std_mps2=2.0)


def prior3(t0=0.0, batch=()):
    return at.GaussianState(
        mean=np.zeros(batch + (3,)), cov=np.broadcast_to(100.0 * np.eye(3), batch + (3, 3)), time=t0
    )


def irregular_times(rng, n, shape=()):
    return np.cumsum(rng.uniform(0.02, 0.3, shape + (n,)), axis=-1)


def test_online_step_gives_identical_numbers(rng):
    t = irregular_times(rng, 60)
    z = rng.normal(size=(60, 1)) * 3
    res = at.kalman_filter(t, z, SINGER, H3, [[0.25]], prior3(t[0]))
    state = prior3(t[0])
    for k in range(t.size):
        state, info = at.kalman_step(state, z[k], SINGER, H3, [[0.25]], time=t[k])
        np.testing.assert_array_equal(state.mean, res.filtered.mean[k])
        np.testing.assert_array_equal(state.cov, res.filtered.cov[k])
        np.testing.assert_array_equal(info.nis, res.info.nis[k])
        np.testing.assert_array_equal(info.log_likelihood, res.info.log_likelihood[k])


@pytest.mark.parametrize("per_track_times", [False, True])
def test_batch_equals_loop(rng, per_track_times):
    n_tracks, n_steps = 5, 40
    t = irregular_times(rng, n_steps, (n_tracks,) if per_track_times else ())
    z = rng.normal(size=(n_tracks, n_steps, 1)) * 2
    res = at.kalman_filter(t, z, SINGER, H3, [[0.5]], prior3(float(np.min(t[..., 0]))))
    for i in range(n_tracks):
        ti = t[i] if per_track_times else t
        one = at.kalman_filter(ti, z[i], SINGER, H3, [[0.5]], prior3(float(np.min(t[..., 0]))))
        for a, b in (
            (res.filtered.mean[i], one.filtered.mean),
            (res.filtered.cov[i], one.filtered.cov),
            (res.predicted.mean[i], one.predicted.mean),
            (res.info.log_likelihood[i], one.info.log_likelihood),
            (res.transition[i], one.transition),
        ):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    "model",
    [
        SINGER,
        ConstantVelocity(accel_psd=0.7, n_axes=1),
        Singer(time_constant_s=0.2, accel_std_mps2=3.0),
    ],
    ids=["singer", "cv", "singer_fast"],
)
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_jittered_per_track_times_use_series_tables_equal_to_expm(rng, model, backend):
    """40 tracks x 60 jittered steps (more distinct step lengths than ``SERIES_MIN_STEPS``:
    the series table is evaluated for every step) against each track alone on its own 1-D
    times (fewer: one matrix exponential per distinct step): transitions, noise and estimates
    equal to 1e-10 (the fast Singer, tau = 0.2 s, takes doublings on its 0.3 s steps)."""
    from adaptrack.filters.run import SERIES_MIN_STEPS

    n_tracks, n_steps = 40, 60
    assert n_steps < SERIES_MIN_STEPS <= n_tracks * n_steps
    t = irregular_times(rng, n_steps, (n_tracks,))
    n = model.state_dim
    h = np.eye(1, n)
    z = rng.normal(size=(n_tracks, n_steps, 1)) * 2
    prior = at.GaussianState(np.zeros(n), 100.0 * np.eye(n), 0.0)
    res = at.kalman_filter(t, z, model, h, [[0.5]], prior, backend=backend)
    for i in range(0, n_tracks, 7):
        one = at.kalman_filter(t[i], z[i], model, h, [[0.5]], prior, backend=backend)
        for a, b in (
            (res.transition[i], one.transition),
            (res.process_cov[i], one.process_cov),
            (res.filtered.mean[i], one.filtered.mean),
            (res.filtered.cov[i], one.filtered.cov),
            (res.info.log_likelihood[i], one.info.log_likelihood),
        ):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def test_shared_and_general_paths_agree(rng):
    t = irregular_times(rng, 50)
    z = rng.normal(size=(4, 50, 1))
    shared = at.kalman_filter(t, z, SINGER, H3, [[0.3]], prior3(t[0]))
    # a per-track prior covariance forces the general path
    general = at.kalman_filter(t, z, SINGER, H3, [[0.3]], prior3(t[0], batch=(4,)))
    assert shared.filtered.cov.strides[0] == 0 and general.filtered.cov.strides[0] != 0
    for a, b in (
        (shared.filtered.mean, general.filtered.mean),
        (shared.filtered.cov, general.filtered.cov),
        (shared.info.nis, general.info.nis),
        (shared.info.log_likelihood, general.info.log_likelihood),
    ):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-13)


def test_log_likelihood_and_nis_match_scipy(rng):
    model = ConstantVelocity(accel_psd=0.7, n_axes=2)
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    r = np.array([[2.0, 0.3], [0.3, 1.0]])
    t = irregular_times(rng, 20)
    z = rng.normal(size=(20, 2)) * 3
    res = at.kalman_filter(t, z, model, h, r, at.GaussianState(np.zeros(4), 10 * np.eye(4), t[0]))
    for k in range(20):
        s = h @ res.predicted.cov[k] @ h.T + r
        mean = h @ res.predicted.mean[k]
        want = multivariate_normal(mean, s).logpdf(z[k])
        assert res.info.log_likelihood[k] == pytest.approx(want, rel=1e-12)
        nu = z[k] - mean
        assert res.info.nis[k] == pytest.approx(nu @ np.linalg.solve(s, nu), rel=1e-12)
    assert res.log_likelihood == pytest.approx(res.info.log_likelihood.sum())


def test_scalar_random_walk_reaches_riccati_steady_state():
    q, r = 0.3, 2.0
    model = at.models.LinearSDE([[0.0]], [[1.0]], [[q]], ("x",))
    t = np.arange(300.0)
    res = at.kalman_filter(
        t, np.zeros((300, 1)), model, [[1.0]], [[r]], at.GaussianState([0.0], [[50.0]], 0.0)
    )
    p_pred = solve_discrete_are(np.eye(1), np.eye(1), q * np.eye(1), r * np.eye(1))[0, 0]
    p_filt = p_pred * r / (p_pred + r)
    assert res.predicted.cov[-1, 0, 0] == pytest.approx(p_pred, rel=1e-12)
    assert res.filtered.cov[-1, 0, 0] == pytest.approx(p_filt, rel=1e-12)
    # closed form of the scalar Riccati fixed point: P = (q + sqrt(q^2 + 4 q r)) / 2
    assert p_pred == pytest.approx((q + math.sqrt(q * q + 4 * q * r)) / 2, rel=1e-12)


def test_whole_measurement_missing_predicts_through(rng):
    t = irregular_times(rng, 30)
    z = rng.normal(size=(30, 1))
    mask = np.ones(30, dtype=bool)
    mask[10:15] = False
    z_nan = z.copy()
    z_nan[10:15] = np.nan
    res = at.kalman_filter(t, z_nan, SINGER, H3, [[0.25]], prior3(t[0]), mask=mask)
    np.testing.assert_array_equal(res.filtered.mean[10:15], res.predicted.mean[10:15])
    np.testing.assert_array_equal(res.filtered.cov[10:15], res.predicted.cov[10:15])
    assert np.all(res.info.log_likelihood[10:15] == 0) and np.all(res.info.nis[10:15] == 0)
    assert np.all(res.info.n_observed[10:15] == 0)
    # identical to running the two available stretches with a gap
    keep = mask
    ref = at.kalman_filter(t[keep], z[keep], SINGER, H3, [[0.25]], prior3(t[0]))
    np.testing.assert_allclose(res.filtered.mean[keep], ref.filtered.mean, rtol=1e-12)
    # nan_policy="missing" is the same as the mask
    res2 = at.kalman_filter(t, z_nan, SINGER, H3, [[0.25]], prior3(t[0]), nan_policy="missing")
    np.testing.assert_array_equal(res2.filtered.mean, res.filtered.mean)


def test_partial_measurement_equals_reduced_measurement_model(rng):
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    r = np.array([[1.0, 0.4], [0.4, 2.0]])
    prior = at.GaussianState(np.zeros(4), 5 * np.eye(4), 0.0)
    z = np.array([1.0, np.nan])
    post, info = at.update(prior, z, h, r, mask=np.array([True, False]))
    ref, ref_info = at.update(prior, z[:1], h[:1], r[:1, :1])
    np.testing.assert_allclose(post.mean, ref.mean, rtol=1e-14)
    np.testing.assert_allclose(post.cov, ref.cov, rtol=1e-14)
    assert info.log_likelihood == pytest.approx(ref_info.log_likelihood, rel=1e-14)
    assert info.nis == pytest.approx(ref_info.nis, rel=1e-14)
    assert info.n_observed == 1 and info.innovation[1] == 0


def test_per_track_masks_and_per_step_measurement_cov(rng):
    t = irregular_times(rng, 25)
    z = rng.normal(size=(3, 25, 1))
    mask = rng.uniform(size=(3, 25)) > 0.3
    r = rng.uniform(0.1, 2.0, size=(3, 25, 1, 1))
    res = at.kalman_filter(t, z, SINGER, H3, r, prior3(t[0]), mask=mask)
    for i in range(3):
        one = at.kalman_filter(t, z[i], SINGER, H3, r[i], prior3(t[0]), mask=mask[i])
        np.testing.assert_allclose(res.filtered.mean[i], one.filtered.mean, rtol=1e-12)


def test_initial_time_before_first_measurement_is_predicted(rng):
    t = 2.0 + irregular_times(rng, 10)
    z = rng.normal(size=(10, 1))
    prior = prior3(0.0)
    res = at.kalman_filter(t, z, SINGER, H3, [[0.25]], prior)
    phi, qd = discretize(SINGER, t[0] - 0.0)
    np.testing.assert_allclose(res.predicted.cov[0], phi @ prior.cov @ phi.T + qd, rtol=1e-13)
    np.testing.assert_allclose(res.transition[0], phi, rtol=1e-15)
    # equal times: step 0 is update-only
    res0 = at.kalman_filter(t, z, SINGER, H3, [[0.25]], prior3(t[0]))
    np.testing.assert_array_equal(res0.transition[0], np.eye(3))
    np.testing.assert_array_equal(res0.predicted.cov[0], prior.cov)


def test_seed000_filter_including_source_form(rng):
    """Spec A.6: (8)-(13) with C restored, D S D^T and the noise mean removed."""
    tau, sw = 3.0, 0.8
    model = Singer(time_constant_s=tau, accel_std_mps2=sw)
    c3, c2 = 1.2, 0.9
    c_seed = np.array([[0.0, 0.0, c3], [0.0, c2, 0.0]])  # seed order [w, v, r]
    pi = at.models.seed000_permutation()
    d = np.array([[1.0, 0.2], [0.0, 1.5]])
    s_eta = np.diag([0.3, 0.05])
    m_eta = np.array([0.1, -0.02])
    t = irregular_times(rng, 40)
    y = rng.normal(size=(40, 2)) + np.array([5.0, 1.0])
    m0_seed = np.array([0.0, 1.0, 5.0])
    p0_seed = np.diag([sw**2, 4.0, 9.0])
    ry = d @ s_eta @ d.T
    for method in ("source", "expm"):
        res = at.kalman_filter(
            t,
            y,
            model,
            c_seed @ pi,
            ry,
            at.GaussianState(pi @ m0_seed, pi @ p0_seed @ pi.T, t[0]),
            method=method,
            measurement_noise_mean=d @ m_eta,
        )
        x, p = m0_seed, p0_seed
        for k in range(t.size):
            if k > 0:
                phi, qd = discretize(model, t[k] - t[k - 1], method)
                phi, qd = pi @ phi @ pi.T, pi @ qd @ pi.T
                x = phi @ x  # (8)
                p = phi @ p @ phi.T + qd  # (10)
            s = c_seed @ p @ c_seed.T + ry
            gain = p @ c_seed.T @ np.linalg.inv(s)  # (13)
            x = x + gain @ (y[k] - c_seed @ x - d @ m_eta)  # (9), C restored
            p = p - p @ c_seed.T @ np.linalg.inv(s) @ c_seed @ p  # (11), (12)
            np.testing.assert_allclose(pi @ res.filtered.mean[k], x, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(pi @ res.filtered.cov[k] @ pi, p, rtol=1e-9, atol=1e-12)


def test_inputs_are_not_mutated(rng):
    t = irregular_times(rng, 15)
    z = rng.normal(size=(2, 15, 1))
    r = np.array([[0.25]])
    prior = prior3(t[0])
    copies = [a.copy() for a in (t, z, r)]
    res = at.kalman_filter(t, z, SINGER, H3, r, prior)
    at.rts_smooth(res)
    for a, b in zip((t, z, r), copies):
        np.testing.assert_array_equal(a, b)
    assert not res.filtered.mean.flags.writeable and not res.filtered.cov.flags.writeable
