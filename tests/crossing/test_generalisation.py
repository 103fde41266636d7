"""Site adaptation generalises: on every built-in site the deployed estimator, chosen on
validation runs, stays within 1.1x of the best candidate on runs no step has seen, and meets
the requirement there."""

import pytest

from adaptrack.crossing.site.model import builtin_sites, load_site
from adaptrack.crossing.studies.compliance import evaluate_site
from adaptrack.crossing.studies.selection import criterion_value, select_estimator


def _per_pair(rows, label):
    return [
        (r.position_rms_m, r.speed_rms_kmh, r.speed_rel_rms_pct, r.n_epochs, r.n_speed_epochs)
        for r in rows
        if r.filter == label
    ]


@pytest.mark.slow
@pytest.mark.distributed
@pytest.mark.parametrize("name", builtin_sites())
def test_deployed_estimator_holds_on_held_out_runs(name, dask_pool):
    site = load_site(name)
    tuning, _ = select_estimator(
        site, seed=20261124, training_runs=2, validation_runs=8, pool=dask_pool
    )
    trackers = {c.label: c.tracker() for c in tuning.candidates}
    held_out = evaluate_site(site, 8, 977, trackers=trackers, bound=False, pool=dask_pool)
    score = {label: criterion_value(_per_pair(held_out.rows, label), "tail") for label in trackers}
    deployed = tuning.winner.label
    assert score[deployed] <= 1.1 * min(score.values()), score
    worst = max(r.requirement_ratio for r in held_out.rows if r.filter == deployed)
    assert worst <= 1.0, f"{name}: deployed {deployed} reaches {worst:.3f} of the limits"
