"""Design-time adaptation to a site."""

import numpy as np
import pytest

from adaptrack.crossing.site import load_site
from adaptrack.crossing.tuning import (
    load_tuning,
    road_criterion,
    training_runs,
    tune_road_model,
)
from adaptrack.models import InverseDynamics


def test_tuning_is_never_worse_than_cv_and_round_trips(tmp_path):
    site = load_site("lx_default")
    res = tune_road_model(site, n_runs=1, seed=3, lambdas=(0.01, 0.3))
    # nesting oracle: lambda = 0 (the CV model) is part of the profile
    assert res.criterion <= res.baseline_criterion
    assert res.profile["lambda_per_s2"][0] == 0.0
    assert res.profile["criterion"][0] == res.baseline_criterion
    # the reported criterion is what the tuned model achieves on the same training runs
    training = training_runs(site, 1, 3)
    again = road_criterion(res.model(), site, training)
    assert np.isclose(again, res.criterion, rtol=1e-12)
    path = tmp_path / "tuned.toml"
    path.write_text(res.to_toml())
    back = load_tuning(path)
    assert back == res
    assert isinstance(back.model(), InverseDynamics)


@pytest.mark.distributed
def test_tuning_on_a_dask_cluster_is_bit_identical(dask_pool):
    site = load_site("lx_default")
    a = tune_road_model(site, n_runs=1, seed=5, lambdas=(0.1,))
    b = tune_road_model(site, n_runs=1, seed=5, lambdas=(0.1,), pool=dask_pool)
    assert a == b


def test_m2_tuning_round_trips_and_selects_the_better_model(tmp_path):
    from adaptrack.crossing.tuning import tune_road_shaping
    from adaptrack.models import ShapingFilter

    site = load_site("lx_default")
    m1 = tune_road_model(site, n_runs=1, seed=3, lambdas=(0.1,))
    both = tune_road_shaping(site, m1, n_runs=1, seed=3, max_evaluations=6)
    assert set(both.shaping) == {"lambda_per_s2", "alpha_per_s", "shaping_std", "criterion"}
    assert both.shaping["lambda_per_s2"] >= 1e-4 * (1 - 1e-9)
    chosen = both.model()
    if both.shaping["criterion"] < both.criterion:
        assert isinstance(chosen, ShapingFilter)
    else:
        assert isinstance(chosen, InverseDynamics)
    path = tmp_path / "t.toml"
    path.write_text(both.to_toml())
    assert load_tuning(path) == both
