"""Nonlinear motion models: the nearly-coordinated turn with an unknown turn rate.

A :class:`NonlinearMotionModel` gives the filters what they need of a discrete nonlinear
transition: the propagated mean and its Jacobian over a step, and the process noise of the
step. The EKF predicts with the Jacobian, the UKF with sigma points through
:meth:`~NonlinearMotionModel.propagate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .._typing import FloatArray

SERIES_BELOW = 1e-3  # |turn rate x step| under which sin/cos terms use their series


@runtime_checkable
class NonlinearMotionModel(Protocol):
    """A discrete nonlinear transition ``x(t + dt) = f(x(t), dt) + w``, ``w ~ N(0, Q(dt))``."""

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the state components, in state order."""
        ...

    @property
    def state_dim(self) -> int:
        """State size n."""
        ...

    def propagate(self, mean: FloatArray, dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``f(mean, dt)`` (..., n) and its Jacobian ``df/dx`` (..., n, n); dt (...) [s]."""
        ...

    def process_cov(self, dt: FloatArray) -> FloatArray:
        """Process noise covariance ``Q(dt)`` (..., n, n) of steps ``dt`` (...) [s]."""
        ...


def _turn_terms(u: FloatArray, dt: FloatArray) -> tuple[FloatArray, ...]:
    """Return ``sin(w dt)/w``, ``(1 - cos(w dt))/w`` and their derivatives in ``w``.

    ``u = w dt``; below :data:`SERIES_BELOW` the Taylor series replace the quotients, which
    would lose all digits at a straight flight.
    """
    small = np.abs(u) < SERIES_BELOW
    w = np.where(small, 1.0, u / np.where(dt > 0, dt, 1.0))  # safe divisor
    s, c = np.sin(u), np.cos(u)
    u2 = u * u
    a = np.where(small, dt * (1 - u2 / 6 + u2 * u2 / 120), s / w)
    b = np.where(small, dt * u * (0.5 - u2 / 24 + u2 * u2 / 720), (1 - c) / w)
    da = np.where(small, dt * dt * u * (-1 / 3 + u2 / 30), (dt * c - a) / w)
    db = np.where(small, dt * dt * (0.5 - u2 / 8 + u2 * u2 / 144), (dt * s - b) / w)
    return s, c, a, b, da, db


@dataclass(frozen=True)
class CoordinatedTurn:
    """Nearly-coordinated turn: constant speed and turn rate in the horizontal plane.

    State ``(x, y, vx, vy, omega)``, with ``(x, y, z, vx, vy, vz, omega)`` for
    ``n_axes=3`` (the vertical is nearly constant velocity): positions [m], velocities
    [m/s], ``omega`` the turn rate [rad/s], positive counter-clockwise (from x towards y).
    Over a step ``T`` the horizontal velocity turns by ``omega T`` at constant speed; the
    mean transition is exact for a constant turn rate. Noise: white accelerations of PSD
    ``accel_psd`` [m^2/s^3] along x and y and ``vertical_psd`` along z (the CV blocks
    ``q [[T^3/3, T^2/2], [T^2/2, T]]``), and a random-walk turn rate of PSD ``turn_psd``
    [rad^2/s^3] (``turn_psd T``); the horizontal noise blocks neglect the turn during the
    step, as Bar-Shalom, Li and Kirubarajan (2001, sec. 11.7) and Stone Soup's
    ``ConstantTurn`` do.

    Examples
    --------
    >>> import numpy as np
    >>> ct = CoordinatedTurn(accel_psd=0.1, turn_psd=1e-4)
    >>> x, f = ct.propagate(np.array([0.0, 0.0, 100.0, 0.0, np.pi / 20]), np.array(20.0))
    >>> np.round(x[:4], 6)  # a half circle of radius 100 / (pi / 20) m
    array([   0.      , 1273.239545, -100.      ,    0.      ])
    """

    accel_psd: float = 1.0
    turn_psd: float = 1e-4
    vertical_psd: float = 1.0
    n_axes: int = 2

    def __post_init__(self) -> None:
        if isinstance(self.n_axes, bool) or self.n_axes not in (2, 3):
            raise ValueError(f"n_axes must be 2 or 3; got {self.n_axes!r}")
        for name in ("accel_psd", "turn_psd", "vertical_psd"):
            value = getattr(self, name)
            if isinstance(value, bool) or not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0; got {value!r}")

    @property
    def state_names(self) -> tuple[str, ...]:
        """``x, y[, z], vx, vy[, vz], omega``."""
        axes = ("x", "y", "z")[: self.n_axes]
        return axes + tuple("v" + a for a in axes) + ("omega",)

    @property
    def state_dim(self) -> int:
        """5 (planar) or 7."""
        return 2 * self.n_axes + 1

    def propagate(self, mean: FloatArray, dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return the state after ``dt`` [s] (..., n) and the Jacobian (..., n, n)."""
        k = self.n_axes
        dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), mean.shape[:-1])
        vx, vy, w = mean[..., k], mean[..., k + 1], mean[..., -1]
        s, c, a, b, da, db = _turn_terms(w * dt, dt)
        out = np.array(mean, dtype=np.float64)
        out[..., 0] += a * vx - b * vy
        out[..., 1] += b * vx + a * vy
        out[..., k] = c * vx - s * vy
        out[..., k + 1] = s * vx + c * vy
        jac = np.zeros(mean.shape + (mean.shape[-1],))
        n = self.state_dim
        jac[..., range(n), range(n)] = 1.0
        jac[..., 0, k], jac[..., 0, k + 1], jac[..., 0, -1] = a, -b, da * vx - db * vy
        jac[..., 1, k], jac[..., 1, k + 1], jac[..., 1, -1] = b, a, db * vx + da * vy
        jac[..., k, k], jac[..., k, k + 1], jac[..., k, -1] = c, -s, -dt * (s * vx + c * vy)
        jac[..., k + 1, k], jac[..., k + 1, k + 1] = s, c
        jac[..., k + 1, -1] = dt * (c * vx - s * vy)
        if k == 3:
            out[..., 2] += dt * mean[..., 5]
            jac[..., 2, 5] = dt
        return out, jac

    def process_cov(self, dt: FloatArray) -> FloatArray:
        """Return ``Q(dt)`` (..., n, n) of steps ``dt`` (...) [s]."""
        t = np.asarray(dt, dtype=np.float64)
        k, n = self.n_axes, self.state_dim
        q = np.zeros(t.shape + (n, n))
        psd = (self.accel_psd, self.accel_psd, self.vertical_psd)
        for axis in range(k):
            p, v = axis, k + axis
            q[..., p, p] = psd[axis] * t**3 / 3
            q[..., p, v] = q[..., v, p] = psd[axis] * t**2 / 2
            q[..., v, v] = psd[axis] * t
        q[..., -1, -1] = self.turn_psd * t
        return q


__all__ = ["CoordinatedTurn", "NonlinearMotionModel"]
