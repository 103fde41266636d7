"""Property tests of discretisation (Hypothesis)."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    InverseDynamics,
    ShapingFilter,
    Singer,
    discretize,
)

pos = st.floats(0.01, 50.0)


@st.composite
def models(draw):
    kind = draw(st.integers(0, 4))
    if kind == 0:
        return Singer(
            time_constant_s=draw(st.floats(0.1, 100.0)), accel_std_mps2=draw(st.floats(0.0, 20.0))
        )
    if kind == 1:
        return ConstantVelocity(accel_psd=draw(st.floats(0.0, 100.0)), n_axes=2)
    if kind == 2:
        return ConstantAcceleration(jerk_psd=draw(pos))
    if kind == 3:
        return InverseDynamics(lambda_per_s2=draw(st.floats(0.0, 4.0)), accel_psd=draw(pos))
    return ShapingFilter(
        lambda_per_s2=draw(st.floats(1e-4, 4.0)),
        alpha_per_s=draw(st.floats(0.01, 5.0)),
        shaping_std=draw(pos),
    )


dts = st.floats(0.0, 200.0)
exact_methods = st.sampled_from(["expm", "analytic"])


@given(
    models(),
    dts,
    st.sampled_from(["expm", "analytic", "taylor"]),
    st.sampled_from(["white", "piecewise"]),
)
def test_outputs_symmetric_psd_and_finite(model, dt, method, noise):
    if method == "taylor":
        dt = min(dt, 0.1)
    phi, qd = discretize(model, dt, method, noise=noise, order=4)
    assert np.all(np.isfinite(phi)) and np.all(np.isfinite(qd))
    np.testing.assert_array_equal(qd, qd.T)
    scale = max(np.abs(qd).max(), 1e-300)
    assert np.linalg.eigvalsh(qd).min() >= -1e-12 * scale


@given(models(), st.sampled_from(["expm", "analytic", "taylor", "source"]))
def test_dt_zero_is_identity(model, method):
    if method == "source" and not isinstance(model, Singer):
        return
    phi, qd = discretize(model, 0.0, method)
    np.testing.assert_array_equal(phi, np.eye(model.state_dim))
    assert not np.any(qd)


@given(models(), st.floats(0.0, 30.0), st.floats(0.0, 30.0), exact_methods)
def test_two_steps_compose_to_one(model, a, b, method):
    pa, qa = discretize(model, a, method)
    pb, qb = discretize(model, b, method)
    pab, qab = discretize(model, a + b, method)
    scale_p = np.abs(pab).max()
    scale_q = max(np.abs(qab).max(), 1e-300)
    np.testing.assert_allclose(pb @ pa, pab, rtol=0, atol=1e-11 * scale_p)
    np.testing.assert_allclose(pb @ qa @ pb.T + qb, qab, rtol=0, atol=1e-11 * scale_q)


@given(models(), st.lists(dts, min_size=1, max_size=6), exact_methods)
def test_batch_of_steps_equals_loop_and_input_untouched(model, steps, method):
    arr = np.array(steps)
    before = arr.copy()
    phi, qd = discretize(model, arr, method)
    np.testing.assert_array_equal(arr, before)
    for i, dt in enumerate(steps):
        p1, q1 = discretize(model, dt, method)
        np.testing.assert_array_equal(phi[i], p1)
        np.testing.assert_array_equal(qd[i], q1)
