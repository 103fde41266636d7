"""EKF and UKF with the coordinated-turn model against Stone Soup's ``ConstantTurn``.

Stone Soup's state order is (x, vx, y, vy, omega), ours (x, y, vx, vy, omega). Its EKF
differentiates the transition numerically, with one-sided steps: its Jacobian is about 1e-6
relative from our analytic one (which tests/models/test_turn.py checks by central
differences). The EKF recursions are compared with Stone Soup given our Jacobian, and its own
Jacobian against ours at the differencing's accuracy.
"""

import datetime

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import CoordinatedTurn, PositionMeasurement
from adaptrack.types import GaussianState

pytestmark = pytest.mark.crosscheck

ORDER = [0, 2, 1, 3, 4]  # ours -> Stone Soup
EPOCH = datetime.datetime(2026, 11, 27)


def stone_soup_models(ct, r, analytic=False):
    """Stone Soup's ConstantTurn (with our Jacobian if ``analytic``) and a position sensor."""
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.nonlinear import ConstantTurn

    class AnalyticTurn(ConstantTurn):
        def jacobian(self, state, **kwargs):
            x = np.asarray(state.state_vector, float)[:, 0][np.argsort(ORDER)]
            dt = kwargs["time_interval"].total_seconds()
            return ct.propagate(x, np.array(dt))[1][np.ix_(ORDER, ORDER)]

    kind = AnalyticTurn if analytic else ConstantTurn
    motion = kind(linear_noise_coeffs=np.array([ct.accel_psd] * 2), turn_noise_coeff=ct.turn_psd)
    return motion, LinearGaussian(ndim_state=5, mapping=(0, 2), noise_covar=r)


def test_ekf_equals_stone_soup_extended_kalman_filter():
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState as SSGaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    rng = np.random.default_rng(3)
    t = np.round(np.cumsum(rng.uniform(0.4, 1.6, 40)), 6)  # Stone Soup holds microseconds
    turn = np.deg2rad(4.0)
    z = np.c_[5000.0 + 900 * np.sin(turn * t), 6000.0 + 900 * (1 - np.cos(turn * t))]
    z = z + rng.normal(size=z.shape) * 4.0
    r = 16.0 * np.eye(2)
    ct = CoordinatedTurn(accel_psd=0.3, turn_psd=1e-5)
    prior = GaussianState([5000.0, 6000.0, 60.0, 5.0, 0.05], np.diag([50, 50, 25, 25, 1e-3]), 0.0)
    ours = at.ekf_filter(t, z, ct, PositionMeasurement(r), prior)

    motion, mm = stone_soup_models(ct, r, analytic=True)
    predictor, updater = ExtendedKalmanPredictor(motion), ExtendedKalmanUpdater(mm)
    state = SSGaussianState(prior.mean[ORDER, None], prior.cov[np.ix_(ORDER, ORDER)], EPOCH)
    for k in range(t.size):
        when = EPOCH + datetime.timedelta(seconds=float(t[k]))
        pred = predictor.predict(state, timestamp=when)
        state = updater.update(SingleHypothesis(pred, Detection(z[k, :, None], when, mm)))
        mean = np.asarray(state.state_vector, float)[:, 0]
        np.testing.assert_allclose(ours.filtered.mean[k, ORDER], mean, rtol=1e-10, atol=1e-8)
        cov = np.asarray(state.covar, float)
        np.testing.assert_allclose(
            ours.filtered.cov[k][np.ix_(ORDER, ORDER)], cov, rtol=1e-8, atol=1e-12
        )
    numeric, _ = stone_soup_models(ct, r)
    jac = numeric.jacobian(state, time_interval=datetime.timedelta(seconds=0.8))
    mine = ct.propagate(np.asarray(state.state_vector, float)[np.argsort(ORDER), 0], 0.8)[1]
    np.testing.assert_allclose(
        mine[np.ix_(ORDER, ORDER)], jac, rtol=0, atol=1e-5 * np.abs(jac).max()
    )


def test_ukf_prediction_equals_stone_soup_unscented_predictor():
    """One prediction from a diagonal prior (whose Cholesky factor does not depend on the
    state order, so both libraries draw the same sigma points)."""
    from stonesoup.predictor.kalman import UnscentedKalmanPredictor
    from stonesoup.types.state import GaussianState as SSGaussianState

    ct = CoordinatedTurn(accel_psd=0.3, turn_psd=1e-4)
    prior = GaussianState(
        [5000.0, 6000.0, 60.0, -25.0, 0.1], np.diag([400, 300, 100, 80, 0.01]), 0.0
    )
    ours, _, _ = at.filters.ukf.ukf_predict_step(prior, ct, np.array(3.0), np.array(3.0))
    motion, _ = stone_soup_models(ct, np.eye(2))
    predictor = UnscentedKalmanPredictor(motion, alpha=1.0, beta=2.0, kappa=0.0)
    state = SSGaussianState(prior.mean[ORDER, None], prior.cov[np.ix_(ORDER, ORDER)], EPOCH)
    pred = predictor.predict(state, timestamp=EPOCH + datetime.timedelta(seconds=3))
    np.testing.assert_allclose(
        ours.mean[ORDER], np.asarray(pred.state_vector, float)[:, 0], rtol=1e-12
    )
    np.testing.assert_allclose(ours.cov[np.ix_(ORDER, ORDER)], np.asarray(pred.covar, float),
                               rtol=1e-10, atol=1e-12)  # fmt: skip
