"""Error metrics."""

import numpy as np

from adaptrack.analysis.metrics import anees_band, nees, rmse


def test_nees_of_singular_covariance_is_infinite_off_its_range():
    cov = np.array([[[1.0, 0.0], [0.0, 0.0]], [[2.0, 0.0], [0.0, 4.0]]])
    err = np.array([[1.0, 1.0], [2.0, 2.0]])
    out = nees(err, cov)
    assert out[0] == np.inf and out[1] == 2.0 + 1.0
    assert nees([[2.0, 0.0]], [[[1.0, 0.0], [0.0, 0.0]]])[0] == 4.0


def test_rmse_and_anees_band():
    assert rmse([[3.0, 4.0], [0.0, 0.0]]) == np.sqrt(12.5)
    lo, hi = anees_band(2, 50)
    assert round(lo, 2) == 1.48 and round(hi, 2) == 2.59  # DOMAIN section 5


def test_pcrlb_equals_the_matched_kalman_filter_covariance():
    import adaptrack as at
    from adaptrack.analysis.bounds import pcrlb_linear
    from adaptrack.models import Singer

    model = Singer(time_constant_s=4.0, accel_std_mps2=2.0)
    t = np.cumsum(np.random.default_rng(0).uniform(0.05, 0.3, 50))
    p0 = np.diag([25.0, 4.0, 4.0])
    bound = pcrlb_linear(model, t, [[1.0, 0, 0]], [[1.0]], p0)
    kf = at.kalman_filter(
        t, np.zeros((50, 1)), model, [[1.0, 0, 0]], [[1.0]], at.GaussianState(np.zeros(3), p0, t[0])
    )
    np.testing.assert_allclose(bound, kf.filtered.cov, rtol=1e-12)
    # information form of the recursion (Tichavsky): J_k = (Q + F J^-1 F^T)^-1 + H^T R^-1 H
    phi, qd = at.discretize(model, t[1] - t[0])
    j1 = np.linalg.inv(qd + phi @ bound[0] @ phi.T) + np.diag([1.0, 0, 0])
    np.testing.assert_allclose(np.linalg.inv(j1), bound[1], rtol=1e-9)
