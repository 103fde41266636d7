"""Online Kalman filter for measurement streams: one compiled step per measurement.

:class:`OnlineFilter` keeps its state, the model matrices and all scratch space in one
preallocated buffer and runs the same predict + Joseph update as the batch kernel
(:func:`adaptrack.filters._kernels.kf_step`), so a stream filtered step by step gives the
numbers of :func:`adaptrack.kalman_filter` to rounding. Transitions are cached by step length:
regular sampling discretises once; every new ``dt`` costs one discretisation. Step lengths
within 1 ns of a cached one share it (clock round-off, e.g. ``0.15 - 0.1 != 0.05``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_symmetric_pd
from ..models.continuous import MotionModel, as_motion_model
from ..models.discretize import Method, Noise, discretize_with_input
from ..types import GaussianState, as_gaussian_state
from ._codegen import DT_TOLERANCE_S, GENERATED_MAX_STATES, online_kernel
from ._kernels import _LOG_2PI, kf_step
from .kalman import CovarianceError, UpdateForm, _check_form

_HEADER = 7  # n, m, Joseph form (0/1), nis, log-likelihood, observed components, time
_TIME = 6


def _offsets(n: int, m: int) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Offset and shape of every block of the work buffer."""
    shapes = {
        "x": (n,),
        "p": (n, n),
        "h": (m, n),
        "r": (m, m),
        "off": (m,),
        "xp": (n,),
        "pp": (n, n),
        "tmp": (n, n),
        "hm": (m, n),
        "rm": (m, m),
        "hp": (m, n),
        "s": (m, m),
        "lo": (m, m),
        "kt": (m, n),
        "nu": (m,),
        "w": (m,),
        "ikh": (n, n),
    }
    out, pos = {}, _HEADER
    for name, shape in shapes.items():
        out[name] = (pos, shape)
        pos += math.prod(shape)
    out["end"] = (pos, ())
    return out


@numba.njit(cache=True, inline="always")
def _view(ws, pos, rows, cols):  # type: ignore[no-untyped-def]
    return ws[pos : pos + rows * cols].reshape((rows, cols))


@numba.njit(cache=True)
def _online_step_masked(ws, trans, z, mask):  # type: ignore[no-untyped-def]
    """Advance the filter in ``ws`` by ``trans`` and update where ``mask`` is True.

    ``trans`` = [Phi, Qd, u] flattened; any update form (the generic path).

    Returns 0, 1 (a present component of ``z`` is not finite; nothing changed) or 2 (the
    innovation covariance is not positive definite; nothing changed).
    """
    n = int(ws[0])
    m = int(ws[1])
    joseph = ws[2] != 0.0
    for a in range(m):
        if mask[a] and not math.isfinite(z[a]):
            return 1
    nn, mn, mm = n * n, m * n, m * m
    pos = _HEADER
    x = ws[pos : pos + n]
    pos += n
    p = _view(ws, pos, n, n)
    pos += nn
    h = _view(ws, pos, m, n)
    pos += mn
    r = _view(ws, pos, m, m)
    pos += mm
    off = ws[pos : pos + m]
    pos += m
    xp = ws[pos : pos + n]
    pos += n
    pp = _view(ws, pos, n, n)
    pos += nn
    tmp = _view(ws, pos, n, n)
    pos += nn
    hm = _view(ws, pos, m, n)
    pos += mn
    rm = _view(ws, pos, m, m)
    pos += mm
    hp = _view(ws, pos, m, n)
    pos += mn
    s = _view(ws, pos, m, m)
    pos += mm
    lo = _view(ws, pos, m, m)
    pos += mm
    kt = _view(ws, pos, m, n)
    pos += mn
    nu = ws[pos : pos + m]
    pos += m
    w = ws[pos : pos + m]
    pos += m
    ikh = _view(ws, pos, n, n)
    phi = trans[:nn].reshape((n, n))
    qd = trans[nn : 2 * nn].reshape((n, n))
    u = trans[2 * nn : 2 * nn + n]
    ok, nis, logdet, nobs = kf_step(
        x, p, phi, qd, u, z, mask, h, r, off, joseph, xp, pp, tmp, hm, rm, hp, s, lo, kt, nu, w, ikh
    )
    if not ok:
        return 2
    ws[3] = nis
    ws[4] = -0.5 * (logdet + nis + nobs * _LOG_2PI) if nobs > 0 else 0.0
    ws[5] = nobs
    return 0


class OnlineFilter:
    """Kalman filter fed one measurement at a time (streams, live radar).

    Every component present, the Joseph form and up to 6 states run a kernel generated for the
    (n, m) at hand (under a microsecond per call from Python); a ``mask``,
    ``form="standard"`` or larger states use the generic compiled step (a few microseconds).
    Both give the numbers of :func:`adaptrack.kalman_filter` to rounding.

    Parameters
    ----------
    model : MotionModel
        Continuous motion model, discretised per step length (cached).
    measurement_matrix, measurement_cov : array_like
        ``H`` (m, n) and ``R`` (m, m), symmetric positive definite.
    initial : GaussianState
        Prior of one track: mean (n,), covariance (n, n), time [s].
    method, noise, order, form
        As in :func:`adaptrack.kalman_filter`.
    measurement_noise_mean : array_like, shape (m,), optional
        Known mean of the measurement noise.
    cache_size : int
        Distinct step lengths whose transitions are kept (oldest replaced first).

    Examples
    --------
    >>> import adaptrack as at
    >>> f = OnlineFilter(at.models.ConstantVelocity(accel_psd=0.1), [[1.0, 0.0]], [[0.5]],
    ...                  at.GaussianState([0.0, 0.0], [[10.0, 0.0], [0.0, 10.0]], time=0.0))
    >>> nis = f.update(0.1, [0.3])
    >>> f.mean.shape, f.time
    ((2,), 0.1)
    """

    def __init__(
        self,
        model: MotionModel,
        measurement_matrix: ArrayLike,
        measurement_cov: ArrayLike,
        initial: GaussianState,
        *,
        method: Method = "expm",
        noise: Noise = "white",
        order: int = 2,
        form: UpdateForm = "joseph",
        measurement_noise_mean: ArrayLike | None = None,
        cache_size: int = 16,
    ) -> None:
        self.model = as_motion_model(model)
        initial = as_gaussian_state(initial, "initial")
        n = self.model.state_dim
        h = as_float_array(measurement_matrix, "measurement_matrix", min_ndim=2)
        if h.ndim != 2 or h.shape[1] != n:
            raise ValueError(f"measurement_matrix must have shape (m, {n}); got {h.shape}")
        m = h.shape[0]
        r = as_float_array(measurement_cov, "measurement_cov", min_ndim=2)
        if r.shape != (m, m):
            raise ValueError(f"measurement_cov must have shape ({m}, {m}); got {r.shape}")
        check_symmetric_pd(r, "measurement_cov")
        if initial.mean.shape != (n,):
            raise ValueError(
                f"initial must be one track with mean ({n},); got {initial.mean.shape}"
            )
        check_symmetric_pd(initial.cov, "initial.cov", semidefinite=True)
        if cache_size < 1:
            raise ValueError(f"cache_size must be >= 1; got {cache_size}")
        joseph = _check_form(form) == "joseph"
        self._discretization = (method, noise, order)
        self._bank = np.full((int(cache_size), 1 + 2 * n * n + n), np.nan)  # [dt, Phi, Qd, u]
        self._next_row = 0
        self._layout = _offsets(n, m)
        self._ws = np.zeros(self._layout["end"][0])
        self._ws[0], self._ws[1], self._ws[2] = n, m, 1.0 if joseph else 0.0
        self._ws[_TIME] = float(initial.time)
        self._block("x")[:] = initial.mean
        self._block("p")[:] = initial.cov
        self._block("h")[:] = h
        self._block("r")[:] = r
        if measurement_noise_mean is not None:
            self._block("off")[:] = as_float_array(measurement_noise_mean, "measurement_noise_mean")
        self._m = m
        self._fast = None
        if joseph and n <= GENERATED_MAX_STATES:
            at = self._layout
            offsets = (_TIME, at["x"][0], at["p"][0], at["h"][0], at["r"][0], at["off"][0])
            self._fast = online_kernel(n, m, offsets)

    def _block(self, name: str) -> FloatArray:
        pos, shape = self._layout[name]
        return self._ws[pos : pos + math.prod(shape)].reshape(shape)

    def _row(self, dt: float) -> int:
        """Row of the transition bank holding step ``dt`` (discretised on first use)."""
        hit = np.flatnonzero(np.abs(self._bank[:, 0] - dt) <= DT_TOLERANCE_S)
        if hit.size:
            return int(hit[0])
        method, noise, order = self._discretization
        phi, qd, u = discretize_with_input(self.model, dt, method, noise=noise, order=order)
        row = self._next_row
        self._bank[row] = np.concatenate([[dt], phi.ravel(), qd.ravel(), u.ravel()])
        self._next_row = (row + 1) % self._bank.shape[0]
        return row

    def update(self, time: float, measurement: ArrayLike, mask: ArrayLike | None = None) -> float:
        """Predict to ``time`` [s] (>= the filter time) and update with ``measurement`` (m,).

        ``mask`` (m,) bool marks present components (default all). Returns the NIS.

        Raises
        ------
        ValueError
            For a time before the filter's (out-of-order stream), a wrong shape, or a present
            component that is NaN/inf; the filter is left unchanged, so nothing is lost.
        CovarianceError
            If the innovation covariance is not positive definite (filter unchanged).
        """
        z = measurement if type(measurement) is np.ndarray else np.asarray(measurement, float)
        if mask is None and self._fast is not None:
            status = self._fast(self._ws, self._bank, time, z)
            if status == 0:
                return self._ws[3]
            if status != 3:  # 3: a step length not in the bank yet
                self._raise(status, time, z)
        return self._update_slow(float(time), np.asarray(z, dtype=np.float64), mask)

    def _update_slow(self, t: float, z: FloatArray, mask: ArrayLike | None) -> float:
        dt = t - self._ws[_TIME]
        if not (dt >= 0.0 and math.isfinite(t)):
            self._raise(5, t, z)
        if z.shape != (self._m,):
            self._raise(4, t, z)
        present = np.ones(self._m, dtype=np.bool_) if mask is None else np.asarray(mask)
        if present.shape != (self._m,) or present.dtype != np.bool_:
            raise ValueError(f"mask must be boolean of shape ({self._m},); got {present.shape}")
        row = self._row(dt)
        status = _online_step_masked(self._ws, self._bank[row, 1:], z, present)
        if status:
            self._raise(status, t, z)
        self._ws[_TIME] = t
        return float(self._ws[3])

    def _raise(self, status: int, time: float, z: FloatArray) -> None:
        if status == 1:
            raise ValueError(f"measurement at t = {time} s is not finite where present: {z}")
        if status == 2:
            raise CovarianceError(
                f"innovation covariance is not positive definite at t = {time} s; check the "
                "model, measurement_cov and the state"
            )
        if status == 4:
            raise ValueError(f"measurement must have shape ({self._m},); got {np.shape(z)}")
        raise ValueError(
            f"time must be finite and not before the filter time {self._ws[_TIME]} s "
            f"(out-of-order stream?); got {time}"
        )

    @property
    def time(self) -> float:
        """Time [s] of the current estimate."""
        return float(self._ws[_TIME])

    @property
    def mean(self) -> FloatArray:
        """Filtered mean (n,) (a copy)."""
        return self._block("x").copy()

    @property
    def cov(self) -> FloatArray:
        """Filtered covariance (n, n) (a copy)."""
        return self._block("p").copy()

    @property
    def state(self) -> GaussianState:
        """The current belief."""
        return GaussianState(self.mean, self.cov, np.float64(self.time))

    @property
    def log_likelihood(self) -> float:
        """Log-likelihood of the last measurement."""
        return float(self._ws[4])


__all__ = ["OnlineFilter"]
