"""RTS smoother: dense joint posterior oracle, batching, missing data, all three forms."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import Singer, discretize
from tests.oracles.reference import kalman_mp


def dense_posterior(prior_mean, prior_cov, phis, qds, h, r, z, mask):
    """Joint Gaussian of all states, conditioned on all measurements (no recursion)."""
    n_steps, n = len(phis), prior_mean.size
    # x_k = Phi_k ... Phi_0 x_init + sum of noises: build mean and covariance of the stack
    means, transfer = [], []
    a = np.eye(n)
    for k in range(n_steps):
        a = phis[k] @ a
        transfer.append(a)
        means.append(a @ prior_mean)
    big = np.zeros((n_steps * n, n_steps * n))
    # covariance: x_k = A_k x0 + sum_{j<=k} Phi_{k..j+1} w_j
    noise_maps = [[None] * n_steps for _ in range(n_steps)]
    for k in range(n_steps):
        m = np.eye(n)
        for j in range(k, -1, -1):
            noise_maps[k][j] = m
            m = m @ phis[j]
    for k in range(n_steps):
        for l in range(n_steps):
            c = transfer[k] @ prior_cov @ transfer[l].T
            for j in range(min(k, l) + 1):
                c = c + noise_maps[k][j] @ qds[j] @ noise_maps[l][j].T
            big[k * n : (k + 1) * n, l * n : (l + 1) * n] = c
    rows = [k for k in range(n_steps) if mask[k]]
    hb = np.zeros((len(rows) * h.shape[0], n_steps * n))
    for i, k in enumerate(rows):
        hb[i * h.shape[0] : (i + 1) * h.shape[0], k * n : (k + 1) * n] = h
    zb = np.concatenate([z[k] for k in rows])
    mu = np.concatenate(means)
    s = hb @ big @ hb.T + np.kron(np.eye(len(rows)), r)
    gain = big @ hb.T @ np.linalg.inv(s)
    post_mean = mu + gain @ (zb - hb @ mu)
    post_cov = big - gain @ hb @ big
    return post_mean.reshape(n_steps, n), np.array(
        [post_cov[k * n : (k + 1) * n, k * n : (k + 1) * n] for k in range(n_steps)]
    )


def test_rts_equals_dense_joint_posterior(rng):
    model = Singer(time_constant_s=2.0, accel_std_mps2=1.5)
    t = np.cumsum(rng.uniform(0.1, 0.6, 12))
    z = rng.normal(size=(12, 1)) * 2
    mask = np.ones(12, dtype=bool)
    mask[[4, 5, 9]] = False
    h, r = np.array([[1.0, 0.0, 0.0]]), np.array([[0.4]])
    prior = at.GaussianState([1.0, -0.5, 0.2], np.diag([4.0, 2.0, 1.0]), t[0] - 0.3)
    res = at.kalman_filter(t, z, model, h, r, prior, mask=mask)
    sm = at.rts_smooth(res)
    dts = np.diff(np.concatenate([[t[0] - 0.3], t]))
    phis, qds = discretize(model, dts)
    mean, cov = dense_posterior(prior.mean, prior.cov, phis, qds, h, r, z, mask)
    np.testing.assert_allclose(sm.mean, mean, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(sm.cov, cov, rtol=1e-8, atol=1e-10)
    # the last smoothed state is the last filtered state
    np.testing.assert_array_equal(sm.mean[-1], res.filtered.mean[-1])


def test_rts_batch_equals_loop_both_paths(rng):
    model = Singer(time_constant_s=4.0, accel_std_mps2=1.0)
    t = np.cumsum(rng.uniform(0.05, 0.2, (3, 30)), axis=1)
    z = rng.normal(size=(3, 30, 1))
    h = [[1.0, 0.0, 0.0]]
    prior = at.GaussianState(np.zeros(3), 10 * np.eye(3), 0.0)
    for times in (t, t[0]):  # per-track (general) and shared times (shared covariances)
        sm = at.rts_smooth(at.kalman_filter(times, z, model, h, [[0.2]], prior))
        for i in range(3):
            ti = times[i] if times.ndim == 2 else times
            one = at.rts_smooth(at.kalman_filter(ti, z[i], model, h, [[0.2]], prior))
            np.testing.assert_allclose(sm.mean[i], one.mean, rtol=1e-11, atol=1e-12)
            np.testing.assert_allclose(sm.cov[i], one.cov, rtol=1e-11, atol=1e-12)


def test_rts_rejects_non_results():
    import pytest

    with pytest.raises(TypeError, match="result must be a FilterResult"):
        at.rts_smooth("not a result")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("form", ["standard", "joseph", "sqrt"])
def test_smoother_with_a_singular_prediction_is_least_squares(backend, form):
    """Known velocity, no process noise: every prediction is singular (rank 1).

    The smoothed position at step 0 is the least-squares fit of ``z_k - v t_k`` with the
    prior as one more observation: variance ``1 / (1 / p0 + T / r)``.
    """
    t = np.arange(6.0)
    z = (2.0 * t + np.array([0.3, -0.1, 0.4, -0.5, 0.2, 0.0]))[:, None]
    prior = at.GaussianState([1.0, 2.0], np.diag([100.0, 0.0]), 0.0)
    model = at.models.ConstantVelocity(accel_psd=0.0)
    res = at.kalman_filter(t, z, model, [[1.0, 0.0]], [[0.5]], prior, backend=backend)
    sm = at.rts_smooth(res, form=form, backend=backend)
    info = 1.0 / 100.0 + 6 / 0.5
    x0 = (1.0 / 100.0 + np.sum(z[:, 0] - 2.0 * t) / 0.5) / info
    np.testing.assert_allclose(sm.mean[:, 0], x0 + 2.0 * t, rtol=1e-12)
    np.testing.assert_allclose(sm.cov[:, 0, 0], 1.0 / info, rtol=1e-10)
    np.testing.assert_array_equal(sm.cov[:, 1, :], 0.0)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_joseph_and_square_root_smoothers_equal_the_difference_form_when_all_are_exact(backend):
    rng = np.random.default_rng(11)
    model = at.models.Singer(time_constant_s=[4.0, 9.0], accel_std_mps2=[1.5, 0.4], n_axes=2)
    t = np.cumsum(rng.uniform(0.05, 3.0, (3, 50)), axis=-1)
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    z = rng.normal(size=(3, 50, 2)) * 20
    prior = at.GaussianState(np.zeros((3, 6)), np.broadcast_to(30 * np.eye(6), (3, 6, 6)), 0.0)
    res = at.kalman_filter(t, z, model, h, np.diag([1.0, 4.0]), prior, backend=backend)
    a = at.rts_smooth(res, form="standard", backend=backend)
    b = at.rts_smooth(res, form="joseph", backend=backend)
    c = at.rts_smooth(res, form="sqrt", backend=backend)
    ref = at.rts_smooth(res, form="joseph", backend="numpy")
    pairs = ((a.mean, b.mean), (a.cov, b.cov), (ref.cov, b.cov), (a.mean, c.mean), (a.cov, c.cov))
    for x, y in pairs:
        assert np.max(np.abs(x - y)) <= 1e-9 * np.max(np.abs(x))


def ill_conditioned_smoothing_problem():
    """Two-axis constant acceleration, steps 1e-6 to 0.1 s, R of condition 1e11, a prior of
    acceleration variance 1e5 m^2/s^4: filtered covariances of condition 1.6e16.

    Measured against the 60-digit smoother: the difference and Joseph forms' means are 3.4
    (NumPy) and 2.6 (compiled) posterior sigmas off, the square-root form's 0.009 (the filter's
    own error is 0.008).
    """
    rng = np.random.default_rng(1)
    model = at.models.ConstantAcceleration(jerk_psd=1e-3, n_axes=2)
    t = np.cumsum(10 ** rng.uniform(-6, -1, 14))
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    u, _ = np.linalg.qr(rng.normal(size=(2, 2)))
    r = (u * [6e-13, 5.5e-2]) @ u.T
    r = 0.5 * (r + r.T)
    z = rng.normal(size=(14, 2)) * 0.5
    mask = np.ones((14, 2), bool)
    mask[[0, 1, 4], 0] = False
    prior = at.GaussianState(np.zeros(6), np.diag([4.5, 0.2, 9.5e4, 1.1, 9.5e3, 6e-4]), 0.0)
    return at.kalman_filter(t, z, model, h, r, prior, mask=mask, backend="numpy"), (z, mask)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_smoother_matches_a_60_digit_reference_where_the_difference_form_fails(
    backend,
):
    res, (z, mask) = ill_conditioned_smoothing_problem()
    mean, cov = kalman_mp(
        res.transition,
        res.process_cov,
        res.measurement_matrix,
        res.measurement_cov,
        z,
        np.zeros(6),
        np.diag([4.5, 0.2, 9.5e4, 1.1, 9.5e3, 6e-4]),
        dps=60,
        mask=mask,
        smooth=True,
    )
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    scale = sigma[..., :, None] * sigma[..., None, :]
    sm = at.rts_smooth(res, form="sqrt", backend=backend)
    assert np.max(np.abs(sm.mean - mean) / sigma) < 0.05
    assert np.max(np.abs(sm.cov - cov) / scale) < 1e-6
    assert np.all(np.linalg.eigvalsh(sm.cov)[..., 0] >= 0.0)
    plain = at.rts_smooth(res, form="standard", backend=backend)
    assert np.max(np.abs(plain.mean - mean) / sigma) > 1.0  # the case the form exists for
    # "auto" recognises the problem (the filter's criterion) and takes the square-root form
    auto = at.rts_smooth(res, backend=backend)
    np.testing.assert_array_equal(auto.mean, sm.mean)


def test_auto_form_keeps_the_difference_form_on_a_well_conditioned_problem():
    t = np.arange(20.0)
    prior = at.GaussianState([0.0, 0.0], 10.0 * np.eye(2), 0.0)
    res = at.kalman_filter(
        t, np.sin(t)[:, None], at.models.ConstantVelocity(accel_psd=0.1), [[1.0, 0.0]], [[1.0]],
        prior,
    )  # fmt: skip
    auto, plain = at.rts_smooth(res), at.rts_smooth(res, form="standard")
    np.testing.assert_array_equal(auto.mean, plain.mean)
    np.testing.assert_array_equal(auto.cov, plain.cov)


def test_rts_smooth_rejects_an_unknown_form():
    t = np.arange(3.0)
    prior = at.GaussianState([0.0, 0.0], np.eye(2), 0.0)
    res = at.kalman_filter(
        t, t[:, None], at.models.ConstantVelocity(accel_psd=0.1), [[1.0, 0.0]], [[1.0]], prior
    )
    with pytest.raises(ValueError, match="'standard', 'joseph' or 'sqrt'; got 'ud'"):
        at.rts_smooth(res, form="ud")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_smoother_continues_from_the_filters_factors(backend):
    """Fuzz case (17, 73728): trace(S) up to 1.7e20 times the smallest measurement variance.
    The square-root filter's result carries its filtered factors and the smoother starts from
    them: both backends 1.9e-9 (covariances) off the 60-digit smoother, where factoring the
    stored covariances again left them 3e-4 (NumPy) and 2.3e-3 (compiled) off."""
    from tests.stress.fuzz import Source, _filter, problem

    p = problem(Source(np.random.default_rng((17, 73728))))
    res = _filter(p, form="sqrt", backend=backend)
    f, cov = res.filtered.factor, res.filtered.cov
    d = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    assert (
        np.max(np.abs(f @ np.swapaxes(f, -1, -2) - cov) / (d[..., :, None] * d[..., None, :]))
        < 1e-12
    )
    sm = at.rts_smooth(res, form="sqrt", backend=backend)
    mask = np.broadcast_to(p.mask, p.z.shape)
    for tr in range(p.z.shape[0]):
        mean, cov = kalman_mp(
            res.transition[tr], res.process_cov[tr], p.h, p.r, p.z[tr], p.prior.mean[tr],
            p.prior.cov[tr], dps=60, mask=mask[tr], offset=p.offset, smooth=True,
        )  # fmt: skip
        sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
        assert np.max(np.abs(sm.mean[tr] - mean) / sigma) < 1e-2
        assert np.max(np.abs(sm.cov[tr] - cov) / (sigma[..., :, None] * sigma[..., None, :])) < 1e-6
