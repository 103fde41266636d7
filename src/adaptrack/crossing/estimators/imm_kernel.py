"""Compiled (numba) road-constrained IMM of :func:`.road_filters.track_on_road_imm`.

Per run (runs in parallel) and scan: switching probabilities of the step from the series table
of the mode chain's generator, IMM interaction (:func:`adaptrack.filters._imm_kernel.mix_into`),
per mode the road EKF predict (series-table transition), the no-reversal hold and the Joseph
update at the mode's prediction (:func:`.kernels.measure`) or, on a missed detection,
the Doppler-gate pseudo-measurement and the miss's likelihood (:func:`.kernels.
gate_update_into`), mode probabilities and the
combination over the common states ``[s, ds/dt, d]``, written as planar estimates. Agrees with
the NumPy reference to rounding (tests).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from ...filters._imm_kernel import combine_into, mix_into, mode_update_into
from ...filters._kernels import _LOG_2PI, predict_into, series_transition_into, update_into
from .kernels import (
    ROAD,
    _planar_into,
    doppler_usable,
    folded_log_likelihood_gap,
    gate_update_into,
    innovation_into,
    measure,
)


@numba.njit(cache=True, parallel=True)
def road_imm_kernel(  # type: ignore[no-untyped-def]
    times,
    sizes,
    phi_coef,
    qd_coef,
    h_max,
    chain_coef,
    chain_h_max,
    log_mu0,
    emb_dst,
    emb_src,
    emb_cnt,
    out_idx,
    z,
    detected,
    first,
    m0,
    p0,
    radar,
    noise_tab,
    noise_cnt,
    fields,
    pd_tab,
    pd_cnt,
    road,
    half_width,
    scatter_std,
    pos,
    vel,
    speed,
    pcov,
    probs,
    status,
):
    """Run the road IMM over every run from its first detection.

    Shapes (M modes padded to ``nmax`` states; mode j has ``sizes[j]`` states, the lateral
    offset last): ``phi_coef`` (M, P, nmax, nmax), ``qd_coef`` (M, Q, nmax, nmax), ``h_max``
    (M,) the modes' series tables (zero-padded); ``chain_coef`` (C, M, M) the series of
    ``expm(L^T h)`` of the chain generator ``L`` (``chain_h_max``); ``emb_*``/``out_idx`` as
    in :func:`adaptrack.filters._imm_kernel.imm_kernel`; ``m0`` (M, N, nmax), ``p0``
    (M, N, nmax, nmax) the initial states at ``first`` (N,). ``pos``/``vel``/``speed``/
    ``pcov`` as in :func:`.kernels.ekf_kernel`, ``probs`` (N, T, M) the mode
    probabilities (NaN before the start); ``status[i] = t + 1`` if run ``i`` stops at step
    ``t`` (S not positive definite).
    """
    n_modes, _, nmax = m0.shape
    n_runs, n_steps = detected.shape
    n_out = out_idx.shape[1]
    no_off = np.zeros((0, nmax))
    no_chain_qd = np.zeros((1, n_modes, n_modes))
    no_chain_off = np.zeros((0, n_modes))
    for i in prange(n_runs):
        f = first[i]
        if f < 0:
            continue
        xs, ps = m0[:, i].copy(), p0[:, i].copy()
        mx, mp = np.zeros((n_modes, nmax)), np.zeros((n_modes, nmax, nmax))
        em, ep = np.zeros(nmax), np.zeros((nmax, nmax))
        log_mu = log_mu0.copy()
        log_c, ll, joint = np.empty(n_modes), np.empty(n_modes), np.empty(n_modes)
        log_joint, w = np.empty((n_modes, n_modes)), np.empty((n_modes, n_modes))
        log_pi = np.empty((n_modes, n_modes))
        chain, chain_qd = np.empty((n_modes, n_modes)), np.empty((n_modes, n_modes))
        chain_u, chain_tmp = np.empty(n_modes), np.empty((n_modes, n_modes))
        phi, qd, tmp = np.empty((nmax, nmax)), np.empty((nmax, nmax)), np.empty((nmax, nmax))
        xp, pp, u, wv = np.empty(nmax), np.empty((nmax, nmax)), np.zeros(nmax), np.empty(3)
        ikh, h, hp, kt = (
            np.empty((nmax, nmax)),
            np.zeros((3, nmax)),
            np.empty((3, nmax)),
            np.empty((3, nmax)),
        )
        zp, resid, rm = np.empty(3), np.empty(3), np.empty((3, 3))
        s, lo, jp, jv = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 2)), np.empty((3, 2))
        xc, pc = np.empty(n_out), np.empty((n_out, n_out))
        nu1, r1 = np.empty(1), np.empty((1, 1))
        miss_run = np.ones(n_modes)
        for j in range(n_modes):
            probs[i, f, j] = math.exp(log_mu[j])
        combine_into(xs, ps, probs[i, f], out_idx, xc, pc)
        speed[i, f] = _planar_into(
            ROAD, xc, pc, n_out - 1, road, half_width, pos[i, f], vel[i, f], pcov[i, f]
        )
        for t in range(f + 1, n_steps):
            dt = times[i, t] - times[i, t - 1]
            series_transition_into(
                dt, chain_coef, no_chain_qd, no_chain_off, chain_h_max,
                chain, chain_qd, chain_u, chain_tmp,
            )  # fmt: skip
            for a in range(n_modes):  # pi[a, b] = P(b now | a before) = expm(L dt)[a, b]
                for b in range(n_modes):
                    log_pi[a, b] = math.log(max(chain[b, a], 1e-300))
            mix_into(
                xs, ps, sizes, log_mu, log_pi, emb_dst, emb_src, emb_cnt,
                mx, mp, log_c, log_joint, w, em, ep,
            )  # fmt: skip
            for j in range(n_modes):
                nj = sizes[j]
                k = nj - 1
                series_transition_into(
                    dt, phi_coef[j, :, :nj, :nj], qd_coef[j, :, :nj, :nj], no_off[:, :nj],
                    h_max[j], phi[:nj, :nj], qd[:nj, :nj], u[:nj], tmp[:nj, :nj],
                )  # fmt: skip
                predict_into(
                    mx[j, :nj], mp[j, :nj, :nj], phi[:nj, :nj], qd[:nj, :nj], u[:nj],
                    xp[:nj], pp[:nj, :nj], tmp[:nj, :nj],
                )  # fmt: skip
                if xp[1] > 0:  # an approaching vehicle does not reverse
                    for a in range(1, k):
                        xp[a] = 0.0
                if detected[i, t]:
                    measure(
                        ROAD, xp[:nj], k, radar, noise_tab, noise_cnt, road, half_width,
                        scatter_std, zp, h[:, :nj], rm, jp, jv,
                    )  # fmt: skip
                    doppler = doppler_usable(h[:, :nj], pp[:nj, :nj], rm, radar)
                    innovation_into(z[i, t], zp, radar, doppler, resid)
                    ok, nis, logdet = update_into(
                        xp[:nj], pp[:nj, :nj], resid, h[:, :nj], rm, True, xs[j, :nj],
                        ps[j, :nj, :nj], hp[:, :nj], s, lo, kt[:, :nj], wv, ikh[:nj, :nj],
                        tmp[:nj, :nj],
                    )  # fmt: skip
                    if not ok:
                        status[i] = t + 1
                        break
                    ll[j] = -0.5 * (logdet + nis + 3.0 * _LOG_2PI)
                    if not doppler:
                        ll[j] += folded_log_likelihood_gap(rm, radar)
                    miss_run[j] = 1.0
                else:  # a missed detection: its probability weighs the modes
                    ll[j], miss_run[j] = gate_update_into(
                        ROAD, xp[:nj], pp[:nj, :nj], k, radar, noise_tab, noise_cnt, fields,
                        pd_tab, pd_cnt, road, half_width, scatter_std, miss_run[j], xs[j, :nj],
                        ps[j, :nj, :nj], zp, h[:, :nj], rm, jp, jv, hp[:1, :nj], s[:1, :1],
                        lo[:1, :1], kt[:1, :nj], wv[:1], ikh[:nj, :nj], tmp[:nj, :nj], nu1, r1,
                    )  # fmt: skip
            if status[i] != 0:
                break
            mode_update_into(ll, log_c, joint, log_mu, probs[i, t])
            combine_into(xs, ps, probs[i, t], out_idx, xc, pc)
            speed[i, t] = _planar_into(
                ROAD, xc, pc, n_out - 1, road, half_width, pos[i, t], vel[i, t], pcov[i, t]
            )
