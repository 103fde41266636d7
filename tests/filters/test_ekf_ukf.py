"""EKF and UKF: linear oracle, missing components, consistency, smoothing, bad input."""

import numpy as np
import pytest
from scipy import stats

import adaptrack as at
from adaptrack.filters import _nonlinear_run
from adaptrack.filters.ekf import ekf_update_step
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    FunctionMeasurement,
    PositionMeasurement,
    RadarMeasurement,
)
from adaptrack.types import GaussianState
from tests.cv_truth import cv_states


def irregular_times(rng, n_tracks, n_steps):
    return np.cumsum(rng.uniform(0.2, 2.0, (n_tracks, n_steps)), axis=1)


@pytest.mark.parametrize("run", [at.ekf_filter, at.ukf_filter])
def test_linear_measurement_reproduces_the_kalman_filter(run):
    """With h linear the EKF is the Kalman filter and the unscented transform is exact."""
    rng = np.random.default_rng(5)
    model = ConstantAcceleration(jerk_psd=[0.3, 0.1], n_axes=2)
    t = irregular_times(rng, 3, 40)
    z = rng.normal(0, 50, (3, 40, 2))
    mask = rng.random((3, 40, 2)) > 0.2
    r = np.array([[4.0, 1.0], [1.0, 9.0]])
    prior = GaussianState(np.zeros(6), np.diag([100, 100, 25, 25, 4, 4.0]), 0.0)
    ours = run(t, z, model, PositionMeasurement(r), prior, mask=mask)
    ref = at.kalman_filter(t, z, model, ["x", "y"], r, prior, mask=mask, form="joseph",
                           backend="numpy")  # fmt: skip
    tol = 1e-12 if run is at.ekf_filter else 1e-8
    for a, b in [(ours.filtered.mean, ref.filtered.mean), (ours.filtered.cov, ref.filtered.cov),
                 (ours.predicted.cov, ref.predicted.cov)]:  # fmt: skip
        np.testing.assert_allclose(a, b, rtol=tol, atol=tol * np.abs(b).max())
    np.testing.assert_allclose(ours.log_likelihood, ref.log_likelihood, rtol=tol)
    np.testing.assert_array_equal(ours.info.n_observed, ref.info.n_observed)


def test_a_missing_component_is_the_update_without_it():
    rng = np.random.default_rng(11)
    full = RadarMeasurement(noise_cov=[4.0, 1e-6])
    range_only = RadarMeasurement(noise_cov=[4.0], components=("range",))
    a = rng.normal(size=(4, 4))
    prior = GaussianState(
        np.array([800.0, 1500.0, 10.0, -5.0]), a @ a.T + np.diag([50, 50, 4, 4.0]), 1.0
    )
    z = np.array([1700.0, np.nan])
    idx = np.arange(2)
    got, info, _ = ekf_update_step(prior, z, full, idx, full.noise_cov, np.array([True, False]))
    ref, ref_info, _ = ekf_update_step(prior, z[:1], range_only, idx, range_only.noise_cov,
                                       np.array([True]))  # fmt: skip
    np.testing.assert_allclose(got.mean, ref.mean, rtol=1e-13)
    np.testing.assert_allclose(got.cov, ref.cov, rtol=1e-12, atol=1e-12)
    assert info.log_likelihood == pytest.approx(ref_info.log_likelihood, rel=1e-13)
    assert info.n_observed == 1


def test_azimuth_wraps_when_a_target_passes_due_south():
    """A target crossing the radar's +-pi azimuth cut keeps a sub-metre track."""
    rng = np.random.default_rng(3)
    radar = RadarMeasurement(noise_cov=[1.0, (0.5e-3) ** 2])
    t = np.arange(0.0, 60.0, 1.0)
    truth = np.stack([-300.0 + 10.0 * t, np.full_like(t, -3000.0)], -1)
    z = radar.predict(truth) + rng.normal(0, 1, (60, 2)) * [1.0, 0.5e-3]
    assert np.any(z[:, 1] > 3.0) and np.any(z[:, 1] < -3.0)
    prior = GaussianState([-300.0, -3000.0, 0.0, 0.0], np.diag([100, 100, 400, 400.0]), 0.0)
    model = ConstantVelocity(0.01, n_axes=2)
    for run in (at.ekf_filter, at.ukf_filter):
        res = run(t, z, model, radar, prior)
        err = np.linalg.norm(res.filtered.mean[10:, :2] - truth[10:], axis=-1)
        assert err.max() < 3.0, run.__name__
        assert np.all(np.abs(res.info.innovation[:, 1]) < 0.01)


def simulate_radar_runs(rng, n_runs, n_steps, radar, q, start):
    """CV truth (own closed form) and 3-D radar measurements, irregular steps, per run."""
    t = np.cumsum(rng.uniform(0.5, 1.5, (n_runs, n_steps)), axis=1)
    states = np.empty((n_runs, n_steps, 6))
    for i in range(n_runs):
        s = np.array(start, dtype=float)
        dt = np.diff(t[i], prepend=0.0)
        for k in range(n_steps):
            s = cv_states(rng, s, dt[k], q, 1)[0]
            states[i, k] = np.concatenate([s[:, 0], s[:, 1]])
    noise = rng.multivariate_normal(np.zeros(4), radar.noise_cov, (n_runs, n_steps))
    return t, states, radar.predict(states) + noise


@pytest.mark.statistical
@pytest.mark.parametrize("run", [at.ekf_filter, at.ukf_filter])
def test_filters_are_consistent_on_a_3d_radar_with_range_rate(run):
    """Average NEES over 200 runs inside its two-sided 99.9 % chi-square band.

    Truth: CV drawn from its own closed form; radar 8-15 km away, 1 mrad angles, so the
    linearisation error is far below the noise. At each of the last 20 steps the summed
    NEES of 200 runs is chi-square(1200) under consistency; one band per filter and step,
    Bonferroni over 20 steps (false-failure probability below 2 %).
    """
    rng = np.random.default_rng(1127)
    radar = RadarMeasurement(
        noise_cov=np.diag([25.0, 1e-6, 1e-6, 0.25]),
        components=("range", "azimuth", "elevation", "range_rate"), n_axes=3,
        sensor_position=[0.0, 0.0, 10.0],
    )  # fmt: skip
    q = 0.5
    start = [[8000.0, -60.0], [9000.0, 40.0], [3000.0, 0.0]]
    t, states, z = simulate_radar_runs(rng, 200, 40, radar, q, start)
    prior = GaussianState(
        states[:, 0] + rng.normal(0, 1, (200, 6)) * [30, 30, 30, 20, 20, 5],
        np.broadcast_to(np.diag([900.0, 900, 900, 400, 400, 25]), (200, 6, 6)), t[:, 0],
    )  # fmt: skip
    res = run(t, z, ConstantVelocity(q, n_axes=3), radar, prior)
    err = res.filtered.mean - states
    whitened = np.linalg.solve(res.filtered.cov, err[..., None])[..., 0]
    nees = np.einsum("...i,...i->...", err, whitened)
    total = nees[:, -20:].sum(axis=0)
    alpha = 1e-3 / 20
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], 200 * 6)
    assert np.all((total > lo) & (total < hi)), (total.min(), total.max(), lo, hi)


def test_ekf_result_smooths_and_the_smoother_helps():
    rng = np.random.default_rng(8)
    radar = RadarMeasurement(noise_cov=np.diag([25.0, 1e-6, 1e-6, 0.25]),
                             components=("range", "azimuth", "elevation", "range_rate"),
                             n_axes=3)  # fmt: skip
    t, states, z = simulate_radar_runs(
        rng, 30, 60, radar, 0.5, [[8000.0, -60.0], [9000.0, 40.0], [3000.0, 0.0]]
    )
    cov0 = np.broadcast_to(np.diag([900.0, 900, 900, 400, 400, 25]), (30, 6, 6))
    prior = GaussianState(states[:, 0], cov0, t[:, 0])
    res = at.ekf_filter(t, z, ConstantVelocity(0.5, n_axes=3), radar, prior)
    smooth = at.rts_smooth(res)
    filt_rms = np.sqrt(np.mean((res.filtered.mean[:, :, :3] - states[:, :, :3]) ** 2))
    smooth_rms = np.sqrt(np.mean((smooth.mean[:, :, :3] - states[:, :, :3]) ** 2))
    assert smooth_rms < 0.8 * filt_rms
    assert np.all(np.linalg.eigvalsh(res.filtered.cov - smooth.cov) > -1e-6)


def test_user_function_without_jacobian_runs_in_both_filters():
    rng = np.random.default_rng(2)
    radar = RadarMeasurement(noise_cov=[4.0, 1e-6])
    user = FunctionMeasurement(radar.predict, radar.reads, radar.names, radar.noise_cov,
                               angular=radar.angular)  # fmt: skip
    t = np.arange(20.0)
    truth = np.stack([2000.0 + 5 * t, 1000.0 - 3 * t], -1)
    z = radar.predict(truth) + rng.normal(0, 1, (20, 2)) * [2.0, 1e-3]
    prior = GaussianState([2000.0, 1000.0, 0.0, 0.0], np.diag([100, 100, 100, 100.0]), 0.0)
    model = ConstantVelocity(0.1, n_axes=2)
    for run in (at.ekf_filter, at.ukf_filter):
        a = run(t, z, model, radar, prior)
        b = run(t, z, model, user, prior)
        np.testing.assert_allclose(b.filtered.mean, a.filtered.mean, rtol=1e-7)


def test_bad_input_is_named():
    radar = RadarMeasurement(noise_cov=[4.0, 1e-6])
    model = ConstantVelocity(0.1, n_axes=2)
    prior = GaussianState([100.0, 100.0, 0.0, 0.0], np.eye(4), 0.0)
    t = np.arange(3.0)
    z = np.full((3, 2), 100.0)
    with pytest.raises(ValueError, match="2 components"):
        at.ekf_filter(t, z[:, :1], model, radar, prior)
    with pytest.raises(ValueError, match="strictly increasing"):
        at.ekf_filter(t[::-1], z, model, radar, prior)
    bad = z.copy()
    bad[1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN at step 1, component 1"):
        at.ukf_filter(t, bad, model, radar, prior)
    res = at.ukf_filter(t, bad, model, radar, prior, nan_policy="missing")
    assert res.info.n_observed.tolist() == [2, 1, 2]
    with pytest.raises(ValueError, match=r"reads state\(s\) \['z'\]"):
        at.ekf_filter(t, np.zeros((3, 3)), model,
                      RadarMeasurement([1, 1, 1], ("range", "azimuth", "elevation"), n_axes=3),
                      prior)  # fmt: skip
    with pytest.raises(TypeError, match="measurement_model must provide"):
        at.ekf_filter(t, z, model, [[1.0, 0.0, 0.0, 0.0]], prior)
    with pytest.raises(ValueError, match="measurement_cov"):
        at.ekf_filter(t, z, model, radar, prior, measurement_cov=-np.eye(2))
    with pytest.raises(ValueError, match="form must be"):
        at.ekf_filter(t, z, model, radar, prior, form="cholesky")
    with pytest.raises(ValueError, match="form must be 'auto', 'joseph' or 'sqrt'"):
        at.ukf_filter(t, z, model, radar, prior, form="standard")
    with pytest.raises(ValueError, match="backend must be"):
        at.ekf_filter(t, z, model, radar, prior, backend="gpu")
    with pytest.raises(ValueError, match="NaN at step 1, component 1"):
        at.ekf_filter(t, bad, model, radar, prior, backend="numba")


def test_a_known_state_component_is_kept_by_both_filters():
    """A prior with a zero variance (a known component, PSD not PD): the UKF's sigma points
    come from a factor of the correlation matrix, so it runs and keeps it, as the EKF."""
    rng = np.random.default_rng(4)
    radar = RadarMeasurement(noise_cov=[4.0, 1e-6])
    t = np.arange(10.0)
    truth = np.stack([2000.0 + 5 * t, 1000.0 + 0 * t], -1)
    z = radar.predict(truth) + rng.normal(0, 1, (10, 2)) * [2.0, 1e-3]
    prior = GaussianState([2000.0, 1000.0, 5.0, 0.0], np.diag([100.0, 100.0, 0.0, 0.0]), 0.0)
    model = ConstantVelocity(0.0, n_axes=2)  # no process noise: the velocity stays known
    for run in (at.ekf_filter, at.ukf_filter):
        res = run(t, z, model, radar, prior)
        np.testing.assert_allclose(res.filtered.mean[:, 2:], [[5.0, 0.0]] * 10, atol=1e-9)
        assert np.all(np.linalg.eigvalsh(res.filtered.cov) > -1e-9)


def _same_result(got, ref):
    """Every array of two FilterResults, to rounding at each array's own scale."""
    pairs = [(got.predicted.mean, ref.predicted.mean), (got.predicted.cov, ref.predicted.cov),
             (got.filtered.mean, ref.filtered.mean), (got.filtered.cov, ref.filtered.cov),
             (got.transition, ref.transition), (got.process_cov, ref.process_cov),
             (got.control, ref.control), (got.measurement_matrix, ref.measurement_matrix),
             (got.measurement_cov, ref.measurement_cov), (got.mask, ref.mask)]  # fmt: skip
    pairs += [
        (getattr(got.info, f), getattr(ref.info, f))
        for f in ("innovation", "innovation_cov", "nis", "log_likelihood", "gain", "n_observed")
    ]
    for a, b in pairs:
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(b).max()))


@pytest.mark.parametrize("form", ["joseph", "standard"])
@pytest.mark.parametrize("case", ["radar3d+rr, CV", "radar2d, CT", "position 3-D, CA", "one track"])
def test_compiled_ekf_gives_the_numpy_result(case, form, monkeypatch):
    """``backend="numba"`` records every output of the NumPy EKF, to rounding: three tracks on
    their own irregular time grids with their own priors, missing components (NaN), per-step
    ``R``; radars with a heading and an offset position (the azimuth wrapping across south
    included: the targets fly through it), a coordinated turn (its F and Q per step)."""
    rng = np.random.default_rng(sum(map(ord, case)))
    n_tr, n_st = (1, 80) if case == "one track" else (3, 50)
    t = np.cumsum(rng.uniform(0.3, 2.0, (n_tr, n_st)), axis=1)
    if case.startswith("radar3d") or case == "one track":
        measure = RadarMeasurement(np.diag([25.0, 1e-6, 4e-6, 0.25]),
                                   ("range", "azimuth", "elevation", "range_rate"), n_axes=3,
                                   sensor_position=[50.0, -20.0, 10.0], heading=0.3)  # fmt: skip
        model = ConstantVelocity(0.5, n_axes=3)
    elif case.startswith("radar2d"):
        measure = RadarMeasurement(np.diag([25.0, 1e-6]), heading=-0.2, sensor_position=[30, 5])
        model = CoordinatedTurn(0.5, 1e-3)
    else:
        measure = PositionMeasurement(np.diag([9.0, 16.0, 25.0]), ("x", "y", "z"))
        model = ConstantAcceleration(jerk_psd=[0.3, 0.3, 0.05], n_axes=3)
    n = model.state_dim
    k = 3 if measure.reads[-1] == "z" or len(measure.reads) > 3 else 2
    pos = np.zeros((n_tr, n_st, k))
    pos[..., 0] = 1500.0 - 60.0 * t  # passes south of the radar: the azimuth wraps
    pos[..., 1] = -3000.0 + 10.0 * t
    s = np.zeros((n_tr, n_st, len(measure.reads)))
    s[..., :k] = pos
    if len(measure.reads) > k:  # the velocities a range-rate reads
        s[..., k:] = [-60.0, 10.0, 0.0][: len(measure.reads) - k]
    z = measure.predict(s) + rng.normal(size=(n_tr, n_st, len(measure.names))) * np.sqrt(
        np.diag(measure.noise_cov))  # fmt: skip
    mask = rng.uniform(size=z.shape) > 0.15
    z[~mask] = np.nan
    r = np.broadcast_to(measure.noise_cov, (n_tr, n_st) + measure.noise_cov.shape).copy()
    r[:, ::7] *= 4.0
    mean0 = np.zeros((n_tr, n))
    mean0[:, :2] = [1500.0, -3000.0]
    mean0[:, k] = -60.0
    mean0 += rng.normal(size=(n_tr, n)) * 5.0
    if isinstance(model, CoordinatedTurn):
        mean0[:, -1] = 0.01
    var = np.r_[[400.0] * k, [100.0] * (n - k)]
    if isinstance(model, CoordinatedTurn):
        var[-1] = 1e-3
    prior = GaussianState(mean0, np.broadcast_to(np.diag(var), (n_tr, n, n)), t[:, 0] - 0.5)
    kw = dict(measurement_cov=r, mask=mask, nan_policy="missing", form=form)
    if isinstance(measure, RadarMeasurement):
        jumps = np.abs(np.diff(np.where(mask[..., 1], z[..., 1], np.nan), axis=-1))
        assert np.nanmax(jumps) > np.pi  # the measured azimuth wraps
    ref = at.ekf_filter(t, z, model, measure, prior, backend="numpy", **kw)
    monkeypatch.setattr(_nonlinear_run, "_steps", None)  # the NumPy loop must not run
    got = at.ekf_filter(t, z, model, measure, prior, backend="numba", **kw)
    _same_result(got, ref)
    assert np.all(np.isfinite(got.filtered.mean))


def test_compiled_ekf_leaves_what_it_cannot_run_to_numpy():
    """A state on the radar's vertical axis stops the kernel: the NumPy path names it. A
    measurement model the kernel does not cover (a user's function) runs in NumPy."""
    radar = RadarMeasurement(noise_cov=[25.0, 1e-6])
    t, z = np.arange(3.0), np.tile([10.0, 0.1], (3, 1))
    prior = GaussianState(np.zeros(4), np.diag([1e4, 1e4, 400, 400]), 0.0)
    with pytest.raises(ValueError, match="vertical axis"):
        at.ekf_filter(t, z, ConstantVelocity(0.1, n_axes=2), radar, prior, backend="numba")
    user = FunctionMeasurement(lambda s: s, ("x", "y"), ("x_m", "y_m"), [4.0, 4.0])
    zz = np.stack([t, 2 * t], -1)
    got = at.ekf_filter(t, zz, ConstantVelocity(0.1, n_axes=2), user, prior, backend="numba")
    ref = at.ekf_filter(t, zz, ConstantVelocity(0.1, n_axes=2), user, prior, backend="numpy")
    _same_result(got, ref)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_ekf_matches_a_50_digit_reference_on_an_ill_conditioned_problem(backend):
    """The square-root filter's hard problem (R of condition 1e11, prior of 1 km, gaps 1e-6
    to 100 s) through ``ekf_filter`` with a position measurement: ``form="sqrt"`` and the
    default ``"auto"`` (which takes the square root here, the Joseph form's scaled ratio being
    far past the limit) are within 1e-2 posterior sigma of the 50-digit textbook filter;
    ``"joseph"`` is not (it is measured here, to show the problem is one)."""
    from adaptrack.filters.run import JOSEPH_MAX_RATIO, worst_joseph_ratio

    t, z, model, measure, prior, mean, cov, sigma, scale = _fifty_digit_filter()
    for form in ("sqrt", "auto"):
        res = at.ekf_filter(t, z, model, measure, prior, form=form, backend=backend)
        assert np.max(np.abs(res.filtered.mean - mean) / sigma) < 1e-2
        assert np.max(np.abs(res.filtered.cov - cov) / scale) < 1e-6
        assert res.filtered.factor is not None  # the square root ran
    joseph = at.ekf_filter(t, z, model, measure, prior, form="joseph", backend=backend)
    assert worst_joseph_ratio(joseph) > JOSEPH_MAX_RATIO
    assert np.max(np.abs(joseph.filtered.mean - mean) / sigma) > 1e-2


@pytest.mark.parametrize("motion", ["cv", "ct"])
def test_square_root_ekf_equals_the_joseph_ekf_on_a_well_conditioned_radar(motion):
    """A 3-D radar with range-rate (metres and radians: the scaled ratio stays small), linear
    and coordinated-turn motion: ``form="sqrt"`` gives the Joseph form's result to rounding,
    with the factor of its covariance; ``"auto"`` keeps the Joseph form (no factor)."""
    t, z, model, radar, prior = _radar_runs(31, motion)
    joseph = at.ekf_filter(t, z, model, radar, prior, form="joseph")
    root = at.ekf_filter(t, z, model, radar, prior, form="sqrt")
    auto = at.ekf_filter(t, z, model, radar, prior)
    assert auto.filtered.factor is None
    np.testing.assert_array_equal(auto.filtered.mean, joseph.filtered.mean)
    sigma = np.sqrt(np.diagonal(joseph.filtered.cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(root.filtered.mean - joseph.filtered.mean) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(root.filtered.cov - joseph.filtered.cov) / scale) < 1e-8
    f = root.filtered.factor
    np.testing.assert_allclose(f @ np.swapaxes(f, -1, -2), root.filtered.cov, atol=1e-9 * 900)
    for name in ("innovation", "innovation_cov", "log_likelihood", "nis"):
        np.testing.assert_allclose(getattr(root.info, name), getattr(joseph.info, name),
                                   rtol=1e-8, atol=1e-9)  # fmt: skip


def test_square_root_ukf_matches_a_50_digit_reference_on_an_ill_conditioned_problem():
    """The same hard problem through ``ukf_filter``: ``form="sqrt"`` (sigma points from the
    carried factor, ``S`` and the posterior factor triangularised) and the default ``"auto"``
    are within 1e-2 posterior sigma of the 50-digit filter; the plain form is not."""
    t, z, model, measure, prior, mean, cov, sigma, scale = _fifty_digit_filter()
    for form in ("sqrt", "auto"):
        res = at.ukf_filter(t, z, model, measure, prior, form=form)
        assert res.filtered.factor is not None
        assert np.max(np.abs(res.filtered.mean - mean) / sigma) < 1e-2
        assert np.max(np.abs(res.filtered.cov - cov) / scale) < 1e-6
    plain = at.ukf_filter(t, z, model, measure, prior, form="joseph")
    assert np.max(np.abs(plain.filtered.mean - mean) / sigma) > 1e-2


@pytest.mark.parametrize("motion", ["cv", "ct"])
def test_square_root_ukf_is_the_ukf_on_a_well_conditioned_radar(motion):
    """A 3-D radar with range-rate, linear and coordinated-turn motion: the square-root UKF's
    sigma points come from another square root of the same covariance, so it differs from the
    plain UKF by the unscented transform's own approximation, here (targets 8-15 km out, 1 mrad)
    below 1e-8 posterior sigma (measured: 2.4e-12); ``"auto"`` keeps the plain form. Negative
    covariance weights (``alpha`` < 1 with ``kappa`` 0) are refused by the square-root form."""
    t, z, model, radar, prior = _radar_runs(32, motion)
    plain = at.ukf_filter(t, z, model, radar, prior, form="joseph")
    root = at.ukf_filter(t, z, model, radar, prior, form="sqrt")
    auto = at.ukf_filter(t, z, model, radar, prior)
    assert auto.filtered.factor is None
    np.testing.assert_array_equal(auto.filtered.mean, plain.filtered.mean)
    sigma = np.sqrt(np.diagonal(plain.filtered.cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(root.filtered.mean - plain.filtered.mean) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(root.filtered.cov - plain.filtered.cov) / scale) < 1e-8
    with pytest.raises(ValueError, match="non-negative covariance weights"):
        at.ukf_filter(t, z, model, radar, prior, form="sqrt",
                      sigma_points=at.SigmaPoints(alpha=0.1))  # fmt: skip


def test_the_auto_rule_does_not_count_units_as_ill_conditioning():
    """``worst_joseph_ratio`` is the same whether a component is measured in metres or in
    kilometres (its R and S entries scale by 1e-6), while the unscaled ``trace(S) /
    lambda_min(R)`` changes by orders of magnitude; with every component present it is
    ``trace(S R^-1)`` for a diagonal R."""
    from adaptrack.filters.run import worst_joseph_ratio

    def unscaled(res):
        s_trace = np.trace(res.info.innovation_cov, axis1=-2, axis2=-1)
        return np.max(s_trace / np.linalg.eigvalsh(res.measurement_cov)[0])

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.5, 1.5, 30))
    xy = np.stack([10.0 * t, -5.0 * t], -1) + rng.normal(size=(30, 2)) * [3.0, 2.0]
    prior = GaussianState(np.zeros(4), np.diag([1e4, 1e4, 100.0, 100.0]), 0.0)
    model = ConstantVelocity(0.3, n_axes=2)
    metres = at.ekf_filter(t, xy, model, PositionMeasurement([9.0, 4.0]), prior, form="joseph")
    km = FunctionMeasurement(lambda s: s * [1.0, 1e-3], ("x", "y"), ("x_m", "y_km"),
                             [9.0, 4e-6])  # fmt: skip
    kilo = at.ekf_filter(t, xy * [1.0, 1e-3], model, km, prior, form="joseph")
    assert worst_joseph_ratio(kilo) == pytest.approx(worst_joseph_ratio(metres), rel=1e-6)
    assert unscaled(kilo) > 1e5 * unscaled(metres)
    s = metres.info.innovation_cov
    expected = np.max(s[..., 0, 0] / 9.0 + s[..., 1, 1] / 4.0)
    assert worst_joseph_ratio(metres) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("how", ["ekf", "ukf"])
@pytest.mark.parametrize("motion", ["cv", "ct"])
def test_a_one_model_imm_in_square_root_form_is_the_square_root_filter(motion, how):
    """A 3-D radar with range-rate, linear or coordinated-turn motion: the one-model IMM's
    square-root form (its factor mixed with itself, then the EKF's or UKF's square-root
    predict and update) gives ``ekf_filter`` / ``ukf_filter(form="sqrt")`` to rounding."""
    from adaptrack.filters.imm import imm_filter

    t, z, model, radar, prior = _radar_runs(33, motion)
    imm = imm_filter(t, z, [model], radar, None, [prior], initial_probs=[1.0],
                     switching_rates=[[0.0]], nonlinear=how, form="sqrt")  # fmt: skip
    single = (at.ekf_filter if how == "ekf" else at.ukf_filter)(
        t, z, model, radar, prior, form="sqrt"
    )
    sigma = np.sqrt(np.diagonal(single.filtered.cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(imm.filtered.mean - single.filtered.mean) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(imm.filtered.cov - single.filtered.cov) / scale) < 1e-8
    np.testing.assert_allclose(imm.log_likelihood, single.info.log_likelihood, rtol=1e-9)


@pytest.mark.parametrize("how", ["ekf", "ukf"])
def test_square_root_imm_of_a_measurement_model_matches_a_50_digit_reference(how):
    """The hard problem (R of condition 1e11, gaps 1e-6 to 100 s) through an IMM of two copies
    of its model (so the IMM is that model's filter) with a user's measurement function:
    ``form="sqrt"`` and the default ``"auto"`` (whose scaled ratio is past the limit here) are
    within 1e-2 posterior sigma of the 50-digit textbook filter; the Joseph form is not."""
    from adaptrack.filters.imm import imm_filter

    t, z, model, position, prior, mean, cov, sigma, scale = _fifty_digit_filter()

    def unit(s):
        return np.broadcast_to(np.eye(2), s.shape[:-1] + (2, 2))

    ident = FunctionMeasurement(lambda s: s, ("x", "vx"), ("x", "vx"), position.noise_cov, unit)

    def run(form):
        return imm_filter(t, z, [model, model], ident, None, [prior, prior],
                          initial_probs=[0.5, 0.5], switching_rates=[[-0.1, 0.1], [0.1, -0.1]],
                          nonlinear=how, form=form)  # fmt: skip

    for form in ("sqrt", "auto"):
        res = run(form)
        assert np.max(np.abs(res.filtered.mean - mean) / sigma) < 1e-2, form
        assert np.max(np.abs(res.filtered.cov - cov) / scale) < 1e-6, form
    assert np.max(np.abs(run("joseph").filtered.mean - mean) / sigma) > 1e-2


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_radar_imm_auto_keeps_the_joseph_form_where_it_keeps_its_digits(backend):
    """A CV + CT IMM-EKF on a 3-D radar with range-rate (well conditioned at unit diagonal,
    though its unscaled ratio mixes metres and radians): ``"auto"`` is the Joseph run to the
    bit, and the square-root form (NumPy) agrees with it to 1e-8 posterior sigma."""
    from adaptrack.filters.imm import imm_filter

    t, z, ct, radar, p_ct = _radar_runs(34, "ct")
    cv = ConstantVelocity(0.5, n_axes=3)
    p_cv = GaussianState(p_ct.mean[:, :6], p_ct.cov[:, :6, :6], p_ct.time)

    def run(form):
        return imm_filter(t, z, [cv, ct], radar, None, [p_cv, p_ct], initial_probs=[0.5, 0.5],
                          switching_rates=[[-0.05, 0.05], [0.05, -0.05]], form=form,
                          backend=backend)  # fmt: skip

    joseph, auto, root = run("joseph"), run("auto"), run("sqrt")
    np.testing.assert_array_equal(auto.filtered.mean, joseph.filtered.mean)
    np.testing.assert_array_equal(auto.filtered.cov, joseph.filtered.cov)
    sigma = np.sqrt(np.diagonal(joseph.filtered.cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(root.filtered.mean - joseph.filtered.mean) / sigma) < 1e-8
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(root.filtered.cov - joseph.filtered.cov) / scale) < 1e-8
    np.testing.assert_allclose(root.mode_probabilities, joseph.mode_probabilities, atol=1e-8)


def _radar_runs(seed, motion):
    """Four runs of a 3-D radar with range-rate (8-15 km out, 1 mrad), CV or coordinated-turn
    motion (``motion`` "cv" or "ct") and priors near the truth: times, plots, model, radar,
    prior."""
    rng = np.random.default_rng(seed)
    radar = RadarMeasurement(np.diag([25.0, 1e-6, 1e-6, 0.25]),
                             ("range", "azimuth", "elevation", "range_rate"), n_axes=3,
                             sensor_position=[0.0, 0.0, 10.0])  # fmt: skip
    t, states, z = simulate_radar_runs(
        rng, 4, 60, radar, 0.5, [[8000.0, -60.0], [9000.0, 40.0], [3000.0, 0.0]]
    )
    p0 = np.diag([900.0, 900, 900, 400, 400, 25])
    mean0 = states[:, 0] + rng.normal(0, 1, (4, 6)) * 20
    model = ConstantVelocity(0.5, n_axes=3)
    if motion == "ct":
        model = CoordinatedTurn(0.5, 1e-4, 0.5, n_axes=3)
        p0 = np.pad(p0, ((0, 1), (0, 1)))
        p0[-1, -1] = 1e-4
        mean0 = np.c_[mean0, np.zeros(4)]
    return t, z, model, radar, GaussianState(mean0, np.broadcast_to(p0, (4,) + p0.shape), t[:, 0])


def _fifty_digit_filter():
    """The square-root filter's hard problem (``ill_conditioned_problem``) with a position
    measurement model, and its 50-digit filtered means, sigmas and sigma products."""
    from tests.filters.test_square_root import ill_conditioned_problem
    from tests.oracles.reference import kalman_mp

    t, z, model, h, r, prior = ill_conditioned_problem()
    kf = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend="numpy")
    mean, cov = kalman_mp(kf.transition, kf.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    measure = PositionMeasurement(r, ("x", "vx"))
    return t, z, model, measure, prior, mean, cov, sigma, sigma[..., :, None] * sigma[..., None, :]
