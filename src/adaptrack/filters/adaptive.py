"""Adaptive Kalman filter of seed 002: gain identified from innovation correlations.

Spec C.3-C.6. The base model is constant velocity per axis (position measured, uniform step
``T``); manoeuvres are an unknown input. Each axis runs its own recursion (``per_axis`` of the
spec; a 3-D run equals three 1-D runs), and all tracks and axes are processed at once.

``identification="published"`` (C.5, the algorithm as printed, default): finite differences of
order ``N`` annihilate polynomial trajectories of degree ``N - 1``; running averages (EWMA of
memory ``L`` or a sliding window) of innovation products estimate ``P_a C^T`` by (17) and ``R``
by (18); guards G1-G3 fall back to the nominal gain. This estimator is biased (spec C.6: in a
stationary setting even its sign can be wrong), and it is reproduced as published.

``identification="mehra"`` (C.6): the consistent Mehra (1970) relation on short blocks of
innovations under a gain held constant within each block, with relaxation.

Initialisation (C.3, mandatory): two-point differencing at ``n = 1``; the estimate at ``n = 0``
is the measured position (velocity undefined: NaN). The reported covariance is the
nominal-model covariance of the gain actually applied (C.3), not a consistency claim.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb
from typing import Literal

import numpy as np

from .._backend import Backend, use_compiled
from .._typing import ArrayLike, BoolArray, FloatArray
from .._validation import as_float_array, broadcast_as, check_positive_scalar, check_times
from ..types import GaussianState, _trusted

Identification = Literal["published", "mehra"]


@dataclass(frozen=True, slots=True, eq=False)
class AdaptiveResult:
    """Output of :func:`innovation_adaptive_filter`.

    Attributes
    ----------
    filtered : GaussianState
        Estimates ``[x.., vx..]`` (..., T, 2 d) and the nominal-model covariance of the applied
        gain (..., T, 2 d, 2 d). Velocity at the first epoch is NaN (undefined, spec C.3).
    identified : ndarray of bool, shape (..., T, d)
        True where the identified gain was applied (False: nominal gain or no update).
    fallback_fraction : float
        Published form: share of steps with enough statistics on which guard G3 rejected the
        identified gain. Mehra form: share of rejected blocks.
    """

    filtered: GaussianState
    identified: BoolArray
    fallback_fraction: float


def binomial_difference(order: int) -> FloatArray:
    """Coefficients ``c_i = (-1)^i binom(N, i)``, i = 0..N, of the backward difference."""
    return np.array([(-1) ** i * comb(order, i) for i in range(order + 1)], dtype=np.float64)


def _rho_cv(k: FloatArray, t: float) -> FloatArray:
    """Spectral radius of ``Phi (I - K C)`` for ``Phi = [[1,T],[0,1]]``, ``C = [1, 0]``."""
    tr = 2 - k[..., 0] - t * k[..., 1]
    det = 1 - k[..., 0]
    disc = tr**2 - 4 * det
    return np.where(disc >= 0, (np.abs(tr) + np.sqrt(np.abs(disc))) / 2, np.sqrt(np.abs(det)))


def _joseph(p: FloatArray, k: FloatArray, r: FloatArray) -> FloatArray:
    ikc = np.broadcast_to(np.eye(2), p.shape).copy()
    ikc[..., :, 0] -= k
    out = (
        ikc @ p @ np.swapaxes(ikc, -1, -2) + k[..., :, None] * k[..., None, :] * r[..., None, None]
    )
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def innovation_adaptive_filter(
    times: ArrayLike,
    measurements: ArrayLike,
    *,
    measurement_var: float | ArrayLike,
    dwna_accel_var: float | ArrayLike | None = None,
    nominal_process_cov: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    identification: Identification = "published",
    adapt: bool = True,
    difference_order: int = 3,
    memory: int = 50,
    averaging: Literal["ewma", "window"] = "ewma",
    min_statistics: int | None = None,
    block_length: int = 30,
    lags: int = 4,
    relaxation: float = 0.5,
    warmup: int = 50,
    step_s: float | None = None,
    backend: Backend = "auto",
) -> AdaptiveResult:
    """Run the seed-002 adaptive Kalman filter on position measurements.

    Parameters
    ----------
    times : array_like, shape (T,) or (N, T)
        Uniformly spaced times [s] (``|dt - T| <= 1e-6 T``).
    measurements : array_like, shape (T, d) or (N, T, d)
        Measured positions [m], d = 1-3 axes.
    measurement_var : float or array_like, shape (d,)
        Nominal measurement variance ``R0`` per axis [m^2] (required).
    dwna_accel_var : float or array_like, shape (d,), optional
        Nominal model as discrete white-noise acceleration variance [m^2/s^4]:
        ``Q0 = q [[T^4/4, T^3/2], [T^3/2, T^2]]``. Give this or ``nominal_process_cov``.
    nominal_process_cov : array_like, shape (2, 2) or (d, 2, 2), optional
        Nominal ``Q0`` per axis in ``[x, v]`` order.
    mask : array_like of bool, shape (..., T), optional
        False where a measurement is missing (prediction only; statistics buffers restart).
        The first two epochs must be present (two-point initialisation).
    identification : {"published", "mehra"}
    adapt : bool
        False freezes adaptation: the result is the nominal Kalman filter (spec C2.9).
    difference_order, memory, averaging, min_statistics
        Published form: ``N`` (default 3), ``L`` (50), ``"ewma"`` or ``"window"``, and the
        warm-up ``n_min`` (default ``2 (N + 2)``).
    block_length, lags, relaxation, warmup
        Mehra form: ``L_b`` (30), ``p`` (4), ``eta`` (0.5), ``n_w`` (50).
    step_s : float, optional
        Sampling step ``T`` (default ``t_1 - t_0``).
    backend : {"auto", "numpy", "numba"}
        Published form: the NumPy reference or the compiled kernel (same numbers to rounding);
        ``"auto"`` compiles from 20,000 (track x axis)-steps on. The Mehra form runs in NumPy.

    Returns
    -------
    AdaptiveResult
    """
    t = as_float_array(times, "times", min_ndim=1)
    z = as_float_array(measurements, "measurements", min_ndim=2, allow_nan=True)
    if z.ndim > 3 or t.shape not in (z.shape[-2:-1], z.shape[:-1]):
        raise ValueError(
            f"times (T,) or (N, T) and measurements (T, d) or (N, T, d) must "
            f"match; got {t.shape} and {z.shape}"
        )
    check_times(t, "times")
    batch, n_steps, d = z.shape[:-2], z.shape[-2], z.shape[-1]
    if not 1 <= d <= 3:
        raise ValueError(f"measurements must have 1-3 axes (last axis); got {d}")
    if n_steps < 3:
        raise ValueError(f"measurements must hold at least 3 epochs; got {n_steps}")
    step = float(t[..., 1].flat[0] - t[..., 0].flat[0]) if step_s is None else float(step_s)
    check_positive_scalar(step, "step_s")
    off = np.abs(np.diff(t, axis=-1) - step) > 1e-6 * step
    if np.any(off):
        idx = np.argwhere(off)[0]
        raise ValueError(
            f"times must be uniformly spaced with step {step} s (spec C.3); "
            f"step {int(idx[-1]) + 1} differs"
        )
    mk = np.ones(batch + (n_steps,), dtype=bool) if mask is None else np.asarray(mask)
    if mk.dtype != np.bool_:
        raise TypeError(f"mask must be boolean (True = measured); got dtype {mk.dtype}")
    mk = broadcast_as(mk, batch + (n_steps,), "mask")
    if not np.all(mk[..., :2]):
        raise ValueError(
            "the first two epochs must be measured (two-point initialisation, spec C.3)"
        )
    if np.any(np.isnan(z) & mk[..., None]):
        idx = tuple(int(i) for i in np.argwhere(np.isnan(z) & mk[..., None])[0])
        raise ValueError(f"measurements is NaN at index {idx} where mask says it is measured")
    r0 = broadcast_as(as_float_array(measurement_var, "measurement_var"), (d,), "measurement_var")
    if np.any(r0 <= 0):
        raise ValueError(f"measurement_var must be > 0; got {r0}")
    q0 = _nominal_q(dwna_accel_var, nominal_process_cov, step, d)
    if identification not in ("published", "mehra"):
        raise ValueError(f"identification must be 'published' or 'mehra'; got {identification!r}")
    if averaging not in ("ewma", "window"):
        raise ValueError(f"averaging must be 'ewma' or 'window'; got {averaging!r}")
    for name, v in (
        ("difference_order", difference_order),
        ("memory", memory),
        ("block_length", block_length),
        ("lags", lags),
        ("warmup", warmup),
    ):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{name} must be an int >= 1; got {v!r}")
    if lags < 2 or block_length <= lags:
        raise ValueError("lags must be >= 2 (rank of O_p) and block_length > lags")
    if warmup < 2:
        raise ValueError(f"warmup must be >= 2; got {warmup}")
    if not 0 < relaxation <= 1:
        raise ValueError(f"relaxation must be in (0, 1]; got {relaxation}")
    # one row per (track, axis)
    rows = int(np.prod(batch, dtype=int)) * d
    zr = np.moveaxis(z.reshape((-1, n_steps, d)), -1, 1).reshape(rows, n_steps)
    mr = np.repeat(mk.reshape(-1, n_steps), d, axis=0)
    r_rows = np.tile(r0, rows // d)
    q_rows = np.tile(q0, (rows // d, 1, 1))
    compiled = use_compiled(backend, rows * n_steps)
    if identification == "published":
        n_min = 2 * (difference_order + 2) if min_statistics is None else min_statistics
        run = _published_compiled if compiled else _published
        est, cov, used, frac = run(
            zr,
            mr,
            step,
            q_rows,
            r_rows,
            difference_order,
            memory,
            averaging,
            n_min if adapt else None,
        )
    else:
        est, cov, used, frac = _mehra(
            zr, mr, step, q_rows, r_rows, block_length, lags, relaxation, warmup if adapt else None
        )
    return _assemble(est, cov, used, frac, batch, n_steps, d, t)


def _nominal_q(
    dwna: float | ArrayLike | None, q: ArrayLike | None, step: float, d: int
) -> FloatArray:
    if (dwna is None) == (q is None):
        raise ValueError(
            "give exactly one of dwna_accel_var and nominal_process_cov (the "
            "nominal model Q0 is required, spec C.3)"
        )
    if dwna is not None:
        var = broadcast_as(as_float_array(dwna, "dwna_accel_var"), (d,), "dwna_accel_var")
        if np.any(var < 0):
            raise ValueError(f"dwna_accel_var must be >= 0; got {var}")
        base = np.array([[step**4 / 4, step**3 / 2], [step**3 / 2, step**2]])
        return var[:, None, None] * base
    if q is None:  # unreachable: exactly one of the two is given
        raise ValueError("nominal_process_cov is required when dwna_accel_var is not given")
    qa = as_float_array(q, "nominal_process_cov", min_ndim=2)
    if qa.shape not in ((2, 2), (d, 2, 2)):
        raise ValueError(
            f"nominal_process_cov must have shape (2, 2) or ({d}, 2, 2); got {qa.shape}"
        )
    from .._validation import check_symmetric_pd

    check_symmetric_pd(qa, "nominal_process_cov", semidefinite=True)
    return np.broadcast_to(qa, (d, 2, 2)).copy()


def _init(
    z: FloatArray, step: float, r0: FloatArray, n_steps: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    rows = z.shape[0]
    est = np.full((rows, n_steps, 2), np.nan)
    cov = np.full((rows, n_steps, 2, 2), np.nan)
    est[:, 0, 0] = z[:, 0]
    cov[:, 0, 0, 0] = r0
    xh = np.stack([z[:, 1], (z[:, 1] - z[:, 0]) / step], axis=-1)
    p1 = r0[:, None, None] * np.array([[1, 1 / step], [1 / step, 2 / step**2]])
    est[:, 1], cov[:, 1] = xh, p1
    return est, cov, xh, p1


def _published(
    z: FloatArray,
    mask: BoolArray,
    step: float,
    q0: FloatArray,
    r0: FloatArray,
    order: int,
    memory: int,
    averaging: str,
    n_min: int | None,
) -> tuple[FloatArray, FloatArray, BoolArray, float]:
    """Spec C.5 per-axis recursion, one row per (track, axis)."""
    rows, n_steps = z.shape
    phi = np.array([[1.0, step], [0.0, 1.0]])
    c = binomial_difference(order)
    nb = order + 2
    r_floor = 1e-3 * r0
    est, cov, xh, p_nom = _init(z, step, r0, n_steps)
    p_rep = p_nom.copy()
    used = np.zeros((rows, n_steps), dtype=bool)
    bx: FloatArray = np.zeros((rows, nb, 2))
    bv: FloatArray = np.zeros((rows, nb))
    bg: FloatArray = np.zeros((rows, nb))
    count = np.zeros(rows, dtype=int)
    ns = np.zeros(rows, dtype=int)
    sxv, hh, sr = np.zeros((rows, 2)), np.zeros((rows, nb)), np.zeros(rows)
    hist = np.zeros((rows, memory, 2 + nb + 1)) if averaging == "window" else None
    n_attempt = n_fallback = 0
    for n in range(2, n_steps):
        present = mask[:, n]
        xa = xh @ phi.T
        v = np.where(present, z[:, n] - xa[:, 0], 0.0)
        p0a = phi @ p_nom @ phi.T + q0
        k0 = p0a[:, :, 0] / (p0a[:, 0, 0] + r0)[:, None]
        # step 3: buffers (index 0 = newest); a missing measurement empties them
        bx, bv, bg = (np.roll(a, 1, axis=1) for a in (bx, bv, bg))
        bx[:, 0], bv[:, 0], bg[:, 0] = xa, v, np.where(present, z[:, n], 0.0)
        count = np.where(present, np.minimum(count + 1, nb), 0)
        full = present & (count == nb)
        # step 4: statistics
        ns = ns + full
        dx = sum(c[j] * bx[:, j] for j in range(order + 1))  # fixed summation order (as the
        dg = sum(bg[:, j] * c[j] for j in range(order + 1))  # compiled kernel)
        prod = np.concatenate([dx * v[:, None], v[:, None] * bv, (v * dg)[:, None]], axis=1)
        if hist is None:
            b = 1.0 / np.minimum(np.maximum(ns, 1), memory)
            stats = np.concatenate([sxv, hh, sr[:, None]], axis=1)
            stats = np.where(full[:, None], stats + b[:, None] * (prod - stats), stats)
        else:
            slot = (ns - 1) % memory
            hist[full, slot[full]] = prod[full]
            filled = np.minimum(ns, memory)
            stats = hist.sum(axis=1) / np.maximum(filled, 1)[:, None]
        sxv, hh, sr = stats[:, :2], stats[:, 2 : 2 + nb], stats[:, -1]
        # step 5: gain
        k = k0
        ready = present & (ns >= n_min) if n_min is not None else np.zeros(rows, dtype=bool)
        if ready.any():
            s1 = sum(hh[:, j] * c[j] for j in range(1, order + 1))
            s2 = sum((hh[:, j] - hh[:, j + 1]) * c[j] for j in range(1, order + 1))
            pc = -sxv.copy()
            pc[:, 0] -= s1
            pc[:, 1] -= s2 / step
            a_s = np.maximum(pc[:, 0], 0.0)
            r_hat = np.maximum(sr, r_floor)
            pc[:, 0] = a_s
            with np.errstate(all="ignore"):
                ka = pc / (a_s + r_hat)[:, None]
                good = ready & np.isfinite(ka).all(axis=1) & (a_s > 0) & (_rho_cv(ka, step) < 1)
            k = np.where(good[:, None], ka, k0)
            used[:, n] = good
            n_attempt += int(ready.sum())
            n_fallback += int((ready & ~good).sum())
        # step 6: update (prediction only where the measurement is missing)
        xh = np.where(present[:, None], xa + k * v[:, None], xa)
        p_nom = np.where(present[:, None, None], _joseph(p0a, k0, r0), p0a)
        pa = phi @ p_rep @ phi.T + q0
        p_rep = np.where(present[:, None, None], _joseph(pa, k, r0), pa)
        est[:, n], cov[:, n] = xh, p_rep
    return est, cov, used, n_fallback / max(n_attempt, 1)


def _published_compiled(
    z: FloatArray,
    mask: BoolArray,
    step: float,
    q0: FloatArray,
    r0: FloatArray,
    order: int,
    memory: int,
    averaging: str,
    n_min: int | None,
) -> tuple[FloatArray, FloatArray, BoolArray, float]:
    """Run the recursion of :func:`_published` in the compiled kernel."""
    from ._adaptive_kernels import published_kernel

    rows, n_steps = z.shape
    est, cov, _, _ = _init(z, step, r0, n_steps)
    used = np.zeros((rows, n_steps), dtype=bool)
    attempts = np.zeros(rows, dtype=np.int64)
    fallbacks = np.zeros(rows, dtype=np.int64)
    published_kernel(
        np.ascontiguousarray(z),
        np.ascontiguousarray(mask),
        step,
        np.ascontiguousarray(q0),
        np.ascontiguousarray(r0),
        binomial_difference(order),
        memory,
        averaging == "window",
        -1 if n_min is None else n_min,
        est,
        cov,
        used,
        attempts,
        fallbacks,
    )
    return est, cov, used, int(fallbacks.sum()) / max(int(attempts.sum()), 1)


def _mehra(
    z: FloatArray,
    mask: BoolArray,
    step: float,
    q0: FloatArray,
    r0: FloatArray,
    block_length: int,
    lags: int,
    relaxation: float,
    warmup: int | None,
) -> tuple[FloatArray, FloatArray, BoolArray, float]:
    """Spec C.6 block-form Mehra identification, one row per (track, axis)."""
    rows, n_steps = z.shape
    phi = np.array([[1.0, step], [0.0, 1.0]])
    r_floor = 1e-3 * r0
    est, cov, xh, p_nom = _init(z, step, r0, n_steps)
    p_rep = p_nom.copy()
    used = np.zeros((rows, n_steps), dtype=bool)
    kb = np.zeros((rows, 2))
    block = np.zeros((rows, block_length))
    count = np.zeros(rows, dtype=int)
    n_blocks = n_accepted = 0
    for n in range(2, n_steps):
        present = mask[:, n]
        xa = xh @ phi.T
        v = np.where(present, z[:, n] - xa[:, 0], 0.0)
        p0a = phi @ p_nom @ phi.T + q0
        k0 = p0a[:, :, 0] / (p0a[:, 0, 0] + r0)[:, None]
        p_nom = np.where(present[:, None, None], _joseph(p0a, k0, r0), p0a)
        if warmup is None or n < warmup:
            k = k0
        else:
            if n == warmup:
                kb = k0.copy()
            k = kb.copy()  # the new block gain applies from the next step
            used[:, n] = present
            block[np.arange(rows), np.minimum(count, block_length - 1)] = v
            count = np.where(present, count + 1, 0)  # a missing measurement ends the block
            done = count == block_length
            if done.any():
                kb[done], ok = _mehra_block(
                    block[done], kb[done], phi, step, lags, relaxation, r_floor[done]
                )
                n_blocks += int(done.sum())
                n_accepted += int(ok.sum())
                count[done] = 0
        xh = np.where(present[:, None], xa + k * v[:, None], xa)
        pa = phi @ p_rep @ phi.T + q0
        p_rep = np.where(present[:, None, None], _joseph(pa, k, r0), pa)
        est[:, n], cov[:, n] = xh, p_rep
    return est, cov, used, 1.0 - n_accepted / max(n_blocks, 1)


def _mehra_block(
    v: FloatArray,
    kb: FloatArray,
    phi: FloatArray,
    step: float,
    lags: int,
    eta: float,
    r_floor: FloatArray,
) -> tuple[FloatArray, BoolArray]:
    """Identify a new gain from one block of innovations per row (spec C.6 steps 3-5).

    Returns the gain for the next block (the relaxed new gain where accepted, else the old
    one) and which rows accepted.
    """
    lb = v.shape[1]
    h = np.stack(
        [(v[:, j:] * v[:, : lb - j]).sum(axis=1) / (lb - j) for j in range(lags + 1)], axis=1
    )
    c = np.array([1.0, 0.0])
    a = phi @ (np.eye(2) - kb[:, :, None] * c)  # A = Phi (I - Kb C), (B, 2, 2)
    obs_rows = []
    mk = np.broadcast_to(phi, a.shape)
    for _ in range(lags):
        obs_rows.append(mk[:, 0, :])  # C A^j Phi
        mk = a @ mk
    o = np.stack(obs_rows, axis=1)  # O_p, (B, p, 2)
    q, r = np.linalg.qr(o)  # least squares O_p x = [H_1 .. H_p]
    corr = np.linalg.solve(r, np.einsum("bpi,bp->bi", q, h[:, 1:])[..., None])[..., 0]
    pc = kb * h[:, :1] + corr
    a_s = np.maximum(pc[:, 0], 0.0)
    r_hat = np.maximum(h[:, 0] - a_s, r_floor)
    pc[:, 0] = a_s
    with np.errstate(all="ignore"):
        kn = pc / (a_s + r_hat)[:, None]
        ok = np.isfinite(kn).all(axis=1) & (a_s > 0) & (_rho_cv(kn, step) < 1)
        kr = kb + eta * (kn - kb)
        ok &= _rho_cv(kr, step) < 1
    return np.where(ok[:, None], kr, kb), ok


def _assemble(
    est: FloatArray,
    cov: FloatArray,
    used: BoolArray,
    frac: float,
    batch: tuple[int, ...],
    n_steps: int,
    d: int,
    t: FloatArray,
) -> AdaptiveResult:
    """Rows (track, axis) -> adaptrack layout [x.., v..] with block-diagonal covariances."""
    e = est.reshape(batch + (d, n_steps, 2))
    e = np.moveaxis(e, -3, -1)  # (..., T, 2, d)
    mean = e.reshape(batch + (n_steps, 2 * d))
    c = cov.reshape(batch + (d, n_steps, 2, 2))
    full = np.zeros(batch + (n_steps, 2 * d, 2 * d))
    for a in range(d):
        idx = [a, d + a]
        full[..., np.ix_(idx, idx)[0], np.ix_(idx, idx)[1]] = c[..., a, :, :, :]
    u = np.moveaxis(used.reshape(batch + (d, n_steps)), -2, -1)
    state = _trusted(
        GaussianState, mean=mean, cov=full, time=np.broadcast_to(t, batch + (n_steps,))
    )
    return AdaptiveResult(state, u, float(frac))


__all__ = ["AdaptiveResult", "binomial_difference", "innovation_adaptive_filter"]
