"""Differential-Taylor transform (spec D.4): algebra of scaled Taylor spectra.

The spectrum of ``z(t)`` about ``t_v`` with scale ``H`` is ``Z(K) = H^K / K! z^(K)(t_v)``,
``K = 0..Kmax``, and ``z(t) ~ sum_K Z(K) ((t - t_v) / H)^K``. Spectra are arrays whose last axis
is ``K``. Products, sine/cosine and derivatives are exact up to the truncation order; they turn
the polynomial models of radar coordinates into Cartesian polynomials (stage 1 of D.3).
"""

from __future__ import annotations

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array


def dt_product(u: ArrayLike, v: ArrayLike) -> FloatArray:
    """Spectrum of ``u v``: ``(u v)(K) = sum_{l <= K} U(l) V(K - l)`` (same length)."""
    a = as_float_array(u, "u", min_ndim=1)
    b = as_float_array(v, "v", min_ndim=1)
    n = a.shape[-1]
    if b.shape[-1] != n:
        raise ValueError(f"u and v must have the same number of terms; got {n} and {b.shape[-1]}")
    out = np.zeros(np.broadcast_shapes(a.shape, b.shape))
    for k in range(n):
        out[..., k] = np.einsum("...l,...l->...", a[..., : k + 1], b[..., k::-1])
    return out


def dt_sin_cos(u: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Spectra of ``sin(u)`` and ``cos(u)`` by the recurrences of spec D.4."""
    a = as_float_array(u, "u", min_ndim=1)
    n = a.shape[-1]
    s = np.zeros(a.shape)
    c = np.zeros(a.shape)
    s[..., 0], c[..., 0] = np.sin(a[..., 0]), np.cos(a[..., 0])
    for k in range(n - 1):
        lk = np.arange(1, k + 2)
        s[..., k + 1] = np.einsum("...l,...l->...", lk * a[..., 1 : k + 2], c[..., k::-1]) / (k + 1)
        c[..., k + 1] = -np.einsum("...l,...l->...", lk * a[..., 1 : k + 2], s[..., k::-1]) / (
            k + 1
        )
    return s, c


def dt_derivative(z: ArrayLike, scale: float) -> FloatArray:
    """Spectrum of ``dz/dt``: ``(K + 1) Z(K + 1) / H`` (one term shorter)."""
    a = as_float_array(z, "z", min_ndim=1)
    k = np.arange(1, a.shape[-1])
    return k * a[..., 1:] / scale


def radar_spectra_to_enu(
    range_spec: ArrayLike, azimuth_spec: ArrayLike, elevation_spec: ArrayLike
) -> FloatArray:
    """ENU spectra (..., 3, K) from spectra of range, azimuth and elevation (spec D.4).

    ``X_E = Rg * cos(beta) * sin(eps)``, ``X_N = Rg * cos(beta) * cos(eps)``,
    ``X_U = Rg * sin(beta)`` with ``*`` the truncated product. With ``H = 1`` the terms are
    position, velocity and half the acceleration.
    """
    rg = as_float_array(range_spec, "range_spec", min_ndim=1)
    se, ce = dt_sin_cos(azimuth_spec)
    sb, cb = dt_sin_cos(elevation_spec)
    rc = dt_product(rg, cb)
    return np.stack([dt_product(rc, se), dt_product(rc, ce), dt_product(rg, sb)], axis=-2)


__all__ = ["dt_derivative", "dt_product", "dt_sin_cos", "radar_spectra_to_enu"]
