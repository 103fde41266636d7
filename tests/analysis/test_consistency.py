"""Innovation consistency without truth: chi-square, binomial and whiteness bands."""

import numpy as np
import pytest
from scipy.stats import binom

import adaptrack as at
from adaptrack.analysis.consistency import innovation_consistency
from adaptrack.models import ConstantVelocity
from tests.cv_truth import cv_states

Q, R, DT, N = 0.5, 0.25, 0.1, 500
MODEL = ConstantVelocity(accel_psd=Q, n_axes=2)


def _track(seed, n=N):
    """Planar CV truth from its own closed form, positions measured with variance R."""
    rng = np.random.default_rng(seed)
    pos = cv_states(rng, [[0.0, 5.0], [0.0, -2.0]], DT, Q, n)[:, :, 0]
    return DT * np.arange(1, n + 1), pos + rng.normal(0.0, np.sqrt(R), (n, 2))


def _run(t, z, q=Q, r=R):
    prior = at.GaussianState([0.0, 0.0, 5.0, -2.0], np.diag([1.0, 1.0, 1.0, 1.0]), 0.0)
    model = ConstantVelocity(accel_psd=q, n_axes=2)
    return at.kalman_filter(t, z, model, ["x", "y"], r * np.eye(2), prior)


@pytest.mark.statistical
def test_a_right_filter_is_inside_each_band_at_its_rate():
    """40 seeded runs of the filter of the simulated model: each band holds in about 95 % of
    runs. The count inside is binomial(40, 0.95): fewer than 34 has probability 0.3 % for
    each test; all three at once (about 0.857 a run), fewer than 28 has 0.3 %."""
    checks = [innovation_consistency(_run(*_track(seed))) for seed in range(40)]
    floor = 34
    assert binom.cdf(floor - 1, 40, 0.95) < 0.004 and binom.cdf(27, 40, 0.95**3) < 0.004
    inside = {
        "mean": sum(c.mean_nis_band[0] <= c.mean_nis <= c.mean_nis_band[1] for c in checks),
        "lag1": sum(abs(c.lag1) <= c.lag1_limit for c in checks),
        "outside": sum(c.outside_band[0] <= c.outside <= c.outside_band[1] for c in checks),
    }
    assert all(v >= floor for v in inside.values()), inside
    assert sum(c.verdict == "consistent" for c in checks) >= 28
    assert all(c.dof == 2 and c.n_updates == N for c in checks)


def test_wrong_noise_and_wrong_motion_are_named():
    """Noise variance taken 4x too small: overconfident; 4x too large: underconfident; a
    motion PSD 1000x too small leaves correlated innovations (lag-1 beyond its band)."""
    t, z = _track(7)
    assert innovation_consistency(_run(t, z, r=R / 4)).verdict.startswith("overconfident")
    assert innovation_consistency(_run(t, z, r=R * 4)).verdict.startswith("underconfident")
    slow = innovation_consistency(_run(t, z, q=Q / 1000))
    assert slow.lag1 > slow.lag1_limit


def test_missing_updates_are_left_out_and_bad_calls_named():
    t, z = _track(8, 60)
    z[10:20] = np.nan
    prior = at.GaussianState([0.0, 0.0, 5.0, -2.0], np.eye(4), 0.0)
    res = at.kalman_filter(t, z, MODEL, ["x", "y"], R * np.eye(2), prior, nan_policy="missing")
    assert innovation_consistency(res).n_updates == 50
    batch = at.kalman_filter(
        t, np.stack([z, z]), MODEL, ["x", "y"], R * np.eye(2), prior, nan_policy="missing"
    )
    with pytest.raises(ValueError, match="one track"):
        innovation_consistency(batch)
    with pytest.raises(ValueError, match="level"):
        innovation_consistency(res, level=1.5)
