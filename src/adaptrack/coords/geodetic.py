"""WGS-84 geodetic <-> ECEF <-> local ENU (spec D.3 stages 2-3), radians, vectorised.

Closed forms of the spec, verified against pymap3d in the tests. Geodetic latitude and
longitude in radians, height above the ellipsoid in metres.
"""

from __future__ import annotations

import numpy as np

from .._linalg import mT, symmetrize
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, broadcast_shape, check_symmetric_pd

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_B = WGS84_A * (1.0 - WGS84_F)


def _check_latitude(lat: FloatArray, name: str) -> None:
    if np.any(np.abs(lat) > np.pi / 2 + 1e-12):
        bad = lat[np.abs(lat) > np.pi / 2 + 1e-12].flat[0]
        raise ValueError(
            f"{name} must be in [-pi/2, pi/2] radians; got {bad} (degrees "
            "passed where radians are expected?)"
        )


def geodetic_to_ecef(lat: ArrayLike, lon: ArrayLike, height: ArrayLike) -> FloatArray:
    """ECEF position (..., 3) [m] of geodetic latitude, longitude [rad] and height [m].

    Examples
    --------
    >>> geodetic_to_ecef(0.0, 0.0, 0.0)
    array([6378137.,       0.,       0.])
    """
    la = as_float_array(lat, "lat")
    lo = as_float_array(lon, "lon")
    h = as_float_array(height, "height")
    shape = broadcast_shape(lat=la.shape, lon=lo.shape, height=h.shape)
    la, lo, h = (np.broadcast_to(a, shape) for a in (la, lo, h))
    _check_latitude(la, "lat")
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(la) ** 2)
    return np.stack(
        [
            (n + h) * np.cos(la) * np.cos(lo),
            (n + h) * np.cos(la) * np.sin(lo),
            (n * (1.0 - WGS84_E2) + h) * np.sin(la),
        ],
        axis=-1,
    )


def ecef_to_geodetic(ecef: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Geodetic latitude, longitude [rad] and height [m] of ECEF positions (..., 3).

    Bowring's parametric start followed by Newton iterations on the latitude (converged to
    below 1e-12 rad and 1e-6 m for heights from -1e4 m to 1e8 m).
    """
    p = as_float_array(ecef, "ecef", min_ndim=1)
    if p.shape[-1] != 3:
        raise ValueError(f"ecef must have shape (..., 3); got {p.shape}")
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    lon = np.arctan2(y, x)
    rho = np.hypot(x, y)
    ep2 = WGS84_E2 / (1.0 - WGS84_E2)
    beta = np.arctan2(z * WGS84_A, rho * WGS84_B)
    lat = np.arctan2(
        z + ep2 * WGS84_B * np.sin(beta) ** 3, rho - WGS84_E2 * WGS84_A * np.cos(beta) ** 3
    )
    for _ in range(4):
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        lat = np.arctan2(z + WGS84_E2 * n * np.sin(lat), rho)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    cl, sl = np.cos(lat), np.sin(lat)
    h = rho * cl + z * sl - WGS84_A**2 / n  # well conditioned at every latitude
    return lat, lon, h


def enu_to_ecef_rotation(lat: ArrayLike, lon: ArrayLike) -> FloatArray:
    """Rotation (..., 3, 3) whose columns are the east, north, up unit vectors in ECEF."""
    la = as_float_array(lat, "lat")
    lo = as_float_array(lon, "lon")
    broadcast_shape(lat=la.shape, lon=lo.shape)
    _check_latitude(la, "lat")
    sl, cl, so, co = np.sin(la), np.cos(la), np.sin(lo), np.cos(lo)
    zero = np.zeros_like(sl * so)
    return np.stack(
        [
            np.stack([-so + zero, -sl * co, cl * co], -1),
            np.stack([co + zero, -sl * so, cl * so], -1),
            np.stack([zero, cl + zero, sl + zero], -1),
        ],
        -2,
    )


def enu_to_ecef(enu: ArrayLike, lat0: float, lon0: float, h0: float) -> FloatArray:
    """ECEF positions (..., 3) of ENU positions (..., 3) relative to a site (lat0, lon0, h0)."""
    e = _vectors(enu, "enu")
    rot = enu_to_ecef_rotation(*_site(lat0, lon0, h0)[:2])
    return geodetic_to_ecef(lat0, lon0, h0) + e @ rot.T


def ecef_to_enu(ecef: ArrayLike, lat0: float, lon0: float, h0: float) -> FloatArray:
    """ENU positions (..., 3) relative to a site of ECEF positions (..., 3)."""
    p = _vectors(ecef, "ecef")
    rot = enu_to_ecef_rotation(*_site(lat0, lon0, h0)[:2])
    return (p - geodetic_to_ecef(lat0, lon0, h0)) @ rot


def _vectors(value: ArrayLike, name: str) -> FloatArray:
    v = as_float_array(value, name, min_ndim=1)
    if v.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3); got {v.shape}")
    return v


def _site(lat0: float, lon0: float, h0: float) -> tuple[float, float, float]:
    """Return the site's (lat0 [rad], lon0 [rad], h0 [m]) as finite scalars."""
    out = []
    for name, value in (("lat0", lat0), ("lon0", lon0), ("h0", h0)):
        a = as_float_array(value, name)
        if a.ndim:
            raise ValueError(f"{name} must be a scalar; got shape {a.shape}")
        out.append(float(a))
    _check_latitude(np.asarray(out[0]), "lat0")
    return out[0], out[1], out[2]


def rotate_cov(cov: ArrayLike, rotation: ArrayLike) -> FloatArray:
    """Return ``R P R^T`` (exactly symmetric) of covariances (..., n, n), rotations (..., k, n).

    E.g. ENU -> ECEF with the site rotation.
    """
    p = as_float_array(cov, "cov", min_ndim=2)
    r = as_float_array(rotation, "rotation", min_ndim=2)
    check_symmetric_pd(p, "cov", semidefinite=True)
    if r.shape[-1] != p.shape[-1]:
        raise ValueError(
            f"rotation (..., k, {p.shape[-1]}) must match cov {p.shape}; got {r.shape}"
        )
    broadcast_shape(cov=p.shape[:-2], rotation=r.shape[:-2])
    return symmetrize(r @ p @ mT(r))


__all__ = [
    "WGS84_A",
    "WGS84_B",
    "WGS84_E2",
    "WGS84_F",
    "ecef_to_enu",
    "ecef_to_geodetic",
    "enu_to_ecef",
    "enu_to_ecef_rotation",
    "geodetic_to_ecef",
    "rotate_cov",
]
