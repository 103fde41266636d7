"""Cross-checks against FilterPy's KalmanFilter and rts_smoother on randomised problems."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, rts_smoother

import adaptrack as at
from adaptrack.models import ConstantVelocity, InverseDynamics, ShapingFilter, Singer, discretize

pytestmark = pytest.mark.crosscheck


def random_model(rng, i):
    choice = i % 4
    n_axes = int(rng.integers(1, 4))
    if choice == 0:
        return Singer(
            time_constant_s=rng.uniform(0.5, 30, n_axes),
            accel_std_mps2=rng.uniform(0.1, 5, n_axes),
            n_axes=n_axes,
        )
    if choice == 1:
        return ConstantVelocity(accel_psd=rng.uniform(0.01, 10, n_axes), n_axes=n_axes)
    if choice == 2:
        return InverseDynamics(
            lambda_per_s2=rng.uniform(0, 1, n_axes),
            accel_psd=rng.uniform(0.1, 5, n_axes),
            n_axes=n_axes,
        )
    return ShapingFilter(
        lambda_per_s2=rng.uniform(0.001, 1, n_axes),
        alpha_per_s=rng.uniform(0.05, 2, n_axes),
        shaping_std=rng.uniform(0.1, 5, n_axes),
        n_axes=n_axes,
    )


def relative(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


@pytest.mark.parametrize("case", range(12))
def test_kalman_filter_and_rts_match_filterpy(case):
    rng = np.random.default_rng(1000 + case)
    model = random_model(rng, case)
    n = model.state_dim
    m = int(rng.integers(1, n + 1))
    h = rng.normal(size=(m, n))
    a = rng.normal(size=(m, m))
    r = a @ a.T + m * np.eye(m)
    n_steps = 40
    t = np.cumsum(rng.uniform(0.01, 2.0, n_steps))
    z = rng.normal(size=(n_steps, m)) * 5
    b = rng.normal(size=(n, n))
    p0 = b @ b.T + np.eye(n)
    x0 = rng.normal(size=n)
    res = at.kalman_filter(t, z, model, h, r, at.GaussianState(x0, p0, t[0]))
    sm = at.rts_smooth(res)

    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P, kf.H, kf.R = x0.copy(), p0.copy(), h.copy(), r.copy()
    fx, fp, ll, fs, qs = [], [], [], [], []
    for k in range(n_steps):
        dt = 0.0 if k == 0 else t[k] - t[k - 1]
        phi, qd = discretize(model, dt)
        kf.F, kf.Q = phi, qd
        if k > 0:
            kf.predict()
        kf.update(z[k].copy())
        fx.append(kf.x.copy())
        fp.append(kf.P.copy())
        ll.append(kf.log_likelihood)
        fs.append(phi)
        qs.append(qd)
    fx, fp = np.array(fx), np.array(fp)
    assert relative(res.filtered.mean, fx) <= 1e-9
    assert relative(res.filtered.cov, fp) <= 1e-9
    assert relative(res.info.log_likelihood, np.array(ll)) <= 1e-9
    # FilterPy's rts_smoother uses Fs[k+1] for the step k -> k+1 through Fs[k]; pass shifted
    xs, ps, _, _ = rts_smoother(fx, fp, np.array(fs[1:] + [fs[-1]]), np.array(qs[1:] + [qs[-1]]))
    assert relative(sm.mean, xs) <= 1e-9
    assert relative(sm.cov, ps) <= 1e-9


def test_a_filterpy_layout_converts_with_filterpy_order():
    """A problem set up the FilterPy way (its own CV model, x vx y vy) gives adaptrack's answer.

    FilterPy's ``Q_discrete_white_noise(block_size=2)`` and its F are built by FilterPy, not
    by adaptrack; converted with ``filterpy_order``, adaptrack's filter on its own model
    reproduces FilterPy's estimates. The FilterPy-ordered H given as is measures the wrong
    components: names (``["x", "y"]``) say what is meant.
    """
    from filterpy.common import Q_discrete_white_noise

    from adaptrack.models import filterpy_order, measurement_matrix

    rng = np.random.default_rng(7)
    dt, q, n_steps = 0.5, 0.3, 60
    truth = np.cumsum(np.full((n_steps, 2), [3.0, -1.0]) * dt, axis=0) + [100.0, 50.0]
    z = truth + rng.normal(0.0, 2.0, size=truth.shape)
    r = 4.0 * np.eye(2)
    kf = KalmanFilter(dim_x=4, dim_z=2)  # FilterPy's layout: x, vx, y, vy
    kf.F = np.kron(np.eye(2), [[1.0, dt], [0.0, 1.0]])
    kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=q / dt, block_size=2)  # variance q / dt
    kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    kf.R = r
    x0, p0 = np.array([z[0, 0], 0.0, z[0, 1], 0.0]), np.diag([4.0, 100.0, 4.0, 100.0])
    kf.x, kf.P = x0.copy(), p0.copy()
    fx = []
    for k in range(n_steps):
        if k:
            kf.predict()
        kf.update(z[k])
        fx.append(kf.x.copy())
    fx = np.array(fx)

    model = ConstantVelocity(accel_psd=q, n_axes=2)
    p = filterpy_order(model)
    np.testing.assert_allclose(at.discretize(model, dt)[0], kf.F[np.ix_(p, p)])
    t = dt * np.arange(n_steps)
    prior = at.GaussianState(x0[p], p0[np.ix_(p, p)], t[0])
    h = kf.H[:, p]
    np.testing.assert_array_equal(h, measurement_matrix(model, ["x", "y"]))
    ours = at.kalman_filter(t, z, model, ["x", "y"], r, prior).filtered.mean
    # FilterPy's Q is the piecewise-constant acceleration's (adaptrack's noise="piecewise")
    same = at.kalman_filter(t, z, model, h, r, prior, noise="piecewise").filtered.mean
    np.testing.assert_allclose(same, fx[:, p], rtol=1e-9, atol=1e-9)
    right_rmse = np.sqrt(np.mean((ours[:, :2] - truth) ** 2))
    assert right_rmse < 2.0  # (noise sigma 2 m) the exact-white-noise model tracks too
    wrong = at.kalman_filter(t, z, model, kf.H, r, prior).filtered.mean  # FilterPy's H as is
    assert np.sqrt(np.mean((wrong[:, :2] - truth) ** 2)) > 5.0 * right_rmse


def test_unknown_component_names_are_refused():
    from adaptrack.models import measurement_matrix

    model = ConstantVelocity(n_axes=2)
    with pytest.raises(ValueError, match=r"unknown state component\(s\) \['vz'\]; "
                       r"ConstantVelocity has \['x', 'y', 'vx', 'vy'\]"):  # fmt: skip
        measurement_matrix(model, ["x", "vz"])
    t = np.arange(3.0)
    prior = at.GaussianState(np.zeros(4), np.eye(4), 0.0)
    with pytest.raises(ValueError, match="unknown state component"):
        at.kalman_filter(t, np.zeros((3, 1)), model, ["z"], [[1.0]], prior)
    f = at.OnlineFilter(model, ["x", "y"], np.eye(2), prior)
    assert f.update(1.0, [1.0, 2.0]) >= 0.0
