"""EM of a linear model's noise: monotone likelihood, same maximum as direct maximisation."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import ConstantVelocity
from adaptrack.tuning import fit_by_likelihood
from adaptrack.tuning.em import em_fit
from tests.cv_truth import cv_states


def test_em_climbs_to_the_maximum_likelihood_of_direct_maximisation():
    """A 2-D CV truth (q 0.8) seen with correlated position noise; EM from a poor start
    (q 0.1, R the identity) against scipy's maximisation of the same likelihood: the same
    maximum (measured: q 0.5348 against 0.5352, R to 1e-4), the likelihood never falling."""
    rng = np.random.default_rng(12)
    dt, n, q = 0.5, 400, 0.8
    states = cv_states(rng, [[0.0, 5.0], [0.0, -2.0]], dt, q, n)
    r_true = np.array([[4.0, 1.2], [1.2, 2.0]])
    z = states[:, :, 0] + rng.multivariate_normal(np.zeros(2), r_true, n)
    t = dt * np.arange(1, n + 1)
    prior = at.GaussianState([z[0, 0], z[0, 1], 0.0, 0.0], np.diag([10.0, 10.0, 100.0, 100.0]),
                             t[0])  # fmt: skip
    unit = ConstantVelocity(accel_psd=0.1, n_axes=2)
    fit = em_fit(t, z, unit, ["x", "y"], np.eye(2), prior, tolerance=1e-9)
    assert fit.converged
    assert np.all(np.diff(fit.log_likelihood) >= -1e-8 * np.abs(fit.log_likelihood[1:]))

    def loglik(p):
        r = np.array([[p["r_xx"], p["r_xy"]], [p["r_xy"], p["r_yy"]]])
        if np.linalg.eigvalsh(r)[0] <= 0:
            return -1e12
        res = at.kalman_filter(t, z, ConstantVelocity(accel_psd=p["q"], n_axes=2), ["x", "y"],
                               r, prior)  # fmt: skip
        return float(res.log_likelihood.sum())

    direct = fit_by_likelihood(loglik, {"q": 0.5, "r_xx": 3.0, "r_yy": 3.0}, signed={"r_xy": 0.5})
    assert 0.1 * fit.process_scale == pytest.approx(direct.value("q"), rel=0.02)
    r_direct = [[direct.value("r_xx"), direct.value("r_xy")],
                [direct.value("r_xy"), direct.value("r_yy")]]  # fmt: skip
    np.testing.assert_allclose(fit.measurement_cov, r_direct, rtol=0.02, atol=0.02)
    assert fit.log_likelihood[-1] == pytest.approx(direct.log_likelihood, abs=0.05)


def test_em_refuses_missing_measurements():
    t = np.arange(5.0)
    z = np.ones((5, 1))
    z[2, 0] = np.nan
    prior = at.GaussianState([0.0, 0.0], np.eye(2), 0.0)
    with pytest.raises(ValueError, match="every measurement component present"):
        em_fit(t, z, ConstantVelocity(1.0), ["x"], [[1.0]], prior)
