"""OnlineFilter: the stream filter equals the sequence API; bad input loses nothing."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.filters.online import OnlineFilter
from adaptrack.models import ConstantAcceleration, ConstantVelocity, Singer
from tests.filters.test_square_root import ill_conditioned_problem
from tests.oracles.reference import kalman_mp

CASES = [
    (ConstantVelocity(accel_psd=0.5), 1),
    (Singer(time_constant_s=5.0, accel_std_mps2=2.0), 1),
    (ConstantAcceleration(jerk_psd=0.3, n_axes=2), 2),
    (Singer(time_constant_s=8.0, accel_std_mps2=1.0, n_axes=3), 3),
]


def _stream(model, m, rng, n_steps=60):
    n = model.state_dim
    t = np.cumsum(rng.choice([0.05, 0.1, 0.25], n_steps))  # a few distinct step lengths
    h = np.zeros((m, n))
    h[np.arange(m), np.arange(m)] = 1.0
    a = rng.standard_normal((m, m))
    r = a @ a.T + 0.5 * np.eye(m)
    z = 10.0 * rng.standard_normal((n_steps, m)) + 3.0 * t[:, None]
    prior = at.GaussianState(rng.standard_normal(n), np.diag(rng.uniform(1, 50, n)), t[0] - 0.1)
    return t, z, h, r, prior


@pytest.mark.parametrize("form", ["joseph", "standard", "sqrt"])
@pytest.mark.parametrize(("model", "m"), CASES)
def test_stream_equals_the_sequence_filter(model, m, form, rng):
    t, z, h, r, prior = _stream(model, m, rng)
    mu = 0.2 * rng.standard_normal(m)
    mask = rng.random(z.shape) > 0.2
    mask[::7] = True
    ref = at.kalman_filter(
        t, z, model, h, r, prior, form=form, measurement_noise_mean=mu, backend="numpy"
    )
    ref_masked = at.kalman_filter(
        t, z, model, h, r, prior, mask=mask, form=form, measurement_noise_mean=mu, backend="numpy"
    )
    for masked, expected in ((False, ref), (True, ref_masked)):
        f = OnlineFilter(
            model, h, r, prior, form=form, measurement_noise_mean=mu, cache_size=2
        )  # 3 step lengths in a 2-row cache: rows are replaced and rebuilt
        for k in range(t.size):
            nis = f.update(t[k], z[k], mask=mask[k] if masked else None)
            scale = np.abs(expected.filtered.mean[k]).max()
            assert np.abs(f.mean - expected.filtered.mean[k]).max() <= 1e-10 * scale
            assert np.abs(f.cov - expected.filtered.cov[k]).max() <= 1e-10 * np.abs(f.cov).max()
            assert nis == pytest.approx(expected.info.nis[k], rel=1e-9, abs=1e-12)
            assert f.log_likelihood == pytest.approx(expected.info.log_likelihood[k], rel=1e-9)
        assert f.time == t[-1]
        assert f.state.mean.shape == (model.state_dim,)


def test_clock_round_off_shares_one_discretisation(rng):
    model, m = CASES[1]
    _, _, h, r, prior = _stream(model, m, rng)
    t = prior.time + 0.1 + 0.1 * np.arange(50)  # steps differ from 0.1 by round-off only
    assert np.unique(np.diff(t)).size > 1
    f = OnlineFilter(model, h, r, prior)
    for k in range(t.size):
        f.update(t[k], [float(k)])
    assert np.isfinite(f._bank[:, 0]).sum() == 1  # one step length cached


@pytest.mark.parametrize("block", [False, True])
def test_microsecond_steps_that_differ_by_less_than_a_nanosecond_are_not_shared(block):
    """Fuzz case (11, 2402): steps of 1.37-1.40 us, some 0.1-1 ns apart, shared one
    discretisation under a fixed 1 ns tolerance (0.07 % of the step): the stream ended 0.017
    posterior sigma off the sequence filter. The tolerance is now the time stamp's rounding."""
    rng = np.random.default_rng(3)
    model = ConstantAcceleration(jerk_psd=1.0)
    t = 1e-3 + np.cumsum(rng.uniform(1.37e-6, 1.40e-6, 40))
    z = (300.0 * t + rng.normal(size=40) * 1e-4)[:, None]
    h, r = np.array([[1.0, 0.0, 0.0]]), np.array([[1e-8]])
    prior = at.GaussianState([0.0, 300.0, 0.0], np.diag([1e-2, 7e4, 3e7]), 1e-3)
    ref = at.kalman_filter(t, z, model, h, r, prior).filtered
    f = OnlineFilter(model, h, r, prior)
    if block:
        f.update_many(t, z)
    else:
        for k in range(t.size):
            f.update(t[k], z[k])
    sigma = np.sqrt(np.diag(ref.cov[-1]))
    assert np.max(np.abs(f.mean - ref.mean[-1]) / sigma) < 1e-6


def test_bad_input_raises_and_leaves_the_filter_unchanged(rng):
    model, m = CASES[2]
    t, z, h, r, prior = _stream(model, m, rng)
    f = OnlineFilter(model, h, r, prior)
    f.update(t[0], z[0])
    before = (f.mean, f.cov, f.time)

    def unchanged():
        np.testing.assert_array_equal(f.mean, before[0])
        np.testing.assert_array_equal(f.cov, before[1])
        assert f.time == before[2]

    with pytest.raises(ValueError, match="not before the filter time"):
        f.update(t[0] - 1.0, z[1])
    unchanged()
    with pytest.raises(ValueError, match="not finite where present"):
        f.update(t[1], [np.nan, 1.0])
    unchanged()
    with pytest.raises(ValueError, match=r"measurement must have shape \(2,\)"):
        f.update(t[1], [1.0, 2.0, 3.0])
    unchanged()
    with pytest.raises(ValueError, match="mask must be boolean"):
        f.update(t[1], z[1], mask=[1, 0])
    unchanged()
    f.update(t[1], [np.nan, 1.0], mask=np.array([False, True]))  # NaN where missing is fine
    assert f.time == t[1]
    with pytest.raises(ValueError, match="one track"):
        OnlineFilter(
            model,
            h,
            r,
            at.GaussianState(np.zeros((2, 6)), np.broadcast_to(np.eye(6), (2, 6, 6)), 0.0),
        )
    with pytest.raises(ValueError, match="measurement_cov must be positive definite"):
        OnlineFilter(model, h, -r, prior)


@pytest.mark.parametrize("form", ["joseph", "standard", "sqrt"])
@pytest.mark.parametrize(("model", "m"), CASES)
def test_update_many_equals_row_by_row_updates(model, m, form, rng):
    """A block of rows gives the per-row updates' numbers (and the sequence filter's), also
    when a step length is new mid-block and the cache replaces rows (generated and generic)."""
    t, z, h, r, prior = _stream(model, m, rng)
    mu = 0.2 * rng.standard_normal(m)
    kw = {"form": form, "measurement_noise_mean": mu, "cache_size": 2}
    one, block = OnlineFilter(model, h, r, prior, **kw), OnlineFilter(model, h, r, prior, **kw)
    means, nis = [], []
    for k in range(t.size):
        nis.append(one.update(t[k], z[k]))
        means.append(one.mean)
    head = block.update_many(t[:25], z[:25])  # two blocks: the state carries over
    tail = block.update_many(t[25:], z[25:])
    got = np.concatenate([head.mean, tail.mean])
    np.testing.assert_allclose(got, np.array(means), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.concatenate([head.nis, tail.nis]), nis, rtol=1e-10)
    np.testing.assert_allclose(block.cov, one.cov, rtol=1e-10, atol=1e-12)
    assert block.time == one.time
    assert block.log_likelihood == pytest.approx(one.log_likelihood, rel=1e-10)
    ref = at.kalman_filter(
        t, z, model, h, r, prior, form=form, measurement_noise_mean=mu, backend="numpy"
    )
    var = np.diagonal(ref.filtered.cov, axis1=-2, axis2=-1)
    np.testing.assert_allclose(tail.variance, var[25:], rtol=1e-9)


def test_update_many_rejects_bad_blocks_before_any_step(rng):
    model, m = CASES[2]
    t, z, h, r, prior = _stream(model, m, rng)
    f = OnlineFilter(model, h, r, prior)
    before = f.state
    bad_z = z.copy()
    bad_z[7, 1] = np.nan
    back = t.copy()
    back[9] = back[8] - 0.01
    for args, match in (
        ((t, bad_z), "measurements"),
        ((back, z), "row 9"),
        ((t - 100.0, z), "row 0"),
        ((t, z[:, :1]), "shape"),
    ):
        with pytest.raises(ValueError, match=match):
            f.update_many(*args)
        np.testing.assert_array_equal(f.mean, before.mean)
        assert f.time == before.time


@pytest.mark.parametrize("method", ["expm", "taylor"])
def test_jittered_stream_with_a_known_input_equals_the_sequence_filter(method, rng):
    """Every step length new (timestamp jitter), a mean acceleration: exact methods evaluate
    each step from the series table inside the compiled step, others discretise in NumPy."""
    model = Singer(time_constant_s=4.0, accel_std_mps2=1.5, mean_accel_mps2=[0.4, -0.2], n_axes=2)
    n_steps = 200
    t = np.cumsum(0.05 + rng.uniform(-0.004, 0.004, n_steps))
    h = np.zeros((2, 6))
    h[0, 0] = h[1, 1] = 1.0
    z = rng.standard_normal((n_steps, 2)) + 0.3 * t[:, None] ** 2
    prior = at.GaussianState(np.zeros(6), 25.0 * np.eye(6), t[0])
    ref = at.kalman_filter(t, z, model, h, 0.3 * np.eye(2), prior, method=method, backend="numpy")
    f = OnlineFilter(model, h, 0.3 * np.eye(2), prior, method=method)
    got = f.update_many(t[:150], z[:150]).mean
    for k in range(150, n_steps):
        f.update(t[k], z[k])
    scale = np.abs(ref.filtered.mean).max()
    np.testing.assert_allclose(got, ref.filtered.mean[:150], rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(f.mean, ref.filtered.mean[-1], rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("block", [False, True], ids=["update", "update_many"])
def test_auto_form_continues_in_square_root_form_where_joseph_would_lose_digits(block):
    """The ill-conditioned stream of the batch filter's test (condition ratio 1.1e12): the
    default form switches to the square root at the first such step and matches the 50-digit
    reference as the batch filter does; a well-conditioned stream stays Joseph, bit for bit."""
    t, z, model, h, r, prior = ill_conditioned_problem()
    f = OnlineFilter(model, h, r, at.GaussianState(prior.mean, prior.cov, t[0] - 1.0))
    if block:
        f.update_many(t, z)
    else:
        for k in range(t.size):
            f.update(t[k], z[k])
    res = at.kalman_filter(t, z, model, h, r, at.GaussianState(prior.mean, prior.cov, t[0] - 1.0))
    mean, cov = kalman_mp(res.transition, res.process_cov, h, r, z, prior.mean, prior.cov)
    sigma = np.sqrt(np.diagonal(cov[-1]))
    assert np.max(np.abs(f.mean - mean[-1]) / sigma) < 1e-2
    assert np.max(np.abs(f.cov - cov[-1]) / np.outer(sigma, sigma)) < 1e-6
    easy = np.diag([1.0, 2.0])
    auto, joseph = (OnlineFilter(model, h, easy, prior, form=form) for form in ("auto", "joseph"))
    for k in range(1, t.size):
        assert auto.update(t[k], z[k]) == joseph.update(t[k], z[k])
    np.testing.assert_array_equal(auto.cov, joseph.cov)
