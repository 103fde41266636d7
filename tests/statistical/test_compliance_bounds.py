"""Coverage of the compliance verdict's bounds on crossing Monte Carlos (not on a textbook law).

Squared errors of crossing runs are right-skewed (stops, random manoeuvres): a bound at a nominal
level covers the true RMS less often than that level. The verdict states 95 % and computes at a
nominal 99 % (``adaptrack.crossing.studies.compliance.BOUND_LEVEL``); this test measures how often
the stated upper bound of a small Monte Carlo (10 runs; 40 for a random approach, as the demo runs
them) lies above the RMS of a large one. Scripted cases reach the stated level; random approaches
are heavy-tailed (rare runs with a manoeuvre the radar cannot see dominate the mean) and their bound
is optimistic: the measured coverage is asserted as documented.
"""

import numpy as np
import pytest

from adaptrack.analysis.confidence import rms_with_bounds
from adaptrack.crossing.simulation.radar import simulate_site_case
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.compliance import BOUND_LEVEL, CONFIDENCE, run_sums, runs_of
from adaptrack.crossing.studies.families import FAMILIES


@pytest.mark.statistical
@pytest.mark.parametrize(
    "case_name, vehicle, total, least",
    [("A/stop_go_60", "bus", 6_000, 0.91), ("B/random_60", "motorcycle", 12_000, 0.85)],
)
def test_stated_upper_bound_covers_the_large_monte_carlo_rms(case_name, vehicle, total, least):
    """Stop-and-go (scripted): the 95 % bounds must cover in >= 91 % of 600 repetitions
    (binomial sd 0.9 %; measured 94-96 % over seeds, so 91 % is 3.5 sd below; a nominal-95 %
    bound, 86-88 % here, fails). Random approach: >= 85 % of 300 (sd 1.3 %-2 %; measured
    89-94 % over seeds, the truth itself varying with the rare runs it contains)."""
    site = load_site("lx_default")
    case = next(c for c in site.cases if c.name == case_name)
    veh = site.classes[vehicle]
    tracker = FAMILIES["ca"].tracker({"jerk_psd": 3.0}, "numba")
    squares, counts = [], []
    for block in range(total // 2000):
        runs = simulate_site_case(
            site, case, veh, n_runs=2000, rng=np.random.default_rng([20261124, block])
        )
        sums = run_sums(tracker(runs, site, case, veh), runs, site.zone_m)
        squares.append(sums.squares[:, :2])
        counts.append(sums.counts[:, :2])
    y, x = np.concatenate(squares), np.concatenate(counts)
    truth = np.sqrt(y.sum(axis=0) / x.sum(axis=0))
    n = runs_of(case, 10)
    reps = y.shape[0] // n
    y, x = y[: reps * n].reshape(reps, n, 2), x[: reps * n].reshape(reps, n, 2)
    covered = np.zeros(2)
    for i in range(reps):
        covered += rms_with_bounds(y[i], x[i], BOUND_LEVEL)[2] >= truth
    assert CONFIDENCE == 0.95
    assert np.all(covered / reps >= least), covered / reps
