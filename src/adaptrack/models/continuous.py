"""Continuous-time linear motion models.

A motion model is a linear SDE ``dx = F x dt + G dbeta + B u dt`` with
``E[dbeta dbeta^T] = Qc dt`` and a known constant input ``u``. Kinematic models are built
per axis and assembled block-diagonally in the state order of CONVENTIONS: all positions,
then all velocities, then all accelerations (``x, y, vx, vy, ax, ay``). Parameters may be
one value for every axis or a sequence with one value per axis.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_square, check_symmetric_pd
from ._layout import Block, assemble, interleave_order
from ._phi import phi

AXIS_NAMES = ("x", "y", "z")


@runtime_checkable
class MotionModel(Protocol):
    """What the discretiser and the filters need of a continuous-time linear motion model."""

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the state components, in state order."""
        ...

    @property
    def state_dim(self) -> int:
        """State size n."""
        ...

    def blocks(self) -> tuple[list[Block], np.ndarray]:
        """Independent blocks and the map from concatenated block states to state order."""
        ...


def _full(model: MotionModel, attr: str, square: bool) -> FloatArray:
    blocks, order = model.blocks()
    return assemble([getattr(b, attr) for b in blocks], order, square=square)


def drift_matrix(model: MotionModel) -> FloatArray:
    """Drift matrix ``F`` (n, n) of a motion model."""
    return _full(model, "drift", square=True)


def noise_input_matrix(model: MotionModel) -> FloatArray:
    """Noise input matrix ``G`` (n, w) of a motion model."""
    return _full(model, "noise_input", square=False)


def noise_psd(model: MotionModel) -> FloatArray:
    """White-noise spectral density matrix ``Qc`` (w, w) of a motion model."""
    blocks, _ = model.blocks()
    return assemble(
        [b.noise_psd for b in blocks],
        np.arange(sum(b.noise_psd.shape[0] for b in blocks)),
        square=True,
    )


def _per_axis(
    value: float | Sequence[float],
    n_axes: int,
    name: str,
    *,
    positive: bool = False,
    nonnegative: bool = False,
) -> tuple[float, ...]:
    arr = as_float_array(value, name)
    if arr.ndim == 0:
        arr = np.full(n_axes, float(arr))
    if arr.shape != (n_axes,):
        raise ValueError(
            f"{name} must be a scalar or have one value per axis, shape ({n_axes},); "
            f"got shape {arr.shape}"
        )
    if positive and np.any(arr <= 0):
        i = int(np.argmax(arr <= 0))
        raise ValueError(f"{name} must be > 0; got {arr[i]} for axis {i}")
    if nonnegative and np.any(arr < 0):
        i = int(np.argmax(arr < 0))
        raise ValueError(f"{name} must be >= 0; got {arr[i]} for axis {i}")
    return tuple(float(v) for v in arr)


def _check_axes(n_axes: int) -> int:
    if isinstance(n_axes, bool) or not isinstance(n_axes, (int, np.integer)):
        raise TypeError(f"n_axes must be an int; got {type(n_axes).__name__}")
    if not 1 <= n_axes <= 3:
        raise ValueError(f"n_axes must be 1, 2 or 3; got {n_axes}")
    return int(n_axes)


def _names(n_axes: int, prefixes: Sequence[str]) -> tuple[str, ...]:
    return tuple(p + a if p else a for p in prefixes for a in AXIS_NAMES[:n_axes])


def _no_control(d: int) -> tuple[FloatArray, FloatArray]:
    return np.zeros((d, 0)), np.zeros(0)


def _e(d: int, i: int) -> FloatArray:
    v = np.zeros((d, 1))
    v[i, 0] = 1.0
    return v


@dataclass(frozen=True, eq=False)
class LinearSDE:
    """A generic continuous linear SDE ``dx = F x dt + G dbeta + B u dt``.

    Parameters
    ----------
    drift : array_like, shape (n, n)
        ``F`` [1/s].
    noise_input : array_like, shape (n, w)
        ``G``.
    noise_psd : array_like, shape (w, w)
        ``Qc``, symmetric positive semi-definite spectral density.
    state_names : sequence of str, length n
        Names of the state components.
    control_input : array_like, shape (n, c), optional
        ``B``.
    control : array_like, shape (c,), optional
        Known constant input ``u``.
    """

    drift: FloatArray
    noise_input: FloatArray
    noise_psd: FloatArray
    state_names: tuple[str, ...]
    control_input: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    control: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        f = as_float_array(self.drift, "drift", min_ndim=2)
        n = check_square(f, "drift")
        if f.ndim != 2:
            raise ValueError(f"drift must have shape (n, n); got {f.shape}")
        g = as_float_array(self.noise_input, "noise_input", min_ndim=2)
        if g.ndim != 2 or g.shape[0] != n:
            raise ValueError(f"noise_input must have shape ({n}, w) to match drift; got {g.shape}")
        q = as_float_array(self.noise_psd, "noise_psd", min_ndim=2)
        if q.shape != (g.shape[1], g.shape[1]):
            raise ValueError(
                f"noise_psd must have shape ({g.shape[1]}, {g.shape[1]}) to match noise_input; "
                f"got {q.shape}"
            )
        check_symmetric_pd(q, "noise_psd", semidefinite=True)
        b = as_float_array(self.control_input, "control_input", min_ndim=2)
        if b.size == 0:
            b = np.zeros((n, 0))
        u = as_float_array(self.control, "control", min_ndim=1)
        if b.shape != (n, u.shape[0]):
            raise ValueError(
                f"control_input must have shape ({n}, {u.shape[0]}) to match drift and control; "
                f"got {b.shape}"
            )
        names = tuple(self.state_names)
        if len(names) != n:
            raise ValueError(f"state_names must have {n} entries; got {len(names)}")
        for k, v in (
            ("drift", f),
            ("noise_input", g),
            ("noise_psd", q),
            ("control_input", b),
            ("control", u),
        ):
            v = v.copy()
            v.flags.writeable = False
            object.__setattr__(self, k, v)
        object.__setattr__(self, "state_names", names)

    @property
    def state_dim(self) -> int:
        """State size n."""
        return int(self.drift.shape[0])

    def blocks(self) -> tuple[list[Block], np.ndarray]:
        """One block holding the whole model."""
        return [
            Block(self.drift, self.noise_input, self.noise_psd, self.control_input, self.control)
        ], np.arange(self.state_dim)


class _AxisModel:
    """Shared behaviour of the per-axis kinematic models (state order per CONVENTIONS)."""

    n_axes: int
    _prefixes: tuple[str, ...]

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names: positions, then velocities, then higher derivatives, per axis."""
        return _names(self.n_axes, self._prefixes)

    @property
    def state_dim(self) -> int:
        """State size n = derivatives x axes."""
        return len(self._prefixes) * self.n_axes

    def _axis_block(self, axis: int) -> Block:
        raise NotImplementedError

    def blocks(self) -> tuple[list[Block], np.ndarray]:
        """Per-axis blocks and the interleaving map to state order."""
        blocks = [self._axis_block(a) for a in range(self.n_axes)]
        return blocks, interleave_order(self.n_axes, len(self._prefixes))


@dataclass(frozen=True, eq=False)
class ConstantVelocity(_AxisModel):
    """Nearly-constant-velocity model: white acceleration of PSD ``accel_psd`` per axis.

    State (per axis ``x``): position [m], velocity [m/s]; for several axes
    ``x, y, vx, vy`` etc.

    Parameters
    ----------
    accel_psd : float or sequence of float
        White-acceleration spectral density ``q`` [m^2/s^3], >= 0.
    n_axes : int
        Number of axes, 1-3.

    Examples
    --------
    >>> ConstantVelocity(accel_psd=0.5, n_axes=2).state_names
    ('x', 'y', 'vx', 'vy')
    """

    accel_psd: float | Sequence[float] = 1.0
    n_axes: int = 1
    _prefixes = ("", "v")

    def __post_init__(self) -> None:
        n = _check_axes(self.n_axes)
        object.__setattr__(
            self, "accel_psd", _per_axis(self.accel_psd, n, "accel_psd", nonnegative=True)
        )

    def _axis_block(self, axis: int) -> Block:
        q = self.accel_psd[axis]  # type: ignore[index]

        def closed(dt: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            one, z = np.ones_like(dt), np.zeros_like(dt)
            phi_ = np.stack([np.stack([one, dt], -1), np.stack([z, one], -1)], -2)
            qd = q * np.stack(
                [np.stack([dt**3 / 3, dt**2 / 2], -1), np.stack([dt**2 / 2, dt], -1)], -2
            )
            gam = np.stack([dt**2 / 2, dt], -1)[..., None]
            return phi_, qd, gam

        return Block(
            np.array([[0.0, 1.0], [0.0, 0.0]]),
            _e(2, 1),
            np.array([[q]]),
            *_no_control(2),
            closed_form=closed,
        )


@dataclass(frozen=True, eq=False)
class ConstantAcceleration(_AxisModel):
    """Nearly-constant-acceleration model: white jerk of PSD ``jerk_psd`` per axis.

    State per axis: position [m], velocity [m/s], acceleration [m/s^2].

    Parameters
    ----------
    jerk_psd : float or sequence of float
        White-jerk spectral density [m^2/s^5], >= 0.
    n_axes : int
        Number of axes, 1-3.
    """

    jerk_psd: float | Sequence[float] = 1.0
    n_axes: int = 1
    _prefixes = ("", "v", "a")

    def __post_init__(self) -> None:
        n = _check_axes(self.n_axes)
        object.__setattr__(
            self, "jerk_psd", _per_axis(self.jerk_psd, n, "jerk_psd", nonnegative=True)
        )

    def _axis_block(self, axis: int) -> Block:
        q = self.jerk_psd[axis]  # type: ignore[index]

        def closed(dt: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            one, z = np.ones_like(dt), np.zeros_like(dt)
            phi_ = np.stack(
                [
                    np.stack([one, dt, dt**2 / 2], -1),
                    np.stack([z, one, dt], -1),
                    np.stack([z, z, one], -1),
                ],
                -2,
            )
            qd = q * np.stack(
                [
                    np.stack([dt**5 / 20, dt**4 / 8, dt**3 / 6], -1),
                    np.stack([dt**4 / 8, dt**3 / 3, dt**2 / 2], -1),
                    np.stack([dt**3 / 6, dt**2 / 2, dt], -1),
                ],
                -2,
            )
            gam = np.stack([dt**3 / 6, dt**2 / 2, dt], -1)[..., None]
            return phi_, qd, gam

        f = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
        return Block(f, _e(3, 2), np.array([[q]]), *_no_control(3), closed_form=closed)


@dataclass(frozen=True, eq=False)
class Singer(_AxisModel):
    """Singer model: acceleration is a first-order Gauss-Markov process (spec A.3).

    ``dw/dt = -(w - m_w)/tau + n(t)``, ``dv/dt = w``, ``dr/dt = v`` with
    ``E[n(t) n(s)] = (2 sigma^2 / tau) delta(t - s)``, so the stationary acceleration variance
    is ``accel_std_mps2**2``. State per axis: position [m], velocity [m/s], acceleration
    [m/s^2]. Seed 000 writes the state as ``[w, v, r]``: ``z_seed = P z`` with
    ``P = seed000_permutation()`` (reversal).

    Parameters
    ----------
    time_constant_s : float or sequence of float
        Correlation time ``tau`` of the acceleration [s], > 0.
    accel_std_mps2 : float or sequence of float
        Stationary RMS acceleration ``sigma`` [m/s^2], >= 0.
    mean_accel_mps2 : float or sequence of float
        Known mean acceleration ``m_w`` [m/s^2] (a known input; default 0).
    n_axes : int
        Number of axes, 1-3.

    Examples
    --------
    >>> m = Singer(time_constant_s=5.0, accel_std_mps2=2.0)
    >>> m.state_names
    ('x', 'vx', 'ax')
    """

    time_constant_s: float | Sequence[float] = 20.0
    accel_std_mps2: float | Sequence[float] = 1.0
    mean_accel_mps2: float | Sequence[float] = 0.0
    n_axes: int = 1
    _prefixes = ("", "v", "a")

    def __post_init__(self) -> None:
        n = _check_axes(self.n_axes)
        object.__setattr__(
            self,
            "time_constant_s",
            _per_axis(self.time_constant_s, n, "time_constant_s", positive=True),
        )
        object.__setattr__(
            self,
            "accel_std_mps2",
            _per_axis(self.accel_std_mps2, n, "accel_std_mps2", nonnegative=True),
        )
        object.__setattr__(
            self, "mean_accel_mps2", _per_axis(self.mean_accel_mps2, n, "mean_accel_mps2")
        )

    def _axis_block(self, axis: int) -> Block:
        tau = self.time_constant_s[axis]  # type: ignore[index]
        sw = self.accel_std_mps2[axis]  # type: ignore[index]
        mw = self.mean_accel_mps2[axis]  # type: ignore[index]
        qc = 2.0 * sw**2 / tau
        f = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0 / tau]])
        g = _e(3, 2)
        return Block(
            f,
            g,
            np.array([[qc]]),
            g / tau,
            np.array([mw]),
            closed_form=lambda dt: _singer_analytic(dt, tau, sw),
            source_form=lambda dt: _singer_source(dt, tau, sw),
        )


def _singer_analytic(
    dt: FloatArray, tau: float, sw: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Spec 0.3.2 / A.4 in adaptrack order [r, v, w]: phi forms for x < 1, closed forms else.

    Returns Phi, Qd (white) and Gamma of [G, B] = [e_w, e_w / tau].
    """
    x = dt / tau
    qc = 2.0 * sw**2 / tau
    small = x < 1.0
    # phi forms (evaluated on x clipped into their domain)
    xs = np.where(small, x, 0.0)
    p1, p1d, p2 = phi(1, -xs), phi(1, -2 * xs), phi(2, -xs)
    p3, p3d, p4, p5d = phi(3, -xs), phi(3, -2 * xs), phi(4, -xs), phi(5, -2 * xs)
    # seed order [w, v, r]
    ph_s = {"vw": dt * p1, "rw": dt**2 * p2}
    q_s = {
        "ww": dt * p1d,
        "wv": dt**2 * p1**2 / 2,
        "wr": dt**3 * (4 * p3d - p2),
        "vv": dt**3 * (4 * p3d - 2 * p3),
        "vr": dt**4 * p2**2 / 2,
        "rr": dt**5 * (16 * p5d - 2 * p4),
    }
    q_s = {k: qc * v for k, v in q_s.items()}
    g_s = {"w": dt * p1, "v": dt**2 * p2, "r": dt**3 * p3}
    # closed forms (x >= 1), evaluated with x clipped to >= 1
    t = tau
    dl = np.where(small, t, dt)
    rho = np.exp(-dl / t)
    s2 = sw**2
    ph_l = {"vw": t * (1 - rho), "rw": t * dl - t**2 * (1 - rho)}
    q_l = {
        "ww": s2 * (1 - rho**2),
        "wv": s2 * t * (1 - rho) ** 2,
        "wr": s2 * t * (t * (1 - rho**2) - 2 * dl * rho),
        "vv": s2 * t * (2 * dl - 3 * t + 4 * t * rho - t * rho**2),
        "vr": s2 * t * (dl - t + t * rho) ** 2,
        "rr": s2
        * t
        * (
            2 * dl**3 / 3
            - 2 * dl**2 * t
            + 2 * dl * t**2
            + t**3
            - 4 * dl * t**2 * rho
            - t**3 * rho**2
        ),
    }
    g_l = {
        "w": t * (1 - rho),
        "v": t * dl - t**2 * (1 - rho),
        "r": t * dl**2 / 2 - t**2 * dl + t**3 * (1 - rho),
    }

    def pick(
        key: str, small_d: Mapping[str, FloatArray], large_d: Mapping[str, FloatArray]
    ) -> FloatArray:
        return np.where(small, small_d[key], large_d[key])

    one, z = np.ones_like(dt), np.zeros_like(dt)
    vw, rw = pick("vw", ph_s, ph_l), pick("rw", ph_s, ph_l)
    ew = np.exp(-x)
    # adaptrack order [r, v, w]
    phi_ = np.stack(
        [np.stack([one, dt, rw], -1), np.stack([z, one, vw], -1), np.stack([z, z, ew], -1)], -2
    )
    q = {k: pick(k, q_s, q_l) for k in q_s}
    qd = np.stack(
        [
            np.stack([q["rr"], q["vr"], q["wr"]], -1),
            np.stack([q["vr"], q["vv"], q["wv"]], -1),
            np.stack([q["wr"], q["wv"], q["ww"]], -1),
        ],
        -2,
    )
    gam = np.stack([pick("r", g_s, g_l), pick("v", g_s, g_l), pick("w", g_s, g_l)], -1)
    return phi_, qd, np.stack([gam, gam / tau], -1)


def _singer_source(
    dt: FloatArray, tau: float, sw: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Seed 000's printed Euler-type form (4), (5), in adaptrack order [r, v, w] (spec A.4)."""
    rho = np.exp(-dt / tau)
    one, z = np.ones_like(dt), np.zeros_like(dt)
    phi_ = np.stack(
        [np.stack([one, dt, z], -1), np.stack([z, one, dt], -1), np.stack([z, z, rho], -1)], -2
    )
    qd = np.zeros(dt.shape + (3, 3))
    qd[..., 2, 2] = sw**2 * (1 - rho**2)
    return phi_, qd, np.zeros(dt.shape + (3, 2))


def seed000_permutation() -> FloatArray:
    """Permutation ``P`` with ``[w, v, r] = P [r, v, w]`` (seed 000 order vs adaptrack order).

    ``Phi_seed = P Phi P^T``, ``Qd_seed = P Qd P^T``, ``C_seed = C P^T``; ``P`` is its own
    inverse.
    """
    return np.fliplr(np.eye(3))


def measurement_matrix(model: MotionModel, components: Sequence[str]) -> FloatArray:
    """``H`` (m, n) measuring the named state components of ``model``, one row each.

    Names are the model's :attr:`~MotionModel.state_names` (``x, y, vx, vy`` for a
    two-axis constant-velocity model). Every filter that takes a model accepts the names
    in place of ``H``.

    >>> measurement_matrix(ConstantVelocity(n_axes=2), ["x", "y"])
    array([[1., 0., 0., 0.],
           [0., 1., 0., 0.]])
    """
    names = tuple(model.state_names)
    wanted = list(components)
    unknown = [c for c in wanted if c not in names]
    if unknown or not wanted:
        raise ValueError(
            f"measurement_matrix: unknown state component(s) {unknown or wanted}; "
            f"{type(model).__name__} has {list(names)}"
        )
    h = np.zeros((len(wanted), len(names)))
    for i, c in enumerate(wanted):
        h[i, names.index(c)] = 1.0
    return h


def named_measurement_matrix(h: ArrayLike, model: MotionModel) -> ArrayLike:
    """``h`` unchanged, or :func:`measurement_matrix` of it if it is a sequence of names."""
    if isinstance(h, list | tuple) and h and all(isinstance(c, str) for c in h):
        return measurement_matrix(model, h)
    return h


def filterpy_order(model: MotionModel) -> np.ndarray:
    """Permutation ``p`` from FilterPy's state layout to adaptrack's: ``x = x_filterpy[p]``.

    FilterPy's models (``Q_discrete_white_noise(block_size=...)``, ``kinematic_kf``) list each
    axis's derivatives together (``x, vx, y, vy``); adaptrack lists all positions first
    (``x, y, vx, vy``). Then ``H = H_filterpy[:, p]``, ``P = P_filterpy[np.ix_(p, p)]``,
    ``F = F_filterpy[np.ix_(p, p)]``; the inverse is ``np.argsort(p)``.

    >>> filterpy_order(ConstantVelocity(n_axes=2))
    array([0, 2, 1, 3])
    """
    _, order = model.blocks()  # per-block (FilterPy) index -> model index
    p = np.empty_like(order)
    p[order] = np.arange(order.size)
    return p


def as_motion_model(model: object, name: str = "model") -> MotionModel:
    """Check that ``model`` implements :class:`MotionModel` (TypeError otherwise)."""
    if not isinstance(model, MotionModel):
        raise TypeError(
            f"{name} must be a motion model (e.g. adaptrack.models.Singer); got "
            f"{type(model).__name__}"
        )
    return model


__all__ = [
    "ConstantAcceleration",
    "ConstantVelocity",
    "LinearSDE",
    "MotionModel",
    "Singer",
    "drift_matrix",
    "filterpy_order",
    "measurement_matrix",
    "noise_input_matrix",
    "noise_psd",
    "seed000_permutation",
]
