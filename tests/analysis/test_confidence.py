"""Confidence bounds of a Monte-Carlo RMS (ratio estimator over runs, log scale)."""

import math

import numpy as np
import pytest
from scipy.stats import t as student_t

from adaptrack.analysis.confidence import rms_with_bounds


def test_bounds_oracle_by_hand():
    # 4 runs, squared-error sums y and epoch counts x
    y = np.array([4.0, 9.0, 1.0, 6.0])
    x = np.array([2.0, 3.0, 1.0, 2.0])
    rms, lo, hi = rms_with_bounds(y[:, None], x[:, None], 0.9)
    ratio = 20.0 / 8.0
    resid = y - ratio * x  # [-1, 1.5, -1.5, 1]
    se = math.sqrt(np.sum(resid**2) / (4 * 3)) / 2.0
    log_half = student_t.ppf(0.9, 3) * se / ratio
    assert rms[0] == pytest.approx(math.sqrt(ratio), rel=1e-15)
    assert hi[0] == pytest.approx(math.sqrt(ratio * math.exp(log_half)), rel=1e-14)
    assert lo[0] == pytest.approx(math.sqrt(ratio * math.exp(-log_half)), rel=1e-14)


def test_trailing_quantities_empty_columns_and_one_run():
    y = np.array([[1.0, 0.0], [3.0, 0.0]])
    x = np.array([[1.0, 0.0], [1.0, 0.0]])
    rms, _, hi = rms_with_bounds(y, x)
    assert rms[0] == pytest.approx(math.sqrt(2.0)) and np.isnan(rms[1]) and np.isnan(hi[1])
    rms1, lo1, hi1 = rms_with_bounds(y[:1], x[:1])
    assert rms1[0] == 1.0 and lo1[0] == 0.0 and hi1[0] == math.inf
    zero, lo0, hi0 = rms_with_bounds(np.zeros((3, 1)), np.ones((3, 1)))
    assert zero[0] == lo0[0] == hi0[0] == 0.0  # no error at all: no spread


def test_bounds_narrow_with_runs():
    rng = np.random.default_rng(3)
    y = rng.chisquare(4, (400, 1))
    x = np.ones((400, 1))
    widths = [
        np.diff(rms_with_bounds(y[:n], x[:n], 0.95)[1:], axis=0)[0, 0] for n in (10, 100, 400)
    ]
    assert widths[0] > widths[1] > widths[2] > 0


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"squares": [[1.0]], "counts": [[1.0], [2.0]]}, "counts must have the shape"),
        ({"squares": [[-1.0]], "counts": [[1.0]]}, "must be >= 0"),
        ({"squares": [[1.0]], "counts": [[1.0]], "confidence": 1.0}, r"confidence must lie in"),
        ({"squares": [[np.nan]], "counts": [[1.0]]}, "squares"),
    ],
)
def test_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        rms_with_bounds(**kwargs)
