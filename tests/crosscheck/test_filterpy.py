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
