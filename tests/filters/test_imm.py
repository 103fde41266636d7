"""IMM: reduction to the KF, FilterPy cross-check, models of different sizes, batching."""

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

import adaptrack as at
from adaptrack.filters.imm import imm_filter
from adaptrack.models import ConstantAcceleration, ConstantVelocity, ShapingFilter, discretize


def data(rng, n_tracks=3, n_steps=80):
    t = np.cumsum(rng.uniform(0.05, 0.3, n_steps))
    z = rng.normal(size=(n_tracks, n_steps, 1)) * 2 + (5 * t + 0.3 * t**2)[:, None]
    return t, z


def test_single_model_imm_is_the_kalman_filter(rng):
    t, z = data(rng)
    model = ConstantVelocity(accel_psd=2.0)
    prior = at.GaussianState([0.0, 1.0], np.diag([100.0, 10.0]), t[0])
    res = imm_filter(t, z, [model], ("x",), [[4.0]], [prior], [[1.0]], [1.0])
    kf = at.kalman_filter(t, z, model, [[1.0, 0.0]], [[4.0]], prior)
    np.testing.assert_allclose(res.filtered.mean, kf.filtered.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res.filtered.cov, kf.filtered.cov, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(res.log_likelihood, kf.info.log_likelihood, rtol=1e-12)
    np.testing.assert_array_equal(res.mode_probabilities, 1.0)


@pytest.mark.crosscheck
def test_matches_filterpy_imm_with_equal_state_sizes(rng):
    dt = 0.1
    t = dt * np.arange(60)
    z = rng.normal(size=(60, 1)) * 3 + (10 * t + np.where(t > 3, 4 * (t - 3) ** 2, 0))[:, None]
    models = [ConstantVelocity(accel_psd=0.05), ConstantVelocity(accel_psd=50.0)]
    pi = np.array([[0.97, 0.03], [0.05, 0.95]])
    mu0 = np.array([0.6, 0.4])
    priors = [
        at.GaussianState([0.0, 5.0], np.diag([25.0, 9.0]), t[0]),
        at.GaussianState([1.0, 4.0], np.diag([16.0, 30.0]), t[0]),
    ]
    # FilterPy's initial probabilities are those of the step before the first measurement
    # (its first update weights by mu0 @ M); adaptrack's are the prior at the first one
    res = imm_filter(t, z, models, ("x",), [[9.0]], priors, pi, mu0 @ pi)
    filters = []
    for m, p in zip(models, priors):
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.F, kf.Q = discretize(m, dt)
        kf.H, kf.R = np.array([[1.0, 0.0]]), np.array([[9.0]])
        kf.x, kf.P = np.array(p.mean), np.array(p.cov)
        filters.append(kf)
    imm = IMMEstimator(filters, mu0.copy(), pi.copy())
    xs, ps, mus = [], [], []
    for k in range(t.size):
        if k:
            imm.predict()
        imm.update(z[k].copy())
        xs.append(imm.x.copy())
        ps.append(imm.P.copy())
        mus.append(imm.mu.copy())
    np.testing.assert_allclose(res.filtered.mean, np.array(xs), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.filtered.cov, np.array(ps), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.mode_probabilities, np.array(mus), rtol=1e-9, atol=1e-12)


def test_models_of_different_sizes(rng):
    t = np.cumsum(rng.uniform(0.05, 0.3, 80))
    z = rng.normal(size=(3, 80, 1)) * 2 + (5 * t + 5 * t**2)[:, None]  # 10 m/s^2
    models = [
        ConstantVelocity(accel_psd=0.1),
        ConstantAcceleration(jerk_psd=1.0),
        ShapingFilter(lambda_per_s2=0.05, alpha_per_s=0.3, shaping_std=5.0),
    ]
    priors = [
        at.GaussianState(np.zeros(m.state_dim), 100 * np.eye(m.state_dim), t[0]) for m in models
    ]
    pi = np.full((3, 3), 0.025) + 0.925 * np.eye(3)
    res = imm_filter(t, z, models, ("x",), [[4.0]], priors, pi, [1 / 3] * 3)
    assert res.state_names == ("x", "vx")
    np.testing.assert_allclose(res.mode_probabilities.sum(-1), 1.0, atol=1e-12)
    assert res.components[1].mean.shape == (3, 80, 3)
    eig = np.linalg.eigvalsh(res.filtered.cov)
    assert np.all(eig > 0)
    # accelerating data: the CA model gains weight over the pure CV model
    assert res.mode_probabilities[:, -20:, 1].mean() > res.mode_probabilities[:, -20:, 0].mean()
    # batch == loop
    for i in range(3):
        one = imm_filter(t, z[i], models, ("x",), [[4.0]], priors, pi, [1 / 3] * 3)
        np.testing.assert_allclose(res.filtered.mean[i], one.filtered.mean, rtol=1e-11, atol=1e-11)


def test_imm_bad_input(rng):
    t, z = data(rng)
    m = ConstantVelocity()
    p = at.GaussianState([0.0, 0.0], np.eye(2), t[0])
    with pytest.raises(ValueError, match=r"models\[0\] has no state\(s\) \['y'\]"):
        imm_filter(t, z, [m], ("y",), [[1.0]], [p], [[1.0]], [1.0])
    with pytest.raises(ValueError, match="rows summing to 1"):
        imm_filter(t, z, [m, m], ("x",), [[1.0]], [p, p], [[0.5, 0.4], [0.5, 0.5]], [0.5, 0.5])
    with pytest.raises(ValueError, match="initial_probs must be non-negative and sum to 1"):
        imm_filter(t, z, [m], ("x",), [[1.0]], [p], [[1.0]], [0.5])
    with pytest.raises(ValueError, match="initial must hold one GaussianState per model"):
        imm_filter(t, z, [m, m], ("x",), [[1.0]], [p], np.eye(2), [0.5, 0.5])


@pytest.mark.parametrize("per_track_times", [False, True])
def test_compiled_imm_equals_the_numpy_reference(rng, per_track_times):
    """Models of different sizes, 2-D measurements with missing components, per-step R."""
    n_tracks, n_steps = 5, 60
    shape = (n_tracks, n_steps) if per_track_times else (n_steps,)
    t = np.cumsum(rng.choice([0.05, 0.1, 0.2], shape), axis=-1)
    tt = np.broadcast_to(t, (n_tracks, n_steps))
    z = rng.normal(size=(n_tracks, n_steps, 2)) * 2 + np.stack([5 * tt, 3 * tt**2], -1)
    mask = rng.random(z.shape) > 0.15
    z[~mask] = np.nan
    models = [
        ConstantVelocity(accel_psd=0.1, n_axes=2),
        ConstantAcceleration(jerk_psd=1.0, n_axes=2),
        ShapingFilter(lambda_per_s2=0.05, alpha_per_s=0.3, shaping_std=5.0, n_axes=2),
    ]
    priors = [
        at.GaussianState(
            rng.normal(size=(n_tracks, m.state_dim)),
            np.broadcast_to(50 * np.eye(m.state_dim), (n_tracks, m.state_dim, m.state_dim)),
            float(np.min(t)) - 0.1,
        )
        for m in models
    ]
    a = rng.normal(size=(n_tracks, n_steps, 2, 2))
    r = a @ np.swapaxes(a, -1, -2) + np.eye(2)
    pi = np.full((3, 3), 0.025) + 0.925 * np.eye(3)
    args = (t, z, models, ("x", "y"), r, priors, pi, [0.5, 0.3, 0.2])
    ref = imm_filter(*args, mask=mask, backend="numpy")
    got = imm_filter(*args, mask=mask, backend="numba")
    assert got.state_names == ref.state_names == ("x", "y", "vx", "vy")

    def close(x, y):
        assert np.abs(x - y).max() <= 1e-10 * np.abs(y).max()

    close(got.filtered.mean, ref.filtered.mean)
    close(got.filtered.cov, ref.filtered.cov)
    close(got.mode_probabilities, ref.mode_probabilities)
    close(got.log_likelihood, ref.log_likelihood)
    for c_got, c_ref in zip(got.components, ref.components, strict=True):
        close(c_got.mean, c_ref.mean)
        close(c_got.cov, c_ref.cov)
    with pytest.raises(ValueError, match="backend must be"):
        imm_filter(*args, mask=mask, backend="gpu")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_form_matches_a_50_digit_reference_on_an_ill_conditioned_problem(backend):
    """One-model IMM on the square-root filter's hard problem (R of condition 1e11, prior of
    1 km, gaps 1e-6 to 100 s): the default ("auto", square root here) is within 1e-2 posterior
    sigma of the 50-digit textbook filter, as the square-root Kalman filter is; the Joseph form was
    measured 4 (NumPy) and 3200 (compiled) sigmas off on this problem."""
    from tests.filters.test_square_root import ill_conditioned_problem
    from tests.oracles.reference import kalman_mp

    t, z, model, h, r, prior = ill_conditioned_problem()
    res = imm_filter(t, z, [model], ("x", "vx"), r, [prior], [[1.0]], [1.0], backend=backend)
    kf = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend=backend)
    mean, cov = kalman_mp(kf.transition, kf.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(res.filtered.mean - mean) / sigma) < 1e-2
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(res.filtered.cov - cov) / scale) < 1e-6


def _fuzz_imm_problem(seed):
    """The IMM problem of the fuzz campaign's case ``seed`` (tests.stress.fuzz.imm_case)."""
    from tests.stress.fuzz import Source, problem

    src = Source(np.random.default_rng(seed))
    p = problem(src)
    axes = p.h.shape[0]
    models = [
        ConstantVelocity(accel_psd=src.log_real(1e-3, 1.0), n_axes=axes),
        ConstantAcceleration(jerk_psd=src.log_real(1e-2, 10.0), n_axes=axes),
    ]
    priors = [
        at.GaussianState(
            np.zeros(mo.state_dim), np.diag(10.0 ** src.rng.uniform(0, 6, mo.state_dim)), 0.0
        )
        for mo in models
    ]
    stay = src.real(0.5, 0.999)
    pi = np.array([[stay, 1 - stay], [1 - stay, stay]])
    return p, models, priors, pi


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_two_model_square_root_imm_matches_a_60_digit_imm(backend):
    """Fuzz case (21, 5942): constant velocity + constant acceleration, steps of 2-160 us, R of
    condition 1.5e11; the mixed covariances' correlation matrices reach condition 1e11.
    Mixing in factor form (no mixed covariance formed and factored again) leaves both
    backends 0.006 posterior sigma from a 60-digit IMM with the same mixing; refactoring the
    mixed covariance left the compiled kernel 1.15 sigma off."""
    from tests.oracles.reference import imm_mp

    p, models, priors, pi = _fuzz_imm_problem((21, 5942))
    names = models[0].state_names[: p.h.shape[0]]
    z = np.where(p.mask, p.z, np.nan)
    res = imm_filter(p.times, z, models, names, p.r, priors, pi, [0.5, 0.5], mask=p.mask,
                     backend=backend)  # fmt: skip
    t = np.broadcast_to(p.times, p.z.shape[:-1])[0]
    dt = np.diff(np.concatenate([[0.0], t]))
    disc = [at.discretize(mo, dt) for mo in models]
    hs = [np.eye(mo.state_dim)[[mo.state_names.index(s) for s in names]] for mo in models]
    ref = imm_mp(
        [d.transition for d in disc], [d.process_cov for d in disc], hs,
        [mo.state_names for mo in models], p.r, p.z[0], np.broadcast_to(p.mask, p.z.shape)[0],
        [(pr.mean, pr.cov) for pr in priors], pi, [0.5, 0.5],
    )  # fmt: skip
    sigma = np.sqrt(np.diagonal(res.filtered.cov[0], axis1=-2, axis2=-1))
    assert np.max(np.abs(res.filtered.mean[0] - ref) / sigma) < 0.02


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_and_joseph_forms_agree_on_a_well_conditioned_batch(rng, backend):
    t, z = data(rng)
    models = [ConstantVelocity(accel_psd=0.5), ConstantAcceleration(jerk_psd=3.0)]
    priors = [
        at.GaussianState(np.zeros(m.state_dim), 50.0 * np.eye(m.state_dim), 0.0) for m in models
    ]
    pi = np.array([[0.9, 0.1], [0.2, 0.8]])
    mask = rng.uniform(size=z.shape[:-1]) > 0.2
    runs = [
        imm_filter(
            t,
            z,
            models,
            ("x",),
            [[4.0]],
            priors,
            pi,
            [0.5, 0.5],
            mask=mask,
            form=form,
            backend=backend,
        )
        for form in ("sqrt", "joseph")
    ]
    a, b = (r.filtered for r in runs)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(runs[0].mode_probabilities, runs[1].mode_probabilities, atol=1e-10)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_auto_form_is_joseph_where_it_keeps_its_digits_and_the_square_root_where_not(rng, backend):
    """'auto' returns exactly the Joseph run on a well-conditioned batch (trace(S) / R below
    1e8: no square-root cost) and exactly the square-root run where a 1 km prior meets a
    1 mm measurement sigma (trace(S) / R = 1e12 at the first step, R itself well-conditioned)."""
    t, z = data(rng)
    models = [ConstantVelocity(accel_psd=0.5), ConstantAcceleration(jerk_psd=3.0)]
    pi = np.array([[0.9, 0.1], [0.2, 0.8]])

    def run(prior_var, r, form):
        priors = [
            at.GaussianState(np.zeros(m.state_dim), prior_var * np.eye(m.state_dim), 0.0)
            for m in models
        ]
        res = imm_filter(t, z, models, ("x",), [[r]], priors, pi, [0.5, 0.5], form=form,
                         backend=backend)  # fmt: skip
        return res.filtered.mean, res.filtered.cov, res.mode_probabilities

    for prior_var, r, expected in ((50.0, 4.0, "joseph"), (1e6, 1e-6, "sqrt")):
        auto, chosen = run(prior_var, r, "auto"), run(prior_var, r, expected)
        for a, b in zip(auto, chosen, strict=True):
            np.testing.assert_array_equal(a, b)
    joseph, root = run(1e6, 1e-6, "joseph"), run(1e6, 1e-6, "sqrt")
    assert not np.array_equal(joseph[0], root[0])  # the two forms do differ there


@pytest.mark.crosscheck
def test_switching_rates_match_filterpy_with_expm_per_step(rng):
    """Irregular steps: FilterPy's IMMEstimator given expm(L dt) as its M before every step."""
    from scipy.linalg import expm

    t = np.cumsum(rng.uniform(0.02, 0.8, 70))
    z = rng.normal(size=(70, 1)) * 3 + (10 * t + np.where(t > 12, 4 * (t - 12) ** 2, 0))[:, None]
    models = [ConstantVelocity(accel_psd=0.05), ConstantVelocity(accel_psd=50.0)]
    rates = np.array([[-0.3, 0.3], [0.5, -0.5]])  # [1/s]
    mu0 = np.array([0.6, 0.4])
    priors = [
        at.GaussianState([0.0, 5.0], np.diag([25.0, 9.0]), t[0]),
        at.GaussianState([1.0, 4.0], np.diag([16.0, 30.0]), t[0]),
    ]
    filters = []
    for p in priors:
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.H, kf.R = np.array([[1.0, 0.0]]), np.array([[9.0]])
        kf.x, kf.P = np.array(p.mean), np.array(p.cov)
        filters.append(kf)
    imm = IMMEstimator(filters, mu0.copy(), np.eye(2))  # M = I: its first update weighs by mu0
    xs, mus = [], []
    for k in range(t.size):
        if k:
            dt = t[k] - t[k - 1]
            imm.M = expm(rates * dt)
            imm._compute_mixing_probabilities()  # FilterPy mixes with the M of its last update
            for kf, m in zip(filters, models):
                kf.F, kf.Q = discretize(m, dt)
            imm.predict()
        imm.update(z[k].copy())
        xs.append(imm.x.copy())
        mus.append(imm.mu.copy())
    for backend in ("numpy", "numba"):
        res = imm_filter(
            t, z, models, ("x",), [[9.0]], priors, initial_probs=mu0, switching_rates=rates,
            backend=backend,
        )  # fmt: skip
        np.testing.assert_allclose(res.filtered.mean, np.array(xs), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(res.mode_probabilities, np.array(mus), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_switching_rates_on_a_regular_grid_are_the_matrix_exponential(rng, backend):
    from scipy.linalg import expm

    t = 0.25 * np.arange(1, 61)
    z = rng.normal(size=(4, 60, 1)) * 2 + (5 * t + 0.3 * t**2)[:, None]
    models = [ConstantVelocity(accel_psd=0.1), ConstantAcceleration(jerk_psd=1.0)]
    priors = [
        at.GaussianState(np.zeros(m.state_dim), 100 * np.eye(m.state_dim), 0.0) for m in models
    ]
    rates = np.array([[-0.2, 0.2], [0.4, -0.4]])
    by_rates = imm_filter(t, z, models, ("x",), [[4.0]], priors, None, [0.5, 0.5],
                          switching_rates=rates, backend=backend)  # fmt: skip
    by_probs = imm_filter(t, z, models, ("x",), [[4.0]], priors, expm(0.25 * rates),
                          [0.5, 0.5], backend=backend)  # fmt: skip
    np.testing.assert_allclose(by_rates.filtered.mean, by_probs.filtered.mean, rtol=1e-12)
    np.testing.assert_allclose(by_rates.mode_probabilities, by_probs.mode_probabilities,
                               rtol=1e-12, atol=1e-15)  # fmt: skip


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"transition_probs": np.eye(2), "switching_rates": -np.eye(2) + 1}, "give one of"),
        ({}, "give one of"),
        ({"switching_rates": [[-0.1, 0.1, 0.0]]}, r"must have shape \(2, 2\)"),
        ({"switching_rates": [[0.1, -0.1], [0.2, -0.2]]}, "off-diagonal rates"),
        ({"switching_rates": [[-0.1, 0.2], [0.2, -0.2]]}, "row 0 sums to 0.1"),
    ],
)
def test_switching_rates_bad_input(rng, kwargs, message):
    t, z = data(rng, 1, 10)
    models = [ConstantVelocity(accel_psd=0.1), ConstantVelocity(accel_psd=10.0)]
    priors = [at.GaussianState([0.0, 0.0], 100 * np.eye(2), t[0])] * 2
    with pytest.raises(ValueError, match=message):
        imm_filter(t, z[0], models, ("x",), [[4.0]], priors, initial_probs=[0.5, 0.5], **kwargs)


def test_imm_with_a_linear_measurement_model_is_the_linear_imm(rng):
    """IMM-EKF and IMM-UKF with h linear (a user's function): the linear IMM (models of
    different sizes); a PositionMeasurement is run as that linear IMM."""
    from adaptrack.models import FunctionMeasurement, PositionMeasurement

    t = np.cumsum(rng.uniform(0.5, 1.5, 40))
    z = rng.normal(0, 20, (2, 40, 2)) + np.stack([30 * t, 0.5 * t**2], -1)
    models = [ConstantVelocity(1.0, n_axes=2), ConstantAcceleration(0.5, n_axes=2)]
    priors = [
        at.GaussianState(np.c_[z[:, 0], np.zeros((2, 2))],
                         np.broadcast_to(np.diag([400.0, 400, 900, 900]), (2, 4, 4)), t[0]),
        at.GaussianState(np.c_[z[:, 0], np.zeros((2, 4))],
                         np.broadcast_to(np.diag([400.0, 400, 900, 900, 25, 25]), (2, 6, 6)),
                         t[0]),
    ]  # fmt: skip
    r = np.array([[400.0, 50.0], [50.0, 300.0]])
    rates = [[-0.05, 0.05], [0.1, -0.1]]
    ref = imm_filter(t, z, models, ("x", "y"), r, priors, initial_probs=[0.7, 0.3],
                     switching_rates=rates, form="joseph", backend="numpy")  # fmt: skip
    linear = FunctionMeasurement(lambda s_: s_, ("x", "y"), ("x_m", "y_m"), r,
                                 jacobian_function=lambda s_: np.broadcast_to(
                                     np.eye(2), s_.shape[:-1] + (2, 2)))  # fmt: skip
    for kind, sensor in (("ekf", linear), ("ukf", linear), ("ekf", PositionMeasurement(r))):
        res = imm_filter(t, z, models, sensor, None, priors,
                         initial_probs=[0.7, 0.3], switching_rates=rates,
                         nonlinear=kind)  # fmt: skip
        tol = 1e-10 if kind == "ekf" else 1e-7
        np.testing.assert_allclose(res.filtered.mean, ref.filtered.mean, rtol=tol, atol=tol)
        np.testing.assert_allclose(res.mode_probabilities, ref.mode_probabilities, atol=tol)
        np.testing.assert_allclose(res.log_likelihood, ref.log_likelihood, rtol=tol)


@pytest.mark.crosscheck
def test_imm_ekf_matches_filterpy_imm_of_extended_filters(rng):
    """Two CV radar EKFs (quiet and agile) in FilterPy's IMMEstimator, identical inputs."""
    from filterpy.common import Q_continuous_white_noise
    from filterpy.kalman import ExtendedKalmanFilter

    from adaptrack.models import RadarMeasurement

    radar = RadarMeasurement(noise_cov=np.diag([25.0, 4e-6]))
    dt, n = 1.0, 60
    t = dt * np.arange(n)
    turn = np.where(t > 30, (t - 30) ** 2 * 0.8, 0.0)
    truth = np.stack([3000.0 + 80 * t, 6000.0 - 20 * t + turn], -1)
    z = radar.predict(truth) + rng.normal(size=(n, 2)) * [5.0, 2e-3]
    qs = (0.1, 30.0)
    models = [ConstantVelocity(q, n_axes=2) for q in qs]
    pi = np.array([[0.95, 0.05], [0.1, 0.9]])
    mu0 = np.array([0.8, 0.2])
    prior = at.GaussianState([3000.0, 6000.0, 70.0, -10.0], np.diag([400.0, 400, 400, 400]), 0.0)
    res = imm_filter(t, z, models, radar, None, [prior, prior], pi, mu0 @ pi)
    perm, inv = [0, 2, 1, 3], np.argsort([0, 2, 1, 3])

    def wrapped(a, b):
        return np.r_[a[0] - b[0], (a[1] - b[1] + np.pi) % (2 * np.pi) - np.pi]

    class RadarEKF(ExtendedKalmanFilter):
        def predict(self, u=None):  # IMMEstimator passes u=None, which EKF.predict cannot take
            super().predict(0)

        def update(self, z):
            super().update(
                z, lambda x: radar.jacobian(x[inv][:2]) @ np.eye(4)[:2][:, perm],
                lambda x: radar.predict(x[inv]),
                residual=wrapped,
            )  # fmt: skip

    filters = []
    for q in qs:
        f = RadarEKF(dim_x=4, dim_z=2)
        f.F = np.kron(np.eye(2), [[1.0, dt], [0.0, 1.0]])
        f.Q = Q_continuous_white_noise(2, dt, q, block_size=2)
        f.R = radar.noise_cov.copy()
        f.x, f.P = prior.mean[perm].copy(), prior.cov[np.ix_(perm, perm)].copy()
        filters.append(f)
    imm = IMMEstimator(filters, mu0.copy(), pi.copy())
    for k in range(n):
        if k:
            imm.predict()
        imm.update(z[k].copy())
        np.testing.assert_allclose(res.filtered.mean[k], imm.x[inv], rtol=1e-9, atol=1e-7)
        np.testing.assert_allclose(res.mode_probabilities[k], imm.mu, atol=1e-9)


@pytest.mark.statistical
@pytest.mark.crosscheck
def test_mixing_of_cv_and_ca_is_at_least_as_good_as_filterpy_with_a_padded_cv():
    """CV (2 states) + CA (3 states) against FilterPy's IMMEstimator, whose CV is padded to
    three states (acceleration held at zero), on identical parameters and measurements.

    Manoeuvring 1-D truths (three acceleration bursts of 5-15 s), 60 seeded runs. The test
    fails if our mean squared position error exceeds FilterPy's by more than 3 standard
    errors of the paired difference (false failure below 0.2 % if they were equal; measured:
    ours 0.2-0.4 % lower in RMSE on three seeds).
    """
    from filterpy.kalman import IMMEstimator, KalmanFilter

    rng = np.random.default_rng(27)
    dt, n, runs, r = 1.0, 150, 60, 100.0
    cv, ca = ConstantVelocity(0.05), ConstantAcceleration(1.0)
    pi, mu0 = np.array([[0.95, 0.05], [0.05, 0.95]]), np.array([0.5, 0.5])
    t = dt * np.arange(n)
    f_cv, q_cv = np.zeros((3, 3)), np.zeros((3, 3))
    f_cv[:2, :2], q_cv[:2, :2] = discretize(cv, dt)
    f_ca, q_ca = discretize(ca, dt)
    diff = []
    for _ in range(runs):
        acc = np.zeros(n)
        for s in rng.choice(n - 20, 3, replace=False):
            acc[s : s + rng.integers(5, 15)] = rng.normal(0, 4)
        x = np.cumsum(np.cumsum(acc) * dt + 50.0) * dt
        z = x + rng.normal(0, 10, n)
        p_cv = at.GaussianState([z[0], 50.0], np.diag([100.0, 400.0]), t[0])
        p_ca = at.GaussianState([z[0], 50.0, 0.0], np.diag([100.0, 400.0, 25.0]), t[0])
        ours = imm_filter(t, z[:, None], [cv, ca], ("x",), [[r]], [p_cv, p_ca], pi, mu0 @ pi)
        filters = []
        for f, q, p0 in ((f_cv, q_cv, [100.0, 400.0, 0.0]), (f_ca, q_ca, [100.0, 400.0, 25.0])):
            kf = KalmanFilter(dim_x=3, dim_z=1)
            kf.F, kf.Q, kf.H, kf.R = f, q, np.array([[1.0, 0.0, 0.0]]), np.array([[r]])
            kf.x, kf.P = np.array([z[0], 50.0, 0.0]), np.diag(p0)
            filters.append(kf)
        imm = IMMEstimator(filters, mu0.copy(), pi.copy())
        theirs = []
        for k in range(n):
            if k:
                imm.predict()
            imm.update(z[k : k + 1])
            theirs.append(imm.x[0])
        warm = slice(20, None)
        diff.append(
            np.mean((ours.filtered.mean[warm, 0] - x[warm]) ** 2)
            - np.mean((np.array(theirs)[warm] - x[warm]) ** 2)
        )
    diff = np.array(diff)
    assert diff.mean() < 3 * diff.std(ddof=1) / np.sqrt(runs)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_jittered_per_track_times_take_the_series_tables_with_the_same_result(rng, backend):
    """600 distinct step lengths (series tables) against each track alone (200 steps: one
    matrix exponential per step), CV + CA."""
    from adaptrack.filters.run import SERIES_MIN_STEPS

    n_tr, n_st = 3, 200
    t = np.cumsum(rng.uniform(0.05, 0.3, (n_tr, n_st)), axis=1)
    assert n_tr * n_st >= SERIES_MIN_STEPS > n_st
    z = rng.normal(size=(n_tr, n_st, 1)) * 2 + (5 * t + 0.3 * t**2)[..., None]
    models = [ConstantVelocity(accel_psd=2.0), ConstantAcceleration(jerk_psd=0.5)]
    priors = [at.GaussianState([0.0, 1.0], np.diag([100.0, 10.0]), 0.0),
              at.GaussianState([0.0, 1.0, 0.0], np.diag([100.0, 10.0, 4.0]), 0.0)]  # fmt: skip
    kw = dict(initial_probs=[0.5, 0.5], switching_rates=[[-0.2, 0.2], [0.3, -0.3]],
              form="joseph", backend=backend)  # fmt: skip
    whole = imm_filter(t, z, models, ("x",), [[4.0]], priors, **kw)
    for i in range(n_tr):
        alone = imm_filter(t[i], z[i], models, ("x",), [[4.0]], priors, **kw)
        np.testing.assert_allclose(whole.filtered.mean[i], alone.filtered.mean, rtol=1e-10,
                                   atol=1e-9)  # fmt: skip
        np.testing.assert_allclose(whole.filtered.cov[i], alone.filtered.cov, rtol=1e-9,
                                   atol=1e-10)  # fmt: skip


@pytest.mark.parametrize("form", ["joseph", "standard"])
@pytest.mark.parametrize("n_axes", [2, 3])
def test_compiled_imm_ekf_of_a_radar_equals_the_numpy_reference(rng, n_axes, form):
    """The kernel's radar geometry, Jacobian and wrapped innovation against the NumPy IMM-EKF,
    in both covariance forms: a moving radar, range-rate, missing components, per-track
    irregular times, a pass across the azimuth cut (due south of the radar)."""
    from adaptrack.models import RadarMeasurement

    comps = ("range", "azimuth") + (("elevation",) if n_axes == 3 else ()) + ("range_rate",)
    radar = RadarMeasurement(
        np.diag([25.0, 1e-6, 4e-6, 0.25][: len(comps) - 1] + [0.25]), comps, n_axes=n_axes,
        sensor_position=[50.0, -20.0, 10.0][:n_axes], sensor_velocity=[1.0, 2.0, 0.5][:n_axes],
        heading=0.3,
    )  # fmt: skip
    t = np.cumsum(rng.uniform(0.5, 1.5, (3, 80)), -1)
    x0, v = np.array([-400.0, -3000.0, 500.0][:n_axes]), np.array([12.0, 1.0, 0.5][:n_axes])
    truth = x0 + t[..., None] * v
    full = np.concatenate([truth, np.broadcast_to(v, truth.shape)], -1)
    z = radar.predict(full) + rng.normal(size=(3, 80, len(comps))) * np.sqrt(
        np.diag(radar.noise_cov)
    )
    mask = rng.uniform(size=z.shape) > 0.1
    k = n_axes
    models = [ConstantVelocity(0.5, n_axes=k), ConstantAcceleration(0.1, n_axes=k)]
    priors = [at.GaussianState(np.r_[x0, v] + 10, np.diag([400.0] * k + [100.0] * k), 0.0),
              at.GaussianState(np.r_[x0, v, np.zeros(k)] + 10,
                               np.diag([400.0] * k + [100.0] * k + [4.0] * k), 0.0)]  # fmt: skip
    kw = dict(initial_probs=[0.5, 0.5], switching_rates=[[-0.1, 0.1], [0.2, -0.2]], mask=mask,
              form=form)  # fmt: skip
    ref = imm_filter(t, z, models, radar, None, priors, backend="numpy", **kw)
    got = imm_filter(t, z, models, radar, None, priors, backend="numba", **kw)
    assert np.abs(np.diff(np.sign(ref.filtered.mean[..., 0]))).max() > 0  # crossed the cut
    np.testing.assert_allclose(got.filtered.mean, ref.filtered.mean, rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(got.filtered.cov, ref.filtered.cov, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(got.log_likelihood, ref.log_likelihood, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.mode_probabilities, ref.mode_probabilities, atol=1e-9)
    # a prediction on the radar's vertical axis: the reference's error, not a kernel status
    on_axis = at.GaussianState(np.r_[radar.sensor_position, np.zeros(k)], np.eye(2 * k), 0.0)
    with pytest.raises(ValueError, match="vertical axis"):
        imm_filter(t[0, :3], z[0, :3], models[:1], radar, None, [on_axis], initial_probs=[1.0],
                   switching_rates=[[0.0]], backend="numba")  # fmt: skip


def test_the_square_root_imm_mixes_without_a_second_qr():
    """The fuzz's case (47, 61913) (``R`` of condition 3e11, a Joseph ratio of 1e30, missing
    components), first track: the square-root IMM of two copies of its model is within 0.01
    posterior sigma of a 60-digit Kalman filter, as the square-root Kalman filter is (0.0065;
    measured 0.0071). Triangularising the mixed factor before the prediction's QR left it
    0.0275 off. With numpy 2.4.6 / scipy 1.17.1 the same code gives 0.0135 (the square-root
    KF still 0.0065; the IMM's own sensitivity to a 1e-15 change of the detections is 5e-4):
    the bound is 0.02, below the defect's 0.0275, until the library-dependent part is found."""
    from dataclasses import replace

    from tests.oracles.reference import kalman_mp
    from tests.stress.fuzz import Source, problem

    p = replace(problem(Source(np.random.default_rng((47, 61913)))), offset=None)
    names = list(p.model.state_names[: p.h.shape[0]])
    z = np.where(p.mask, p.z, np.nan)
    kf = at.kalman_filter(p.times, z, p.model, p.h, p.r, p.prior, mask=p.mask, form="sqrt")
    imm = imm_filter(p.times, z, [p.model, p.model], names, p.r, [p.prior, p.prior],
                     initial_probs=[0.5, 0.5], transition_probs=[[0.9, 0.1], [0.1, 0.9]],
                     mask=p.mask, form="sqrt", backend="numpy")  # fmt: skip
    prior_mean = np.broadcast_to(p.prior.mean, z.shape[:-1][:1] + p.prior.mean.shape[-1:])
    prior_cov = np.broadcast_to(p.prior.cov, z.shape[:-1][:1] + p.prior.cov.shape[-2:])
    mean, cov = kalman_mp(kf.transition[0], kf.process_cov[0], p.h, p.r, np.nan_to_num(z[0]),
                          prior_mean[0], prior_cov[0], dps=60, mask=p.mask[0])  # fmt: skip
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(kf.filtered.mean[0] - mean) / sigma) < 0.01
    assert np.max(np.abs(imm.filtered.mean[0] - mean) / sigma) < 0.02
