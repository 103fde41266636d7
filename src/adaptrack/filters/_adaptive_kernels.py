"""Compiled (numba) kernel of seed 002's published adaptive filter (spec C.5).

The NumPy recursion in :mod:`adaptrack.filters.adaptive` is the readable reference; this kernel
runs the same steps row by row (one row per track and axis, rows in parallel) and agrees with
it to rounding (tests: <= 1e-10 relative, identical gain decisions).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange


@numba.njit(cache=True, inline="always")
def _rho_cv(k0, k1, t):  # type: ignore[no-untyped-def]
    """Spectral radius of ``Phi (I - K C)`` for the constant-velocity model."""
    tr = 2.0 - k0 - t * k1
    det = 1.0 - k0
    disc = tr * tr - 4.0 * det
    if disc >= 0:
        return (abs(tr) + math.sqrt(abs(disc))) / 2.0
    return math.sqrt(abs(det))


@numba.njit(cache=True, inline="always")
def _joseph_into(p, k0, k1, r, out):  # type: ignore[no-untyped-def]
    """``(I - K C) P (I - K C)^T + K R K^T`` (symmetrised) for ``C = [1, 0]``."""
    a00, a10 = 1.0 - k0, -k1  # I - K C = [[a00, 0], [a10, 1]]
    m00 = a00 * p[0, 0]
    m01 = a00 * p[0, 1]
    m10 = a10 * p[0, 0] + p[1, 0]
    m11 = a10 * p[0, 1] + p[1, 1]
    o00 = m00 * a00 + k0 * k0 * r
    o01 = m00 * a10 + m01 + k0 * k1 * r
    o10 = m10 * a00 + k1 * k0 * r
    o11 = m10 * a10 + m11 + k1 * k1 * r
    out[0, 0] = o00
    out[1, 1] = o11
    out[0, 1] = out[1, 0] = 0.5 * (o01 + o10)


@numba.njit(cache=True, inline="always")
def _predict_cov(p, step, q, out):  # type: ignore[no-untyped-def]
    """``Phi P Phi^T + Q`` for ``Phi = [[1, T], [0, 1]]``."""
    a00 = p[0, 0] + step * p[1, 0]
    a01 = p[0, 1] + step * p[1, 1]
    out[0, 0] = a00 + step * a01 + q[0, 0]
    out[0, 1] = a01 + q[0, 1]
    out[1, 0] = p[1, 0] + step * p[1, 1] + q[1, 0]
    out[1, 1] = p[1, 1] + q[1, 1]


@numba.njit(cache=True, parallel=True)
def published_kernel(  # type: ignore[no-untyped-def]
    z, mask, step, q0, r0, c, memory, window, n_min, est, cov, used, attempts, fallbacks
):
    """Run spec C.5 from epoch 2 on (``est``/``cov`` hold the two-point start at 0 and 1).

    ``z``, ``mask`` (rows, T); ``q0`` (rows, 2, 2); ``r0`` (rows,); ``c`` the difference
    coefficients (N + 1,); ``n_min < 0`` freezes adaptation. Fills ``est`` (rows, T, 2),
    ``cov`` (rows, T, 2, 2), ``used`` (rows, T) and per-row ``attempts``, ``fallbacks``.
    """
    rows, n_steps = z.shape
    order = c.shape[0] - 1
    nb = order + 2
    n_stat = 2 + nb + 1
    for row in prange(rows):
        r = r0[row]
        r_floor = 1e-3 * r
        xh0, xh1 = est[row, 1, 0], est[row, 1, 1]
        p_nom = cov[row, 1].copy()
        p_rep = cov[row, 1].copy()
        p0a = np.empty((2, 2))
        pa = np.empty((2, 2))
        bx = np.zeros((nb, 2))
        bv = np.zeros(nb)
        bg = np.zeros(nb)
        stats = np.zeros(n_stat)
        prod = np.empty(n_stat)
        hist = np.zeros((memory if window else 1, n_stat))
        count = 0
        ns = 0
        for n in range(2, n_steps):
            present = mask[row, n]
            xa0 = xh0 + step * xh1
            xa1 = xh1
            v = z[row, n] - xa0 if present else 0.0
            _predict_cov(p_nom, step, q0[row], p0a)
            k00 = p0a[0, 0] / (p0a[0, 0] + r)
            k01 = p0a[1, 0] / (p0a[0, 0] + r)
            # step 3: buffers (index 0 = newest)
            for j in range(nb - 1, 0, -1):
                bx[j, 0] = bx[j - 1, 0]
                bx[j, 1] = bx[j - 1, 1]
                bv[j] = bv[j - 1]
                bg[j] = bg[j - 1]
            bx[0, 0], bx[0, 1], bv[0] = xa0, xa1, v
            bg[0] = z[row, n] if present else 0.0
            count = min(count + 1, nb) if present else 0
            full = present and count == nb
            # step 4: statistics
            if full:
                ns += 1
                dx0 = 0.0
                dx1 = 0.0
                dg = 0.0
                for j in range(order + 1):
                    dx0 += c[j] * bx[j, 0]
                    dx1 += c[j] * bx[j, 1]
                    dg += bg[j] * c[j]
                prod[0], prod[1] = dx0 * v, dx1 * v
                for j in range(nb):
                    prod[2 + j] = v * bv[j]
                prod[n_stat - 1] = v * dg
                if window:
                    slot = (ns - 1) % memory
                    for j in range(n_stat):
                        hist[slot, j] = prod[j]
                    filled = min(ns, memory)
                    for j in range(n_stat):
                        acc = 0.0
                        for s in range(memory):
                            acc += hist[s, j]
                        stats[j] = acc / filled
                else:
                    b = 1.0 / min(max(ns, 1), memory)
                    for j in range(n_stat):
                        stats[j] = stats[j] + b * (prod[j] - stats[j])
            # step 5: gain
            k0, k1 = k00, k01
            if n_min >= 0 and present and ns >= n_min:
                s1 = 0.0
                s2 = 0.0
                for j in range(1, order + 1):
                    s1 += stats[2 + j] * c[j]
                    s2 += (stats[2 + j] - stats[3 + j]) * c[j]
                pc0 = -stats[0] - s1
                pc1 = -stats[1] - s2 / step
                a_s = max(pc0, 0.0)
                r_hat = max(stats[n_stat - 1], r_floor)
                den = a_s + r_hat
                ka0 = a_s / den
                ka1 = pc1 / den
                good = (
                    math.isfinite(ka0)
                    and math.isfinite(ka1)
                    and a_s > 0
                    and _rho_cv(ka0, ka1, step) < 1
                )
                if good:
                    k0, k1 = ka0, ka1
                used[row, n] = good
                attempts[row] += 1
                fallbacks[row] += 0 if good else 1
            # step 6: update (prediction only where the measurement is missing)
            _predict_cov(p_rep, step, q0[row], pa)
            if present:
                xh0 = xa0 + k0 * v
                xh1 = xa1 + k1 * v
                _joseph_into(p0a, k00, k01, r, p_nom)
                _joseph_into(pa, k0, k1, r, p_rep)
            else:
                xh0, xh1 = xa0, xa1
                p_nom[:, :] = p0a
                p_rep[:, :] = pa
            est[row, n, 0] = xh0
            est[row, n, 1] = xh1
            cov[row, n] = p_rep
