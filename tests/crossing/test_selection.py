"""Design-time selection: criteria, family tuning, tuned.toml, the choice on validation runs."""

import copy
import math

import pytest

from adaptrack.crossing.site.model import site_from_mapping
from adaptrack.crossing.studies.families import FAMILIES
from adaptrack.crossing.studies.selection import (
    Candidate,
    SiteTuning,
    criterion_value,
    load_tuning,
    select_estimator,
    training_criterion,
    training_set,
    tune_family,
)
from adaptrack.crossing.studies.trackers import IMMTracker, RoadTracker

from .test_report import SMALL


@pytest.fixture(scope="module")
def small_site():
    return site_from_mapping(copy.deepcopy(SMALL), "small.toml")


def test_criteria_by_hand():
    # (position m, speed km/h, relative speed %, position epochs, speed epochs) per pair
    pairs = [
        (0.35, 1.0, math.nan, 100, 100),  # ratios 0.5, 0.5
        (0.14, 1.6, math.nan, 300, 300),  # 0.2, 0.8
        (0.07, math.nan, 1.0, 100, 0),  # 0.1, relative 0.5
        (0.21, 0.2, math.nan, 100, 100),  # 0.3, 0.1
    ]
    assert criterion_value(pairs, "worst") == pytest.approx(0.8)
    # the tail: mean of the largest max(3, 10 %) ratios -> (0.8 + 0.5 + 0.5) / 3
    assert criterion_value(pairs, "tail") == pytest.approx(0.6)
    pos = math.sqrt((0.35**2 * 100 + 0.14**2 * 300 + 0.07**2 * 100 + 0.21**2 * 100) / 600)
    assert criterion_value(pairs, "pooled_position") == pytest.approx(pos)
    spd = math.sqrt((1.0**2 * 100 + 1.6**2 * 300 + 0.2**2 * 100) / 500)
    req = math.sqrt(((pos / 0.7) ** 2 + (spd / 2.0) ** 2) / 2)
    assert criterion_value(pairs, "pooled_requirement") == pytest.approx(req)
    # a pair with no scored epoch: the estimator lost the vehicle
    lost = [*pairs, (math.nan, math.nan, math.nan, 0, 0)]
    assert criterion_value(lost, "tail") == math.inf


def test_m1_profile_contains_the_cv_member_and_is_never_worse(small_site):
    training = training_set(small_site, 1, 4)
    cv, _ = tune_family("cv", small_site, training)
    m1, profile = tune_family("m1", small_site, training)
    assert profile["lambda_per_s2"][0] == 0.0
    # lambda = 0 is CV: same search, same criterion (the nesting oracle of spec B.7)
    assert profile["criterion"][0] == pytest.approx(cv.training_criterion, rel=1e-12)
    assert m1.training_criterion <= cv.training_criterion
    # the reported criterion is what the tuned tracker scores on the same runs
    again = training_criterion(m1.tracker("numba"), small_site, training)
    assert again == pytest.approx(m1.training_criterion, rel=1e-12)


def test_tuned_families_build_their_trackers():
    imm = FAMILIES["imm"].tracker({"accel_psd": 0.1, "jerk_psd": 3.0, "sojourn_s": 5.0})
    assert isinstance(imm, IMMTracker) and imm.sojourn_s == (5.0, 5.0)
    m2 = FAMILIES["m2"].tracker({"lambda_per_s2": 0.1, "alpha_per_s": 0.3, "shaping_std": 4.0})
    assert isinstance(m2, RoadTracker) and m2.model.state_names == ("x", "vx", "xi_x")
    with pytest.raises(ValueError, match="family 'singer' needs accel_std_mps2"):
        FAMILIES["singer"].tracker({"time_constant_s": 3.0})


@pytest.fixture(scope="module")
def selection(small_site):
    return select_estimator(
        small_site, seed=2, training_runs=1, validation_runs=3, families=("cv", "ca", "imm")
    )


def test_the_winner_is_the_best_candidate_on_validation(selection):
    tuning, validation = selection
    assert {c.family for c in tuning.candidates} == {"cv", "ca", "imm"}
    best = min(tuning.candidates, key=lambda c: (not c.meets_requirement, c.validation_criterion))
    assert tuning.deployed == best.family
    assert tuning.reason.startswith(best.label)
    # the validation rows: every candidate on every pair of the site
    assert len(validation.rows) == 3 * 4
    for c in tuning.candidates:
        rows = [r for r in validation.rows if r.filter == c.label]
        assert c.worst_ratio == pytest.approx(max(r.requirement_ratio for r in rows))


def test_tuned_toml_round_trips(selection, tmp_path):
    tuning, _ = selection
    path = tmp_path / "tuned.toml"
    path.write_text(tuning.to_toml())
    back = load_tuning(path)
    assert back == tuning
    assert SiteTuning.from_json(tuning.to_json()) == tuning
    assert type(back.tracker()) is type(tuning.tracker())


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda t: t.replace('family = "', 'family = "x', 1), "not a tuned configuration"),
        (lambda t: t.replace("[candidates.cv]", "[candidates.kalman]"), "unknown family 'kalman'"),
        (lambda t: t.replace("accel_psd = ", "accel_pds = ", 1), "needs accel_psd"),
        (lambda t: t.replace("criterion = ", "criterium = ", 1), r"missing 'criterion'"),
        (lambda t: t + "\n[[[", "invalid TOML"),
    ],
)
def test_bad_tuned_toml(selection, tmp_path, change, message):
    tuning, _ = selection
    path = tmp_path / "bad.toml"
    path.write_text(change(tuning.to_toml()))
    with pytest.raises(ValueError, match=message):
        load_tuning(path)


def test_select_rejects_unknown_criterion_and_family(small_site):
    with pytest.raises(ValueError, match="criterion must be one of"):
        select_estimator(small_site, criterion="best")
    with pytest.raises(ValueError, match="families must be among"):
        select_estimator(small_site, families=("kalman",))


@pytest.mark.distributed
def test_selection_on_a_dask_cluster_is_bit_identical(small_site, dask_pool):
    kw = {"seed": 3, "training_runs": 1, "validation_runs": 2, "families": ("cv", "m1")}
    a, va = select_estimator(small_site, **kw)
    b, vb = select_estimator(small_site, pool=dask_pool, **kw)
    assert a == b
    assert [r.position_rms_m for r in va.rows] == [r.position_rms_m for r in vb.rows]


def test_candidate_meets_requirement_property():
    c = Candidate("cv", "road EKF (CV)", {"accel_psd": 1.0}, 0.4, 3, 0.5, 1.2, "car / x")
    assert not c.meets_requirement
