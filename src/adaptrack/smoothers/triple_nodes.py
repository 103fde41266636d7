"""Radar triple nodes (spec D.2): position, velocity and acceleration from a radar's samples.

At each epoch the extended radar vector ``a = [r, eps, beta, rd, eps', beta', rdd, eps'',
beta'']`` holds the measured range, azimuth and elevation, the range-rate and range
acceleration (measured, or derived from the range samples), and the angle rates, which a
radar does not measure: they come from a sliding least-squares fit (degree ``degree``,
``window`` samples nearest the epoch, centred where the record allows) of the unwrapped
angle samples. ``a`` maps to local ``[p, pd, pdd]`` (spec D.3); its covariance comes from the
fit weights with the sensor's a-priori sigmas, never from the fit's residuals.

Nodes share samples, so they are correlated: :meth:`RadarTripleNodes.covariance` gives the
covariance of any set of nodes, ``J_Y R_raw J_Y^T`` (spec D.6, the honest covariance), for
the sandwich of :func:`~adaptrack.smoothers.batch_ls.fit_polynomial`; ``node_cov`` holds each
node's own 9 x 9 block, the weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array
from ..coords.radar import polar_kinematics_jacobian, polar_kinematics_to_enu, wrap_to_pi
from ..types import GaussianState, _trusted
from .batch_ls import fit_polynomial

MAX_ELEVATION_RAD = math.radians(85.0)  # above it the azimuth rate is ill-conditioned
RAW = ("range", "azimuth", "elevation", "range_rate", "range_accel")


def rate_fit_weights(
    times: FloatArray, node: int, window: int, degree: int, scale_s: float
) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """Sample indices and the weights of the first and second derivative at ``times[node]``.

    The ``window`` samples nearest the node (centred where the record allows, else the first
    or last ``window``), fitted by an unweighted degree-``degree`` polynomial in
    ``tau = (t - t_node) / scale_s``: ``w1 = Wf[1] / scale_s``, ``w2 = 2 Wf[2] / scale_s^2``.
    """
    n = times.size
    start = min(max(node - window // 2, 0), n - window)
    idx = np.arange(start, start + window)
    tau = (times[idx] - times[node]) / scale_s
    basis = tau[:, None] ** np.arange(degree + 1)
    wf = np.linalg.pinv(basis)  # (degree + 1, window)
    w2 = 2.0 * wf[2] / scale_s**2 if degree >= 2 else np.zeros(window)
    return idx, wf[1] / scale_s, w2


@dataclass(frozen=True)
class RadarTripleNodes:
    """Triple nodes of a radar record and what their covariance needs.

    Attributes
    ----------
    times : ndarray, shape (n,)
        Node epochs [s].
    values : ndarray, shape (n, 9)
        ``[p, pd, pdd]`` in the radar's local east-north-up frame [m, m/s, m/s^2].
    node_cov : ndarray, shape (n, 9, 9)
        Each node's covariance ``J_loc R_a J_loc^T`` (the weights).
    raw_index : ndarray of int, shape (n, window)
        The samples each node depends on.
    raw_jacobian : ndarray, shape (n, 9, window, q)
        ``d values / d raw samples`` over those samples (q measured quantities per sample).
    raw_var : ndarray, shape (q,)
        Variances of the measured quantities (``R_radar``, diagonal).
    """

    times: FloatArray
    values: FloatArray
    node_cov: FloatArray
    raw_index: np.ndarray
    raw_jacobian: FloatArray
    raw_var: FloatArray

    def covariance(self, nodes: ArrayLike | None = None) -> FloatArray:
        """Covariance (9k, 9k) of the values of ``nodes`` (default all), node-major.

        ``J_Y R_raw J_Y^T`` over the samples those nodes depend on: the rates of nodes whose
        windows overlap are correlated.
        """
        sel = np.arange(self.times.size) if nodes is None else np.asarray(nodes, dtype=int)
        samples = np.unique(self.raw_index[sel])
        q = self.raw_var.size
        pos = np.searchsorted(samples, self.raw_index[sel])  # (k, window)
        jac = np.zeros((sel.size, 9, samples.size, q))
        for row, node in enumerate(sel):
            jac[row][:, pos[row]] = self.raw_jacobian[node]  # a window's samples are distinct
        j = jac.reshape(sel.size * 9, samples.size * q)
        return (j * np.tile(self.raw_var, samples.size)) @ j.T

    def as_nodes(self) -> tuple[FloatArray, np.ndarray, FloatArray, FloatArray]:
        """Return times, orders (0, 1, 2 per epoch), values (3n, 3) and covariances (3n, 3, 3).

        The input of :func:`~adaptrack.smoothers.batch_ls.fit_polynomial`, node-major in the
        order of :meth:`covariance`.
        """
        n = self.times.size
        blocks = np.stack([self.node_cov[:, 3 * d : 3 * d + 3, 3 * d : 3 * d + 3]
                           for d in range(3)], 1)  # fmt: skip
        return (
            np.repeat(self.times, 3),
            np.tile(np.arange(3), n),
            self.values.reshape(3 * n, 3),
            blocks.reshape(3 * n, 3, 3),
        )

    def weight_cov(self, nodes: ArrayLike | None = None) -> FloatArray:
        """Block-diagonal (9k, 9k) of the nodes' own covariances: the weights of spec D.6."""
        sel = np.arange(self.times.size) if nodes is None else np.asarray(nodes, dtype=int)
        out = np.zeros((9 * sel.size, 9 * sel.size))
        for row, node in enumerate(sel):
            out[9 * row : 9 * row + 9, 9 * row : 9 * row + 9] = self.node_cov[node]
        return out


def radar_triple_nodes(
    times: ArrayLike,
    range_m: ArrayLike,
    azimuth: ArrayLike,
    elevation: ArrayLike,
    *,
    range_std_m: float,
    azimuth_std_rad: float,
    elevation_std_rad: float,
    range_rate: ArrayLike | None = None,
    range_rate_std_mps: float | None = None,
    range_accel: ArrayLike | None = None,
    range_accel_std_mps2: float | None = None,
    window: int = 7,
    degree: int = 2,
    max_elevation_rad: float = MAX_ELEVATION_RAD,
) -> RadarTripleNodes:
    """Build the triple nodes of one target's radar record (spec D.2).

    Parameters
    ----------
    times : array_like, shape (n,)
        Sample times [s], strictly increasing.
    range_m, azimuth, elevation : array_like, shape (n,)
        Slant range [m], azimuth (clockwise from north) and elevation [rad]; azimuths may
        wrap, they are unwrapped before the rate fits.
    range_std_m, azimuth_std_rad, elevation_std_rad : float
        The sensor's noise sigmas.
    range_rate, range_accel : array_like, shape (n,), optional
        Measured range-rate [m/s] and range acceleration [m/s^2] with their sigmas; a
        quantity not measured is derived from the range samples by the same sliding fit
        (never encoded as a measurement of huge variance).
    window, degree : int
        Samples of each rate fit (odd) and its polynomial degree (>= 2).
    max_elevation_rad : float
        Nodes above this elevation raise ValueError (the azimuth rate is ill-conditioned).
    """
    t = as_float_array(times, "times", min_ndim=1)
    n = t.size
    cols = {"range": range_m, "azimuth": azimuth, "elevation": elevation}
    sig = {"range": range_std_m, "azimuth": azimuth_std_rad, "elevation": elevation_std_rad}
    for name, value, s in (
        ("range_rate", range_rate, range_rate_std_mps),
        ("range_accel", range_accel, range_accel_std_mps2),
    ):
        if value is not None:
            if s is None:
                raise ValueError(f"a measured {name} needs its sigma ({name}_std_...)")
            cols[name], sig[name] = value, s
    raw_names = [c for c in RAW if c in cols]
    raw = np.stack([as_float_array(cols[c], c, min_ndim=1) for c in raw_names], -1)
    if raw.shape != (n, len(raw_names)):
        raise ValueError(f"times and every measured series must have shape ({n},)")
    for c in raw_names:
        if not (np.isfinite(sig[c]) and sig[c] > 0):
            raise ValueError(f"the {c} sigma must be positive; got {sig[c]}")
    if window % 2 == 0 or window < degree + 1 or degree < 2:
        raise ValueError(
            f"window must be odd and above the degree, degree >= 2; got {window}, {degree}"
        )
    if n < window:
        raise ValueError(f"a record of {n} samples is shorter than the {window}-sample window")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing")
    if np.any(raw[:, 0] <= 0):
        raise ValueError(f"range must be > 0; got {raw[np.argmax(raw[:, 0] <= 0), 0]}")
    high = np.abs(raw[:, 2]) > max_elevation_rad
    if np.any(high):
        i = int(np.argmax(high))
        raise ValueError(
            f"node {i} (t = {t[i]} s): elevation {math.degrees(raw[i, 2]):.1f} deg above "
            f"{math.degrees(max_elevation_rad):.1f} deg, the azimuth rate is ill-conditioned"
        )
    raw[:, 1] = np.unwrap(raw[:, 1])
    col = {c: i for i, c in enumerate(raw_names)}
    q = len(raw_names)
    scale = float(np.median(np.diff(t)))
    a = np.zeros((n, 9))
    da = np.zeros((n, 9, window, q))  # d a_i / d raw samples of its window
    index = np.zeros((n, window), dtype=int)
    for i in range(n):
        idx, w1, w2 = rate_fit_weights(t, i, window, degree, scale)
        c = i - idx[0]  # the node's own sample in its window
        index[i] = idx
        for row, name in ((0, "range"), (1, "azimuth"), (2, "elevation")):
            a[i, row] = raw[i, col[name]]
            da[i, row, c, col[name]] = 1.0
        for rows, name in (((4, 7), "azimuth"), ((5, 8), "elevation")):
            a[i, rows[0]], a[i, rows[1]] = w1 @ raw[idx, col[name]], w2 @ raw[idx, col[name]]
            da[i, rows[0], :, col[name]], da[i, rows[1], :, col[name]] = w1, w2
        for row, name, w in ((3, "range_rate", w1), (6, "range_accel", w2)):
            if name in col:
                a[i, row] = raw[i, col[name]]
                da[i, row, c, col[name]] = 1.0
            else:
                a[i, row] = w @ raw[idx, 0]
                da[i, row, :, 0] = w
    a_out = a.copy()
    a_out[:, 1] = wrap_to_pi(a[:, 1])
    j_loc = polar_kinematics_jacobian(a_out)  # (n, 9, 9)
    jac = np.einsum("nab,nbwq->nawq", j_loc, da)
    var = np.array([sig[c] ** 2 for c in raw_names])
    flat = jac.reshape(n, 9, window * q)
    node_cov = (flat * np.tile(var, window)) @ np.swapaxes(flat, 1, 2)
    return RadarTripleNodes(
        t, polar_kinematics_to_enu(a_out), 0.5 * (node_cov + np.swapaxes(node_cov, 1, 2)),
        index, jac, var,
    )  # fmt: skip


def smooth_triple_nodes(
    nodes: RadarTripleNodes, eval_times: ArrayLike, *, degree: int = 2, window_s: float = 20.0
) -> GaussianState:
    """Sliding-window polynomial fit of triple nodes: ``[p, v, a]`` (T, 9) at ``eval_times``.

    Each evaluation time gets its own fit to the nodes within ``+-window_s / 2`` (weights: each
    node's 9 x 9 covariance), with the honest sandwich covariance over the nodes' shared
    samples (spec D.6). A window that does not determine the polynomial gives NaN estimates
    there (never a silent omission).
    """
    te = np.atleast_1d(as_float_array(eval_times, "eval_times"))
    if not window_s > 0:
        raise ValueError(f"window_s must be > 0; got {window_s}")
    times, orders, values, covs = nodes.as_nodes()
    means, cov_out = np.full((te.size, 9), np.nan), np.full((te.size, 9, 9), np.nan)
    for i, tt in enumerate(te):
        sel = np.flatnonzero(np.abs(nodes.times - tt) <= window_s / 2)
        rows = (3 * sel[:, None] + np.arange(3)).reshape(-1)
        try:
            fit = fit_polynomial(
                times[rows], orders[rows], values[rows], covs[rows], degree=degree,
                center_s=float(tt), weight_cov=nodes.weight_cov(sel),
                full_cov=nodes.covariance(sel),
            )  # fmt: skip
        except ValueError:
            continue  # too few nodes in this window: NaN
        est = fit.evaluate([tt])
        means[i], cov_out[i] = est.mean[0], est.cov[0]
    return _trusted(GaussianState, mean=means, cov=cov_out, time=te)


__all__ = ["RadarTripleNodes", "radar_triple_nodes", "rate_fit_weights", "smooth_triple_nodes"]
