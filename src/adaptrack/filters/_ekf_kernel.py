"""Compiled (numba) extended Kalman filter (:func:`adaptrack.filters.ekf.ekf_filter`).

Per track (tracks in parallel) and step: the prediction of a linear motion model (its
``Phi``, ``Qd``, ``u`` computed beforehand, as the NumPy path does) or of a
:class:`~adaptrack.models.CoordinatedTurn` (linearised at the filtered mean:
:func:`~adaptrack.filters._turn_kernel.turn_predict_into`); the update with a linear position
measurement (:func:`~adaptrack.filters._kernels.masked_update_into`) or a
:class:`~adaptrack.models.RadarMeasurement`
(:func:`~adaptrack.filters._radar_update.radar_update_into`), Joseph or standard form. The
same arithmetic as the IMM kernel's, which agrees with the NumPy reference to rounding; every
output of the NumPy filter is recorded.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

from ._kernels import (
    filter_outputs,
    masked_update_into,
    predict_into,
    start_track,
    store_step,
)
from ._radar_update import radar_update_into
from ._turn_kernel import turn_predict_into


@numba.njit(cache=True, parallel=True)
def ekf_kernel(x0, p0, phi, qd, u, dt, z, mask, r, h, turn_par, codes, pose, reads, joseph):  # type: ignore[no-untyped-def]
    """Filter every track of the batch.

    Shapes: ``x0`` (N|1, n), ``p0`` (N|1, n, n); a linear motion model's ``phi``, ``qd``
    (N|1, T, n, n) and ``u`` (N|1, T, n); or a coordinated turn (``turn_par`` (4,) of
    :func:`~adaptrack.filters._turn_kernel.turn_parameters`, ``turn_par[3] > 0``), whose
    ``F`` and ``Q`` of each step are written into ``phi``, ``qd`` (N, T, n, n); ``dt`` (N, T)
    the steps [s]; ``z``, ``mask`` (N, T, m); ``r`` (N|1, T|1, m, m); ``h`` (m, n) a linear
    measurement when ``codes`` is empty, else the radar's ``codes`` (m,), ``pose`` (8,) and
    the states it ``reads`` (k,).

    Returns the outputs of :func:`~adaptrack.filters._kernels.filter_outputs`, the
    measurement matrix of each step (N, T, m, n) and a status per track: 0, or 1 when an
    innovation covariance was not positive definite (or the radar's azimuth undefined) and
    the track stopped there.
    """
    n_tr, n_st, m = z.shape
    n = x0.shape[1]
    turning = turn_par[3] > 0
    radar = codes.shape[0] > 0
    pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o = filter_outputs(n_tr, n_st, n, m)
    h_o = np.zeros((n_tr, n_st, m, n))
    status = np.zeros(n_tr, dtype=np.int64)
    off = np.zeros(m)
    for i in prange(n_tr):
        x, xp, u0 = np.empty(n), np.empty(n), np.zeros(n)
        p, pp, tmp, ikh = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
        hm, hp, kt = np.empty((m, n)), np.empty((m, n)), np.empty((m, n))
        rm, s, lo = np.empty((m, m)), np.empty((m, m)), np.empty((m, m))
        nu, w, zp = np.empty(m), np.empty(m), np.empty(m)
        jac, sread = np.empty((m, reads.shape[0])), np.empty(reads.shape[0])
        ii = numba.int64(i)  # prange's index may be unsigned: min() with it gives a float
        ip, ir, iu = start_track(ii, x0, p0, phi, r, u, x, p)
        for k in range(n_st):
            kr = min(k, r.shape[1] - 1)
            if turning:
                turn_predict_into(x, p, dt[i, k], turn_par, xp, pp, tmp, phi[i, k], qd[i, k], u0)
            else:
                predict_into(x, p, phi[ip, k], qd[ip, k], u[iu, k], xp, pp, tmp)
            if radar:
                ok, nis, logdet, nobs = radar_update_into(
                    xp, pp, z[i, k], mask[i, k], codes, pose, reads, r[ir, kr], joseph, x, p,
                    tmp, hm, rm, hp, s, lo, kt, nu, w, ikh, zp, jac, sread,
                )  # fmt: skip
            else:
                ok, nis, logdet, nobs = masked_update_into(
                    xp, pp, z[i, k], mask[i, k], h, r[ir, kr], off, joseph, x, p, tmp, hm, rm,
                    hp, s, lo, kt, nu, w, ikh,
                )  # fmt: skip
            if not ok:
                status[i] = 1
                break
            store_step(pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o, i, k, xp, pp, x, p, kt,
                       nu, s, nis, logdet, nobs)  # fmt: skip
            for a in range(m):
                for b in range(n):
                    h_o[i, k, a, b] = hm[a, b]
    return pm, pc, fm, fc, nu_o, s_o, nis_o, ll_o, k_o, nobs_o, h_o, status
