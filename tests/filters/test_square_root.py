"""The square-root (array) filter: equal to Joseph where both are exact, right where Joseph is not.

The reference for ill-conditioned problems is the textbook filter at 50 digits (mpmath) on the
very transitions and process covariances the filter used, so only the filter's own rounding
is measured.
"""

import dataclasses

import numpy as np
import pytest

import adaptrack as at
from adaptrack.filters.online import OnlineFilter
from adaptrack.filters.square_root import covariance, lower_factor
from adaptrack.models import ConstantAcceleration, ConstantVelocity, Singer
from tests.oracles.reference import kalman_mp


def rel(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_equals_joseph_on_a_well_conditioned_batch(backend):
    rng = np.random.default_rng(5)
    model = Singer(time_constant_s=[3.0, 8.0], accel_std_mps2=[1.0, 2.5], n_axes=2)
    n_tr, n_st = 5, 80
    t = np.cumsum(rng.uniform(0.02, 2.0, (n_tr, n_st)), axis=-1)
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    z = rng.normal(size=(n_tr, n_st, 2)) * 30
    mask = rng.uniform(size=(n_tr, n_st, 2)) > 0.2
    r = np.diag([2.0, 3.0]) * rng.uniform(0.5, 2.0, (n_tr, n_st, 1, 1))
    p0 = np.diag([100.0, 100.0, 10.0, 10.0, 0.0, 1.0])  # a known component: PSD prior
    prior = at.GaussianState(np.zeros((n_tr, 6)), np.broadcast_to(p0, (n_tr, 6, 6)), 0.0)
    kw = dict(mask=mask, measurement_noise_mean=[0.1, -0.2], backend=backend)
    a = at.kalman_filter(t, z, model, h, r, prior, form="joseph", **kw)
    b = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", **kw)
    for x, y in (
        (a.filtered.mean, b.filtered.mean),
        (a.filtered.cov, b.filtered.cov),
        (a.predicted.cov, b.predicted.cov),
        (a.info.innovation_cov, b.info.innovation_cov),
        (a.info.gain, b.info.gain),
        (a.info.log_likelihood, b.info.log_likelihood),
    ):
        assert rel(y, x) <= 1e-9
    np.testing.assert_allclose(b.info.nis, a.info.nis, rtol=1e-8, atol=1e-12)


def ill_conditioned_problem():
    """A fix of 1e-3 m (R of condition 1e11) on a prior of 1 km, gaps 1e-6 to 100 s.

    The largest innovation variance is 1.1e12 times the smallest measurement variance: the
    edge of the domain the filters are specified for. Measured: the Joseph form's means are
    4 (NumPy) and 900 (compiled) posterior sigmas off the reference, the square root's 0.0035.
    """
    rng = np.random.default_rng(480)
    model = Singer(time_constant_s=40.0, accel_std_mps2=0.5)
    t = np.cumsum(np.concatenate([[0.0], 10 ** rng.uniform(-6, 2.0, 29)]))
    u, _ = np.linalg.qr(rng.normal(size=(2, 2)))
    r = (u * [1e-6, 1e5]) @ u.T
    r = 0.5 * (r + r.T)
    h = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    z = np.column_stack([np.linspace(0, 3e3, 30), np.full(30, 12.0)]) + rng.normal(size=(30, 2))
    prior = at.GaussianState([0.0, 0.0, 0.0], np.diag([1e6, 1e4, 1.0]), 0.0)
    return t, z, model, h, r, prior


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_square_root_matches_a_50_digit_reference_on_an_ill_conditioned_problem(backend):
    t, z, model, h, r, prior = ill_conditioned_problem()
    res = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend=backend)
    mean, cov = kalman_mp(res.transition, res.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    err_sigma = np.abs(res.filtered.mean - mean) / sigma
    assert err_sigma.max() < 1e-2
    scale = sigma[..., :, None] * sigma[..., None, :]
    assert np.max(np.abs(res.filtered.cov - cov) / scale) < 1e-6


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_auto_form_uses_the_square_root_filter_where_joseph_would_lose_digits(backend):
    t, z, model, h, r, prior = ill_conditioned_problem()
    auto = at.kalman_filter(t, z, model, h, r, prior, backend=backend)
    sqrt = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend=backend)
    np.testing.assert_array_equal(auto.filtered.mean, sqrt.filtered.mean)
    # a well-conditioned problem keeps the Joseph form (bit for bit)
    t, easy = np.arange(30.0), np.diag([1.0, 2.0])
    auto = at.kalman_filter(t, z, model, h, easy, prior, backend=backend)
    joseph = at.kalman_filter(t, z, model, h, easy, prior, form="joseph", backend=backend)
    np.testing.assert_array_equal(auto.filtered.mean, joseph.filtered.mean)


def units_problem():
    """A position of 100 m and a speed of 1 mm/s measured together (R = diag(1e4, 1e-6)):
    in its own units ``trace(S) / lambda_min(R)`` passes 1e12, at unit diagonal 1.1e6."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.05, 0.2, 200))
    v = 12.0 + np.cumsum(rng.normal(0.0, 0.1, 200))
    z = np.c_[np.cumsum(0.1 * v) + rng.normal(0, 100.0, 200), v + rng.normal(0, 1e-3, 200)]
    prior = at.GaussianState([0.0, 10.0], np.diag([1e6, 1.0]), 0.0)
    return t, z, ConstantVelocity(0.5), np.eye(2), np.diag([1e4, 1e-6]), prior


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_auto_rule_does_not_take_units_for_ill_conditioning(backend):
    """Rescaling a measured component by a power of 2 changes no bit of the Joseph filter, so
    its accuracy cannot depend on units, and neither does the ``"auto"`` rule: on a position
    and a speed in metres (unscaled ratio 1e12) it keeps the Joseph form, which is within
    1e-8 posterior sigma of the 50-digit filter; so does the online filter (it never leaves
    its Joseph kernel: the same numbers as the batch Joseph run to rounding)."""
    from adaptrack.filters.run import worst_joseph_ratio

    t, z, model, h, r, prior = units_problem()
    joseph = at.kalman_filter(t, z, model, h, r, prior, form="joseph", backend=backend)
    d = np.array([1.0, 2.0**-20])
    rescaled = at.kalman_filter(t, z * d, model, h * d[:, None], r * np.outer(d, d), prior,
                                form="joseph", backend=backend)  # fmt: skip
    np.testing.assert_array_equal(rescaled.filtered.mean, joseph.filtered.mean)
    np.testing.assert_array_equal(rescaled.filtered.cov, joseph.filtered.cov)
    s_trace = np.trace(joseph.info.innovation_cov, axis1=-2, axis2=-1)
    assert np.max(s_trace) / 1e-6 > 1e12 and worst_joseph_ratio(joseph) < 2e6
    auto = at.kalman_filter(t, z, model, h, r, prior, backend=backend)
    assert auto.filtered.factor is None
    np.testing.assert_array_equal(auto.filtered.mean, joseph.filtered.mean)
    mean, cov = kalman_mp(joseph.transition, joseph.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(joseph.filtered.mean - mean) / sigma) < 1e-8
    online = OnlineFilter(model, h, r, prior)
    for k in range(t.size):
        online.update(t[k], z[k])
    assert not online._sqrt
    np.testing.assert_allclose(online.mean, joseph.filtered.mean[-1], rtol=0,
                               atol=1e-8 * sigma[-1].min())  # fmt: skip


@pytest.mark.parametrize(
    "model",
    [ConstantVelocity(accel_psd=0.0), ConstantAcceleration(jerk_psd=2.0)],
    ids=["no-process-noise", "long-step"],
)
def test_lower_factor_reproduces_singular_and_badly_scaled_covariances(model):
    dt = np.array([1e-6, 1.0, 1e4])
    qd = at.discretize(model, dt).process_cov
    f = lower_factor(qd)
    scale = np.sqrt(qd.diagonal(axis1=1, axis2=2))
    safe = np.where(scale > 0, scale, 1.0)
    err = np.abs(covariance(f) - qd) / (safe[:, :, None] * safe[:, None, :])
    assert err.max() < 1e-12


def _steps(t, z, model, h, r, prior, form):
    state, means = prior, []
    for k in range(t.size):
        state, _ = at.kalman_step(state, z[k], model, h, r, time=t[k], form=form)
        means.append(state.mean)
    return np.array(means), state


def test_kalman_step_square_root_form_matches_the_50_digit_reference():
    """The step function's square-root form on the ill-conditioned problem: its covariances'
    correlation matrices stay below condition 1e12, so the covariance it carries from step to
    step holds the answer (the Joseph form is 4 sigma off)."""
    t, z, model, h, r, prior = ill_conditioned_problem()
    res = at.kalman_filter(t, z, model, h, r, prior, form="sqrt", backend="numpy")
    mean, cov = kalman_mp(res.transition, res.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    for form, limit in (("sqrt", 1e-2), ("auto", 1e-2)):
        means, last = _steps(t, z, model, h, r, prior, form)
        assert np.max(np.abs(means - mean) / sigma) < limit, form
        assert np.all(np.linalg.eigvalsh(last.cov) > 0.0)
    joseph, _ = _steps(t, z, model, h, r, prior, "joseph")
    assert np.max(np.abs(joseph - mean) / sigma) > 1.0  # the case the forms exist for


def test_update_forms_agree_on_a_well_conditioned_step_and_auto_is_joseph_there():
    prior = at.GaussianState([1.0, 2.0, 0.5], np.diag([4.0, 1.0, 0.25]), 0.0)
    h, r = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.diag([0.5, 0.2])
    z = np.array([1.7, 1.4])
    posts = {f: at.update(prior, z, h, r, form=f) for f in ("auto", "joseph", "standard", "sqrt")}
    for f in ("standard", "sqrt"):
        np.testing.assert_allclose(posts[f][0].mean, posts["joseph"][0].mean, rtol=1e-12)
        np.testing.assert_allclose(posts[f][0].cov, posts["joseph"][0].cov, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(posts[f][1].nis, posts["joseph"][1].nis, rtol=1e-12)
    np.testing.assert_array_equal(posts["auto"][0].mean, posts["joseph"][0].mean)
    np.testing.assert_array_equal(posts["auto"][0].cov, posts["joseph"][0].cov)


def test_the_step_function_carries_the_factor_and_equals_the_batch_filter():
    """Fuzz case (1, 207): covariances whose correlation matrices reach condition 1.2e13.
    Refactoring ``S S^T`` every step (a covariance carried between calls) is 5 sigma off the
    batch square-root filter; the state's ``factor`` carries ``S`` instead: equal to it."""
    from adaptrack.filters.square_root import covariance, sqrt_predict, sqrt_update
    from tests.stress.fuzz import Source, _filter, problem

    p = problem(Source(np.random.default_rng((1, 207))))
    res = _filter(p, form="sqrt", backend="numpy")
    mask = np.broadcast_to(p.mask, p.z.shape)
    times = np.broadcast_to(p.times, p.z.shape[:-1])
    sigma = np.sqrt(np.diagonal(res.filtered.cov[:, -1], axis1=-2, axis2=-1))
    x, f = p.prior.mean, lower_factor(np.asarray(p.prior.cov))
    for k in range(p.z.shape[-2]):
        noise = lower_factor(res.process_cov[:, k])
        x, f = sqrt_predict(x, f, res.transition[:, k], noise, np.zeros_like(x))
        x, f, _ = sqrt_update(x, f, p.z[:, k], p.h, p.r, mask[:, k], p.offset)
        f = lower_factor(covariance(f))  # what a covariance-only state forces
    assert np.max(np.abs(x - res.filtered.mean[:, -1]) / sigma) > 1.0
    state = p.prior
    for k in range(p.z.shape[-2]):
        state, _ = at.kalman_step(
            state, p.z[:, k], p.model, p.h, p.r, time=times[:, k], mask=mask[:, k], form="sqrt"
        )
        assert state.factor is not None
    assert np.max(np.abs(state.mean - res.filtered.mean[:, -1]) / sigma) <= 1e-12
    np.testing.assert_array_equal(state.cov, res.filtered.cov[:, -1])


def test_a_state_factor_is_checked_against_its_covariance():
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    state = at.GaussianState([0.0, 0.0], cov, 0.0, factor=np.linalg.cholesky(cov))
    two = at.GaussianState(
        np.zeros((2, 2)), np.stack([cov, cov]), 0.0, np.stack([state.factor] * 2)
    )
    np.testing.assert_array_equal(two[1].factor, state.factor)
    with pytest.raises(ValueError, match="factor does not reproduce cov"):
        dataclasses.replace(state, cov=np.eye(2))
    dataclasses.replace(state, cov=np.eye(2), factor=None)  # the way to change it
    # "auto" continues a square-root sequence; "joseph" drops the factor
    h, r = np.array([[1.0, 0.0]]), np.array([[0.5]])
    assert at.update(state, [1.0], h, r)[0].factor is not None
    assert at.update(state, [1.0], h, r, form="joseph")[0].factor is None
    assert at.update(dataclasses.replace(state, factor=None), [1.0], h, r)[0].factor is None


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_badly_scaled_prior_is_triangularised_row_by_row_accurately(backend):
    """Fuzz case (13, 19622): constant acceleration, prior variances from 5e-3 to 9e7, R of
    condition 2.8e9. Householder QR of the pre-array without its columns sorted by norm left
    the NumPy path 0.039 and the compiled one 0.0049 posterior sigma off a 60-digit filter;
    sorted: 1.3e-6 and 4.3e-5."""
    from tests.stress.fuzz import Source, _filter, problem

    p = problem(Source(np.random.default_rng((13, 19622))), tracks=1)
    res = _filter(p, form="sqrt", backend=backend)
    mask = np.broadcast_to(p.mask, p.z.shape)[0]
    mean, cov = kalman_mp(
        res.transition[0], res.process_cov[0], p.h, p.r, p.z[0], p.prior.mean[0],
        p.prior.cov[0], dps=60, mask=mask, offset=p.offset,
    )  # fmt: skip
    sigma = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    assert np.max(np.abs(res.filtered.mean[0] - mean) / sigma) < 1e-3
