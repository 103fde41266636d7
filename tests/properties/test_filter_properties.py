"""Property tests of the Kalman filter and smoother (Hypothesis)."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

import adaptrack as at
from adaptrack.models import Singer


@st.composite
def problems(draw):
    n_tracks = draw(st.integers(1, 4))
    n_steps = draw(st.integers(1, 25))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    times = np.cumsum(rng.uniform(1e-3, 5.0, (n_tracks, n_steps)), axis=1)
    z = rng.normal(size=(n_tracks, n_steps, 2)) * draw(st.floats(0.1, 1e3))
    mask = rng.uniform(size=(n_tracks, n_steps, 2)) > draw(st.floats(0.0, 0.6))
    model = Singer(
        time_constant_s=draw(st.floats(0.1, 50.0)), accel_std_mps2=draw(st.floats(0.01, 30.0))
    )
    r = np.diag(rng.uniform(0.01, 100.0, 2))
    return times, z, mask, model, r


H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@given(problems())
def test_covariances_symmetric_psd_and_batch_equals_loop(problem):
    times, z, mask, model, r = problem
    prior = at.GaussianState(np.zeros(3), np.diag([1e4, 1e2, 10.0]), times[:, 0].min())
    res = at.kalman_filter(times, z, model, H, r, prior, mask=mask)
    sm = at.rts_smooth(res)
    for cov in (res.predicted.cov, res.filtered.cov, sm.cov):
        np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))
        eig = np.linalg.eigvalsh(cov)
        assert np.all(eig >= -1e-9 * np.abs(cov).max(axis=(-2, -1))[..., None])
    for i in range(times.shape[0]):
        one = at.kalman_filter(times[i], z[i], model, H, r, prior, mask=mask[i])
        scale = np.abs(one.filtered.mean).max() + 1.0
        np.testing.assert_allclose(
            res.filtered.mean[i], one.filtered.mean, rtol=1e-9, atol=1e-9 * scale
        )
