"""Cross-check of the square-root filter against pykalman's Cholesky and Bierman (UD) filters."""

import numpy as np
import pytest
from pykalman.sqrt import BiermanKalmanFilter, CholeskyKalmanFilter

import adaptrack as at
from adaptrack.models import Singer

pytestmark = pytest.mark.crosscheck


@pytest.mark.parametrize("peer", [CholeskyKalmanFilter, BiermanKalmanFilter])
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_filter_equals_pykalmans_on_identical_inputs(peer, backend):
    rng = np.random.default_rng(7)
    model = Singer(time_constant_s=[5.0, 20.0], accel_std_mps2=[2.0, 0.3], n_axes=2)
    t = np.arange(60) * 0.5
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    u, _ = np.linalg.qr(rng.normal(size=(2, 2)))
    r = (u * [1e-3, 1e3]) @ u.T  # condition number 1e6
    r = 0.5 * (r + r.T)
    z = np.column_stack([0.5 * t**2, 30.0 * t]) + rng.normal(size=(60, 2))
    p0 = np.diag([1e6, 1e6, 1e2, 1e2, 1.0, 1.0])
    prior = at.GaussianState(np.zeros(6), p0, 0.0)
    ours = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend=backend)
    step = at.discretize(model, 0.5)
    kf = peer(
        transition_matrices=step.transition,
        observation_matrices=h,
        transition_covariance=step.process_cov,
        observation_covariance=r,
        initial_state_mean=np.zeros(6),
        initial_state_covariance=p0,
    )
    means, covs = kf.filter(z)
    sigma = np.sqrt(np.diagonal(covs, axis1=-2, axis2=-1))
    assert np.max(np.abs(ours.filtered.mean - means) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(ours.filtered.cov - covs) / scale) < 1e-8
