"""Compiled (numba) EKF update with a :class:`~adaptrack.models.RadarMeasurement`.

The radar's geometry, its analytic Jacobian and the wrapped innovation, as the NumPy model
computes them, followed by the update of :func:`adaptrack.filters._kernels.update_into`
(Joseph or standard form).
The IMM kernel calls it for every model when its measurement is a radar.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._typing import FloatArray
from ..angles import wrapped
from ..models.measurement import RADAR_COMPONENTS, RadarMeasurement
from ._kernels import update_into

RANGE, AZIMUTH, ELEVATION, RANGE_RATE = range(4)  # component codes, RADAR_COMPONENTS order


def radar_layout(radar: RadarMeasurement) -> tuple[np.ndarray, FloatArray]:
    """Component codes (m,) and the pose ``(n_axes, heading, position (3), velocity (3))``."""
    codes = np.array([RADAR_COMPONENTS.index(c) for c in radar.components], dtype=np.int64)
    pose = np.zeros(8)
    k = radar.n_axes
    pose[0], pose[1] = k, radar.heading
    pose[2 : 2 + k] = np.asarray(radar.sensor_position)
    pose[5 : 5 + k] = np.asarray(radar.sensor_velocity)
    return codes, pose


@numba.njit(cache=True, inline="always")
def radar_into(s, codes, pose, zp, jac):  # type: ignore[no-untyped-def]
    """Predicted components ``zp`` (m,) and ``dh/ds`` ``jac`` (m, len(s)) of read states ``s``.

    Returns False on the radar's vertical axis (azimuth undefined).
    """
    k = int(pose[0])
    dx, dy = s[0] - pose[2], s[1] - pose[3]
    dz = s[2] - pose[4] if k == 3 else 0.0
    horiz2 = dx * dx + dy * dy
    if horiz2 == 0.0:
        return False
    r = math.sqrt(horiz2 + dz * dz)
    jac[:, :] = 0.0
    for a in range(codes.shape[0]):
        c = codes[a]
        if c == RANGE:
            zp[a] = r
            jac[a, 0], jac[a, 1] = dx / r, dy / r
            if k == 3:
                jac[a, 2] = dz / r
        elif c == AZIMUTH:
            zp[a] = wrapped(math.atan2(dx, dy) - pose[1], math.pi)
            jac[a, 0], jac[a, 1] = dy / horiz2, -dx / horiz2
        elif c == ELEVATION:
            rho = math.sqrt(horiz2)
            r2 = r * r
            zp[a] = math.atan2(dz, rho)
            jac[a, 0], jac[a, 1], jac[a, 2] = -dx * dz / (rho * r2), -dy * dz / (rho * r2), rho / r2
        else:
            rel0, rel1 = s[k] - pose[5], s[k + 1] - pose[6]
            rel2 = s[k + 2] - pose[7] if k == 3 else 0.0
            rr = (dx * rel0 + dy * rel1 + dz * rel2) / r
            zp[a] = rr
            d = (dx, dy, dz)
            rel = (rel0, rel1, rel2)
            for i in range(k):
                jac[a, i] = (rel[i] - rr * d[i] / r) / r
                jac[a, k + i] = d[i] / r
    return True


@numba.njit(cache=True, inline="always")
def radar_update_into(  # type: ignore[no-untyped-def]
    xp, pp, z, mask, codes, pose, reads, r, joseph, x, p, tmp, hm, rm, hp, s, lo, kt, nu, w,
    ikh, zp, jac, sread,
):  # fmt: skip
    """Update the prior ``xp``, ``pp`` with the radar (EKF) into ``x``, ``p``.

    ``reads`` (k,) the state indices the radar reads; ``zp`` (m,), ``jac`` (m, k), ``sread``
    (k,) scratch; ``joseph`` the covariance form; the rest as
    :func:`~adaptrack.filters._kernels.masked_update_into`. Returns
    ``(ok, nis, log det S, observed components)``.
    """
    n = xp.shape[0]
    m = z.shape[0]
    n_read = reads.shape[0]
    for b in range(n_read):
        sread[b] = xp[reads[b]]
    if not radar_into(sread, codes, pose, zp, jac):
        return False, 0.0, 0.0, 0.0
    nobs = 0.0
    for a in range(m):
        on = mask[a]
        nobs += 1.0 if on else 0.0
        for b in range(n):
            hm[a, b] = 0.0
        for b in range(m):
            rm[a, b] = r[a, b] if on and mask[b] else (1.0 if a == b and not on else 0.0)
        if on:
            for b in range(n_read):
                hm[a, reads[b]] = jac[a, b]
            d = z[a] - zp[a]
            nu[a] = wrapped(d, math.pi) if codes[a] == AZIMUTH or codes[a] == ELEVATION else d
        else:
            nu[a] = 0.0
    ok, nis, logdet = update_into(xp, pp, nu, hm, rm, joseph, x, p, hp, s, lo, kt, w, ikh, tmp)
    return ok, nis, logdet, nobs
