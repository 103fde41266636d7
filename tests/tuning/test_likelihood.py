"""Truth-free tuning by maximum likelihood: estimates and standard errors on seeded data.

The data come from a constant-velocity process simulated here with its own closed-form
transition and noise (not adaptrack's discretisation), observed in white noise.
"""

import math

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import ConstantVelocity
from adaptrack.tuning import fit_by_likelihood

Q, R, DT, T = 0.5, 0.25, 0.1, 300  # white-acceleration PSD [m^2/s^3], noise variance [m^2]


def simulate(seed):
    rng = np.random.default_rng(seed)
    phi = np.array([[1.0, DT], [0.0, 1.0]])
    chol = np.linalg.cholesky(Q * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]]))
    x, xs = np.array([0.0, 3.0]), []
    for _ in range(T):
        x = phi @ x + chol @ rng.standard_normal(2)
        xs.append(x[0])
    return DT * np.arange(1, T + 1), (np.array(xs) + rng.normal(0, np.sqrt(R), T))[:, None]


def fit(t, z):
    def loglik(p):
        prior = at.GaussianState([z[0, 0], 0.0], np.diag([1.0, 100.0]), t[0] - DT)
        res = at.kalman_filter(t, z, ConstantVelocity(accel_psd=p["q"]), ["x"], [[p["r"]]],
                               prior, backend="numba")  # fmt: skip
        return float(res.info.log_likelihood.sum())

    return fit_by_likelihood(loglik, {"q": 1.0, "r": 1.0})


@pytest.mark.statistical
def test_estimates_and_standard_errors_are_honest_over_seeded_runs():
    """40 runs: the log-scale z-scores of q and r are standard normal, the intervals cover.

    z = log(estimate / truth) / (standard error / estimate). Mean within +-0.6 (3.8 standard
    errors of a mean of 40) and sd in [0.7, 1.5] (sd of a sample sd of 40: 0.11; measured
    1.20 for q, 0.94 for r: q's curvature slightly flatters it on 30 s of data); standard
    errors half their size would give sd near 2. 95 % intervals cover in >= 31 of 40 (measured
    37 and 37; at a true 90 % coverage the chance of 30 or fewer is 0.5 %).
    """
    zs, covered = [], np.zeros(2, int)
    for seed in range(40):
        f = fit(*simulate(seed))
        assert f.converged, f.message
        zs.append([np.log(f.value(k) / v) / (f.std_error(k) / f.value(k))
                   for k, v in (("q", Q), ("r", R))])  # fmt: skip
        covered += [f.interval(k)[0] <= v <= f.interval(k)[1] for k, v in (("q", Q), ("r", R))]
    zs = np.array(zs)
    assert np.all(np.abs(zs.mean(axis=0)) < 0.6), zs.mean(axis=0)
    assert np.all((zs.std(axis=0) > 0.7) & (zs.std(axis=0) < 1.5)), zs.std(axis=0)
    assert np.all(covered >= 31), covered


def test_the_maximum_is_a_maximum_and_its_value_is_reported():
    t, z = simulate(100)
    f = fit(t, z)
    assert f.names == ("q", "r") and f.log_likelihood < 0
    for k in ("q", "r"):  # every neighbour is less likely
        for factor in (0.9, 1.1):
            p = {n: f.value(n) for n in f.names}
            p[k] *= factor
            prior = at.GaussianState([z[0, 0], 0.0], np.diag([1.0, 100.0]), t[0] - DT)
            res = at.kalman_filter(t, z, ConstantVelocity(accel_psd=p["q"]), ["x"], [[p["r"]]],
                                   prior)  # fmt: skip
            assert res.info.log_likelihood.sum() < f.log_likelihood


@pytest.mark.parametrize(
    ("initial", "bounds", "message"),
    [
        ({"q": 0.0}, None, "must be finite and > 0"),
        ({"q": np.nan}, None, "must be finite and > 0"),
        ({}, None, "give each parameter once"),
        ({"q": 1.0}, {"q": (2.0, 1.0)}, r"bounds\['q'\] must satisfy"),
    ],
)
def test_bad_input(initial, bounds, message):
    with pytest.raises(ValueError, match=message):
        fit_by_likelihood(lambda p: -1.0, initial, bounds=bounds)


def test_bounds_and_scales_must_name_parameters_of_their_kind():
    with pytest.raises(ValueError, match=r"bounds names \['t'\], which are not among \['q'\]"):
        fit_by_likelihood(lambda p: -1.0, {"q": 1.0}, signed={"t": 0.0}, bounds={"t": (1, 2)})
    with pytest.raises(ValueError, match=r"scales names \['q'\]"):
        fit_by_likelihood(lambda p: -1.0, {"q": 1.0}, scales={"q": 2.0})


def test_a_likelihood_not_finite_at_the_start_is_an_error():
    with pytest.raises(ValueError, match="not finite at the initial values"):
        fit_by_likelihood(lambda p: float("nan"), {"q": 1.0})


@pytest.mark.parametrize("beyond", ["covariance error", "nan", "-inf"])
def test_values_the_filter_cannot_run_with_are_stepped_around_not_fatal(beyond):
    """A log-likelihood with its maximum at q = 2 (log-scale curvature 100: standard error
    0.2) that cannot be evaluated beyond q = 3 (the filter raises ``CovarianceError``, or
    gives NaN or -inf). L-BFGS-B alone stopped at q = 0.14 and called it converged after a
    trial step met q > 3; the fit must find the maximum, its standard error from the
    curvature, and must have met the region (the test can fail)."""
    met = []

    def loglik(p):
        if p["q"] > 3.0:
            met.append(p["q"])
            if beyond == "covariance error":
                raise at.CovarianceError("innovation covariance is not positive definite")
            return float(beyond)
        return -math.sqrt(1.0 + ((math.log(p["q"]) - math.log(2.0)) / 0.1) ** 2)

    fit = fit_by_likelihood(loglik, {"q": 0.05})
    assert met and fit.converged
    assert fit.value("q") == pytest.approx(2.0, rel=1e-4)
    assert fit.std_error("q") == pytest.approx(0.2, rel=1e-2)


def test_a_filter_error_at_the_starting_values_is_the_callers():
    def loglik(p):
        raise at.CovarianceError("innovation covariance is not positive definite at step 1")

    with pytest.raises(at.CovarianceError, match="step 1"):
        fit_by_likelihood(loglik, {"q": 1.0})


def test_a_nearly_flat_likelihood_gives_an_unbounded_interval_not_an_overflow():
    """A parameter whose standard error is 1e6 times its value (a turn PSD on a straight
    drive): the log-scale interval is (0, inf), as exp(+-1.96e6) rounds; a moderate one keeps
    its finite interval."""
    from adaptrack.tuning.likelihood import LikelihoodFit

    fit = LikelihoodFit(("q", "r"), np.array([1e-8, 2.0]), np.diag([1e-4, 0.01]), 0.0, True, "")
    assert fit.interval("q") == (0.0, math.inf)
    lo, hi = fit.interval("r")
    half = 1.959963984540054 * 0.1 / 2.0
    assert (lo, hi) == pytest.approx((2.0 * math.exp(-half), 2.0 * math.exp(half)), rel=1e-12)


def test_trial_steps_beyond_the_float_range_are_infeasible_not_fatal():
    """A maximum far out (log q = 100): L-BFGS-B's trial steps overflow exp (q = inf), which a
    model refuses (as ``CoordinatedTurn`` refuses an infinite PSD). Such a step is infinitely
    unlikely and the search goes on to the maximum."""

    def loglik(v):
        if not (math.isfinite(v["q"]) and v["q"] > 0):
            raise ValueError(f"q must be finite and > 0; got {v['q']}")
        return -abs(math.log(v["q"]) - 100.0) - (v["r"] - 2.0) ** 2

    fit = fit_by_likelihood(loglik, {"q": 1.0, "r": 1.0})
    assert math.log(fit.value("q")) == pytest.approx(100.0, abs=1e-3)
    assert fit.value("r") == pytest.approx(2.0, abs=1e-3)


def test_a_rough_likelihood_gives_no_standard_error_not_a_false_one():
    """A ripple of period 0.9 % in log q (as a filter whose estimates jump with small
    parameter changes gives): the curvature over 1 % steps is the ripple's, which would
    make a tiny interval. The fit names q rough and gives it no standard error; r, smooth
    and independent of q, keeps its own (the curvature 2 / 0.02 of its quadratic)."""

    def loglik(v):
        lq = math.log(v["q"])
        return -100.0 * lq**2 + 5.0 * math.sin(700.0 * lq) - (v["r"] - 2.0) ** 2 / 0.02

    fit = fit_by_likelihood(loglik, {"q": 1.0, "r": 1.0})
    assert fit.rough == ("q",)
    assert math.isnan(fit.std_error("q"))
    assert fit.std_error("r") == pytest.approx(0.1, rel=0.01)


def test_a_smooth_likelihood_is_not_called_rough():
    fit = fit_by_likelihood(lambda v: -((v["q"] - 3.0) ** 2) - math.log(v["r"]) ** 2,
                            {"q": 1.0, "r": 2.0})  # fmt: skip
    assert fit.rough == ()
    assert fit.std_error("q") == pytest.approx(math.sqrt(0.5), rel=0.01)
