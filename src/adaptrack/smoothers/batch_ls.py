"""Weighted least-squares polynomial smoothing with nodes of several orders (spec D.6).

A node is an observation, at time ``t_k``, of the position (order 0), velocity (order 1) or
acceleration (order 2) of the three axes, with a 3x3 covariance. "Triple nodes" are the case
where all three orders share a time; nodes of different orders may also come from different,
unsynchronised sensors. Each axis is a polynomial of degree ``m`` in ``tau = (t - t_c) / T0``;
derivative nodes are scaled by ``T0^d`` (the "correcting matrix" ``Omega``), so estimates do not
depend on ``T0``.

Weights (``weights=``): ``"full"`` (default) ``W = inv(Rt)`` from the per-node 3x3 blocks
(all axes jointly, keeping cross-axis correlations); ``"diagonal"`` ``1/variance`` of the
scaled entries; ``"diagonal_unscaled"`` the source's literal reading (``1/variance`` of the
unscaled values applied to scaled rows; the result then depends on ``T0``). ``joint=False``
fits each axis separately (the source's form). When the nodes are correlated with each other
(``full_cov``), the reported covariance is the sandwich
``D = inv(N) Phi^T W Rt_full W Phi inv(N)``; otherwise ``D = inv(N)`` with the optimal weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.polynomial import legendre

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_symmetric_pd
from ..filters.square_root import covariance, lower_factor
from ..types import GaussianState, _trusted

Weights = Literal["full", "diagonal", "diagonal_unscaled"]
Basis = Literal["monomial", "legendre"]


def _basis_rows(tau: FloatArray, order: np.ndarray, degree: int, basis: str) -> FloatArray:
    """Rows (K, m + 1): the ``order_k``-th tau-derivative of the basis at ``tau_k``."""
    rows = np.zeros((tau.size, degree + 1))
    for d in range(3):
        sel = order == d
        if not sel.any():
            continue
        if basis == "monomial":
            for j in range(d, degree + 1):
                rows[sel, j] = math.perm(j, d) * tau[sel] ** (j - d)
        else:
            for j in range(degree + 1):
                c = np.zeros(degree + 1)
                c[j] = 1.0
                rows[sel, j] = legendre.legval(tau[sel], legendre.legder(c, d) if d else c)
    return rows


@dataclass(frozen=True, eq=False)
class PolynomialFit:
    """A fitted 3-axis polynomial trajectory with the covariance of its coefficients.

    Attributes
    ----------
    coef : ndarray, shape (3, m + 1)
        Coefficients per axis in the fit's basis of ``tau = (t - center_s) / scale_s``.
    coef_cov : ndarray, shape (3 (m + 1), 3 (m + 1))
        Their covariance (axis-major order).
    degree : int
    center_s, scale_s : float
    basis : str
    residual_var_factor : float
        A-posteriori variance factor ``s0^2`` (weighted residuals / degrees of freedom).
    n_observations : int
        Number of scalar observations.
    """

    coef: FloatArray
    coef_cov: FloatArray
    degree: int
    center_s: float
    scale_s: float
    basis: str
    residual_var_factor: float
    n_observations: int

    def evaluate(self, times: ArrayLike) -> GaussianState:
        """Position, velocity, acceleration ``[p(3), v(3), a(3)]`` (T, 9) and covariance."""
        t = np.atleast_1d(as_float_array(times, "times"))
        tau = (t - self.center_s) / self.scale_s
        g = np.zeros((t.size, 9, 3 * (self.degree + 1)))
        for d in range(3):
            rows = _basis_rows(tau, np.full(t.size, d), self.degree, self.basis)
            rows = rows / self.scale_s**d
            for axis in range(3):
                block = slice(axis * (self.degree + 1), (axis + 1) * (self.degree + 1))
                g[:, 3 * d + axis, block] = rows
        mean = g @ self.coef.reshape(-1)
        gf = g @ lower_factor(self.coef_cov)  # (G F)(G F)^T: PSD to rounding, whatever G's rank
        return _trusted(GaussianState, mean=mean, cov=covariance(gf), time=t)


def fit_polynomial(
    times: ArrayLike,
    orders: ArrayLike,
    values: ArrayLike,
    covs: ArrayLike,
    *,
    degree: int = 2,
    center_s: float | None = None,
    scale_s: float | None = None,
    weights: Weights = "full",
    joint: bool = True,
    full_cov: ArrayLike | None = None,
    basis: Basis = "monomial",
    weight_cov: ArrayLike | None = None,
) -> PolynomialFit:
    """Fit a 3-axis polynomial to position/velocity/acceleration nodes (spec D.6).

    Parameters
    ----------
    times : array_like, shape (K,)
        Node times [s] (any order; nodes of different orders may share a time).
    orders : array_like of int, shape (K,)
        0 = position [m], 1 = velocity [m/s], 2 = acceleration [m/s^2].
    values : array_like, shape (K, 3)
        Observed 3-axis vectors.
    covs : array_like, shape (K, 3, 3)
        Their covariances (symmetric positive definite): the weights.
    degree : int
        Polynomial degree m (m + 1 coefficients per axis).
    center_s, scale_s : float, optional
        Reference epoch ``t_c`` (default: mid-range of the times) and ``T0`` (default: the
        median spacing of the distinct node times).
    weights : {"full", "diagonal", "diagonal_unscaled"}
    joint : bool
        Fit the axes jointly (default) or one at a time (cross-axis covariances ignored).
    full_cov : array_like, shape (3 K, 3 K), optional
        Covariance of all node values (node-major, 3 per node) when nodes are correlated;
        gives the honest sandwich covariance.
    basis : {"monomial", "legendre"}
        Polynomial basis (estimates do not depend on it).
    weight_cov : array_like, shape (3 K, 3 K), optional
        The covariance whose inverse weights the nodes (``weights="full"``, joint), node-major
        like ``full_cov``: e.g. radar triple nodes, whose position, velocity and acceleration
        at one epoch are correlated (:meth:`~adaptrack.smoothers.triple_nodes.
        RadarTripleNodes.weight_cov`). Default: the per-node ``covs``.

    Returns
    -------
    PolynomialFit

    Raises
    ------
    ValueError
        Bad shapes, non-finite values, orders outside {0, 1, 2}, non-positive-definite
        covariances, or too few nodes for the degree (singular normal equations).
    """
    t = as_float_array(times, "times", min_ndim=1)
    o = np.asarray(orders)
    y = as_float_array(values, "values", min_ndim=2)
    r = as_float_array(covs, "covs", min_ndim=3)
    k = t.size
    if t.ndim != 1 or o.shape != (k,) or y.shape != (k, 3) or r.shape != (k, 3, 3):
        raise ValueError(
            f"times (K,), orders (K,), values (K, 3) and covs (K, 3, 3) must match; "
            f"got {t.shape}, {o.shape}, {y.shape}, {r.shape}"
        )
    if not np.issubdtype(o.dtype, np.integer) or np.any((o < 0) | (o > 2)):
        raise ValueError("orders must be integers 0 (position), 1 (velocity) or 2 (acceleration)")
    if isinstance(degree, bool) or not isinstance(degree, int) or degree < 0:
        raise ValueError(f"degree must be an int >= 0; got {degree!r}")
    if weights not in ("full", "diagonal", "diagonal_unscaled"):
        raise ValueError(
            f"weights must be 'full', 'diagonal' or 'diagonal_unscaled'; got {weights!r}"
        )
    if basis not in ("monomial", "legendre"):
        raise ValueError(f"basis must be 'monomial' or 'legendre'; got {basis!r}")
    check_symmetric_pd(r, "covs")
    n_coef = degree + 1
    if 3 * k < 3 * n_coef:
        raise ValueError(
            f"too few nodes for a degree-{degree} polynomial: {k} nodes give {3 * k}"
            f" observations, {3 * n_coef} coefficients are needed"
        )
    uniq = np.unique(t)
    tc = float((t.min() + t.max()) / 2) if center_s is None else float(center_s)
    t0 = (
        (float(np.median(np.diff(uniq))) if uniq.size > 1 else 1.0)
        if scale_s is None
        else float(scale_s)
    )
    if not t0 > 0:
        raise ValueError(f"scale_s must be > 0; got {t0}")
    tau = (t - tc) / t0
    rows = _basis_rows(tau, o, degree, basis)  # (K, n_coef)
    scale = t0 ** o.astype(float)  # Omega per node
    yt = y * scale[:, None]
    rt = r * (scale**2)[:, None, None]
    if not joint:
        rt = rt * np.eye(3)
    # design matrix, node-major observations (3 per node), axis-major coefficients
    phi = np.zeros((k, 3, 3 * n_coef))
    for axis in range(3):
        phi[:, axis, axis * n_coef : (axis + 1) * n_coef] = rows
    phi2 = phi.reshape(3 * k, 3 * n_coef)
    wh_full = None
    if weight_cov is not None:
        if weights != "full" or not joint:
            raise ValueError("weight_cov needs weights='full' and joint=True")
        wc = as_float_array(weight_cov, "weight_cov", min_ndim=2)
        if wc.shape != (3 * k, 3 * k):
            raise ValueError(f"weight_cov must have shape ({3 * k}, {3 * k}); got {wc.shape}")
        check_symmetric_pd(wc, "weight_cov")
        s3 = np.repeat(scale, 3)
        wh_full = np.linalg.inv(np.linalg.cholesky(wc * s3[:, None] * s3[None, :]))
        a, b = wh_full @ phi2, wh_full @ yt.reshape(-1)
    elif weights == "full":
        chol = np.linalg.cholesky(rt)  # whitening per node
        a = np.linalg.solve(chol, phi).reshape(3 * k, 3 * n_coef)
        b = np.linalg.solve(chol, yt[..., None]).reshape(3 * k)
    else:
        var = np.diagonal(rt if weights == "diagonal" else r, axis1=1, axis2=2).reshape(-1)
        w_half = 1.0 / np.sqrt(var)
        a = phi2 * w_half[:, None]
        b = yt.reshape(-1) * w_half
    q, rr = np.linalg.qr(a)
    sv = np.abs(np.diagonal(rr))
    if sv.min() <= 1e-12 * max(sv.max(), 1e-300):
        raise ValueError(
            f"singular normal equations: the nodes do not determine a degree-"
            f"{degree} polynomial in every axis (too few distinct times or "
            "orders)"
        )
    coef = np.linalg.solve(rr, q.T @ b)
    rinv = np.linalg.solve(rr, np.eye(rr.shape[0]))
    n_inv = rinv @ rinv.T  # inv(Phi^T W Phi)
    resid = b - a @ coef
    dof = 3 * k - 3 * n_coef
    s0 = float(resid @ resid / dof) if dof > 0 else float("nan")
    optimal = weights == "full" and joint
    if full_cov is not None or not optimal:
        rt_full = _scaled_full_cov(full_cov, rt, r, scale, k, joint)
        # sandwich: D = inv(N) A^T (Wh Rt_full Wh^T) A inv(N), with whitened rows A = Wh Phi
        wh = _whitening(rt, r, weights, scale, k) if wh_full is None else wh_full
        m_mat = wh @ rt_full @ wh.T
        coef_cov = n_inv @ a.T @ m_mat @ a @ n_inv
    else:
        coef_cov = n_inv
    return PolynomialFit(
        coef.reshape(3, n_coef), 0.5 * (coef_cov + coef_cov.T), degree, tc, t0, basis, s0, 3 * k
    )


def _whitening(
    rt: FloatArray, r: FloatArray, weights: str, scale: FloatArray, k: int
) -> FloatArray:
    """Return the (3K, 3K) matrix that maps scaled observations to whitened ones."""
    if weights == "full":
        inv_chol = np.linalg.solve(np.linalg.cholesky(rt), np.broadcast_to(np.eye(3), rt.shape))
    else:
        var = np.diagonal(rt if weights == "diagonal" else r, axis1=1, axis2=2)
        inv_chol = np.eye(3) / np.sqrt(var)[:, None, :]
    out = np.zeros((3 * k, 3 * k))
    for i in range(k):
        out[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = inv_chol[i]
    return out


def _scaled_full_cov(
    full_cov: ArrayLike | None,
    rt: FloatArray,
    r: FloatArray,
    scale: FloatArray,
    k: int,
    joint: bool,
) -> FloatArray:
    """Covariance of all scaled observations: given (correlated nodes) or block diagonal."""
    if full_cov is None:
        out = np.zeros((3 * k, 3 * k))
        scaled = r * (scale**2)[:, None, None]  # the true node covariances (incl. cross-axis)
        for i in range(k):
            out[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = scaled[i]
        return out
    f = as_float_array(full_cov, "full_cov", min_ndim=2)
    if f.shape != (3 * k, 3 * k):
        raise ValueError(f"full_cov must have shape ({3 * k}, {3 * k}); got {f.shape}")
    check_symmetric_pd(f, "full_cov", semidefinite=True)
    s = np.repeat(scale, 3)
    return f * s[:, None] * s[None, :]


def smooth_polynomial(
    times: ArrayLike,
    orders: ArrayLike,
    values: ArrayLike,
    covs: ArrayLike,
    eval_times: ArrayLike,
    *,
    degree: int = 2,
    window_s: float | None = None,
    weights: Weights = "full",
    joint: bool = True,
    insufficient: Literal["raise", "nan"] = "raise",
) -> GaussianState:
    """Smoothed ``[p, v, a]`` (T, 9) at ``eval_times``: one fit over all nodes, or sliding.

    With ``window_s``, each evaluation time gets its own fit to the nodes within
    ``+-window_s / 2`` of it (centred there); otherwise a single whole-interval fit is used.
    A window whose nodes do not determine the polynomial (a gap in the data) raises, or with
    ``insufficient="nan"`` gives NaN estimates at that time (never a silent omission).
    """
    te = np.atleast_1d(as_float_array(eval_times, "eval_times"))
    if window_s is None:
        return fit_polynomial(
            times, orders, values, covs, degree=degree, weights=weights, joint=joint
        ).evaluate(te)
    t = as_float_array(times, "times", min_ndim=1)
    o, y, r = np.asarray(orders), np.asarray(values, float), np.asarray(covs, float)
    if not window_s > 0:
        raise ValueError(f"window_s must be > 0; got {window_s}")
    means, cov_out = np.empty((te.size, 9)), np.empty((te.size, 9, 9))
    for i, tt in enumerate(te):
        sel = np.abs(t - tt) <= window_s / 2
        try:
            fit = fit_polynomial(
                t[sel],
                o[sel],
                y[sel],
                r[sel],
                degree=degree,
                center_s=tt,
                weights=weights,
                joint=joint,
            )
        except ValueError as exc:
            if insufficient == "raise":
                raise ValueError(f"window at t = {tt} s: {exc}") from None
            means[i], cov_out[i] = np.nan, np.nan
            continue
        est = fit.evaluate([tt])
        means[i], cov_out[i] = est.mean[0], est.cov[0]
    return _trusted(GaussianState, mean=means, cov=cov_out, time=te)


__all__ = ["PolynomialFit", "fit_polynomial", "smooth_polynomial"]
