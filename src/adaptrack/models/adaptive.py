"""Adaptive motion models of seed 001: M1 (inverse dynamics) and M2 (M1 + shaping filter).

Spec B.3-B.4. Both are per-axis ("per degree of freedom") models assembled in the state order
of CONVENTIONS (all generalised coordinates, then their rates, then the shaping states).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .._typing import FloatArray
from .._validation import check_positive_scalar
from ._layout import Block
from ._phi import phi
from .continuous import _AxisModel, _check_axes, _e, _no_control, _per_axis


def singer_accel_std(max_accel_mps2: float, prob_max_accel: float, prob_no_accel: float) -> float:
    """Singer's rule for the RMS manoeuvre acceleration [m/s^2].

    ``sigma_a = a_max sqrt((1 + 4 P_max - P_0) / 3)``: the acceleration is ``+-a_max`` with
    probability ``P_max`` each, 0 with probability ``P_0`` and uniform in between.

    Examples
    --------
    >>> round(singer_accel_std(9.0, 0.05, 0.5), 2)
    4.35
    """
    a = check_positive_scalar(max_accel_mps2, "max_accel_mps2", allow_zero=True)
    pm = check_positive_scalar(prob_max_accel, "prob_max_accel", allow_zero=True)
    p0 = check_positive_scalar(prob_no_accel, "prob_no_accel", allow_zero=True)
    if 2 * pm + p0 > 1.0:
        raise ValueError(f"2 * prob_max_accel + prob_no_accel must be <= 1; got {2 * pm + p0}")
    return a * math.sqrt((1.0 + 4.0 * pm - p0) / 3.0)


@dataclass(frozen=True, eq=False)
class InverseDynamics(_AxisModel):
    """Model M1 of seed 001: ``q'' = -sqrt(lambda) q' + a(t)`` per axis (spec B.3).

    ``a(t)`` is white acceleration of PSD ``accel_psd`` (the seed's ``lambda * gamma``). The
    speed relaxes towards a white "command" with time constant ``1/sqrt(lambda)``; at
    ``lambda = 0`` the model is exactly the constant-velocity model with the same PSD.
    State per axis: generalised coordinate [m], its rate [m/s].

    Parameters
    ----------
    lambda_per_s2 : float or sequence of float
        Adaptation parameter ``lambda`` [1/s^2], >= 0.
    accel_psd : float or sequence of float
        Acceleration-input spectral density ``q_a`` [m^2/s^3], >= 0.
    n_axes : int
        Number of axes (degrees of freedom), 1-3.

    Examples
    --------
    >>> InverseDynamics(lambda_per_s2=0.03, accel_psd=2.0).state_names
    ('x', 'vx')
    """

    lambda_per_s2: float | Sequence[float] = 0.0
    accel_psd: float | Sequence[float] = 1.0
    n_axes: int = 1
    _prefixes = ("", "v")

    def __post_init__(self) -> None:
        n = _check_axes(self.n_axes)
        object.__setattr__(
            self,
            "lambda_per_s2",
            _per_axis(self.lambda_per_s2, n, "lambda_per_s2", nonnegative=True),
        )
        object.__setattr__(
            self, "accel_psd", _per_axis(self.accel_psd, n, "accel_psd", nonnegative=True)
        )

    @classmethod
    def from_intensity(
        cls, lambda_per_s2: float, intensity_m2ps: float, n_axes: int = 1
    ) -> InverseDynamics:
        """M1 in the seed's parameterisation: input ``w`` of intensity ``gamma`` [m^2/s].

        The acceleration PSD is then ``lambda * gamma`` (spec B.3, option ``gamma_fixed``).
        """
        lam = check_positive_scalar(lambda_per_s2, "lambda_per_s2", allow_zero=True)
        g = check_positive_scalar(intensity_m2ps, "intensity_m2ps", allow_zero=True)
        return cls(lambda_per_s2=lam, accel_psd=lam * g, n_axes=n_axes)

    def _axis_block(self, axis: int) -> Block:
        k = math.sqrt(self.lambda_per_s2[axis])  # type: ignore[index]
        qa = self.accel_psd[axis]  # type: ignore[index]
        return Block(
            np.array([[0.0, 1.0], [0.0, -k]]),
            _e(2, 1),
            np.array([[qa]]),
            *_no_control(2),
            closed_form=lambda dt: _m1_analytic(dt, k, qa),
        )


def _m1_analytic(dt: FloatArray, k: float, qa: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Spec 0.3.2 / B.5: phi forms for ``k dt < 1`` (valid at k = 0), closed forms (77), (78)."""
    y = k * dt
    small = y < 1.0
    ys = np.where(small, y, 0.0)
    p1, p1d, p2 = phi(1, -ys), phi(1, -2 * ys), phi(2, -ys)
    p3, p3d = phi(3, -ys), phi(3, -2 * ys)
    s_p01, s_g0, s_g1 = dt * p1, dt**2 * p2, dt * p1
    s_q00, s_q01, s_q11 = (qa * dt**3 * (4 * p3d - 2 * p3), qa * dt**2 * p1**2 / 2, qa * dt * p1d)
    kl = k if k > 0 else 1.0
    dl = np.where(small, 1.0 / kl, dt)
    rk = np.exp(-kl * dl)
    g = qa / kl**2
    l_p01, l_g0, l_g1 = (1 - rk) / kl, (dl - (1 - rk) / kl) / kl, (1 - rk) / kl
    l_q00 = g * (dl - (1 - rk) * (3 - rk) / (2 * kl))
    l_q01 = g * (1 - rk) ** 2 / 2
    l_q11 = g * kl * (1 - rk**2) / 2
    p01 = np.where(small, s_p01, l_p01)
    one, z = np.ones_like(dt), np.zeros_like(dt)
    phi_ = np.stack([np.stack([one, p01], -1), np.stack([z, np.exp(-y)], -1)], -2)
    q00, q01, q11 = (
        np.where(small, s_q00, l_q00),
        np.where(small, s_q01, l_q01),
        np.where(small, s_q11, l_q11),
    )
    qd = np.stack([np.stack([q00, q01], -1), np.stack([q01, q11], -1)], -2)
    gam = np.stack([np.where(small, s_g0, l_g0), np.where(small, s_g1, l_g1)], -1)
    return phi_, qd, gam[..., None]


@dataclass(frozen=True, eq=False)
class ShapingFilter(_AxisModel):
    """Model M2 of seed 001: M1 driven by exponentially correlated noise (spec B.4).

    Per axis ``q'' = -k q' + c xi``, ``xi' = -alpha xi + w`` with ``k = sqrt(lambda)``,
    ``E[w w] = 2 alpha sigma_M^2`` so that ``xi`` is stationary with RMS ``shaping_std``.
    With ``coupling="sqrt_lambda"`` (default, the seed's matrices) ``c = k`` and ``xi`` is a
    speed [m/s]; with ``coupling="unit"`` (documented deviation) ``c = 1`` and ``xi`` is an
    acceleration [m/s^2]. State per axis: coordinate [m], rate [m/s], ``xi``.

    Parameters
    ----------
    lambda_per_s2 : float or sequence of float
        Adaptation parameter ``lambda`` [1/s^2], >= 0.
    alpha_per_s : float or sequence of float
        Inverse manoeuvre duration ``alpha`` [1/s], > 0.
    shaping_std : float or sequence of float
        Stationary RMS ``sigma_M`` of ``xi`` [m/s, or m/s^2 with unit coupling], >= 0.
    coupling : {"sqrt_lambda", "unit"}
        Coupling of ``xi`` into the acceleration.
    n_axes : int
        Number of axes, 1-3.
    """

    lambda_per_s2: float | Sequence[float] = 0.01
    alpha_per_s: float | Sequence[float] = 1.0 / 3.0
    shaping_std: float | Sequence[float] = 1.0
    coupling: Literal["sqrt_lambda", "unit"] = "sqrt_lambda"
    n_axes: int = 1
    _prefixes = ("", "v", "xi_")

    def __post_init__(self) -> None:
        n = _check_axes(self.n_axes)
        object.__setattr__(
            self,
            "lambda_per_s2",
            _per_axis(self.lambda_per_s2, n, "lambda_per_s2", nonnegative=True),
        )
        object.__setattr__(
            self, "alpha_per_s", _per_axis(self.alpha_per_s, n, "alpha_per_s", positive=True)
        )
        object.__setattr__(
            self, "shaping_std", _per_axis(self.shaping_std, n, "shaping_std", nonnegative=True)
        )
        if self.coupling not in ("sqrt_lambda", "unit"):
            raise ValueError(f"coupling must be 'sqrt_lambda' or 'unit'; got {self.coupling!r}")

    @classmethod
    def from_singer_rule(
        cls,
        lambda_per_s2: float,
        alpha_per_s: float,
        max_accel_mps2: float,
        prob_max_accel: float,
        prob_no_accel: float,
        n_axes: int = 1,
    ) -> ShapingFilter:
        """M2 with ``sigma_M = sigma_a / sqrt(lambda)`` from Singer's rule (spec B.4).

        The acceleration input ``k xi`` then has RMS ``sigma_a``; ``lambda`` must be > 0.
        """
        lam = check_positive_scalar(lambda_per_s2, "lambda_per_s2")
        sa = singer_accel_std(max_accel_mps2, prob_max_accel, prob_no_accel)
        return cls(
            lambda_per_s2=lam,
            alpha_per_s=alpha_per_s,
            shaping_std=sa / math.sqrt(lam),
            n_axes=n_axes,
        )

    def _axis_block(self, axis: int) -> Block:
        k = math.sqrt(self.lambda_per_s2[axis])  # type: ignore[index]
        a = self.alpha_per_s[axis]  # type: ignore[index]
        sm = self.shaping_std[axis]  # type: ignore[index]
        c = k if self.coupling == "sqrt_lambda" else 1.0
        f = np.array([[0.0, 1.0, 0.0], [0.0, -k, c], [0.0, 0.0, -a]])
        return Block(f, _e(3, 2), np.array([[2.0 * a * sm**2]]), *_no_control(3))


__all__ = ["InverseDynamics", "ShapingFilter", "singer_accel_std"]
