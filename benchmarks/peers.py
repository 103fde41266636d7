"""The same filter (3-state Singer, position measured) in adaptrack and in every peer library.

Each function takes shared times ``t`` (T,) and measurements ``z`` (N, T, 1) and returns the
filtered (or smoothed) means (N, T, 3), so results can be compared before timings are trusted.
"""

from __future__ import annotations

import numpy as np

import adaptrack as at
from adaptrack.smoothers.rts import SmootherForm

DT = 0.05
MODEL = at.models.Singer(time_constant_s=5.0, accel_std_mps2=2.0)
H = np.array([[1.0, 0.0, 0.0]])
R = np.array([[0.25]])
P0 = np.diag([1.0, 100.0, 10.0])


def data(n_tracks: int, n_steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Shared times (T,) and simulated position measurements (N, T, 1)."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(n_steps)
    truth = at.simulation.simulate_linear_trajectory(
        MODEL, t, [0.0, 10.0, 0.0], P0, n_runs=n_tracks, rng=rng
    )
    z = at.simulation.simulate_linear_measurements(truth, H, R, rng=rng)
    return t, z


def _prior(t: np.ndarray, n_tracks: int | None = None) -> at.GaussianState:
    if n_tracks is None:
        return at.GaussianState(np.zeros(3), P0, t[0])
    return at.GaussianState(np.zeros((n_tracks, 3)), np.broadcast_to(P0, (n_tracks, 3, 3)), t[0])


def adaptrack_filter(t: np.ndarray, z: np.ndarray, backend: str = "auto") -> np.ndarray:
    """``kalman_filter`` with its full result (per-step covariances, gains, innovations)."""
    return at.kalman_filter(t, z, MODEL, H, R, _prior(t), backend=backend).filtered.mean


def adaptrack_per_track_cov(
    t: np.ndarray, z: np.ndarray, backend: str = "auto", form: str = "auto"
) -> np.ndarray:
    """``kalman_filter``'s general path: every track carries its own covariance recursion.

    ``t`` (T,) shared or (N, T) per track (the prior at the earliest time).
    """
    prior = _prior(np.atleast_1d(t.min(axis=0)) if t.ndim > 1 else t, z.shape[0])
    return at.kalman_filter(t, z, MODEL, H, R, prior, backend=backend, form=form).filtered.mean


def adaptrack_fleet(
    t: np.ndarray, z: np.ndarray, out: np.ndarray | None = None, smooth: bool = False
) -> np.ndarray:
    """``shared_gain_filter``: means per track, covariances once, optional output buffer."""
    return at.shared_gain_filter(t, z, MODEL, H, R, _prior(t), out=out, smooth=smooth).mean


def adaptrack_rts(t: np.ndarray, z: np.ndarray, form: SmootherForm = "auto") -> np.ndarray:
    """``kalman_filter`` then ``rts_smooth`` in ``form`` (full results)."""
    return at.rts_smooth(at.kalman_filter(t, z, MODEL, H, R, _prior(t)), form=form).mean


def _filterpy_means(make, z: np.ndarray, dim: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Means (N, T, dim) of a FilterPy filter ``make()`` run on every track in turn."""
    out = np.empty(z.shape[:-1] + (dim,))
    for i in range(z.shape[0]):
        f = make()
        for k in range(z.shape[1]):
            if k:
                f.predict()
            f.update(z[i, k])
            out[i, k] = f.x
    return out


def filterpy_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from filterpy.kalman import KalmanFilter

    phi, qd = at.discretize(MODEL, DT)

    def make() -> KalmanFilter:
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = np.zeros(3), P0.copy(), phi, qd, H, R
        return kf

    return _filterpy_means(make, z, 3)


def filterpy_jittered(times: np.ndarray, z: np.ndarray, t0: float) -> np.ndarray:
    """FilterPy per track on its own times (N, T) from a prior at ``t0``: each step's Phi and
    Q by Van Loan."""
    from filterpy.kalman import KalmanFilter
    from scipy.linalg import expm

    blocks, _ = MODEL.blocks()
    f = blocks[0].drift
    w = blocks[0].noise_input @ blocks[0].noise_psd @ blocks[0].noise_input.T
    out = np.zeros(z.shape[:2] + (3,))
    for i in range(z.shape[0]):
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.x, kf.P, kf.H, kf.R = np.zeros(3), P0.copy(), H, R
        prev = t0
        for k in range(z.shape[1]):
            dt = times[i, k] - prev
            prev = times[i, k]
            vl = expm(np.block([[-f, w], [np.zeros((3, 3)), f.T]]) * dt)
            kf.F = vl[3:, 3:].T
            kf.Q = kf.F @ vl[:3, 3:]
            kf.predict()
            kf.update(z[i, k])
            out[i, k] = kf.x
    return out


def filterpy_rts(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from filterpy.kalman import rts_smoother

    phi, qd = at.discretize(MODEL, DT)
    res = at.kalman_filter(t, z[0], MODEL, H, R, _prior(t))
    n = t.size
    fs, qs = np.broadcast_to(phi, (n, 3, 3)), np.broadcast_to(qd, (n, 3, 3))
    return rts_smoother(res.filtered.mean, res.filtered.cov, fs, qs)[0][None]


def pykalman_filter(t: np.ndarray, z: np.ndarray, square_root: bool = False) -> np.ndarray:
    """pykalman's ``KalmanFilter`` (or its ``CholeskyKalmanFilter``), one track at a time."""
    from pykalman import KalmanFilter
    from pykalman.sqrt import CholeskyKalmanFilter

    phi, qd = at.discretize(MODEL, DT)
    out = np.empty(z.shape[:-1] + (3,))
    for i in range(z.shape[0]):
        kf = (CholeskyKalmanFilter if square_root else KalmanFilter)(
            transition_matrices=phi,
            observation_matrices=H,
            transition_covariance=qd,
            observation_covariance=R,
            initial_state_mean=np.zeros(3),
            initial_state_covariance=P0,
        )
        out[i] = kf.filter(z[i])[0]
    return out


def _simdkalman(smoothed: bool):  # type: ignore[no-untyped-def]
    import simdkalman

    phi, qd = at.discretize(MODEL, DT)
    kf = simdkalman.KalmanFilter(
        state_transition=phi, process_noise=qd, observation_model=H, observation_noise=R
    )

    def run(t: np.ndarray, z: np.ndarray) -> np.ndarray:
        res = kf.compute(
            z[..., 0],
            0,
            initial_value=np.zeros(3),
            initial_covariance=P0,
            filtered=not smoothed,
            smoothed=smoothed,
            covariances=False,
            observations=False,
        )
        return (res.smoothed if smoothed else res.filtered).states.mean

    return run


def simdkalman_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    return _simdkalman(smoothed=False)(t, z)  # type: ignore[no-any-return]


def simdkalman_smoother(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    return _simdkalman(smoothed=True)(t, z)  # type: ignore[no-any-return]


def stonesoup_filter(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from datetime import datetime, timedelta

    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    phi, qd = at.discretize(MODEL, DT)
    transition = LinearGaussianTimeInvariantTransitionModel(
        transition_matrix=phi, covariance_matrix=qd
    )
    measurement = LinearGaussian(ndim_state=3, mapping=(0,), noise_covar=R)
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    start = datetime(2026, 1, 1)
    out = np.empty(z.shape[:-1] + (3,))
    for i in range(z.shape[0]):
        state = GaussianState(np.zeros((3, 1)), P0, timestamp=start)
        for k in range(z.shape[1]):
            when = start + timedelta(seconds=float(t[k] - t[0]))
            prediction = predictor.predict(state, timestamp=when) if k else state
            det = Detection(z[i, k].reshape(1, 1), timestamp=when, measurement_model=measurement)
            state = updater.update(SingleHypothesis(prediction, det))
            out[i, k] = np.asarray(state.state_vector).ravel()
    return out


def stream_adaptrack(t: np.ndarray, z: np.ndarray, form: str = "auto") -> np.ndarray:
    """``OnlineFilter.update`` once per measurement, from Python."""
    f = at.OnlineFilter(MODEL, H, R, _prior(t), form=form)  # type: ignore[arg-type]
    out = np.empty((1, t.size, 3))
    times = t.tolist()
    meas = list(z[0])
    update = f.update
    for k in range(t.size):
        update(times[k], meas[k])
    out[0, -1] = f.mean
    return out


def adaptrack_update_many(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``OnlineFilter.update_many`` per track: means, variances and NIS per step."""
    out = np.empty(z.shape[:-1] + (3,))
    for i in range(z.shape[0]):
        out[i] = at.OnlineFilter(MODEL, H, R, _prior(t)).update_many(t, z[i]).mean
    return out


def stream_filterpy(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from filterpy.kalman import KalmanFilter

    phi, qd = at.discretize(MODEL, DT)
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = np.zeros(3), P0.copy(), phi, qd, H, R
    meas = list(z[0])
    for k in range(t.size):
        if k:
            kf.predict()
        kf.update(meas[k])
    out = np.empty((1, t.size, 3))
    out[0, -1] = kf.x
    return out


def stream_pykalman(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    from pykalman import KalmanFilter

    phi, qd = at.discretize(MODEL, DT)
    kf = KalmanFilter(
        transition_matrices=phi,
        observation_matrices=H,
        transition_covariance=qd,
        observation_covariance=R,
    )
    # pykalman's online step predicts first: start from the prior predicted back one step
    mean, cov = (
        np.linalg.solve(phi, np.zeros(3)),
        np.linalg.solve(phi, np.linalg.solve(phi, (P0 - qd).T).T),
    )
    for k in range(t.size):
        mean, cov = kf.filter_update(mean, cov, z[0, k])
    out = np.empty((1, t.size, 3))
    out[0, -1] = mean
    return out


# IMM: two constant-velocity modes (quiet, manoeuvring) on the same measurements; the prior
# mode probabilities are FilterPy's ``mu0 @ pi`` (its first update weighs by them).
IMM_MODELS = (
    at.models.ConstantVelocity(accel_psd=0.05),
    at.models.ConstantVelocity(accel_psd=50.0),
)
IMM_PI = np.array([[0.97, 0.03], [0.05, 0.95]])
IMM_MU0 = np.array([0.6, 0.4])
IMM_P0 = np.diag([1.0, 100.0])


def adaptrack_imm(t: np.ndarray, z: np.ndarray, form: str = "auto") -> np.ndarray:
    """``imm_filter`` over the batch; combined means (N, T, 2)."""
    from adaptrack.filters.imm import imm_filter

    priors = [at.GaussianState(np.zeros(2), IMM_P0, t[0])] * 2
    res = imm_filter(
        t,
        z,
        IMM_MODELS,
        ("x",),
        R,
        priors,
        IMM_PI,
        IMM_MU0 @ IMM_PI,
        form=form,  # type: ignore[arg-type]
    )
    return res.filtered.mean


def filterpy_imm(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """FilterPy's ``IMMEstimator``, one track at a time."""
    from filterpy.kalman import IMMEstimator, KalmanFilter

    def make() -> IMMEstimator:
        filters = []
        for model in IMM_MODELS:
            kf = KalmanFilter(dim_x=2, dim_z=1)
            kf.F, kf.Q = at.discretize(model, DT)
            kf.H, kf.R, kf.x, kf.P = np.array([[1.0, 0.0]]), R, np.zeros(2), IMM_P0.copy()
            filters.append(kf)
        return IMMEstimator(filters, IMM_MU0.copy(), IMM_PI.copy())

    return _filterpy_means(make, z, 2)


RADAR_Q = 0.5  # white acceleration PSD of the radar workload's CV model [m^2/s^3]
RADAR = at.models.RadarMeasurement(
    np.diag([25.0, 1e-6, 1e-6, 0.25]), ("range", "azimuth", "elevation", "range_rate"), n_axes=3
)
RADAR_P0 = np.diag([400.0, 400.0, 400.0, 400.0, 400.0, 100.0])


def radar_data(n_tracks: int, n_steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """1 s scans of straight-flying targets 5-20 km out: plots (N, T, 4) with noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_steps, dtype=float)
    p0 = rng.uniform([-20e3, 5e3, 500.0], [20e3, 20e3, 3000.0], (n_tracks, 3))
    v0 = rng.uniform([-150.0, -150.0, -2.0], [150.0, 150.0, 2.0], (n_tracks, 3))
    pos = p0[:, None] + v0[:, None] * t[None, :, None]
    states = np.concatenate([pos, np.broadcast_to(v0[:, None], pos.shape)], -1)
    noise = rng.multivariate_normal(np.zeros(4), RADAR.noise_cov, (n_tracks, n_steps))
    return t, RADAR.predict(states) + noise


def _radar_prior(z0: np.ndarray) -> np.ndarray:
    """Prior means (N, 6) at the first plots (velocity 0)."""
    r, az, el = z0[..., 0], z0[..., 1], z0[..., 2]
    pos = r[..., None] * np.stack(
        [np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1
    )
    return np.concatenate([pos, np.zeros_like(pos)], -1)


def adaptrack_radar_ekf(t: np.ndarray, z: np.ndarray, backend: str = "auto") -> np.ndarray:
    """``ekf_filter`` over every track at once; means (N, T, 6)."""
    n = z.shape[0]
    prior = at.GaussianState(_radar_prior(z[:, 0]), np.broadcast_to(RADAR_P0, (n, 6, 6)), t[0])
    model = at.models.ConstantVelocity(RADAR_Q, n_axes=3)
    return at.ekf_filter(t, z, model, RADAR, prior, backend=backend).filtered.mean  # type: ignore[arg-type]


def _filterpy_radar_layout(dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """FilterPy's state order of ours (``perm``) and back (``inv``), and the CV transition and
    process noise over ``dt`` [s] in FilterPy's order (x, vx, y, vy, z, vz)."""
    from filterpy.common import Q_continuous_white_noise

    perm = np.array([0, 3, 1, 4, 2, 5])
    f = np.kron(np.eye(3), [[1.0, dt], [0.0, 1.0]])
    return perm, np.argsort(perm), f, Q_continuous_white_noise(2, dt, RADAR_Q, block_size=3)


def _radar_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` of radar plots, azimuth and elevation wrapped to [-pi, pi)."""
    d = a - b
    d[1:3] = (d[1:3] + np.pi) % (2 * np.pi) - np.pi
    return d


def filterpy_radar_ekf(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """FilterPy's ``ExtendedKalmanFilter``, one track at a time; means (N, T, 6) in our order."""
    from filterpy.kalman import ExtendedKalmanFilter

    perm, inv, f, q = _filterpy_radar_layout(float(t[1] - t[0]))

    out = np.empty(z.shape[:-1] + (6,))
    x0 = _radar_prior(z[:, 0])
    for i in range(z.shape[0]):
        ekf = ExtendedKalmanFilter(dim_x=6, dim_z=4)
        ekf.x, ekf.P, ekf.F, ekf.Q, ekf.R = (
            x0[i][perm],
            RADAR_P0[np.ix_(perm, perm)],
            f,
            q,
            RADAR.noise_cov,
        )
        for k in range(z.shape[1]):
            if k:
                ekf.predict()
            ekf.update(z[i, k], lambda x: RADAR.jacobian(x[inv])[:, perm],
                       lambda x: RADAR.predict(x[inv]), residual=_radar_residual)  # fmt: skip
            out[i, k] = ekf.x[inv]
    return out


def adaptrack_radar_ukf(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``ukf_filter`` over every track at once; means (N, T, 6)."""
    n = z.shape[0]
    prior = at.GaussianState(_radar_prior(z[:, 0]), np.broadcast_to(RADAR_P0, (n, 6, 6)), t[0])
    model = at.models.ConstantVelocity(RADAR_Q, n_axes=3)
    return at.ukf_filter(t, z, model, RADAR, prior).filtered.mean


def filterpy_radar_ukf(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """FilterPy's ``UnscentedKalmanFilter`` (Van der Merwe's points, alpha 1, beta 2, kappa
    0, as ours), one track at a time; means (N, T, 6) in our order."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    dt = float(t[1] - t[0])
    perm, inv, f, q = _filterpy_radar_layout(dt)

    out = np.empty(z.shape[:-1] + (6,))
    x0 = _radar_prior(z[:, 0])
    points = MerweScaledSigmaPoints(6, alpha=1.0, beta=2.0, kappa=0.0)
    for i in range(z.shape[0]):
        ukf = UnscentedKalmanFilter(
            6, 4, dt, hx=lambda x: RADAR.predict(x[inv]), fx=lambda x, dt: f @ x, points=points,
            residual_z=_radar_residual,
        )  # fmt: skip
        ukf.x, ukf.P, ukf.R = x0[i][perm], RADAR_P0[np.ix_(perm, perm)], RADAR.noise_cov
        ukf.Q = np.zeros((6, 6))  # FilterPy draws its sigma points in predict: the prior's own
        ukf.predict(fx=lambda x, dt: x)
        ukf.Q = q
        for k in range(z.shape[1]):
            if k:
                ukf.predict()
            ukf.update(z[i, k])
            out[i, k] = ukf.x[inv]
    return out


RADAR_IMM_Q = (0.1, 30.0)  # white acceleration PSDs of the quiet and agile CV modes [m^2/s^3]
RADAR_IMM_PI = np.array([[0.95, 0.05], [0.1, 0.9]])
RADAR_IMM_MU0 = np.array([0.8, 0.2])


def adaptrack_radar_imm(t: np.ndarray, z: np.ndarray, backend: str = "auto") -> np.ndarray:
    """``imm_filter`` of two radar EKFs over every track at once; combined means (N, T, 6)."""
    from adaptrack.filters.imm import imm_filter

    n = z.shape[0]
    prior = at.GaussianState(_radar_prior(z[:, 0]), np.broadcast_to(RADAR_P0, (n, 6, 6)), t[0])
    models = [at.models.ConstantVelocity(q, n_axes=3) for q in RADAR_IMM_Q]
    # FilterPy weighs its first update with mu0 @ pi (its IMMEstimator's cbar): the same here
    return imm_filter(t, z, models, RADAR, None, [prior, prior], RADAR_IMM_PI,
                      RADAR_IMM_MU0 @ RADAR_IMM_PI, backend=backend).filtered.mean  # fmt: skip


def filterpy_radar_imm(t: np.ndarray, z: np.ndarray) -> np.ndarray:
    """FilterPy's ``IMMEstimator`` of two ``ExtendedKalmanFilter``, one track at a time."""
    from filterpy.common import Q_continuous_white_noise
    from filterpy.kalman import ExtendedKalmanFilter, IMMEstimator

    perm = np.array([0, 3, 1, 4, 2, 5])  # FilterPy (x, vx, y, vy, z, vz) of ours
    inv = np.argsort(perm)
    dt = float(t[1] - t[0])

    class RadarEKF(ExtendedKalmanFilter):
        def predict(self, u: object = None) -> None:  # IMMEstimator passes u=None
            super().predict(0)

        def update(self, zk: np.ndarray) -> None:
            super().update(zk, lambda x: RADAR.jacobian(x[inv])[:, perm],
                           lambda x: RADAR.predict(x[inv]), residual=_radar_residual)  # fmt: skip

    out = np.empty(z.shape[:-1] + (6,))
    x0 = _radar_prior(z[:, 0])
    for i in range(z.shape[0]):
        filters = []
        for q in RADAR_IMM_Q:
            f = RadarEKF(dim_x=6, dim_z=4)
            f.F = np.kron(np.eye(3), [[1.0, dt], [0.0, 1.0]])
            f.Q = Q_continuous_white_noise(2, dt, q, block_size=3)
            f.R, f.x, f.P = RADAR.noise_cov, x0[i][perm], RADAR_P0[np.ix_(perm, perm)]
            filters.append(f)
        imm = IMMEstimator(filters, RADAR_IMM_MU0.copy(), RADAR_IMM_PI.copy())
        for k in range(z.shape[1]):
            if k:
                imm.predict()
            imm.update(z[i, k].copy())
            out[i, k] = imm.x[inv]
    return out
