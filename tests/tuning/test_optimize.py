"""Design-time tuning (spec B.7): nesting oracle, profile, recovery of a known parameter."""

import json

import numpy as np
import pytest

from adaptrack.analysis.evaluation import tracking_data
from adaptrack.models import ConstantVelocity
from adaptrack.simulation.scenario import load_scenario
from adaptrack.tuning import (
    rms_criterion,
    tune_constant_velocity,
    tune_inverse_dynamics,
    tune_shaping_filter,
)
from adaptrack.tuning.optimize import TrackingData, run_filter


@pytest.fixture(scope="module")
def training():
    return tracking_data(load_scenario("zimchuk_table1"), 8, 123)


def test_m1_never_worse_than_cv_on_training_runs(training):
    cv = tune_constant_velocity(training)
    m1 = tune_inverse_dynamics(training, cv=cv, lambdas=np.geomspace(1e-4, 1.0, 9))
    assert m1.criterion <= cv.criterion  # nesting oracle (lambda = 0 is the CV model)
    prof = m1.profile
    assert prof["lambda_per_s2"][0] == 0.0 and prof["criterion"][0] == cv.criterion
    assert len(prof["criterion"]) == 10
    # the reported criterion is what the built model achieves
    pos, vel, _ = run_filter(m1.build(1), training, 0.0)
    assert rms_criterion(pos, vel, training) == pytest.approx(m1.criterion, rel=1e-12)
    json.dumps(m1.to_dict())  # serialisable


@pytest.mark.slow
@pytest.mark.distributed
def test_m1_profile_on_a_dask_cluster_is_bit_identical(training, dask_pool):
    cv = tune_constant_velocity(training)
    grid = np.geomspace(1e-4, 1.0, 5)
    local = tune_inverse_dynamics(training, cv=cv, lambdas=grid)
    assert tune_inverse_dynamics(training, cv=cv, lambdas=grid, pool=dask_pool) == local


@pytest.mark.slow
def test_m2_tuning_runs_and_is_bounded(training):
    cv = tune_constant_velocity(training)
    m1 = tune_inverse_dynamics(training, cv=cv, lambdas=np.geomspace(1e-4, 1.0, 5))
    m2 = tune_shaping_filter(training, m1=m1)
    assert m2.params["lambda_per_s2"] >= 1e-4 * (1 - 1e-9)
    assert np.isfinite(m2.criterion) and m2.criterion > 0


@pytest.mark.statistical
def test_cv_tuning_recovers_the_true_noise_level():
    """A CV target with white acceleration of PSD q: the MSE-optimal filter is the matched one."""
    from adaptrack.simulation.linear import (
        simulate_linear_measurements,
        simulate_linear_trajectory,
    )

    rng = np.random.default_rng(42)
    q_true = 2.0
    t = 0.1 * np.arange(400)
    x = simulate_linear_trajectory(
        ConstantVelocity(accel_psd=q_true), t, [0.0, 10.0], np.diag([1.0, 1.0]), n_runs=200, rng=rng
    )
    z = simulate_linear_measurements(x, [[1.0, 0.0]], [[4.0]], rng=rng)
    score = np.ones((200, 400), dtype=bool)
    score[:, :100] = False  # steady state
    data = TrackingData(
        np.broadcast_to(t, (200, 400)),
        z,
        np.array([[4.0]]),
        np.ones((200, 400), dtype=bool),
        x[..., :1],
        x[..., 1:],
        score,
    )
    cv = tune_constant_velocity(data)
    # the criterion is flat near its minimum: accept a factor 1.5 either way (80,000 errors)
    assert q_true / 1.5 < cv.params["accel_psd"] < q_true * 1.5
