"""Measurement models: what a sensor measures of a state, ``z = h(x) + v``, ``v ~ N(0, R)``.

A measurement model reads named state components (``reads``, e.g. ``("x", "y", "z", "vx",
"vy", "vz")``) of whatever motion model it is used with, so one radar model serves constant
velocity, constant acceleration and the adaptive models alike. It gives ``h`` and its
Jacobian over those components, its noise covariance ``noise_cov``, and marks which
components are angles (``angular``): their residuals are wrapped to [-pi, pi) and their
sigma-point means are circular.

Models: :class:`PositionMeasurement` (local frame, linear), :class:`RadarMeasurement`
(planar or 3-D: range, azimuth, elevation, range-rate at a sensor pose),
:class:`GeodeticMeasurement` (GNSS latitude, longitude, height of a local ENU state) and
:class:`FunctionMeasurement` (any user function). Conventions of :mod:`adaptrack.coords`:
azimuth clockwise from north, elevation above the horizontal, range-rate positive receding.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_symmetric_pd, frozen
from ..coords.geodetic import (
    WGS84_A,
    WGS84_E2,
    ecef_to_geodetic,
    enu_to_ecef_rotation,
    geodetic_to_ecef,
)
from ..coords.radar import wrap_to_pi

RADAR_COMPONENTS = ("range", "azimuth", "elevation", "range_rate")
AXES = ("x", "y", "z")


@runtime_checkable
class MeasurementModel(Protocol):
    """What the EKF and UKF need of a measurement model.

    Attributes
    ----------
    names : tuple of str
        Measured components, length m (the columns of a measurement table).
    reads : tuple of str
        State components ``h`` depends on, length k (names of the motion model's states).
    angular : tuple of bool
        Per measured component: an angle [rad] (wrapped residual, circular mean).
    noise_cov : ndarray, shape (m, m)
        ``R`` in the components' units (m^2, rad^2, (m/s)^2).
    """

    @property
    def names(self) -> tuple[str, ...]:  # noqa: D102
        ...

    @property
    def reads(self) -> tuple[str, ...]:  # noqa: D102
        ...

    @property
    def angular(self) -> tuple[bool, ...]:  # noqa: D102
        ...

    @property
    def noise_cov(self) -> FloatArray:  # noqa: D102
        ...

    def predict(self, s: FloatArray) -> FloatArray:
        """``h`` of the read components ``s`` (..., k): (..., m)."""
        ...

    def jacobian(self, s: FloatArray) -> FloatArray:
        """``dh/ds`` (..., m, k) at ``s`` (..., k)."""
        ...


def _noise_cov(value: ArrayLike, m: int) -> FloatArray:
    r = as_float_array(value, "noise_cov", min_ndim=1)
    if r.shape == (m,):
        r = np.diag(r)
    if r.shape != (m, m):
        raise ValueError(f"noise_cov must have shape ({m}, {m}) or ({m},) variances; got {r.shape}")
    check_symmetric_pd(r, "noise_cov")
    return frozen(r)


def residual(model: MeasurementModel, z: FloatArray, z_pred: FloatArray) -> FloatArray:
    """``z - z_pred`` (..., m) with the angular components wrapped to [-pi, pi)."""
    d = z - z_pred
    ang = np.asarray(model.angular)
    if ang.any():
        d = np.where(ang, wrap_to_pi(d), d)
    return d


def weighted_mean(model: MeasurementModel, points: FloatArray, weights: FloatArray) -> FloatArray:
    """Mean (..., m) of measurement points (..., P, m) with weights (P,).

    Angular components are averaged on the circle (``atan2`` of the weighted sines and
    cosines), so points on both sides of +-pi average near pi, not near 0.
    """
    mean = np.einsum("p,...pm->...m", weights, points)
    ang = np.asarray(model.angular)
    if ang.any():
        s = np.einsum("p,...pm->...m", weights, np.sin(points))
        c = np.einsum("p,...pm->...m", weights, np.cos(points))
        mean = np.where(ang, np.arctan2(s, c), mean)
    return mean


def state_indices(model: MeasurementModel, state_names: Sequence[str]) -> np.ndarray:
    """Return the indices in ``state_names`` of what ``model`` reads (ValueError if absent)."""
    names = tuple(state_names)
    missing = [s for s in model.reads if s not in names]
    if missing:
        raise ValueError(
            f"the measurement model reads state(s) {missing} that the motion model lacks; "
            f"its states are {names}"
        )
    return np.array([names.index(s) for s in model.reads], dtype=int)


@dataclass(frozen=True, eq=False)
class PositionMeasurement:
    """Position in the local frame: ``z = (x, y[, z])`` (linear).

    Parameters
    ----------
    noise_cov : array_like, shape (m, m) or (m,)
        Covariance [m^2] (or variances) of the measured coordinates.
    reads : sequence of str
        Measured state components, default ``("x", "y")``.
    """

    noise_cov: FloatArray
    reads: tuple[str, ...] = ("x", "y")
    names: tuple[str, ...] = field(init=False)
    angular: tuple[bool, ...] = field(init=False)

    def __post_init__(self) -> None:
        reads = tuple(self.reads)
        object.__setattr__(self, "reads", reads)
        object.__setattr__(self, "names", tuple(f"{s}_m" for s in reads))
        object.__setattr__(self, "angular", (False,) * len(reads))
        object.__setattr__(self, "noise_cov", _noise_cov(self.noise_cov, len(reads)))

    def predict(self, s: FloatArray) -> FloatArray:
        """Return the position itself (..., m)."""
        return np.array(s, dtype=np.float64)

    def jacobian(self, s: FloatArray) -> FloatArray:
        """Return the identity (..., m, m)."""
        return np.broadcast_to(np.eye(len(self.reads)), s.shape + s.shape[-1:]).copy()


@dataclass(frozen=True, eq=False)
class RadarMeasurement:
    """Radar at a pose: range [m], azimuth [rad], elevation [rad], range-rate [m/s].

    ``d = p - sensor_position``; range ``|d|``; azimuth ``atan2(d_E, d_N) - heading``
    (clockwise from the sensor's reference direction, wrapped); elevation above the
    horizontal; range-rate ``d . (v - sensor_velocity) / |d|``, positive receding.

    Parameters
    ----------
    noise_cov : array_like, shape (m, m) or (m,)
        Covariance of the measured components in the order of ``components``.
    components : sequence of str
        A subset of ``("range", "azimuth", "elevation", "range_rate")`` in that order.
    n_axes : {2, 3}
        Planar (states ``x, y``; no elevation) or 3-D (``x, y, z``) geometry.
    sensor_position : array_like, shape (n_axes,)
        Sensor position in the local frame [m].
    sensor_velocity : array_like, shape (n_axes,)
        Sensor velocity [m/s] (a moving platform; default at rest).
    heading : float
        Azimuth of the sensor's zero-azimuth direction, clockwise from north [rad]; a
        constant azimuth bias is a heading error.
    """

    noise_cov: FloatArray
    components: tuple[str, ...] = ("range", "azimuth")
    n_axes: int = 2
    sensor_position: FloatArray | None = None
    sensor_velocity: FloatArray | None = None
    heading: float = 0.0
    names: tuple[str, ...] = field(init=False)
    reads: tuple[str, ...] = field(init=False)
    angular: tuple[bool, ...] = field(init=False)

    def __post_init__(self) -> None:
        comps = tuple(self.components)
        if not comps or tuple(c for c in RADAR_COMPONENTS if c in comps) != comps:
            raise ValueError(
                f"components must be a non-empty subset of {RADAR_COMPONENTS} in that order; "
                f"got {comps}"
            )
        if self.n_axes not in (2, 3):
            raise ValueError(f"n_axes must be 2 (planar) or 3; got {self.n_axes}")
        if self.n_axes == 2 and "elevation" in comps:
            raise ValueError("a planar radar (n_axes=2) measures no elevation")
        k = self.n_axes
        for name in ("sensor_position", "sensor_velocity"):
            value = getattr(self, name)
            v = np.zeros(k) if value is None else as_float_array(value, name, min_ndim=1)
            if v.shape != (k,):
                raise ValueError(f"{name} must have shape ({k},); got {v.shape}")
            object.__setattr__(self, name, frozen(v))
        heading = float(self.heading)
        if not np.isfinite(heading):
            raise ValueError(f"heading must be finite [rad]; got {self.heading}")
        object.__setattr__(self, "heading", heading)
        object.__setattr__(self, "components", comps)
        object.__setattr__(self, "names", comps)
        reads = AXES[:k] + (tuple("v" + a for a in AXES[:k]) if "range_rate" in comps else ())
        object.__setattr__(self, "reads", reads)
        object.__setattr__(self, "angular", tuple(c in ("azimuth", "elevation") for c in comps))
        object.__setattr__(self, "noise_cov", _noise_cov(self.noise_cov, len(comps)))

    def _geometry(self, s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        k = self.n_axes
        d = s[..., :k] - np.asarray(self.sensor_position)
        horiz2 = d[..., 0] ** 2 + d[..., 1] ** 2
        r = np.sqrt(horiz2 + (d[..., 2] ** 2 if k == 3 else 0.0))
        if np.any(horiz2 == 0.0):
            raise ValueError("a state lies on the radar's vertical axis: azimuth is undefined")
        return d, horiz2, r, s[..., k:]

    def predict(self, s: FloatArray) -> FloatArray:
        """Measured components (..., m) of the read states (..., k)."""
        d, horiz2, r, v = self._geometry(s)
        out = {
            "range": r,
            "azimuth": wrap_to_pi(np.arctan2(d[..., 0], d[..., 1]) - self.heading),
        }
        if self.n_axes == 3:
            out["elevation"] = np.arctan2(d[..., 2], np.sqrt(horiz2))
        if "range_rate" in self.components:
            rel = v - np.asarray(self.sensor_velocity)
            out["range_rate"] = np.einsum("...i,...i->...", d, rel) / r
        return np.stack([out[c] for c in self.components], -1)

    def jacobian(self, s: FloatArray) -> FloatArray:
        """Analytic ``dh/ds`` (..., m, k)."""
        d, horiz2, r, v = self._geometry(s)
        k = self.n_axes
        n_read = len(self.reads)
        zero = np.zeros(d.shape[:-1])
        rows = {}
        u = d / r[..., None]
        rows["range"] = np.concatenate([u, np.zeros(d.shape[:-1] + (n_read - k,))], -1)
        az = [d[..., 1] / horiz2, -d[..., 0] / horiz2] + ([zero] if k == 3 else [])
        rows["azimuth"] = np.concatenate(
            [np.stack(az, -1), np.zeros(d.shape[:-1] + (n_read - k,))], -1
        )
        if k == 3:
            rho = np.sqrt(horiz2)
            r2 = r**2
            el = [
                -d[..., 0] * d[..., 2] / (rho * r2),
                -d[..., 1] * d[..., 2] / (rho * r2),
                rho / r2,
            ]
            rows["elevation"] = np.concatenate(
                [np.stack(el, -1), np.zeros(d.shape[:-1] + (n_read - k,))], -1
            )
        if "range_rate" in self.components:
            rel = v - np.asarray(self.sensor_velocity)
            rr = np.einsum("...i,...i->...", d, rel) / r
            dpos = (rel - rr[..., None] * u) / r[..., None]
            rows["range_rate"] = np.concatenate([dpos, u], -1)
        return np.stack([rows[c] for c in self.components], -2)


def _meridian_prime_radii(lat: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Meridian (M) and prime-vertical (N) radii of curvature [m] at geodetic latitude."""
    w2 = 1.0 - WGS84_E2 * np.sin(lat) ** 2
    return WGS84_A * (1.0 - WGS84_E2) / w2**1.5, WGS84_A / np.sqrt(w2)


@dataclass(frozen=True, eq=False)
class GeodeticMeasurement:
    """GNSS fix of a local-ENU state: latitude [rad], longitude [rad], height [m] (WGS-84).

    The state's ``x, y, z`` are east, north, up [m] about ``origin`` (geodetic latitude,
    longitude [rad], height [m]). ``h`` goes ENU -> ECEF -> geodetic; its Jacobian is
    analytic: ``d ECEF = (M + h) n dlat + (N + h) cos(lat) e dlon + u dh`` with the local
    unit vectors ``e, n, u`` at the fix.

    Parameters
    ----------
    noise_cov : array_like, shape (3, 3) or (3,)
        Covariance of (lat, lon, height) [rad^2, rad^2, m^2]; see :meth:`from_metres`.
    origin : sequence of float
        Local frame origin ``(lat0, lon0, h0)`` [rad, rad, m].
    """

    noise_cov: FloatArray
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    names: tuple[str, ...] = ("lat_rad", "lon_rad", "alt_m")
    reads: tuple[str, ...] = ("x", "y", "z")
    angular: tuple[bool, ...] = (False, True, False)

    def __post_init__(self) -> None:
        o = as_float_array(self.origin, "origin", min_ndim=1)
        if o.shape != (3,) or abs(o[0]) > np.pi / 2:
            raise ValueError(
                f"origin must be (lat0 [rad] in [-pi/2, pi/2], lon0 [rad], h0 [m]); got {o}"
            )
        object.__setattr__(self, "origin", (float(o[0]), float(o[1]), float(o[2])))
        object.__setattr__(self, "noise_cov", _noise_cov(self.noise_cov, 3))

    @classmethod
    def from_metres(
        cls, origin: Sequence[float], horizontal_std_m: float, vertical_std_m: float
    ) -> GeodeticMeasurement:
        """Make a model whose (lat, lon) noise is ``horizontal_std_m`` on the ground at origin."""
        m, n = _meridian_prime_radii(np.asarray(origin[0], dtype=float))
        var = [
            (horizontal_std_m / (m + origin[2])) ** 2,
            (horizontal_std_m / ((n + origin[2]) * np.cos(origin[0]))) ** 2,
            vertical_std_m**2,
        ]
        return cls(noise_cov=np.diag(var), origin=(origin[0], origin[1], origin[2]))

    def _ecef(self, s: FloatArray) -> FloatArray:
        lat0, lon0, h0 = self.origin
        rot = enu_to_ecef_rotation(lat0, lon0)
        return geodetic_to_ecef(lat0, lon0, h0) + np.einsum("ij,...j->...i", rot, s[..., :3])

    def predict(self, s: FloatArray) -> FloatArray:
        """(lat [rad], lon [rad], height [m]) (..., 3) of ENU positions (..., 3)."""
        lat, lon, h = ecef_to_geodetic(self._ecef(s))
        return np.stack([lat, lon, h], -1)

    def jacobian(self, s: FloatArray) -> FloatArray:
        """Analytic ``d(lat, lon, h)/d(E, N, U)`` (..., 3, 3)."""
        lat, lon, h = ecef_to_geodetic(self._ecef(s))
        m, n = _meridian_prime_radii(lat)
        at_fix = enu_to_ecef_rotation(lat, lon)  # columns e, n, u at the fix
        rows = np.swapaxes(at_fix, -1, -2)  # rows e, n, u
        scale = np.stack([1.0 / (m + h), 1.0 / ((n + h) * np.cos(lat)), np.ones_like(h)], -1)
        d_geo_d_ecef = rows[..., [1, 0, 2], :] * scale[..., None]
        return d_geo_d_ecef @ enu_to_ecef_rotation(*self.origin[:2])


@dataclass(frozen=True, eq=False)
class FunctionMeasurement:
    """A user's measurement function ``h(s)`` of named state components.

    Parameters
    ----------
    function : callable
        ``h(s) -> z``, vectorised: ``s`` (..., k) in the order of ``reads``, ``z`` (..., m).
    reads : sequence of str
        State components ``h`` reads.
    names : sequence of str
        Measured components (length m).
    noise_cov : array_like, shape (m, m) or (m,)
    jacobian_function : callable, optional
        ``dh/ds`` (..., m, k); default: central differences with a step of
        ``1e-6 * max(1, |s_i|)`` (accurate to about 1e-9 relative for smooth ``h``).
    angular : sequence of bool, optional
        Which components are angles [rad] (default none).
    """

    function: Callable[[FloatArray], FloatArray]
    reads: tuple[str, ...]
    names: tuple[str, ...]
    noise_cov: FloatArray
    jacobian_function: Callable[[FloatArray], FloatArray] | None = None
    angular: tuple[bool, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "reads", tuple(self.reads))
        object.__setattr__(self, "names", tuple(self.names))
        m = len(self.names)
        ang = tuple(bool(a) for a in self.angular) or (False,) * m
        if len(ang) != m:
            raise ValueError(f"angular must have one flag per component ({m}); got {len(ang)}")
        object.__setattr__(self, "angular", ang)
        object.__setattr__(self, "noise_cov", _noise_cov(self.noise_cov, m))

    def predict(self, s: FloatArray) -> FloatArray:
        """``h(s)`` (..., m), shape-checked."""
        z = np.asarray(self.function(s), dtype=np.float64)
        if z.shape != s.shape[:-1] + (len(self.names),):
            raise ValueError(
                f"the measurement function returned shape {z.shape} for states {s.shape}; "
                f"expected {s.shape[:-1] + (len(self.names),)}"
            )
        return z

    def jacobian(self, s: FloatArray) -> FloatArray:
        """Return the user's Jacobian, or central differences of :meth:`predict` (..., m, k)."""
        if self.jacobian_function is not None:
            jac = np.asarray(self.jacobian_function(s), dtype=np.float64)
            expected = s.shape[:-1] + (len(self.names), s.shape[-1])
            if jac.shape != expected:
                raise ValueError(
                    f"jacobian_function returned shape {jac.shape}; expected {expected}"
                )
            return jac
        cols = []
        for i in range(s.shape[-1]):
            step = 1e-6 * np.maximum(1.0, np.abs(s[..., i]))
            up, down = s.copy(), s.copy()
            up[..., i] += step
            down[..., i] -= step
            diff = residual(self, self.predict(up), self.predict(down))
            cols.append(diff / (2.0 * step[..., None]))
        return np.stack(cols, -1)


__all__ = [
    "FunctionMeasurement",
    "GeodeticMeasurement",
    "MeasurementModel",
    "PositionMeasurement",
    "RadarMeasurement",
    "residual",
    "state_indices",
    "weighted_mean",
]
