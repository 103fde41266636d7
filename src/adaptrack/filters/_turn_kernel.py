"""Compiled (numba) EKF prediction through a :class:`~adaptrack.models.CoordinatedTurn`.

The same transition, Jacobian (series below :data:`~adaptrack.models.turn.SERIES_BELOW`) and
noise as the NumPy model; the covariance by :func:`adaptrack.filters._kernels.predict_into`
with the Jacobian. The IMM kernel calls it for its coordinated-turn models.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._typing import FloatArray
from ..models.turn import SERIES_BELOW, CoordinatedTurn
from ._kernels import predict_into


def turn_parameters(model: CoordinatedTurn) -> FloatArray:
    """``(accel_psd, turn_psd, vertical_psd, n_axes)`` of the kernel."""
    return np.array([model.accel_psd, model.turn_psd, model.vertical_psd, model.n_axes], float)


@numba.njit(cache=True, inline="always")
def turn_predict_into(x, p, dt, par, xp, pp, tmp, f, q, u0):  # type: ignore[no-untyped-def]
    """Predict over a step ``dt`` [s]: ``xp = f(x)``, ``pp = F P F^T + Q``.

    ``f``, ``q`` (n, n) and ``u0`` (n,) are scratch (``F``, ``Q`` and zeros afterwards).
    """
    k = int(par[3])
    n = x.shape[0]
    vx, vy, w = x[k], x[k + 1], x[n - 1]
    u = w * dt
    u2 = u * u
    sn, cs = math.sin(u), math.cos(u)
    if abs(u) < SERIES_BELOW:
        a = dt * (1 - u2 / 6 + u2 * u2 / 120)
        b = dt * u * (0.5 - u2 / 24 + u2 * u2 / 720)
        da = dt * dt * u * (-1 / 3 + u2 / 30)
        db = dt * dt * (0.5 - u2 / 8 + u2 * u2 / 144)
    else:
        wr = u / dt
        a = sn / wr
        b = (1 - cs) / wr
        da = (dt * cs - a) / wr
        db = (dt * sn - b) / wr
    for i in range(n):
        u0[i] = 0.0
        for j in range(n):
            f[i, j] = 1.0 if i == j else 0.0
            q[i, j] = 0.0
    f[0, k], f[0, k + 1], f[0, n - 1] = a, -b, da * vx - db * vy
    f[1, k], f[1, k + 1], f[1, n - 1] = b, a, db * vx + da * vy
    f[k, k], f[k, k + 1], f[k, n - 1] = cs, -sn, -dt * (sn * vx + cs * vy)
    f[k + 1, k], f[k + 1, k + 1], f[k + 1, n - 1] = sn, cs, dt * (cs * vx - sn * vy)
    if k == 3:
        f[2, 5] = dt
    for axis in range(k):
        psd = par[2] if axis == 2 else par[0]
        i, j = axis, k + axis
        q[i, i] = psd * dt**3 / 3
        q[i, j] = psd * dt**2 / 2
        q[j, i] = psd * dt**2 / 2
        q[j, j] = psd * dt
    q[n - 1, n - 1] = par[1] * dt
    predict_into(x, p, f, q, u0, xp, pp, tmp)  # the covariance; the mean is f(x):
    for i in range(n):
        xp[i] = x[i]
    xp[0] += a * vx - b * vy
    xp[1] += b * vx + a * vy
    xp[k] = cs * vx - sn * vy
    xp[k + 1] = sn * vx + cs * vy
    if k == 3:
        xp[2] += dt * x[5]
