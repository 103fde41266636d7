"""The compiled Kalman-filter kernel equals the NumPy reference (<= 1e-10 relative)."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import ConstantVelocity, ShapingFilter, Singer


def rel(a, b):
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


CASES = {
    "shared-times": dict(per_track_times=False, partial=False, per_step_r=False),
    "per-track-times": dict(per_track_times=True, partial=False, per_step_r=False),
    "partial-masks": dict(per_track_times=True, partial=True, per_step_r=False),
    "per-step-R": dict(per_track_times=False, partial=True, per_step_r=True),
}


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("form", ["joseph", "standard", "sqrt"])
def test_compiled_equals_numpy(name, form):
    cfg = CASES[name]
    rng = np.random.default_rng(
        [list(CASES).index(name), ["joseph", "standard", "sqrt"].index(form)]
    )
    model = Singer(time_constant_s=[3.0, 8.0], accel_std_mps2=[1.0, 2.5], n_axes=2)
    n_tr, n_st = 4, 60
    t = np.cumsum(rng.uniform(0.02, 0.5, (n_tr, n_st) if cfg["per_track_times"] else n_st), axis=-1)
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    z = rng.normal(size=(n_tr, n_st, 2)) * 10
    mask = (
        rng.uniform(size=(n_tr, n_st, 2)) > 0.3
        if cfg["partial"]
        else rng.uniform(size=(n_tr, n_st)) > 0.1
    )
    r = (
        np.diag([2.0, 3.0]) * rng.uniform(0.5, 2.0, (n_tr, n_st, 1, 1))
        if cfg["per_step_r"]
        else np.array([[2.0, 0.3], [0.3, 1.0]])
    )
    prior = at.GaussianState(
        np.zeros((n_tr, 6)), np.broadcast_to(50 * np.eye(6), (n_tr, 6, 6)), 0.0
    )
    kw = dict(mask=mask, form=form, measurement_noise_mean=[0.1, -0.2])
    a = at.kalman_filter(t, z, model, h, r, prior, backend="numpy", **kw)
    b = at.kalman_filter(t, z, model, h, r, prior, backend="numba", **kw)
    for x, y in (
        (a.filtered.mean, b.filtered.mean),
        (a.filtered.cov, b.filtered.cov),
        (a.predicted.cov, b.predicted.cov),
        (a.info.innovation, b.info.innovation),
        (a.info.gain, b.info.gain),
        (a.info.nis, b.info.nis),
        (a.info.log_likelihood, b.info.log_likelihood),
    ):
        assert rel(y, x) <= 1e-10
    np.testing.assert_array_equal(a.info.n_observed, b.info.n_observed)


def test_auto_uses_numpy_for_small_and_the_kernel_for_large_workloads():
    rng = np.random.default_rng(3)
    model = ConstantVelocity(accel_psd=1.0)
    prior = at.GaussianState([0.0, 0.0], 100 * np.eye(2), 0.0)
    t = 0.05 * np.arange(30_000)
    z = rng.normal(size=(30_000, 1))
    small = at.kalman_filter(t[:100], z[:100], model, [[1.0, 0.0]], [[1.0]], prior)
    ref = at.kalman_filter(t[:100], z[:100], model, [[1.0, 0.0]], [[1.0]], prior, backend="numpy")
    np.testing.assert_array_equal(small.filtered.mean, ref.filtered.mean)
    big = at.kalman_filter(t, z, model, [[1.0, 0.0]], [[1.0]], prior)
    big_ref = at.kalman_filter(t, z, model, [[1.0, 0.0]], [[1.0]], prior, backend="numpy")
    assert rel(big.filtered.mean, big_ref.filtered.mean) <= 1e-10
    with pytest.raises(ValueError, match="backend must be 'auto', 'numpy' or 'numba'"):
        at.kalman_filter(t[:5], z[:5], model, [[1.0, 0.0]], [[1.0]], prior, backend="cuda")


def test_compiled_three_state_models_and_rts_on_top():
    rng = np.random.default_rng(9)
    model = ShapingFilter(lambda_per_s2=0.05, alpha_per_s=0.3, shaping_std=5.0)
    t = np.cumsum(rng.uniform(0.05, 0.2, 80))
    z = rng.normal(size=(2, 80, 1))
    prior = at.GaussianState(np.zeros(3), 10 * np.eye(3), t[0])
    a = at.kalman_filter(t, z, model, [[1.0, 0, 0]], [[0.5]], prior, backend="numpy")
    b = at.kalman_filter(t, z, model, [[1.0, 0, 0]], [[0.5]], prior, backend="numba")
    assert rel(at.rts_smooth(b).mean, at.rts_smooth(a).mean) <= 1e-10


@pytest.mark.parametrize("per_track_times", [False, True])
def test_compiled_rts_equals_numpy(per_track_times):
    rng = np.random.default_rng(11 + per_track_times)
    model = Singer(time_constant_s=4.0, accel_std_mps2=2.0)
    shape = (3, 70) if per_track_times else 70
    t = np.cumsum(rng.uniform(0.05, 0.3, shape), axis=-1)
    z = rng.normal(size=(3, 70, 1))
    prior = at.GaussianState(np.zeros((3, 3)), np.broadcast_to(20 * np.eye(3), (3, 3, 3)), 0.0)
    res = at.kalman_filter(
        t, z, model, [[1.0, 0, 0]], [[0.3]], prior, mask=rng.uniform(size=(3, 70)) > 0.2
    )
    a = at.rts_smooth(res, backend="numpy")
    b = at.rts_smooth(res, backend="numba")
    assert rel(b.mean, a.mean) <= 1e-10 and rel(b.cov, a.cov) <= 1e-10
    with pytest.raises(ValueError, match="backend must be"):
        at.rts_smooth(res, backend="gpu")
