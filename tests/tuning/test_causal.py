"""Causal self-tuning (refit_online): causality, bookkeeping, recovery from a bad start."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import ConstantVelocity
from adaptrack.tuning.causal import refit_online

R = 9.0  # measurement variance [m^2]


def _run(times, meas, p):
    """Kalman filter of one CV track (PSD ``p["q"]``) on its positions."""
    prior = at.GaussianState([meas[0, 0], 0.0], np.diag([R, 100.0]), times[0])
    res = at.kalman_filter(times, meas, ConstantVelocity(p["q"]), ["x"], [[R]], prior)
    return res.info.log_likelihood, res.filtered.mean


def _track(rng, times, q=0.01):
    """Positions of a white-acceleration track (PSD ``q``) and noisy fixes of them."""
    dt = np.diff(times, prepend=times[0])
    v = 2.0 + np.cumsum(rng.normal(0.0, 1.0, times.size) * np.sqrt(q * dt))
    x = np.cumsum(v * dt)
    return x, (x + rng.normal(0.0, np.sqrt(R), times.size))[:, None]


def _two_segments(rng):
    """Two tracks whose times interleave (one every 2 s, the other every 3 s from 1 s)."""
    ta, tb = np.arange(0.0, 240.0, 2.0), np.arange(1.0, 241.0, 3.0)
    return [(ta, _track(rng, ta)[1]), (tb, _track(rng, tb)[1])]


def test_an_estimate_depends_on_no_later_measurement():
    segs = _two_segments(np.random.default_rng(3))
    base = refit_online(segs, _run, {"q": 1.0}, first=20)
    cut = 120.0
    later = [(t, np.where(t[:, None] > cut, z + 50.0, z)) for t, z in segs]
    moved = refit_online(later, _run, {"q": 1.0}, first=20)
    for (t, _), a, b in zip(segs, base.estimates, moved.estimates, strict=True):
        np.testing.assert_array_equal(a[t <= cut], b[t <= cut])
        assert np.all(np.abs(a[t > cut] - b[t > cut]).max(axis=-1) > 0.0)
    early = base.fit_times < cut
    assert early.sum() >= 2 and not early.all()
    for f, g in zip(np.array(base.fits)[early], np.array(moved.fits)[early], strict=True):
        assert f.value("q") == g.value("q") and f.std_error("q") == g.std_error("q")


def test_each_estimate_is_the_filter_with_the_last_fit_before_it():
    segs = _two_segments(np.random.default_rng(4))
    online = refit_online(segs, _run, {"q": 1.0}, first=20, growth=1.5)
    assert len(online.fits) == len(online.fit_times) >= 4
    assert np.all(np.diff(online.fit_times) > 0)
    for (t, z), est, used in zip(segs, online.estimates, online.refit, strict=True):
        assert np.all(np.diff(used) >= 0) and used[0] == -1
        for k in range(0, t.size, 7):
            j = used[k]
            assert j == -1 or online.fit_times[j] <= t[k]
            assert j + 1 == len(online.fits) or online.fit_times[j + 1] >= t[k]
            p = {"q": 1.0} if j < 0 else online.params[j]
            np.testing.assert_array_equal(est[k], _run(t[: k + 1], z[: k + 1], p)[1][k])


def test_refit_counts_grow_by_the_factor_given():
    segs = _two_segments(np.random.default_rng(5))  # 120 + 80 measurements
    online = refit_online(segs, _run, {"q": 1.0}, first=25, growth=2.0)
    seen = [sum(int(np.sum(t <= ft)) for t, _ in segs) for ft in online.fit_times]
    assert seen == [25, 50, 100]


def test_without_a_refit_the_run_is_the_filter_itself():
    t, z = _two_segments(np.random.default_rng(6))[0]
    online = refit_online([(t, z)], _run, {"q": 0.3}, first=t.size)
    assert online.fits == [] and np.all(online.refit[0] == -1)
    np.testing.assert_array_equal(online.estimates[0], _run(t, z, {"q": 0.3})[1])


def test_a_start_a_thousand_times_too_large_is_unlearnt():
    """Seeded Monte Carlo, 12 tracks (q 0.01, sigma 3 m, 1 Hz, 300 s) started at q = 10: past
    the first 100 s the refitted runs' MSE is below the start's by > 3 standard errors of the
    paired difference, and within 15 % of the filter with the true q."""
    rng = np.random.default_rng(11)
    t = np.arange(300.0)
    diffs, online_mse, true_mse = [], [], []
    for _ in range(12):
        x, z = _track(rng, t)
        err = {name: np.mean((est[100:, 0] - x[100:]) ** 2) for name, est in (
            ("online", refit_online([(t, z)], _run, {"q": 10.0}).estimates[0]),
            ("start", _run(t, z, {"q": 10.0})[1]),
            ("true", _run(t, z, {"q": 0.01})[1]),
        )}  # fmt: skip
        diffs.append(err["start"] - err["online"])
        online_mse.append(err["online"])
        true_mse.append(err["true"])
    assert np.mean(diffs) > 3.0 * np.std(diffs, ddof=1) / np.sqrt(len(diffs))
    assert np.mean(online_mse) < 1.15 * np.mean(true_mse)


@pytest.mark.parametrize(
    ("segments", "kwargs", "message"),
    [
        ([], {}, "segments is empty"),
        ([(np.array([0.0, 2.0, 1.0]), np.zeros((3, 1)))], {}, r"segments\[0\]: times must incr"),
        ([(np.array([0.0, np.nan]), np.zeros((2, 1)))], {}, r"segments\[0\]: time 1 is not fin"),
        ([(np.arange(3.0), np.zeros((2, 1)))], {}, "must have 3 rows"),
        ([(np.arange(3.0), np.zeros((3, 1)))], {"first": 1}, "first must be an int >= 2"),
        ([(np.arange(3.0), np.zeros((3, 1)))], {"growth": 1.0}, "growth must be"),
        ([(np.arange(3.0), np.zeros((3, 1)))], {"max_relative_error": 0.0}, "max_relative_e"),
        ([(np.arange(3.0), np.zeros((3, 1)))], {"max_relative_error": np.nan}, "max_relative_e"),
    ],
)
def test_bad_input_is_named(segments, kwargs, message):
    with pytest.raises(ValueError, match=message):
        refit_online(segments, _run, {"q": 1.0}, **kwargs)


def test_measurements_are_checked_by_the_filter_it_wraps():
    """A NaN fix is the wrapped filter's to judge: a filter that raises on it stops the run
    with its error (naming the step); one that takes NaN as missing gets a run whose missing
    steps add nothing to the likelihood and whose estimates are all finite."""
    rng = np.random.default_rng(4)
    (ta, za), (tb, zb) = _two_segments(rng)
    za[[5, 70]] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        refit_online([(ta, za), (tb, zb)], _run, {"q": 1.0}, first=40)

    def run_missing(times, meas, p):
        prior = at.GaussianState([meas[0, 0], 0.0], np.diag([R, 100.0]), times[0])
        res = at.kalman_filter(times, meas, ConstantVelocity(p["q"]), ["x"], [[R]], prior,
                               nan_policy="missing")  # fmt: skip
        return res.info.log_likelihood, res.filtered.mean

    online = refit_online([(ta, za), (tb, zb)], run_missing, {"q": 1.0}, first=40)
    assert all(np.all(np.isfinite(est)) for est in online.estimates)
    assert run_missing(ta, za, {"q": 1.0})[0][[5, 70]].tolist() == [0.0, 0.0]
    assert len(online.fits) == 3  # 200 measurements: refits at 40, 80 and 160
