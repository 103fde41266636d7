"""Radar polar coordinates <-> local ENU, with rates, Jacobians and covariances (spec D.3, D.5).

Conventions: range ``r`` [m]; azimuth ``eps`` [rad] clockwise from north (towards east),
wrapped to [-pi, pi) on output; elevation ``beta`` [rad] above the horizontal plane;
range-rate positive when receding. ``u = [cos b sin e, cos b cos e, sin b]`` (E, N, U).
"""

from __future__ import annotations

import numpy as np

from .._linalg import mT, symmetrize
from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, broadcast_shape, check_symmetric_pd
from ..angles import wrap


def wrap_to_pi(angle: ArrayLike) -> FloatArray:
    """Wrap angles [rad] to [-pi, pi)."""
    return wrap(as_float_array(angle, "angle"))


def _polar(polar: ArrayLike) -> FloatArray:
    """Return validated (range, azimuth, elevation) (..., 3): finite, range >= 0."""
    a = as_float_array(polar, "polar", min_ndim=1)
    if a.shape[-1] != 3:
        raise ValueError(
            f"polar must have shape (..., 3) (range, azimuth, elevation); got {a.shape}"
        )
    if np.any(a[..., 0] < 0):
        idx = tuple(int(i) for i in np.argwhere(a[..., 0] < 0)[0])
        raise ValueError(f"polar range must be >= 0; got {a[idx + (0,)]} at index {idx}")
    return a


def polar_to_enu(polar: ArrayLike) -> FloatArray:
    """ENU positions (..., 3) of (range, azimuth, elevation) (..., 3).

    Examples
    --------
    >>> polar_to_enu([1000.0, 0.0, 0.0]).round(6)
    array([   0., 1000.,    0.])
    """
    a = _polar(polar)
    r, e, b = a[..., 0], a[..., 1], a[..., 2]
    return r[..., None] * np.stack([np.cos(b) * np.sin(e), np.cos(b) * np.cos(e), np.sin(b)], -1)


def enu_to_polar(enu: ArrayLike) -> FloatArray:
    """(range, azimuth, elevation) (..., 3) of ENU positions (..., 3) seen from the origin.

    Raises
    ------
    ValueError
        If a position coincides with the sensor (range 0).
    """
    p = as_float_array(enu, "enu", min_ndim=1)
    if p.shape[-1] != 3:
        raise ValueError(f"enu must have shape (..., 3); got {p.shape}")
    horiz = np.hypot(p[..., 0], p[..., 1])
    r = np.hypot(horiz, p[..., 2])
    if np.any(r == 0):
        raise ValueError("enu: a position coincides with the sensor (range 0)")
    return np.stack(
        [r, wrap_to_pi(np.arctan2(p[..., 0], p[..., 1])), np.arctan2(p[..., 2], horiz)], -1
    )


def enu_to_polar_rates(position: ArrayLike, velocity: ArrayLike) -> FloatArray:
    """(range-rate [m/s], azimuth rate, elevation rate [rad/s]) (..., 3) of ENU kinematics."""
    p = as_float_array(position, "position", min_ndim=1)
    v = as_float_array(velocity, "velocity", min_ndim=1)
    horiz2 = p[..., 0] ** 2 + p[..., 1] ** 2
    r = np.sqrt(horiz2 + p[..., 2] ** 2)
    rd = np.einsum("...i,...i->...", p, v) / r
    ed = (v[..., 0] * p[..., 1] - v[..., 1] * p[..., 0]) / horiz2
    horiz = np.sqrt(horiz2)
    bd = (
        v[..., 2] * horiz - p[..., 2] * (p[..., 0] * v[..., 0] + p[..., 1] * v[..., 1]) / horiz
    ) / r**2
    return np.stack([rd, ed, bd], -1)


def _unit_derivatives(e: FloatArray, b: FloatArray) -> dict[str, FloatArray]:
    ce, se, cb, sb = np.cos(e), np.sin(e), np.cos(b), np.sin(b)
    z = np.zeros_like(ce * cb)
    u = np.stack([cb * se, cb * ce, sb + z], -1)
    ue = np.stack([cb * ce, -cb * se, z], -1)
    ub = np.stack([-sb * se, -sb * ce, cb + z], -1)
    uee = np.stack([-cb * se, -cb * ce, z], -1)
    ueb = np.stack([-sb * ce, sb * se, z], -1)
    ueeb = np.stack([sb * se, sb * ce, z], -1)
    return {
        "u": u,
        "ue": ue,
        "ub": ub,
        "uee": uee,
        "ueb": ueb,
        "ubb": -u,
        "ueee": -ue,
        "ueeb": ueeb,
        "uebb": -ue,
        "ubbb": -ub,
    }


def _radar_vector(
    a: ArrayLike,
) -> tuple[tuple[FloatArray, ...], dict[str, FloatArray], FloatArray, FloatArray]:
    """Split the radar vector and form ``u`` derivatives, ``ud`` and ``udd`` (spec D.3)."""
    x = as_float_array(a, "a", min_ndim=1)
    if x.shape[-1] != 9:
        raise ValueError(f"a must have shape (..., 9); got {x.shape}")
    parts = tuple(x[..., i : i + 1] for i in range(9))
    _, _, _, _, ed, bd, _, edd, bdd = parts
    d = _unit_derivatives(x[..., 1], x[..., 2])
    ud = ed * d["ue"] + bd * d["ub"]
    udd = (
        ed**2 * d["uee"] + 2 * ed * bd * d["ueb"] + bd**2 * d["ubb"] + edd * d["ue"] + bdd * d["ub"]
    )
    return parts, d, ud, udd


def polar_kinematics_to_enu(a: ArrayLike) -> FloatArray:
    """ENU position, velocity, acceleration (..., 9) of the extended radar vector (..., 9).

    ``a = [r, eps, beta, rd, eps', beta', rdd, eps'', beta'']`` (spec D.2); the output is
    ``[p, pd, pdd]`` (spec D.3 stage 1), the derivatives of ``r(t) u(eps(t), beta(t))``.
    """
    (r, _, _, rd, _, _, rdd, _, _), d, ud, udd = _radar_vector(a)
    return np.concatenate(
        [r * d["u"], rd * d["u"] + r * ud, rdd * d["u"] + 2 * rd * ud + r * udd], -1
    )


def polar_kinematics_jacobian(a: ArrayLike) -> FloatArray:
    """Closed-form Jacobian ``d[p, pd, pdd] / d a`` (..., 9, 9) (spec D.5, block triangular)."""
    (r, _, _, rd, ed, bd, rdd, edd, bdd), d, ud, udd = _radar_vector(a)
    ud_e = ed * d["uee"] + bd * d["ueb"]
    ud_b = ed * d["ueb"] + bd * d["ubb"]
    udd_e = (
        ed**2 * d["ueee"]
        + 2 * ed * bd * d["ueeb"]
        + bd**2 * d["uebb"]
        + edd * d["uee"]
        + bdd * d["ueb"]
    )
    udd_b = (
        ed**2 * d["ueeb"]
        + 2 * ed * bd * d["uebb"]
        + bd**2 * d["ubbb"]
        + edd * d["ueb"]
        + bdd * d["ubb"]
    )
    jp = np.stack([d["u"], r * d["ue"], r * d["ub"]], -1)
    jv = np.stack([ud, rd * d["ue"] + r * ud_e, rd * d["ub"] + r * ud_b], -1)
    ja = np.stack(
        [udd, rdd * d["ue"] + 2 * rd * ud_e + r * udd_e, rdd * d["ub"] + 2 * rd * ud_b + r * udd_b],
        -1,
    )
    z = np.zeros_like(jp)
    return np.concatenate(
        [
            np.concatenate([jp, z, z], -1),
            np.concatenate([jv, jp, z], -1),
            np.concatenate([ja, 2 * jv, jp], -1),
        ],
        -2,
    )


def polar_to_enu_cov(polar: ArrayLike, polar_cov: ArrayLike) -> FloatArray:
    """Covariance (..., 3, 3) of ENU positions converted from (r, az, el) with covariance."""
    a = _polar(polar)
    c = as_float_array(polar_cov, "polar_cov", min_ndim=2)
    if c.shape[-2:] != (3, 3):
        raise ValueError(f"polar_cov must have shape (..., 3, 3); got {c.shape}")
    check_symmetric_pd(c, "polar_cov", semidefinite=True)
    batch = broadcast_shape(polar=a.shape[:-1], polar_cov=c.shape[:-2])
    r, e, b = a[..., 0:1], a[..., 1], a[..., 2]
    d = _unit_derivatives(e, b)
    j = np.broadcast_to(np.stack([d["u"], r * d["ue"], r * d["ub"]], -1), batch + (3, 3))
    return symmetrize(j @ c @ mT(j))


def polar_kinematics_cov_to_ecef(
    a: ArrayLike, cov_a: ArrayLike, lat: float, lon: float
) -> FloatArray:
    """Covariance (..., 9, 9) of ECEF ``[p, v, a]`` from the radar vector's covariance (eq. 13).

    ``R_gas = J_abs [J_rel [J_loc R_a J_loc^T] J_rel^T] J_abs^T`` with ``J_loc`` the closed-form
    Jacobian of :func:`polar_kinematics_jacobian`, ``J_rel = blockdiag(R, R, R)`` (``R`` the
    ENU-to-ECEF rotation of the site) and ``J_abs = I`` (a site fixed on the Earth).
    """
    from .geodetic import enu_to_ecef_rotation

    j_loc = polar_kinematics_jacobian(a)
    c = as_float_array(cov_a, "cov_a", min_ndim=2)
    local = j_loc @ c @ mT(j_loc)
    j_rel = np.kron(np.eye(3), enu_to_ecef_rotation(lat, lon))
    return j_rel @ local @ j_rel.T


__all__ = [
    "enu_to_polar",
    "enu_to_polar_rates",
    "polar_kinematics_cov_to_ecef",
    "polar_kinematics_jacobian",
    "polar_kinematics_to_enu",
    "polar_to_enu",
    "polar_to_enu_cov",
    "wrap_to_pi",
]
