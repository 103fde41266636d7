"""Endurance run: 10^7 filter steps on the edge of the specified domain, against a reference.

Every track is a planar constant-velocity target measured in position with a covariance ``R``
of condition number 1e12 (random orientation per track) at steps drawn log-uniformly from
[1e-6, 1e4] s. ``kalman_filter`` (the batch API, in chunks that carry the state over) and
``OnlineFilter`` (one filter per track, fed its stream) run in their default form; the
reference is a square-root filter in extended precision (``np.longdouble``, Householder
triangularisation written here) on the textbook closed form of the model's transition and
process noise, so neither the library's discretisation nor its linear algebra is shared.

Checked: every covariance ``kalman_filter`` returns and every ``OnlineFilter`` covariance
sampled at chunk ends is exactly symmetric and positive semi-definite; the final covariances
are within ``1e-6`` of the reference relative to its norm (``max |P - Pref| / max |Pref|`` per
track). Reported besides: the entry-wise error relative to ``sigma_i sigma_j``, the same for
the reference algorithm run in double precision (what rounding alone costs on these problems:
some variances are formed by cancellation between entries 1e6 times larger), and the final
means' error in reference sigmas.

Run from the repository root::

    python -m tests.stress.endurance --tracks 1000 --steps 10000
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

import adaptrack as at

LD = np.longdouble
ACCEL_PSD = 0.1  # white-acceleration PSD [m^2/s^3]
R_EIG = (1e-4, 1e8)  # measurement variances [m^2]: condition number 1e12
DT_RANGE = (1e-6, 1e4)  # step lengths [s], log-uniform
P0 = (1e6, 1e6, 1e2, 1e2)  # prior variances: positions [m^2], velocities [m^2/s^2]


@dataclass(frozen=True)
class Scenario:
    """Times (N, T) [s], measurements (N, T, 2) [m], covariances (N, 2, 2), the model and prior."""

    times: np.ndarray
    z: np.ndarray
    r: np.ndarray
    model: at.models.ConstantVelocity
    h: np.ndarray
    prior: at.GaussianState


def scenario(n_tracks: int, n_steps: int, seed: int) -> Scenario:
    """Simulate ``n_tracks`` constant-velocity targets over ``n_steps`` irregular steps."""
    rng = np.random.default_rng(seed)
    lo, hi = np.log10(DT_RANGE)
    dt = 10.0 ** rng.uniform(lo, hi, (n_tracks, n_steps))
    times = np.cumsum(dt, axis=1)
    angle = rng.uniform(0.0, np.pi, n_tracks)
    rot = np.stack(
        [
            np.stack([np.cos(angle), -np.sin(angle)], -1),
            np.stack([np.sin(angle), np.cos(angle)], -1),
        ],
        -2,
    )
    r = np.einsum("nij,j,nkj->nik", rot, np.array(R_EIG), rot)
    r = 0.5 * (r + np.swapaxes(r, -1, -2))
    truth = np.zeros((n_tracks, 4))
    truth[:, 2:] = rng.normal(0.0, 10.0, (n_tracks, 2))
    z = np.empty((n_tracks, n_steps, 2))
    chol_r = np.linalg.cholesky(r)
    for k in range(n_steps):
        phi, sq = closed_form(dt[:, k])
        noise = np.einsum("nij,nj->ni", sq, rng.standard_normal((n_tracks, 4)))
        truth = np.einsum("nij,nj->ni", phi, truth) + noise
        z[:, k] = truth[:, :2] + np.einsum("nij,nj->ni", chol_r, rng.standard_normal((n_tracks, 2)))
    model = at.models.ConstantVelocity(accel_psd=ACCEL_PSD, n_axes=2)
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    prior = at.GaussianState(np.zeros((n_tracks, 4)), np.diag(P0) * np.ones((n_tracks, 1, 1)), 0.0)
    return Scenario(times, z, r, model, h, prior)


def closed_form(dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Transition and a lower factor of the process covariance of the planar CV model.

    State ``[x, y, vx, vy]``; ``Qd = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` per axis, whose
    Cholesky factor is ``sqrt(q) [[sqrt(dt^3/3), 0], [sqrt(3 dt)/2, sqrt(dt)/2]]``. Any dtype.
    """
    one, zero = np.ones_like(dt), np.zeros_like(dt)
    q = np.sqrt(dt.dtype.type(ACCEL_PSD))
    eye = np.eye(2, dtype=dt.dtype)

    def blocks(a, b, c, d):
        top = np.concatenate([a[..., None, None] * eye, b[..., None, None] * eye], -1)
        bottom = np.concatenate([c[..., None, None] * eye, d[..., None, None] * eye], -1)
        return np.concatenate([top, bottom], -2)

    phi = blocks(one, dt, zero, one)
    three = dt.dtype.type(3)
    sq = blocks(q * np.sqrt(dt**3 / three), zero, q * np.sqrt(three * dt) / 2, q * np.sqrt(dt) / 2)
    return phi, sq


def triangularize(a: np.ndarray) -> np.ndarray:
    """Lower-triangular ``L`` (N, r, r) with ``L L^T = A A^T`` of ``A`` (N, r, c), any dtype.

    Householder reflections from the right, vectorised over the batch.
    """
    a = a.copy()
    rows = a.shape[1]
    for i in range(rows):
        v = a[:, i, i:].copy()
        norm = np.sqrt(np.sum(v * v, axis=1))
        v[:, 0] -= np.where(v[:, 0] >= 0, -norm, norm)
        vv = np.sum(v * v, axis=1)
        vv = np.where(vv > 0, vv, 1)
        block = a[:, i:, i:]
        block -= (2 * np.einsum("njc,nc->nj", block, v) / vv[:, None])[:, :, None] * v[:, None, :]
    return a[:, :, :rows]


def reference(s: Scenario, dtype: type = LD) -> tuple[np.ndarray, np.ndarray]:
    """Final means (N, 4) and covariances (N, 4, 4) of the square-root filter in ``dtype``."""
    n_tracks, n_steps = s.times.shape
    times = s.times.astype(dtype)
    x = s.prior.mean.astype(dtype)
    fac = np.sqrt(s.prior.cov.astype(dtype))  # diagonal prior
    r = s.r.astype(dtype)
    sr = np.zeros_like(r)
    sr[:, 0, 0] = np.sqrt(r[:, 0, 0])
    sr[:, 1, 0] = r[:, 1, 0] / sr[:, 0, 0]
    sr[:, 1, 1] = np.sqrt(r[:, 1, 1] - sr[:, 1, 0] ** 2)
    h = s.h.astype(dtype)
    pre = np.zeros((n_tracks, 6, 6), dtype=dtype)
    pre[:, :2, :2] = sr
    for k in range(n_steps):
        phi, sq = closed_form(times[:, k] - (times[:, k - 1] if k else dtype(0)))
        xp = np.einsum("nij,nj->ni", phi, x)
        sp = triangularize(np.concatenate([phi @ fac, sq], -1))
        pre[:, :2, 2:] = h @ sp
        pre[:, 2:, 2:] = sp
        pre[:, 2:, :2] = 0
        post = triangularize(pre)
        ss, kb, fac = post[:, :2, :2], post[:, 2:, :2], post[:, 2:, 2:]
        nu = s.z[:, k].astype(dtype) - xp[:, :2]
        w0 = nu[:, 0] / ss[:, 0, 0]
        w1 = (nu[:, 1] - ss[:, 1, 0] * w0) / ss[:, 1, 1]
        x = xp + kb[:, :, 0] * w0[:, None] + kb[:, :, 1] * w1[:, None]
    return x, fac @ np.swapaxes(fac, -1, -2)


@dataclass
class Outcome:
    """What one library path did: steps, sampled covariances and their worst defects."""

    steps: int = 0
    covariances: int = 0
    asymmetric: int = 0
    not_psd: int = 0
    seconds: float = 0.0
    cov_error: float = np.nan  # final, max |P - Pref| / max |Pref| (worst track)
    cov_error_sigma: float = np.nan  # final, max |P - Pref| / (sigma_i sigma_j)
    mean_error: float = np.nan  # final, max |x - xref| / sigma_i

    def check(self, covs: np.ndarray) -> None:
        """Count the covariances (..., n, n) that are not exactly symmetric or not PSD."""
        covs = covs.reshape((-1,) + covs.shape[-2:])
        self.covariances += len(covs)
        self.asymmetric += int(np.sum(np.any(covs != np.swapaxes(covs, -1, -2), axis=(1, 2))))
        eig = np.linalg.eigvalsh(covs)
        scale = np.abs(covs).max(axis=(1, 2))
        self.not_psd += int(np.sum(eig[:, 0] < -1e-12 * scale))

    def compare(self, mean: np.ndarray, cov: np.ndarray, ref: tuple[np.ndarray, np.ndarray]):
        """Final errors against the reference, relative to its sigmas."""
        ref_mean, ref_cov = (np.asarray(a, dtype=float) for a in ref)
        sigma = np.sqrt(np.diagonal(ref_cov, axis1=-2, axis2=-1))
        self.mean_error = float(np.max(np.abs(mean - ref_mean) / sigma))
        scale = sigma[..., :, None] * sigma[..., None, :]
        diff = np.abs(cov - ref_cov)
        self.cov_error_sigma = float(np.max(diff / scale))
        self.cov_error = float(np.max(diff.max(axis=(-2, -1)) / np.abs(ref_cov).max(axis=(-2, -1))))


def run_batch(s: Scenario, chunk: int) -> tuple[Outcome, np.ndarray, np.ndarray]:
    """``kalman_filter`` over chunks of ``chunk`` steps, the state carried between chunks."""
    out, state = Outcome(), s.prior
    start = time.perf_counter()
    for k in range(0, s.times.shape[1], chunk):
        sl = slice(k, k + chunk)
        res = at.kalman_filter(s.times[:, sl], s.z[:, sl], s.model, s.h, s.r, state)
        out.check(res.filtered.cov)
        out.check(res.predicted.cov)
        out.steps += res.filtered.mean.shape[0] * res.filtered.mean.shape[1]
        last = res.filtered.mean.shape[1] - 1
        state = at.GaussianState(
            res.filtered.mean[:, last], res.filtered.cov[:, last], s.times[:, k + last]
        )
    out.seconds = time.perf_counter() - start
    return out, state.mean, state.cov


def run_online(s: Scenario, chunk: int) -> tuple[Outcome, np.ndarray, np.ndarray]:
    """One ``OnlineFilter`` per track fed its stream in blocks of ``chunk`` rows."""
    out = Outcome()
    start = time.perf_counter()
    n_tracks, n_steps = s.times.shape
    filters = [at.OnlineFilter(s.model, s.h, s.r[i], s.prior[i]) for i in range(n_tracks)]
    for k in range(0, n_steps, chunk):
        sl = slice(k, k + chunk)
        for i, f in enumerate(filters):
            est = f.update_many(s.times[i, sl], s.z[i, sl])
            out.steps += len(est.nis)
        out.check(np.stack([f.cov for f in filters]))
    out.seconds = time.perf_counter() - start
    return out, np.stack([f.mean for f in filters]), np.stack([f.cov for f in filters])


def endurance(n_tracks: int, n_steps: int, seed: int = 0, chunk: int = 500) -> dict[str, Outcome]:
    """Run both paths and the reference; return their outcomes by name."""
    s = scenario(n_tracks, n_steps, seed)
    ref = reference(s)
    rounding = Outcome()
    rounding.compare(*(np.asarray(a) for a in reference(s, np.float64)), ref)
    outcomes = {"reference algorithm in double precision": rounding}
    for name, runner in (("kalman_filter", run_batch), ("OnlineFilter", run_online)):
        outcome, mean, cov = runner(s, chunk)
        outcome.compare(mean, cov, ref)
        outcomes[name] = outcome
    return outcomes


def main() -> None:
    """Command line: run and print one line per path; exit 1 if a check fails."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=10_000, help="steps per track")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    start = time.perf_counter()
    outcomes = endurance(args.tracks, args.steps, args.seed)
    failed = False
    rounding = outcomes.pop("reference algorithm in double precision")
    print(
        f"reference algorithm in double precision: final covariance error {rounding.cov_error:.1e}"
        f" of its norm, {rounding.cov_error_sigma:.1e} of sigma_i sigma_j; mean error "
        f"{rounding.mean_error:.1e} sigma"
    )
    for name, o in outcomes.items():
        ok = o.asymmetric == 0 and o.not_psd == 0 and o.cov_error <= 1e-6
        failed |= not ok
        print(
            f"{name}: {o.steps} steps in {o.seconds:.0f} s, {o.covariances} covariances checked, "
            f"{o.asymmetric} asymmetric, {o.not_psd} not PSD; final covariance error "
            f"{o.cov_error:.1e} of its norm (limit 1e-6), {o.cov_error_sigma:.1e} of sigma_i "
            f"sigma_j; mean error {o.mean_error:.1e} sigma: {'ok' if ok else 'FAIL'}"
        )
    print(f"total {time.perf_counter() - start:.0f} s")
    raise SystemExit(1 if failed else 0)


if __name__ == "__main__":
    main()
