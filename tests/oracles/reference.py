"""High-precision reference formulas of the spec (mpmath), independent of adaptrack.

Orders follow the spec: seed 000 uses [w, v, r]; M1 [q, dq]; M2 [q, dq, xi].
"""

import math

import mpmath as mp
import numpy as np


def to_float(rows):
    return np.array([[float(v) for v in row] for row in rows])


def relerr(a, b):
    """Normwise relative error max|a - b| / max|b|."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(1e-300, np.max(np.abs(b))))


def relerr_el(a, b, floor=1e-280):
    """Element-wise relative error over the entries of b with |b| > floor."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    mask = np.abs(b) > floor
    return float(np.max(np.abs(a - b)[mask] / np.abs(b)[mask]))


def singer_mp(dt, tau, sw):
    """Exact Phi, Qd, Gamma (noise input e_w) of spec A.4 in seed order [w, v, r]."""
    with mp.workdps(90):
        dt, t, s2 = mp.mpf(dt), mp.mpf(tau), mp.mpf(sw) ** 2
        rho = mp.e ** (-dt / t)
        q00 = s2 * (1 - rho**2)
        q01 = s2 * t * (1 - rho) ** 2
        q02 = s2 * t * (t * (1 - rho**2) - 2 * dt * rho)
        q11 = s2 * t * (2 * dt - 3 * t + 4 * t * rho - t * rho**2)
        q12 = s2 * t * (dt - t + t * rho) ** 2
        q22 = (
            s2
            * t
            * (
                2 * dt**3 / 3
                - 2 * t * dt**2
                + 2 * t**2 * dt
                + t**3
                - 4 * t**2 * dt * rho
                - t**3 * rho**2
            )
        )
        phi = [[rho, 0, 0], [t * (1 - rho), 1, 0], [t * dt - t**2 * (1 - rho), dt, 1]]
        gam = [
            [t * (1 - rho)],
            [t * dt - t**2 * (1 - rho)],
            [t * dt**2 / 2 - t**2 * dt + t**3 * (1 - rho)],
        ]
        q = [[q00, q01, q02], [q01, q11, q12], [q02, q12, q22]]
        return to_float(phi), to_float(q), to_float(gam)


def singer_closed_float(dt, tau, sw):
    """The printed closed forms of A.4 in float64 (accurate only for dt/tau >= 1)."""
    rho = math.exp(-dt / tau)
    s2, t = sw**2, tau
    q = (
        np.array(
            [
                [1 - rho**2, t * (1 - rho) ** 2, t * (t * (1 - rho**2) - 2 * dt * rho)],
                [0, t * (2 * dt - 3 * t + 4 * t * rho - t * rho**2), t * (dt - t + t * rho) ** 2],
                [
                    0,
                    0,
                    t
                    * (
                        2 * dt**3 / 3
                        - 2 * dt**2 * t
                        + 2 * dt * t**2
                        + t**3
                        - 4 * dt * t**2 * rho
                        - t**3 * rho**2
                    ),
                ],
            ]
        )
        * s2
    )
    return q + np.triu(q, 1).T


def m1_mp(dt, k, qa):
    """M1 exact Phi, Gamma (acceleration input [0, 1]) and white-noise Qd with PSD qa."""
    with mp.workdps(90):
        dt, k, qa = mp.mpf(dt), mp.mpf(k), mp.mpf(qa)
        r = mp.e ** (-k * dt)
        g = qa / k**2
        q = [
            [g * (dt - (1 - r) * (3 - r) / (2 * k)), g * (1 - r) ** 2 / 2],
            [g * (1 - r) ** 2 / 2, g * k * (1 - r**2) / 2],
        ]
        gam = [[(dt - (1 - r) / k) / k], [(1 - r) / k]]
        return to_float([[1, (1 - r) / k], [0, r]]), to_float(gam), to_float(q)


def m2_closed(dt, k, a, switch=1e-6):
    """M2 closed forms of B.5.1 (Phi2, Gamma2 for G2 = e_3), float64 test oracle."""
    rk, ra = math.exp(-k * dt), math.exp(-a * dt)
    if abs(k - a) >= switch * max(k, a):
        p23 = k * (ra - rk) / (k - a)
        p13 = k / (k - a) * ((1 - ra) / a - (1 - rk) / k)
        g1 = k / (k - a) * ((dt - (1 - ra) / a) / a - (dt - (1 - rk) / k) / k)
    else:
        p23 = k * dt * rk
        p13 = (1 - rk - k * dt * rk) / k
        g1 = dt / k - (2 * (1 - rk) - k * dt * rk) / k**2
    phi = np.array([[1, (1 - rk) / k, p13], [0, rk, p23], [0, 0, ra]])
    return phi, np.array([g1, p13, (1 - ra) / a])


def van_loan_mp(f, g, qc, dt):
    """High-precision Van Loan Phi, Qd for a generic (F, G, Qc)."""
    n = f.shape[0]
    g = np.atleast_2d(g).reshape(n, -1)
    gq = g @ np.atleast_2d(qc) @ g.T
    with mp.workdps(int(60 + 0.9 * float(np.abs(f).sum(axis=0).max()) * dt)):
        m = mp.zeros(2 * n, 2 * n)
        for i in range(n):
            for j in range(n):
                m[i, j] = -mp.mpf(f[i, j])
                m[i, n + j] = mp.mpf(gq[i, j])
                m[n + i, n + j] = mp.mpf(f[j, i])
        e = mp.expm(m * mp.mpf(dt))
        phi = e[n:, n:].T
        qd = phi * e[:n, n:]
        return (
            to_float([[phi[i, j] for j in range(n)] for i in range(n)]),
            to_float([[qd[i, j] for j in range(n)] for i in range(n)]),
        )


# seed 000 [w, v, r] <-> adaptrack [r, v, w]
PI = np.fliplr(np.eye(3))


def to_seed(a):
    """Permute an adaptrack-order (r, v, w) matrix or vector to seed order (w, v, r)."""
    a = np.asarray(a)
    return PI @ a @ PI.T if a.ndim == 2 and a.shape == (3, 3) else PI @ a


def kalman_mp(
    transition, process_cov, h, r, z, x0, p0, dps=50, mask=None, offset=None, smooth=False
):
    """Filtered (``smooth``: RTS-smoothed) means and covariances at ``dps`` digits.

    ``transition``, ``process_cov`` (T, n, n) map step k-1 to k (as in a FilterResult), ``z``
    (T, m), ``h`` (m, n), ``r`` (m, m), prior ``x0``, ``p0``; ``mask`` (T, m) marks the present
    components (the update uses only those rows; none: prediction only), ``offset`` (m,) the
    measurement noise mean. Textbook covariance form ``P = P - K S K^T`` with the inverse of
    ``S``: at 50 digits its cancellation is harmless; likewise the smoother's difference form
    ``P_k|T = P_k|k + C (P_k+1|T - P_k+1|k) C^T`` with ``C = P_k|k Phi^T P_k+1|k^-1``.
    """

    def mat(a):
        return mp.matrix(np.asarray(a, dtype=float).tolist())

    z = np.asarray(z, dtype=float)
    mask = np.ones(z.shape, bool) if mask is None else np.asarray(mask, bool)
    offset = np.zeros(z.shape[-1]) if offset is None else np.asarray(offset, dtype=float)
    h, r = np.asarray(h, dtype=float), np.asarray(r, dtype=float)
    with mp.workdps(dps):
        x, p = mat(np.reshape(x0, (-1, 1))), mat(p0)
        filtered, predicted = [], []
        for k in range(len(z)):
            f = mat(transition[k])
            x = f * x
            p = f * p * f.T + mat(process_cov[k])
            predicted.append((x, p))
            on = np.flatnonzero(mask[k])
            if on.size:
                hm, rm = mat(h[on]), mat(r[np.ix_(on, on)])
                s = hm * p * hm.T + rm
                gain = p * hm.T * mp.inverse(s)
                x = x + gain * (mat(np.reshape(z[k, on] - offset[on], (-1, 1))) - hm * x)
                p = p - gain * s * gain.T
                p = (p + p.T) / 2
            filtered.append((x, p))
        if smooth:
            for k in range(len(z) - 2, -1, -1):
                (xf, pf), (xp, pp) = filtered[k], predicted[k + 1]
                c = pf * mat(transition[k + 1]).T * mp.inverse(pp)
                xs, ps = filtered[k + 1]
                filtered[k] = (xf + c * (xs - xp), pf + c * (ps - pp) * c.T)
        means = [[float(v) for v in x] for x, _ in filtered]
        covs = [to_float(((p + p.T) / 2).tolist()) for _, p in filtered]
    return np.array(means), np.array(covs)


def imm_mp(transitions, process_covs, hs, names, r, z, mask, priors, pi, mu0, dps=60):
    """Combined means (T, n_out) of an IMM at ``dps`` digits; its mixing as documented in
    :mod:`adaptrack.filters.imm` (states matched by name; a state that component i lacks is
    taken from model j's own estimate, uncorrelated).

    ``transitions[j]``, ``process_covs[j]`` (T, n_j, n_j) map step k-1 to k (step 0 is
    update-only: pass identities and zeros); ``hs[j]`` (m, n_j); ``names[j]`` state names;
    ``r`` (m, m); ``z`` (T, m); ``mask`` (T, m); ``priors[j]`` (mean, cov); ``pi`` (M, M)
    with ``pi[i, j] = P(j | i)``; ``mu0`` (M,). Textbook (covariance) form at ``dps`` digits.
    """

    def mat(a):
        return mp.matrix(np.asarray(a, dtype=float).tolist())

    n_models = len(hs)
    out = [s for s in names[0] if all(s in nm for nm in names)]
    with mp.workdps(dps):
        xs = [mat(np.reshape(p[0], (-1, 1))) for p in priors]
        ps = [mat(p[1]) for p in priors]
        mu = [mp.mpf(float(v)) for v in mu0]
        means = []
        for k in range(len(z)):
            if k:
                c = [sum(mp.mpf(float(pi[i, j])) * mu[i] for i in range(n_models))
                     for j in range(n_models)]  # fmt: skip
                mixed = []
                for j in range(n_models):
                    nj = len(names[j])
                    w = [mp.mpf(float(pi[i, j])) * mu[i] / c[j] if c[j] > 0 else mp.mpf(0)
                         for i in range(n_models)]  # fmt: skip
                    emb = []
                    for i in range(n_models):
                        x = xs[j].copy()
                        p = ps[j].copy()
                        shared = [a for a in range(nj) if names[j][a] in names[i]]
                        src = [names[i].index(names[j][a]) for a in shared]
                        for a in range(nj):
                            if a in shared:
                                continue
                            for b in shared:
                                p[a, b] = p[b, a] = 0
                        for a, sa in zip(shared, src, strict=True):
                            x[a] = xs[i][sa]
                            for b, sb in zip(shared, src, strict=True):
                                p[a, b] = ps[i][sa, sb]
                        emb.append((x, p))
                    x0 = sum((w[i] * emb[i][0] for i in range(n_models)), mp.zeros(nj, 1))
                    p0 = mp.zeros(nj, nj)
                    for i in range(n_models):
                        d = emb[i][0] - x0
                        p0 += w[i] * (emb[i][1] + d * d.T)
                    mixed.append((x0, p0))
                c_k = c
            else:
                mixed = list(zip(xs, ps, strict=True))
                c_k = mu
            lik = []
            for j in range(n_models):
                f = mat(transitions[j][k])
                x = f * mixed[j][0]
                p = f * mixed[j][1] * f.T + mat(process_covs[j][k])
                on = np.flatnonzero(mask[k])
                if on.size:
                    hm, rm = mat(hs[j][on]), mat(np.asarray(r)[np.ix_(on, on)])
                    s = hm * p * hm.T + rm
                    nu = mat(np.reshape(z[k, on], (-1, 1))) - hm * x
                    gain = p * hm.T * mp.inverse(s)
                    x = x + gain * nu
                    p = p - gain * s * gain.T
                    q = (nu.T * mp.inverse(s) * nu)[0]
                    lik.append(mp.exp(-q / 2) / mp.sqrt(mp.det(2 * mp.pi * s)))
                else:
                    lik.append(mp.mpf(1))
                xs[j], ps[j] = x, (p + p.T) / 2
            tot = sum(lik[j] * c_k[j] for j in range(n_models))
            mu = [lik[j] * c_k[j] / tot for j in range(n_models)]
            comb = [sum(mu[j] * xs[j][names[j].index(s)] for j in range(n_models)) for s in out]
            means.append([float(v) for v in comb])
    return np.array(means)
