"""Shared-gain fleet filter: equal to kalman_filter / rts_smooth, generated kernels, bad input."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.filters.shared_gain import shared_gain_filter
from adaptrack.models import ConstantAcceleration, ConstantVelocity, Singer

CASES = [
    # (model, m, n_tracks): sizes 2..9 states, 1..3 measurements, lane tails (N % 4 != 0)
    (ConstantVelocity(accel_psd=0.5), 1, 9),
    (Singer(time_constant_s=5.0, accel_std_mps2=2.0), 1, 8),
    (ConstantAcceleration(jerk_psd=0.3, n_axes=2), 2, 6),
    (Singer(time_constant_s=8.0, accel_std_mps2=1.0, n_axes=3), 3, 5),
]


def _problem(model, m, n_tracks, rng, n_steps=40):
    n = model.state_dim
    t = np.cumsum(0.05 + 0.1 * rng.random(n_steps))
    h = np.zeros((m, n))
    h[np.arange(m), np.arange(m)] = 1.0  # positions first
    a = rng.standard_normal((m, m))
    r = a @ a.T + 0.5 * np.eye(m)
    z = 10.0 * rng.standard_normal((n_tracks, n_steps, m)) + 3.0 * t[None, :, None]
    mask = rng.random((n_steps, m)) > 0.2
    mask[rng.random(n_steps) < 0.1] = False  # some whole steps missing
    z[:, ~mask] = np.nan
    p0 = np.diag(rng.uniform(1.0, 50.0, n))
    prior = at.GaussianState(
        rng.standard_normal((n_tracks, n)), np.broadcast_to(p0, (n_tracks, n, n)), t[0] - 0.2
    )
    return t, z, h, r, mask, prior


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize(("model", "m", "n_tracks"), CASES)
def test_equals_the_kalman_filter_and_rts_smoother(model, m, n_tracks, backend, rng):
    t, z, h, r, mask, prior = _problem(model, m, n_tracks, rng)
    mu = 0.1 * rng.standard_normal(m)
    full_mask = np.broadcast_to(mask, z.shape)
    ref = at.kalman_filter(
        t, z, model, h, r, prior, mask=full_mask, measurement_noise_mean=mu, backend="numpy"
    )
    smoothed = at.rts_smooth(ref, backend="numpy")
    got = shared_gain_filter(
        t, z, model, h, r, prior, mask=mask, measurement_noise_mean=mu, backend=backend
    )
    scale = np.abs(ref.filtered.mean).max()
    assert np.abs(got.mean - ref.filtered.mean).max() <= 1e-10 * scale
    assert np.abs(got.cov - ref.filtered.cov[0]).max() <= 1e-10 * np.abs(got.cov).max()
    assert not got.smoothed
    got_s = shared_gain_filter(
        t, z, model, h, r, prior, mask=mask, measurement_noise_mean=mu, smooth=True, backend=backend
    )
    assert got_s.smoothed
    assert np.abs(got_s.mean - smoothed.mean).max() <= 1e-10 * scale
    assert np.abs(got_s.cov - smoothed.cov[0]).max() <= 1e-10 * np.abs(got_s.cov).max()


def test_output_buffer_is_reused_and_checked(rng):
    model, m, n_tracks = CASES[1]
    t, z, h, r, mask, prior = _problem(model, m, n_tracks, rng)
    out = np.empty((n_tracks, t.size, 3))
    res = shared_gain_filter(t, z, model, h, r, prior, mask=mask, out=out, backend="numba")
    assert res.mean is out
    again = shared_gain_filter(t, z, model, h, r, prior, mask=mask, backend="numba")
    np.testing.assert_array_equal(out, again.mean)
    for bad in (np.empty((n_tracks, t.size, 2)), np.empty((n_tracks, t.size, 3), np.float32)):
        with pytest.raises(ValueError, match="out must be a writeable float64"):
            shared_gain_filter(t, z, model, h, r, prior, mask=mask, out=bad)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_bad_input_is_named(backend, rng):
    model, m, n_tracks = CASES[2]
    t, z, h, r, mask, prior = _problem(model, m, n_tracks, rng)
    k = int(np.flatnonzero(mask[:, 1])[3])
    z[4, k, 1] = np.nan
    with pytest.raises(ValueError, match=f"nan at track 4, step {k}, component 1 where the"):
        shared_gain_filter(t, z, model, h, r, prior, mask=mask, backend=backend)
    z[4, k, 1] = np.inf  # never valid (as in kalman_filter)
    with pytest.raises(
        ValueError, match=rf"measurements must be finite; got inf at index \(4, {k}"
    ):
        shared_gain_filter(t, z, model, h, r, prior, mask=mask, backend=backend)
    z[4, k, 1] = 0.0
    with pytest.raises(ValueError, match="one pattern shared by all tracks"):
        shared_gain_filter(t, z, model, h, r, prior, mask=np.broadcast_to(mask, z.shape))
    cov = np.array(prior.cov)
    cov[2] *= 2.0
    other = at.GaussianState(prior.mean, cov, prior.time)
    with pytest.raises(ValueError, match="track 2 differs from track 0"):
        shared_gain_filter(t, z, model, h, r, other, mask=mask)
    with pytest.raises(ValueError, match="measurement_cov must be positive definite"):
        shared_gain_filter(t, z, model, h, -r, prior, mask=mask)
    with pytest.raises(ValueError, match="must not be after the first measurement"):
        late = at.GaussianState(prior.mean, prior.cov, t[0] + 1.0)
        shared_gain_filter(t, z, model, h, r, late, mask=mask)
    with pytest.raises(ValueError, match="strictly increasing"):
        shared_gain_filter(t[::-1], z, model, h, r, prior, mask=mask)
