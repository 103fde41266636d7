"""Error metrics."""

import numpy as np

from adaptrack.analysis.metrics import anees_band, nees, rmse


def test_nees_of_singular_covariance_is_infinite_off_its_range():
    cov = np.array([[[1.0, 0.0], [0.0, 0.0]], [[2.0, 0.0], [0.0, 4.0]]])
    err = np.array([[1.0, 1.0], [2.0, 2.0]])
    out = nees(err, cov)
    assert out[0] == np.inf and out[1] == 2.0 + 1.0
    assert nees([[2.0, 0.0]], [[[1.0, 0.0], [0.0, 0.0]]])[0] == 4.0


def test_rmse_and_anees_band():
    assert rmse([[3.0, 4.0], [0.0, 0.0]]) == np.sqrt(12.5)
    lo, hi = anees_band(2, 50)
    assert round(lo, 2) == 1.48 and round(hi, 2) == 2.59  # DOMAIN section 5
