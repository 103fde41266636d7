"""EKF and UKF against FilterPy and Stone Soup on identical radar inputs (irregular steps).

The measurement functions of each library are its own (Stone Soup's radar models) or, for
FilterPy, which has none, our model's functions (checked against pymap3d and numerical
derivatives in tests/models/test_measurement.py): these tests check the recursions.
"""

import datetime

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

import adaptrack as at
from adaptrack.models import ConstantVelocity, RadarMeasurement
from adaptrack.types import GaussianState

pytestmark = pytest.mark.crosscheck

PERM_3D = [0, 3, 1, 4, 2, 5]  # ours (x, y, z, vx, vy, vz) -> FilterPy (x, vx, y, vy, z, vz)
PERM_2D = [0, 2, 1, 3]


def radar_problem(n_axes, seed, n_steps=50, south=True):
    rng = np.random.default_rng(seed)
    if n_axes == 3:
        radar = RadarMeasurement(
            noise_cov=np.diag([25.0, 1e-6, 4e-6, 0.25]),
            components=("range", "azimuth", "elevation", "range_rate"), n_axes=3,
            sensor_position=[50.0, -20.0, 10.0], heading=0.2,
        )  # fmt: skip
        truth0 = np.array([6000.0, 9000.0, 3000.0, -150.0, -60.0, 5.0])
    else:  # south: passes due south of the radar, azimuth crosses +-pi
        radar = RadarMeasurement(noise_cov=np.diag([4.0, 1e-6]))
        truth0 = np.array([-400.0, -3000.0, 12.0, 1.0] if south else [2500, 3000, -12, 8.0])
    t = np.cumsum(rng.uniform(0.3, 1.7, n_steps))
    half = truth0.size // 2
    truth = truth0[:half] + t[:, None] * truth0[half:]
    full = np.concatenate([truth, np.broadcast_to(truth0[half:], truth.shape)], -1)
    z = radar.predict(full) + rng.multivariate_normal(np.zeros(len(radar.names)),
                                                      radar.noise_cov, n_steps)  # fmt: skip
    prior = GaussianState(full[0] + 20.0, np.diag([400.0] * half + [100.0] * half), 0.0)
    return radar, t, z, prior


def full_jacobian(radar, x):
    jac = np.zeros((len(radar.names), x.size))
    jac[:, : len(radar.reads)] = radar.jacobian(x[: len(radar.reads)])
    return jac


def wrap(d, angular):
    d = np.array(d, dtype=float)
    d[angular] = (d[angular] + np.pi) % (2 * np.pi) - np.pi
    return d


@pytest.mark.parametrize(("n_axes", "seed"), [(3, 1), (3, 2), (2, 3)])
def test_ekf_equals_filterpy_extended_kalman_filter(n_axes, seed):
    radar, t, z, prior = radar_problem(n_axes, seed)
    q = 0.7
    perm = PERM_3D if n_axes == 3 else PERM_2D
    ours = at.ekf_filter(t, z, ConstantVelocity(q, n_axes=n_axes), radar, prior)
    ang = np.array(radar.angular)
    fp = ExtendedKalmanFilter(dim_x=2 * n_axes, dim_z=len(radar.names))
    fp.x = prior.mean[perm].copy()
    fp.P = prior.cov[np.ix_(perm, perm)].copy()
    fp.R = radar.noise_cov.copy()
    inv = np.argsort(perm)
    prev = 0.0
    for k in range(len(t)):
        dt = t[k] - prev
        prev = t[k]
        fp.F = np.kron(np.eye(n_axes), np.array([[1.0, dt], [0.0, 1.0]]))
        fp.Q = Q_continuous_white_noise(2, dt, q, block_size=n_axes)
        fp.predict()
        fp.update(
            z[k], lambda x: full_jacobian(radar, x[inv])[:, perm], lambda x: radar.predict(x[inv]),
            residual=lambda a, b: wrap(a - b, ang),
        )  # fmt: skip
        np.testing.assert_allclose(ours.filtered.mean[k], fp.x[inv], rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(ours.filtered.cov[k], fp.P[np.ix_(inv, inv)], rtol=1e-8,
                                   atol=1e-9 * np.abs(fp.P).max())  # fmt: skip


@pytest.mark.parametrize(("n_axes", "seed"), [(3, 4), (2, 5)])
def test_ukf_equals_filterpy_unscented_kalman_filter(n_axes, seed):
    """FilterPy's UKF with its sigma points redrawn after the prediction (as ours draws them).

    A Cholesky square root depends on the order of the state: FilterPy's interleaved order
    would give another (equally valid) sigma-point set, whose estimates differ from ours by
    about 1e-6 relative. Its square root is therefore taken in our order.
    """
    radar, t, z, prior = radar_problem(n_axes, seed)
    q = 0.7
    perm = PERM_3D if n_axes == 3 else PERM_2D
    inv = np.argsort(perm)
    ours = at.ukf_filter(t, z, ConstantVelocity(q, n_axes=n_axes), radar, prior)
    ang = np.array(radar.angular)

    def z_mean(sigmas, wm):
        m = wm @ sigmas
        m[ang] = np.arctan2(wm @ np.sin(sigmas[:, ang]), wm @ np.cos(sigmas[:, ang]))
        return m

    def fx(x, dt):
        return np.kron(np.eye(n_axes), np.array([[1.0, dt], [0.0, 1.0]])) @ x

    def sqrt_in_our_order(a):  # rows: the columns of our Cholesky factor, FilterPy's order
        return np.linalg.cholesky(a[np.ix_(inv, inv)])[perm, :].T

    points = MerweScaledSigmaPoints(2 * n_axes, alpha=1.0, beta=2.0, kappa=0.0,
                                    sqrt_method=sqrt_in_our_order)  # fmt: skip
    fp = UnscentedKalmanFilter(
        dim_x=2 * n_axes, dim_z=len(radar.names), dt=1.0, fx=fx,
        hx=lambda x: radar.predict(x[inv]), points=points, z_mean_fn=z_mean,
        residual_z=lambda a, b: wrap(a - b, ang),
    )  # fmt: skip
    fp.x = prior.mean[perm].copy()
    fp.P = prior.cov[np.ix_(perm, perm)].copy()
    fp.R = radar.noise_cov.copy()
    prev = 0.0
    for k in range(len(t)):
        dt = t[k] - prev
        prev = t[k]
        fp.Q = Q_continuous_white_noise(2, dt, q, block_size=n_axes)
        fp.predict(dt=dt)
        fp.sigmas_f = points.sigma_points(fp.x, fp.P)
        fp.update(z[k])
        np.testing.assert_allclose(ours.filtered.mean[k], fp.x[inv], rtol=1e-9, atol=1e-7)
        np.testing.assert_allclose(ours.filtered.cov[k], fp.P[np.ix_(inv, inv)], rtol=1e-7,
                                   atol=1e-9 * np.abs(fp.P).max())  # fmt: skip


def stonesoup_run(updater_kind, radar, t, z, prior, q):
    """Stone Soup on a planar range-bearing radar, its state in our order (E, N, vE, vN).

    Stone Soup's bearing is ``atan2(y, x)`` counter-clockwise from its x axis: mapping x to
    north and y to east makes it our azimuth (clockwise from north). The state keeps our
    order, so that the Cholesky square roots, hence the sigma points, are the same. Its EKF
    differentiates the radar function numerically with a step of ``1e8 * np.spacing(x)``,
    which is negative for a negative coordinate and then replaced by 1e-8 m: Jacobians off by
    about 1e-4 relative. The problem compared lies in the north-east quadrant (steps of
    5e-5 m).
    """
    from stonesoup.base import Property
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import LinearGaussianTransitionModel
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor, UnscentedKalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState as SSGaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater

    class PlanarCV(LinearGaussianTransitionModel):
        """Nearly constant velocity, state (x, y, vx, vy)."""

        psd: float = Property(doc="white acceleration PSD [m^2/s^3]")

        @property
        def ndim_state(self):
            return 4

        def matrix(self, time_interval, **kwargs):
            dt = time_interval.total_seconds()
            return np.block([[np.eye(2), dt * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])

        def covar(self, time_interval, **kwargs):
            dt = time_interval.total_seconds()
            return self.psd * np.kron([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]], np.eye(2))

    noise = np.diag([radar.noise_cov[1, 1], radar.noise_cov[0, 0]])  # (bearing, range)
    mm = CartesianToBearingRange(ndim_state=4, mapping=(1, 0), noise_covar=noise)
    motion = PlanarCV(psd=q)
    if updater_kind == "ekf":
        predictor, updater = ExtendedKalmanPredictor(motion), ExtendedKalmanUpdater(mm)
    else:
        predictor = UnscentedKalmanPredictor(motion, alpha=1.0, beta=2.0, kappa=0.0)
        updater = UnscentedKalmanUpdater(mm, alpha=1.0, beta=2.0, kappa=0.0)
    epoch = datetime.datetime(2026, 11, 27)
    state = SSGaussianState(prior.mean[:, None], prior.cov, timestamp=epoch)
    means, covs = [], []
    for k in range(len(t)):
        when = epoch + datetime.timedelta(seconds=float(t[k]))
        pred = predictor.predict(state, timestamp=when)
        det = Detection(np.array([[z[k, 1]], [z[k, 0]]]), timestamp=when, measurement_model=mm)
        state = updater.update(SingleHypothesis(pred, det))
        means.append(np.asarray(state.state_vector, dtype=float)[:, 0])
        covs.append(np.asarray(state.covar, dtype=float))
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_planar_filters_equal_stone_soup(kind):
    radar, t, z, prior = radar_problem(2, 6, n_steps=30, south=False)
    t = np.round(t, 6)  # Stone Soup's timestamps hold microseconds
    q = 0.7
    run = at.ekf_filter if kind == "ekf" else at.ukf_filter
    ours = run(t, z, ConstantVelocity(q, n_axes=2), radar, prior)
    means, covs = stonesoup_run(kind, radar, t, z, prior, q)
    np.testing.assert_allclose(ours.filtered.mean, means, rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(ours.filtered.cov, covs, rtol=1e-6, atol=1e-8 * np.abs(covs).max())
