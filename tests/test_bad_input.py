"""Every validation branch raises a clear error naming the argument and the offending index."""

import numpy as np
import pytest

import adaptrack as at
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    InverseDynamics,
    LinearSDE,
    ShapingFilter,
    Singer,
    discretize,
    singer_accel_std,
)

H = [[1.0, 0.0, 0.0]]
M = Singer(time_constant_s=5.0, accel_std_mps2=2.0)
T = np.array([0.0, 0.1, 0.25, 0.4])
Z = np.zeros((4, 1))
R = [[0.25]]


def prior(cov=None, time=0.0, mean=None):
    return at.GaussianState(
        np.zeros(3) if mean is None else mean, 100.0 * np.eye(3) if cov is None else cov, time
    )


def run(**kw):
    args = dict(
        times=T, measurements=Z, model=M, measurement_matrix=H, measurement_cov=R, initial=prior()
    )
    args.update(kw)
    return at.kalman_filter(**args)


# --- kalman_filter -------------------------------------------------------------------------
def test_nan_time():
    with pytest.raises(ValueError, match=r"times must be finite; got nan at index 2"):
        run(times=np.array([0.0, 0.1, np.nan, 0.4]))


def test_inf_measurement():
    z = Z.copy()
    z[1, 0] = np.inf
    with pytest.raises(ValueError, match=r"measurements must be finite; got inf at index \(1, 0\)"):
        run(measurements=z)


def test_nan_measurement_marked_present():
    z = Z.copy()
    z[2, 0] = np.nan
    with pytest.raises(
        ValueError, match="measurements is NaN at step 2, component 0 where it is marked present"
    ):
        run(measurements=z)


def test_nan_measurement_batched_names_track():
    z = np.zeros((3, 4, 1))
    z[1, 3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN at track 1, step 3, component 0"):
        run(measurements=z)


def test_unsorted_times():
    with pytest.raises(ValueError, match=r"unsorted time at step 2: 0.05 after 0.1"):
        run(times=np.array([0.0, 0.1, 0.05, 0.4]))


def test_duplicate_times_per_track():
    t = np.tile(T, (2, 1))
    t[1, 3] = t[1, 2]
    with pytest.raises(ValueError, match="duplicate time at track 1, step 3"):
        run(times=t, measurements=np.zeros((2, 4, 1)))


def test_wrong_measurement_shape():
    with pytest.raises(ValueError, match=r"times must have shape \(5,\) or \(5,\)"):
        run(measurements=np.zeros((5, 1)))
    with pytest.raises(ValueError, match=r"measurements must have at least 2 axes"):
        run(measurements=np.zeros(4))


def test_wrong_measurement_matrix_shape():
    with pytest.raises(ValueError, match=r"measurement_matrix must have shape \(1, 3\)"):
        run(measurement_matrix=[[1.0, 0.0]])


def test_wrong_measurement_cov_shape():
    with pytest.raises(ValueError, match=r"measurement_cov must have shape \(1, 1\)"):
        run(measurement_cov=np.eye(2))


def test_non_positive_measurement_variance():
    with pytest.raises(ValueError, match="measurement_cov must be positive definite"):
        run(measurement_cov=[[0.0]])
    with pytest.raises(
        ValueError,
        match="measurement_cov must be positive definite; not at "
        r"batch index \(2,\)",
    ):
        run(
            measurements=np.zeros((3, 4, 1)), measurement_cov=np.array([[[1.0]], [[1.0]], [[-1.0]]])
        )


def test_asymmetric_cov():
    with pytest.raises(ValueError, match="measurement_cov must be symmetric"):
        run(
            measurement_matrix=np.eye(2, 3),
            measurements=np.zeros((4, 2)),
            measurement_cov=[[1.0, 0.5], [0.0, 1.0]],
        )


def test_non_psd_prior():
    bad = np.diag([1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="initial.cov must be positive semi-definite"):
        run(initial=prior(cov=bad))


def test_prior_wrong_size():
    with pytest.raises(ValueError, match=r"initial.mean must have shape \(\.\.\., 3\)"):
        run(initial=at.GaussianState(np.zeros(2), np.eye(2), 0.0))


def test_prior_after_first_measurement():
    with pytest.raises(ValueError, match="initial.time must not be after the first measurement"):
        run(initial=prior(time=0.05))


def test_prior_wrong_batch():
    with pytest.raises(ValueError, match=r"initial must have batch shape \(\) or \(3,\)"):
        run(
            measurements=np.zeros((3, 4, 1)),
            initial=prior(cov=np.broadcast_to(np.eye(3), (2, 3, 3)), mean=np.zeros((2, 3))),
        )


def test_mask_wrong_dtype_and_shape():
    with pytest.raises(TypeError, match="mask must be boolean"):
        run(mask=np.ones(4))
    with pytest.raises(ValueError, match=r"mask must have shape \(4,\)"):
        run(mask=np.ones(3, dtype=bool))


def test_bad_options():
    with pytest.raises(ValueError, match="nan_policy must be 'raise' or 'missing'"):
        run(nan_policy="drop")
    with pytest.raises(ValueError, match="form must be 'auto', 'joseph', 'standard' or 'sqrt'"):
        run(form="cholesky")
    with pytest.raises(
        ValueError, match="method must be 'expm', 'analytic', 'taylor', 'source' or 'auto'"
    ):
        run(method="euler")


def test_wrong_kinds():
    with pytest.raises(TypeError, match="model must be a motion model"):
        run(model="singer")
    with pytest.raises(TypeError, match="initial must be a GaussianState"):
        run(initial=np.zeros(3))
    with pytest.raises(TypeError, match="measurements must be numeric"):
        run(measurements=np.array([["a"]] * 4))
    with pytest.raises(TypeError, match="times must be numeric"):
        run(times="0 1 2 3")


def test_empty_sequence():
    with pytest.raises(ValueError, match="at least one time step"):
        run(times=np.zeros(0), measurements=np.zeros((0, 1)))


def test_innovation_covariance_not_pd_names_batch_index():
    covs = np.stack([np.eye(3), -10.0 * np.eye(3)])
    state = at.GaussianState(np.zeros((2, 3)), covs, 0.0)
    with pytest.raises(
        at.CovarianceError,
        match=r"innovation covariance is not positive "
        r"definite at batch index \(1,\)",
    ):
        at.update(state, np.zeros((2, 1)), H, R)


def test_the_square_root_forms_name_an_indefinite_prior_instead_of_factoring_it():
    covs = np.stack([np.eye(3), np.diag([1.0, -4.0, 1.0])])  # unobserved negative variance
    state = at.GaussianState(np.zeros((2, 3)), covs, 0.0)
    with pytest.raises(ValueError, match=r"state.cov must be positive semi-definite; not at "):
        at.update(state, np.zeros((2, 1)), H, R, form="sqrt")
    with pytest.raises(ValueError, match=r"state.cov must be positive semi-definite; not at "):
        at.kalman_step(state, np.zeros((2, 1)), M, H, R, time=1.0, form="sqrt")


def test_update_names_a_measurement_cov_that_is_not_positive_definite():
    with pytest.raises(ValueError, match="measurement_cov must be positive definite"):
        at.update(prior(), [1.0], H, [[-1.0]])
    with pytest.raises(ValueError, match="measurement_cov must be symmetric"):
        at.update(prior(), [1.0, 2.0], np.vstack([H, H]), [[1.0, 0.5], [0.0, 1.0]])


# --- update / kalman_step ------------------------------------------------------------------
def test_update_shapes():
    with pytest.raises(ValueError, match=r"measurement must have shape \(\.\.\., 1\)"):
        at.update(prior(), [1.0, 2.0], H, R)
    with pytest.raises(ValueError, match="measurement is NaN at index"):
        at.update(prior(), [np.nan], H, R)


def test_kalman_step_time_before_state():
    with pytest.raises(ValueError, match="time must not precede state.time"):
        at.kalman_step(prior(time=1.0), [0.0], M, H, R, time=0.5)


# --- discretize and models -----------------------------------------------------------------
def test_negative_dt():
    with pytest.raises(ValueError, match=r"dt must be >= 0; got -0.1 at index \(1,\)"):
        discretize(M, np.array([0.1, -0.1]))


def test_nan_dt():
    with pytest.raises(ValueError, match="dt must be finite"):
        discretize(M, np.nan)


def test_bad_method_options():
    with pytest.raises(ValueError, match="noise must be 'white' or 'piecewise'"):
        discretize(M, 0.1, noise="pink")
    with pytest.raises(ValueError, match="order must be an int >= 0"):
        discretize(M, 0.1, "taylor", order=-1)
    with pytest.raises(ValueError, match="method='source' exists only for the Singer model"):
        discretize(ConstantVelocity(), 0.1, "source")
    with pytest.raises(ValueError, match="method='source' assumes zero mean acceleration"):
        discretize(Singer(mean_accel_mps2=1.0), 0.1, "source")
    with pytest.raises(ValueError, match="method='source' defines its own process noise"):
        discretize(M, 0.1, "source", noise="piecewise")


@pytest.mark.parametrize(
    "ctor, match",
    [
        (lambda: Singer(time_constant_s=0.0), "time_constant_s must be > 0; got 0.0 for axis 0"),
        (
            lambda: Singer(accel_std_mps2=[1.0, -1.0], n_axes=2),
            "accel_std_mps2 must be >= 0; got -1.0 for axis 1",
        ),
        (lambda: Singer(time_constant_s=[1.0, 2.0]), r"one value per axis, shape \(1,\)"),
        (lambda: ConstantVelocity(accel_psd=-1.0), "accel_psd must be >= 0"),
        (lambda: ConstantAcceleration(jerk_psd=np.nan), "jerk_psd must be finite"),
        (lambda: InverseDynamics(lambda_per_s2=-0.1), "lambda_per_s2 must be >= 0"),
        (lambda: ShapingFilter(alpha_per_s=0.0), "alpha_per_s must be > 0"),
        (lambda: ShapingFilter(coupling="weak"), "coupling must be 'sqrt_lambda' or 'unit'"),
        (lambda: ConstantVelocity(n_axes=4), "n_axes must be 1, 2 or 3"),
        (
            lambda: ShapingFilter.from_singer_rule(0.0, 0.3, 9.0, 0.05, 0.5),
            "lambda_per_s2 must be finite and > 0",
        ),
        (lambda: singer_accel_std(9.0, 0.5, 0.5), r"2 \* prob_max_accel \+ prob_no_accel must be"),
        (lambda: LinearSDE([[0.0, 1.0]], [[1.0]], [[1.0]], ("a",)), r"drift must have shape"),
        (
            lambda: LinearSDE([[0.0]], [[1.0]], [[-1.0]], ("a",)),
            "noise_psd must be positive semi-definite",
        ),
        (lambda: LinearSDE([[0.0]], [[1.0]], [[1.0]], ("a", "b")), "state_names must have 1"),
    ],
)
def test_model_parameter_errors(ctor, match):
    with pytest.raises(ValueError, match=match):
        ctor()


def test_model_kind_errors():
    with pytest.raises(TypeError, match="n_axes must be an int"):
        ConstantVelocity(n_axes=1.5)
    with pytest.raises(TypeError, match="time_constant_s must be numeric"):
        Singer(time_constant_s="5")


# --- types ---------------------------------------------------------------------------------
def test_gaussian_state_errors():
    with pytest.raises(ValueError, match=r"cov must have shape \(3, 3\) to match mean"):
        at.GaussianState(np.zeros(3), np.eye(2), 0.0)
    with pytest.raises(ValueError, match="time must be broadcastable"):
        at.GaussianState(np.zeros((2, 3)), np.zeros((2, 3, 3)), [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="mean must be finite"):
        at.GaussianState([np.nan], [[1.0]], 0.0)
    with pytest.raises(IndexError, match="too many indices"):
        at.GaussianState(np.zeros(3), np.eye(3), 0.0)[0]


# --- observability -------------------------------------------------------------------------
def test_observability_errors():
    with pytest.raises(ValueError, match=r"transition must have shape \(\.\.\., n, n\)"):
        at.observability_matrix(np.zeros((2, 3)), [[1.0, 0.0]])
    with pytest.raises(ValueError, match=r"measurement_matrix must have shape \(m, 2\)"):
        at.observability_matrix(np.eye(2), [[1.0, 0.0, 0.0]])
