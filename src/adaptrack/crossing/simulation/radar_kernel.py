"""Compiled (numba) detection geometry of :func:`adaptrack.crossing.simulation.radar.simulate_case`.

Given the drawn unit noise, scatter and detection draws (NumPy, in the simulation's order),
computes the noisy (range, azimuth, radial speed) of the reflection point and the detection
mask in one pass over (run, scan) instead of a dozen (N, T) temporaries. The noise standard
deviations and the detection probability are the radar's curves
(:class:`adaptrack.crossing.site.sensor.Curve`) at the true geometry. Same formulas and operation
order as the NumPy expressions they replace (tests compare them).
"""

from __future__ import annotations

import math

import numba
from numba import prange

from ...angles import wrapped
from ..site.geometry import curve_at, in_view


@numba.njit(cache=True, parallel=True)
def detections_kernel(  # type: ignore[no-untyped-def]
    pos,
    direction,
    speed,
    scatter,
    noise,
    draw,
    radar,
    fields,
    noise_tab,
    noise_cnt,
    pd_tab,
    pd_cnt,
    meas,
    detected,
):
    """Fill ``meas`` (N, T, 3; NaN where not detected) and ``detected`` (N, T).

    ``pos`` (N, T, 2) lane point, ``direction`` (N, T, 2) unit travel direction, ``speed``
    (N, T), ``scatter`` (N, T) reflection offset behind the front, ``noise`` (N, T, 3) unit
    normal draws, ``draw`` (N, T) uniform detection draws; ``radar``: x, y, height, azimuth
    bias, boresight, min range, Doppler gate, folding speed (0: none); ``fields`` (F, 2) max
    range and half angle; ``noise_tab``/``noise_cnt`` the range, azimuth (against the angle off
    boresight) and radial-speed sigma curves; ``pd_tab``/``pd_cnt`` the detection probability
    against range (arrays may be broadcast views).
    """
    n_runs, n_steps = speed.shape
    vmax = radar[7]
    for i in prange(n_runs):
        for t in range(n_steps):
            dx, dy = direction[i, t, 0], direction[i, t, 1]
            ex = pos[i, t, 0] - scatter[i, t] * dx - radar[0]
            ey = pos[i, t, 1] - scatter[i, t] * dy - radar[1]
            rng_m = math.hypot(math.hypot(ex, ey), radar[2])
            az = math.atan2(ex, ey)
            vr = (ex * (speed[i, t] * dx) + ey * (speed[i, t] * dy)) / rng_m
            off_axis = abs(wrapped(az - radar[4], math.pi))
            det = (
                in_view(rng_m, off_axis, fields, radar[5])
                and abs(vr) >= radar[6]
                and draw[i, t] < curve_at(pd_tab, pd_cnt, 0, rng_m)
            )
            detected[i, t] = det
            if det:
                meas[i, t, 0] = rng_m + noise[i, t, 0] * curve_at(noise_tab, noise_cnt, 0, rng_m)
                sig_az = curve_at(noise_tab, noise_cnt, 1, off_axis)
                meas[i, t, 1] = wrapped(az + radar[3] + noise[i, t, 1] * sig_az, math.pi)
                m2 = vr + noise[i, t, 2] * curve_at(noise_tab, noise_cnt, 2, rng_m)
                meas[i, t, 2] = wrapped(m2, vmax) if vmax > 0.0 else m2
            else:
                meas[i, t, 0] = meas[i, t, 1] = meas[i, t, 2] = math.nan
