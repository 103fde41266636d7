"""Series tables (matrix polynomials in the step) against the exact discretisation."""

import math

import numpy as np
import pytest

from adaptrack.filters._kernels import SERIES_CHUNK, series_bank_row, series_transitions
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    InverseDynamics,
    ShapingFilter,
    Singer,
    control_offset,
    discretize,
)
from adaptrack.models.series_table import model_series_table, series_table, shortened


def _discretize(dt, table):
    """(Phi, Qd, u) of one step through the kernels' series evaluation."""
    n = table.phi_coef.shape[1]
    row = np.empty((1, 1 + 2 * n * n + n))
    series_bank_row(row, 0, dt, *table)
    return (
        row[0, 1 : 1 + n * n].reshape(n, n),
        row[0, 1 + n * n : 1 + 2 * n * n].reshape(n, n),
        row[0, 1 + 2 * n * n :],
    )


def _evaluate(dt, table):
    return _discretize(dt, table)[:2]


MODELS = [
    ConstantVelocity(accel_psd=3.0, n_axes=2),
    ConstantAcceleration(jerk_psd=3.0),
    Singer(time_constant_s=2.0, accel_std_mps2=3.0),
    InverseDynamics(lambda_per_s2=0.05, accel_psd=0.4),
    InverseDynamics(lambda_per_s2=4.0, accel_psd=0.4),
    ShapingFilter(0.05, 1 / 3, 5.0),
    ShapingFilter(0.09, 0.3, 5.0),  # alpha = sqrt(lambda): confluent
]
STEPS = [0.0, 1e-6, 0.01, 0.0437, 0.05, 0.061, 0.3, 1.0, 5.0, 40.0]


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__)
@pytest.mark.parametrize("max_dt", [0.06, math.inf])
def test_series_equals_exact_discretisation(model, max_dt):
    """Normwise <= 1e-13 against the element-wise accurate closed forms / Van Loan (spec
    0.3: the M2 analytic recipe's accuracy), including steps that need doublings."""
    table = model_series_table(model, max_dt)
    for dt in STEPS:
        phi, qd = _evaluate(dt, table)
        ref_phi, ref_qd = discretize(model, dt, method="analytic")
        assert np.max(np.abs(phi - ref_phi)) <= 1e-13 * np.max(np.abs(ref_phi)), dt
        assert np.max(np.abs(qd - ref_qd)) <= 1e-13 * max(np.max(np.abs(ref_qd)), 1e-300), dt
        np.testing.assert_array_equal(qd, qd.T)
    phi, qd = _evaluate(0.0, table)
    np.testing.assert_array_equal(phi, np.eye(phi.shape[0]))
    assert not qd.any()


WITH_INPUT = Singer(time_constant_s=2.0, accel_std_mps2=1.0, mean_accel_mps2=[0.5, -1.5], n_axes=2)


@pytest.mark.parametrize("model", [*MODELS, WITH_INPUT], ids=lambda m: type(m).__name__)
def test_batched_steps_equal_single_steps_bit_for_bit(model):
    """``series_transitions`` (steps side by side, for jittered batches) gives each step's
    single-step values exactly, over more than one chunk, with doublings and an offset."""
    rng = np.random.default_rng(5)
    dt = np.concatenate([rng.uniform(0.0, 0.07, SERIES_CHUNK + 7), STEPS])
    table = model_series_table(model, 0.06)
    phi, qd, u = series_transitions(dt, table.phi_coef, table.qd_coef, table.offset_coef,
                                    table.h_max)  # fmt: skip
    for k in [*range(0, dt.size, 97), *range(dt.size - len(STEPS), dt.size)]:
        one = _discretize(dt[k], table)
        np.testing.assert_array_equal(phi[k], one[0])
        np.testing.assert_array_equal(qd[k], one[1])
        np.testing.assert_array_equal(u[k], one[2])


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__)
def test_a_shortened_table_for_short_steps_is_still_exact(model):
    """A table for steps up to 0.06 s keeps only the terms above 1e-17 there: fewer of them
    for the non-nilpotent models, and the same accuracy against the closed forms on every
    step (doublings included)."""
    full = model_series_table(model, 0.06)
    table = shortened(full)
    if not math.isinf(full.h_max):
        assert table.phi_coef.shape[0] < full.phi_coef.shape[0]
        assert table.qd_coef.shape[0] < full.qd_coef.shape[0]
    for dt in STEPS:
        phi, qd = _evaluate(dt, table)
        ref_phi, ref_qd = discretize(model, dt, method="analytic")
        assert np.max(np.abs(phi - ref_phi)) <= 1e-13 * np.max(np.abs(ref_phi)), dt
        assert np.max(np.abs(qd - ref_qd)) <= 1e-13 * max(np.max(np.abs(ref_qd)), 1e-300), dt


def test_nilpotent_models_are_exact_without_doublings():
    """Constant velocity/acceleration: finite series (F^3 = 0), any step in one evaluation."""
    table = model_series_table(ConstantAcceleration(jerk_psd=2.0))
    assert table.h_max == math.inf
    assert table.phi_coef.shape[0] == 3 and table.qd_coef.shape[0] == 5
    phi, qd = _evaluate(7.0, table)
    ref_phi, ref_qd = discretize(ConstantAcceleration(jerk_psd=2.0), 7.0, method="analytic")
    np.testing.assert_allclose(phi, ref_phi, rtol=1e-15)
    np.testing.assert_allclose(qd, ref_qd, rtol=1e-14)


def test_appended_random_walk_and_bad_max_dt():
    table = model_series_table(ConstantVelocity(accel_psd=1.0), 0.1, (0.01,))
    phi, qd = _evaluate(0.5, table)
    assert phi[2, 2] == 1.0 and qd[2, 2] == pytest.approx(0.005, rel=1e-15)
    assert not phi[:2, 2].any() and not qd[:2, 2].any()
    with pytest.raises(ValueError, match="max_dt"):
        series_table(np.zeros((2, 2)), np.eye(2), 0.0)


@pytest.mark.parametrize("max_dt", [0.06, math.inf])
def test_known_input_offset_equals_control_offset(max_dt):
    """The known-input offset ``u(dt)`` (mean acceleration of a Singer model), with doublings."""
    model = WITH_INPUT
    table = model_series_table(model, max_dt)
    assert table.offset_coef.shape[1] == 6
    assert model_series_table(Singer(time_constant_s=2.0)).offset_coef.shape == (0, 3)
    for dt in STEPS:
        _, _, u = _discretize(dt, table)
        ref = control_offset(model, dt, method="analytic")
        np.testing.assert_allclose(u, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max(initial=1.0))
