"""A nearly-constant-velocity truth drawn from its own closed-form transition (test oracle)."""

import numpy as np


def cv_states(rng, start, dt, q, n):
    """Position and velocity of each axis at ``n`` steps of ``dt`` [s]: (n, axes, 2).

    ``start`` (axes, 2) is the state before the first step; white acceleration of PSD ``q``
    [m^2/s^3] with the exact discrete noise ``q [[dt^3/3, dt^2/2], [dt^2/2, dt]]``, drawn step
    by step, axis by axis (no code shared with the library's discretisation).
    """
    phi = np.array([[1.0, dt], [0.0, 1.0]])
    chol = np.linalg.cholesky(q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]))
    s = np.array(start, dtype=float)
    states = np.zeros((n, *s.shape))
    for k in range(n):
        for a in range(s.shape[0]):
            s[a] = phi @ s[a] + chol @ rng.standard_normal(2)
        states[k] = s
    return states
