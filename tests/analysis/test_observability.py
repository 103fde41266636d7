"""Observability matrix and rank test."""

import numpy as np

import adaptrack as at
from adaptrack.models import ConstantAcceleration, discretize


def test_rank_is_scale_robust_at_tiny_steps():
    # columns differ by dt and dt^2/2: an unscaled SVD threshold would miss the rank
    for dt in (1e-7, 1e-3, 1.0, 1e3):
        phi, _ = discretize(ConstantAcceleration(jerk_psd=1.0), dt)
        assert at.is_observable(phi, [[1.0, 0.0, 0.0]])
        assert not at.is_observable(phi, [[0.0, 1.0, 0.0]])
        assert not at.is_observable(phi, [[0.0, 0.0, 1.0]])


def test_constant_transition_matches_powers():
    rng = np.random.default_rng(3)
    phi = rng.normal(size=(4, 4))
    h = rng.normal(size=(2, 4))
    o = at.observability_matrix(phi, h)
    want = np.vstack([h @ np.linalg.matrix_power(phi, k) for k in range(4)])
    np.testing.assert_allclose(o, want, rtol=1e-12)
    assert at.observability_rank(o) == 4


def test_multi_axis_unobservable_directions():
    phi, _ = discretize(at.models.ConstantVelocity(n_axes=2), 0.5)
    h = [[1.0, 0.0, 0.0, 0.0]]  # x only: y and vy unobservable
    o = at.observability_matrix(phi, h)
    assert at.observability_rank(o) == 2
    d = at.unobservable_directions(o)
    assert d.shape == (4, 2)
    np.testing.assert_allclose(o @ d, 0.0, atol=1e-12)
    np.testing.assert_allclose(d.T @ d, np.eye(2), atol=1e-12)
