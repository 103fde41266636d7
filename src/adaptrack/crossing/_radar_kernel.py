"""Compiled (numba) detection geometry of :func:`adaptrack.crossing.radar_sim.simulate_case`.

Given the drawn noise, scatter and detection draws (NumPy, in the simulation's order), computes
the noisy (range, azimuth, radial speed) of the reflection point and the detection mask in one
pass over (run, scan) instead of a dozen (N, T) temporaries. Same formulas and operation order
as the NumPy expressions it replaces (tests compare them).
"""

from __future__ import annotations

import math

import numba
from numba import prange


@numba.njit(cache=True, inline="always")
def _wrap(a, half):  # type: ignore[no-untyped-def]
    """Return ``(a + half) % (2 half) - half`` (floored remainder, as Python and NumPy)."""
    return (a + half) % (2.0 * half) - half


@numba.njit(cache=True, parallel=True)
def detections_kernel(  # type: ignore[no-untyped-def]
    pos, direction, speed, scatter, noise, draw, radar, p_detect, meas, detected
):
    """Fill ``meas`` (N, T, 3; NaN where not detected) and ``detected`` (N, T).

    ``pos`` (N, T, 2) lane point, ``direction`` (N, T, 2) unit travel direction, ``speed``
    (N, T), ``scatter`` (N, T) reflection offset behind the front, ``noise`` (N, T, 3) scaled
    measurement noise, ``draw`` (N, T) uniform detection draws; ``radar``: x, y, height,
    azimuth bias, boresight, field-of-view half width, min/max range, Doppler gate, folding
    speed (0: none) (arrays may be broadcast views).
    """
    n_runs, n_steps = speed.shape
    vmax = radar[9]
    for i in prange(n_runs):
        for t in range(n_steps):
            dx, dy = direction[i, t, 0], direction[i, t, 1]
            ex = pos[i, t, 0] - scatter[i, t] * dx - radar[0]
            ey = pos[i, t, 1] - scatter[i, t] * dy - radar[1]
            rng_m = math.hypot(math.hypot(ex, ey), radar[2])
            az = math.atan2(ex, ey)
            vr = (ex * (speed[i, t] * dx) + ey * (speed[i, t] * dy)) / rng_m
            off_axis = _wrap(az - radar[4], math.pi)
            det = (
                abs(off_axis) <= radar[5]
                and rng_m <= radar[7]
                and rng_m >= radar[6]
                and abs(vr) >= radar[8]
                and draw[i, t] < p_detect
            )
            detected[i, t] = det
            if det:
                meas[i, t, 0] = rng_m + noise[i, t, 0]
                meas[i, t, 1] = _wrap(az + radar[3] + noise[i, t, 1], math.pi)
                m2 = vr + noise[i, t, 2]
                meas[i, t, 2] = _wrap(m2, vmax) if vmax > 0.0 else m2
            else:
                meas[i, t, 0] = meas[i, t, 1] = meas[i, t, 2] = math.nan
