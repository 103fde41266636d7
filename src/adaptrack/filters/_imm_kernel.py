"""Compiled (numba) kernel of the IMM estimator (:func:`adaptrack.filters.imm.imm_filter`).

Models of different sizes are padded to the largest; each model's block is used through
views of its own size. Per track (tracks in parallel) and step: mixing with the shared-state
embedding; prediction (linear, or the coordinated turn's) and update (linear as
:func:`adaptrack.filters._kernels.kf_step` does, Joseph or standard form, or a radar's), or
:func:`adaptrack.filters._sqrt_kernel.sqrt_step` from the mixed factor (square-root form: the
models' factors are mixed in factor form, :func:`mix_factor_into`); mode probabilities by
log-sum-exp; combination. Agrees with the NumPy reference to rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from ._kernels import _LOG_2PI, masked_update_into, predict_into
from ._radar_update import radar_update_into
from ._sqrt_kernel import lower_factor_into, lower_triangularize, outer_into, sqrt_step
from ._turn_kernel import turn_predict_into

FORMS = ("standard", "joseph", "sqrt")  # the kernel's form codes 0, 1, 2


@numba.njit(cache=True, inline="always")
def _logsumexp(a):  # type: ignore[no-untyped-def]
    top = -np.inf
    for v in a:
        top = max(top, v)
    if not math.isfinite(top):
        return top
    acc = 0.0
    for v in a:
        acc += math.exp(v - top)
    return top + math.log(acc)


@numba.njit(cache=True)
def mix_into(  # type: ignore[no-untyped-def]
    xs, ps, sizes, log_mu, log_pi, emb_dst, emb_src, emb_cnt, mx, mp, log_c, log_joint, w, em, ep
):
    """IMM interaction: mixed initial conditions ``mx``, ``mp`` of every model, and ``log_c``.

    ``xs``/``ps`` (M, nmax[, nmax]) the models' estimates, ``log_mu`` (M,) their log
    probabilities, ``log_pi`` (M, M) log switching probabilities; a model's states that
    another lacks keep the receiving model's own values (``emb_*``: the (dst, src, count) of
    the states model i shares with model j). ``log_c`` (M,) receives the predicted log
    weights; ``log_joint``, ``w``, ``em``, ``ep`` are scratch.
    """
    n_models = xs.shape[0]
    for a in range(n_models):
        for b in range(n_models):
            log_joint[a, b] = log_mu[a] + log_pi[a, b]
    for b in range(n_models):
        log_c[b] = _logsumexp(log_joint[:, b])
        for a in range(n_models):
            w[a, b] = math.exp(log_joint[a, b] - log_c[b])
    for j in range(n_models):
        nj = sizes[j]
        mx[j, :] = 0.0
        mp[j, :, :] = 0.0
        for src_model in range(n_models):
            # embed model src_model's estimate into model j's states
            em[:nj] = xs[j, :nj]
            ep[:nj, :nj] = ps[j, :nj, :nj]
            cnt = emb_cnt[src_model, j]
            for a in range(cnt):
                da = emb_dst[src_model, j, a]
                em[da] = xs[src_model, emb_src[src_model, j, a]]
                for c in range(nj):
                    ep[da, c] = 0.0
                    ep[c, da] = 0.0
            for a in range(cnt):
                da, sa = emb_dst[src_model, j, a], emb_src[src_model, j, a]
                for b in range(cnt):
                    db, sb = emb_dst[src_model, j, b], emb_src[src_model, j, b]
                    ep[da, db] = ps[src_model, sa, sb]
            wij = w[src_model, j]
            for a in range(nj):
                mx[j, a] += wij * em[a]
            for a in range(nj):
                for b in range(nj):
                    mp[j, a, b] += wij * ep[a, b]
        # spread of the embedded means around the mixed mean
        for src_model in range(n_models):
            em[:nj] = xs[j, :nj]
            for a in range(emb_cnt[src_model, j]):
                em[emb_dst[src_model, j, a]] = xs[src_model, emb_src[src_model, j, a]]
            wij = w[src_model, j]
            for a in range(nj):
                for b in range(nj):
                    mp[j, a, b] += wij * (em[a] - mx[j, a]) * (em[b] - mx[j, b])
        for a in range(nj):
            for b in range(a + 1, nj):
                v = 0.5 * (mp[j, a, b] + mp[j, b, a])
                mp[j, a, b] = v
                mp[j, b, a] = v


@numba.njit(cache=True)
def mix_factor_into(  # type: ignore[no-untyped-def]
    xs, fs, sizes, w, mx, emb_dst, emb_src, emb_cnt, j, shared, pre, out
):  # fmt: skip
    """Write a factor of model ``j``'s mixed covariance, from the factors ``fs``, into ``out``.

    The compiled :func:`adaptrack.filters.imm._mixed_factor`: ``w`` (M, M) the mixing
    probabilities and ``mx`` the mixed means (both from :func:`mix_into`); the pre-array
    ``[sqrt(w_ij) E_i, sqrt(w_ij) d_i]`` over the models ``i`` is built in ``pre``
    (nmax, M (2 nmax + 1)) and triangularised; ``shared`` (nmax,) bool is scratch.
    """
    n_models = xs.shape[0]
    nj = sizes[j]
    col = 0
    for i in range(n_models):
        ni = sizes[i]
        root = math.sqrt(w[i, j])
        width = ni + nj + 1
        for a in range(nj):
            shared[a] = False
            for c in range(col, col + width):
                pre[a, c] = 0.0
            pre[a, col + ni + nj] = root * (xs[j, a] - mx[j, a])
        for a in range(emb_cnt[i, j]):
            da, sa = emb_dst[i, j, a], emb_src[i, j, a]
            shared[da] = True
            pre[da, col + ni + nj] = root * (xs[i, sa] - mx[j, da])
            for c in range(ni):
                pre[da, col + c] = root * fs[i, sa, c]
        for a in range(nj):
            if not shared[a]:
                for c in range(nj):
                    pre[a, col + ni + c] = root * fs[j, a, c]
        col += width
    lower_triangularize(pre[:nj, :col], nj, col)
    for a in range(nj):
        for b in range(nj):
            out[a, b] = pre[a, b]


@numba.njit(cache=True, inline="always")
def mode_update_into(ll, log_c, joint, log_mu, mu):  # type: ignore[no-untyped-def]
    """Posterior mode log probabilities ``log_mu`` and probabilities ``mu`` (M,).

    ``ll`` (M,) measurement log-likelihoods, ``log_c`` (M,) predicted log weights; returns
    the mixture's log-likelihood (``joint`` is scratch).
    """
    n_models = ll.shape[0]
    for j in range(n_models):
        joint[j] = ll[j] + log_c[j]
    total = _logsumexp(joint)
    norm = 0.0
    for j in range(n_models):
        log_mu[j] = joint[j] - total
        mu[j] = math.exp(log_mu[j])
        norm += mu[j]
    for j in range(n_models):  # renormalise: 1 up to the rounding of large log-likelihoods
        mu[j] /= norm
        log_mu[j] -= math.log(norm)
    return total


@numba.njit(cache=True)
def combine_into(xs, ps, mu, out_idx, xm, cm):  # type: ignore[no-untyped-def]
    """Fill the combined mean ``xm`` (n_out,) and covariance ``cm`` of the common states."""
    n_models = xs.shape[0]
    n_out = out_idx.shape[1]
    for a in range(n_out):
        acc = 0.0
        for j in range(n_models):
            acc += mu[j] * xs[j, out_idx[j, a]]
        xm[a] = acc
    for a in range(n_out):
        for b in range(n_out):
            acc = 0.0
            for j in range(n_models):
                ja, jb = out_idx[j, a], out_idx[j, b]
                d = (xs[j, ja] - xm[a]) * (xs[j, jb] - xm[b])
                acc += mu[j] * (ps[j, ja, jb] + d)
            cm[a, b] = acc
    for a in range(n_out):
        for b in range(a + 1, n_out):
            v = 0.5 * (cm[a, b] + cm[b, a])
            cm[a, b] = v
            cm[b, a] = v


@numba.njit(cache=True, parallel=True)
def imm_kernel(  # type: ignore[no-untyped-def]
    sizes,
    x0,
    p0,
    phi,
    qd,
    u,
    didx,
    z,
    mask,
    h,
    codes,
    pose,
    reads,
    kinds,
    turn_par,
    dts,
    r,
    r_scale,
    r_min,
    log_mu0,
    log_pi,
    step_pi,
    emb_dst,
    emb_src,
    emb_cnt,
    out_idx,
    form,
    comp_mean,
    comp_cov,
    probs,
    ll_mix,
    comb_mean,
    comb_cov,
    status,
    worst,
):
    """Run the IMM over every track; outputs are filled in place.

    Shapes (M models padded to ``nmax`` states, m measured): ``x0`` (M, N|1, nmax), ``p0``
    (M, N|1, nmax, nmax); ``phi``/``qd`` (M, U, nmax, nmax) and ``u`` (M, U, nmax) for the U
    distinct step lengths (``qd`` holds factors of ``Qd`` in square-root form), ``log_pi``
    (P, M, M) the log transition matrices and ``step_pi`` (N, T) the one of each step,
    ``form`` an index into :data:`FORMS`, ``didx`` (N|1, T) the step length of every step;
    ``z``/``mask`` (N, T, m), ``h`` (M, m, nmax), ``r`` (N|1, T|1, m, m). A radar measurement
    (IMM-EKF, Joseph form) replaces ``h``: its component ``codes`` (m,; empty for a linear
    measurement), ``pose`` and the ``reads`` (M, k) of each model (see
    :mod:`adaptrack.filters._radar_update`). ``kinds`` (M,) is 1 for a coordinated-turn model
    (``turn_par`` (M, 4) its parameters, predicted over the step lengths ``dts`` (U,)), 0 for
    a linear one. ``emb_*`` the
    (dst, src, count) of the states model i shares with model j, ``out_idx`` (M, n_out).
    ``status[i]`` becomes ``k + 1`` if track ``i`` stops at step ``k`` (S not positive
    definite). ``r_scale`` (N|1, T|1, m) is ``1 / diag(R)`` and ``r_min`` (N|1, T|1) the
    smallest eigenvalue of each ``R`` scaled to unit diagonal; in the Joseph and standard forms
    ``worst[i]`` becomes the largest ``sum_a S_aa r_scale_a / r_min`` of track ``i`` over its
    steps and models (:func:`adaptrack.filters.kalman.joseph_ratio`, the ``"auto"`` form's
    criterion, over observed components).
    """
    n_models, _, nmax = x0.shape
    n_tracks, n_steps, m = z.shape
    off = np.zeros(m)
    for i in prange(n_tracks):
        ii = numba.int64(i)  # prange's index may be unsigned: min() with it gives a float
        ix = min(ii, x0.shape[1] - 1)
        ip = min(ii, didx.shape[0] - 1)
        ir = min(ii, r.shape[0] - 1)
        xs = np.zeros((n_models, nmax))
        ps = np.zeros((n_models, nmax, nmax))
        mx = np.zeros((n_models, nmax))
        mp = np.zeros((n_models, nmax, nmax))
        em = np.zeros(nmax)
        ep = np.zeros((nmax, nmax))
        log_mu = log_mu0.copy()
        log_c = np.empty(n_models)
        log_joint = np.empty((n_models, n_models))
        w = np.empty((n_models, n_models))
        ll = np.empty(n_models)
        joint = np.empty(n_models)
        xp = np.empty(nmax)
        pp = np.empty((nmax, nmax))
        tmp = np.empty((nmax, nmax))
        hm = np.empty((m, nmax))
        rm = np.empty((m, m))
        hp = np.empty((m, nmax))
        s = np.empty((m, m))
        lo = np.empty((m, m))
        kt = np.empty((m, nmax))
        nu = np.empty(m)
        wv = np.empty(m)
        ikh = np.empty((nmax, nmax))
        fac = np.empty((nmax, nmax))
        fs = np.zeros((n_models, nmax, nmax))  # square-root form: the models' factors ...
        mfs = np.zeros((n_models, nmax, nmax))  # ... and their mixed factors
        pre_mix = np.empty((nmax, n_models * (2 * nmax + 1)))
        shared = np.empty(nmax, dtype=np.bool_)
        pre1 = np.empty((nmax, 2 * nmax))
        pre2 = np.empty((m + nmax, m + nmax))
        sr = np.empty((m, m))
        gain = np.empty((nmax, m))
        radar = codes.shape[0] > 0
        fbuf = np.empty((nmax, nmax))
        qbuf = np.empty((nmax, nmax))
        u0 = np.empty(nmax)
        zp = np.empty(m)
        jac = np.empty((m, reads.shape[1]))
        sread = np.empty(reads.shape[1])
        for j in range(n_models):
            for a in range(nmax):
                xs[j, a] = x0[j, ix, a]
                for b in range(nmax):
                    ps[j, a, b] = p0[j, ix, a, b]
        for k in range(n_steps):
            kr = min(k, r.shape[1] - 1)
            q = didx[ip, k]
            qp = step_pi[min(ii, step_pi.shape[0] - 1), k]
            if k == 0:
                mx[:, :] = xs
                mp[:, :, :] = ps
                log_c[:] = log_mu
            else:
                mix_into(
                    xs, ps, sizes, log_mu, log_pi[qp], emb_dst, emb_src, emb_cnt,
                    mx, mp, log_c, log_joint, w, em, ep,
                )  # fmt: skip
            if form == 2:  # mixed factors, from the factors of the step before
                for j in range(n_models):
                    nj = sizes[j]
                    if k == 0:
                        lower_factor_into(ps[j, :nj, :nj], mfs[j, :nj, :nj], tmp[:nj, :nj])
                    else:
                        mix_factor_into(
                            xs, fs, sizes, w, mx, emb_dst, emb_src, emb_cnt, j, shared,
                            pre_mix, mfs[j],
                        )  # fmt: skip
            for j in range(n_models):
                nj = sizes[j]
                xs[j, :nj] = mx[j, :nj]
                ps[j, :nj, :nj] = mp[j, :nj, :nj]
                if form == 2:
                    fac[:nj, :nj] = mfs[j, :nj, :nj]
                    ok, nis, logdet, nobs = sqrt_step(
                        xs[j, :nj], fac[:nj, :nj], phi[j, q, :nj, :nj], qd[j, q, :nj, :nj],
                        u[j, q, :nj], z[i, k], mask[i, k], h[j, :, :nj], r[ir, kr], off,
                        xp[:nj], pre1[:nj, : 2 * nj], pre2[: m + nj, : m + nj], rm, sr, nu, wv,
                        gain[:nj],
                    )  # fmt: skip
                    fs[j, :nj, :nj] = fac[:nj, :nj]
                    outer_into(fac, ps[j], nj)
                else:
                    if kinds[j] == 1:  # coordinated turn: EKF prediction
                        turn_predict_into(
                            xs[j, :nj], ps[j, :nj, :nj], dts[q], turn_par[j], xp[:nj],
                            pp[:nj, :nj], tmp[:nj, :nj], fbuf[:nj, :nj], qbuf[:nj, :nj], u0[:nj],
                        )  # fmt: skip
                    else:
                        predict_into(
                            xs[j, :nj], ps[j, :nj, :nj], phi[j, q, :nj, :nj], qd[j, q, :nj, :nj],
                            u[j, q, :nj], xp[:nj], pp[:nj, :nj], tmp[:nj, :nj],
                        )  # fmt: skip
                    if radar:
                        ok, nis, logdet, nobs = radar_update_into(
                            xp[:nj], pp[:nj, :nj], z[i, k], mask[i, k], codes, pose, reads[j],
                            r[ir, kr], form == 1, xs[j, :nj], ps[j, :nj, :nj], tmp[:nj, :nj],
                            hm[:, :nj], rm, hp[:, :nj], s, lo, kt[:, :nj], nu, wv, ikh[:nj, :nj],
                            zp, jac, sread,
                        )  # fmt: skip
                    else:
                        ok, nis, logdet, nobs = masked_update_into(
                            xp[:nj], pp[:nj, :nj], z[i, k], mask[i, k], h[j, :, :nj], r[ir, kr],
                            off, form == 1, xs[j, :nj], ps[j, :nj, :nj], tmp[:nj, :nj],
                            hm[:, :nj], rm, hp[:, :nj], s, lo, kt[:, :nj], nu, wv, ikh[:nj, :nj],
                        )  # fmt: skip
                    if ok:
                        tr = 0.0
                        for a in range(m):
                            if mask[i, k, a]:
                                tr += s[a, a] * r_scale[ir, kr, a]
                        worst[i] = max(worst[i], tr / r_min[ir, kr])
                if not ok:
                    status[i] = k + 1
                    break
                ll[j] = -0.5 * (logdet + nis + nobs * _LOG_2PI) if nobs > 0 else 0.0
                for a in range(nj):
                    comp_mean[j, i, k, a] = xs[j, a]
                    for b in range(nj):
                        comp_cov[j, i, k, a, b] = ps[j, a, b]
            if status[i] != 0:
                break
            ll_mix[i, k] = mode_update_into(ll, log_c, joint, log_mu, probs[i, k])
            combine_into(xs, ps, probs[i, k], out_idx, comb_mean[i, k], comb_cov[i, k])
