"""Online Kalman filter for measurement streams: one compiled step per measurement.

:class:`OnlineFilter` keeps its state, the model matrices and all scratch space in one
preallocated buffer and runs the same predict + Joseph update as the batch kernel
(:func:`adaptrack.filters._kernels.kf_step`), so a stream filtered step by step gives the
numbers of :func:`adaptrack.kalman_filter` to rounding. Like it, the default ``form="auto"``
continues in square-root form (:func:`adaptrack.filters._sqrt_kernel.sqrt_step`) from the first
step where the Joseph form would lose digits. Transitions are cached by step length
(steps equal to a cached one within 4 units in the last place of the time stamp share it: clock
round-off, e.g. ``0.15 - 0.1 != 0.05``). For
the exact methods a new step length is discretised inside the compiled step from a series table
(:mod:`adaptrack.models.series_table`), so a jittered stream costs about a microsecond per
update too; other methods discretise it in NumPy.
"""

from __future__ import annotations

import math
import numbers
from typing import NamedTuple

import numpy as np

from .._typing import ArrayLike, BoolArray, FloatArray
from .._validation import as_float_array, check_symmetric_pd
from ..models.continuous import MotionModel, as_motion_model, named_measurement_matrix
from ..models.discretize import Method, Noise, discretize_with_input
from ..models.series_table import SeriesTable, model_series_table
from ..types import GaussianState, as_gaussian_state
from ._codegen import (
    GENERATED_MAX_STATES,
    STEP_MATCH_REL,
    WS_H_MAX,
    WS_NEXT_ROW,
    WS_TRACE_LIMIT,
    online_kernel,
    online_run_kernel,
)
from ._kernels import _LOG_2PI, kf_step, series_bank_row
from ._sqrt_kernel import lower_factor_into, outer_into, sqrt_step
from .kalman import JOSEPH_MAX_RATIO, CovarianceError, exceeds_joseph_limit, joseph_scaling
from .run import FilterForm
from .square_root import lower_factor

# header: n, m, Joseph form (0/1), nis, log-likelihood, observed components, time, next bank
# row, series table h_max, Joseph limit of sum_a S_aa / R_aa
_HEADER = 10
_TIME = 6
_SERIES_BLOCKS = ("series_phi", "series_qd", "series_off")


def _offsets(
    n: int, m: int, bank_rows: int, series: SeriesTable | None
) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Offset and shape of every block of the work buffer (the series table's last)."""
    shapes: dict[str, tuple[int, ...]] = {
        "bank": (bank_rows, 1 + 2 * n * n + n),  # transitions by step: [dt, Phi, Qd, u]
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
        # square-root form: factor of P, pre-arrays, factor of Qd and its scratch, gain
        "fac": (n, n),
        "pre1": (n, 2 * n),
        "pre2": (m + n, m + n),
        "sq": (n, n),
        "sq_tmp": (n, n),
        "sr": (m, m),
        "gain": (n, m),
    }
    if series is not None:
        for name, coef in zip(_SERIES_BLOCKS, series[:3], strict=True):
            shapes[name] = coef.shape
    out, pos = {}, _HEADER
    for name, shape in shapes.items():
        out[name] = (pos, shape)
        pos += math.prod(shape)
    out["end"] = (pos, ())
    return out


def _time(value: object) -> float:
    """Return a measurement time [s] as float: a real scalar (Python, NumPy or 0-d array)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.ndarray)):
        raise TypeError(f"time must be a real number [s]; got {type(value).__name__}")
    arr = np.asarray(value)
    if arr.ndim != 0 or not np.isrealobj(arr):
        raise TypeError(f"time must be a real scalar [s]; got an array of shape {arr.shape}")
    return float(arr)


def _measurement(value: ArrayLike) -> FloatArray:
    """Return a measurement as a float array (its shape is checked by the step)."""
    return as_float_array(value, "measurement", allow_nan=True)


class StreamEstimates(NamedTuple):
    """Per-measurement results of :meth:`OnlineFilter.update_many`.

    ``mean`` (T, n) and ``variance`` (T, n) (the covariance diagonal) after each update,
    ``nis`` (T,) the normalised innovation squared of each measurement.
    """

    mean: FloatArray
    variance: FloatArray
    nis: FloatArray


class OnlineFilter:
    """Kalman filter fed one measurement at a time (streams, live radar).

    Every component present, the Joseph form and up to 6 states run a kernel generated for the
    (n, m) at hand (under a microsecond per call from Python); a ``mask``,
    ``form="standard"`` or larger states use the generic compiled step (a few microseconds).
    Both give the numbers of :func:`adaptrack.kalman_filter` to rounding. The square-root form
    (``form="sqrt"``, and ``"auto"`` from the first step whose
    :func:`~adaptrack.filters.kalman.joseph_ratio` exceeds ``JOSEPH_MAX_RATIO``: a long gap, a
    vast prior, an ill-conditioned ``R``) runs a compiled step from Python (several microseconds).

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
        form: FilterForm = "auto",
        measurement_noise_mean: ArrayLike | None = None,
        cache_size: int = 16,
    ) -> None:
        self.model = as_motion_model(model)
        measurement_matrix = named_measurement_matrix(measurement_matrix, self.model)
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
        if form not in ("auto", "joseph", "standard", "sqrt"):
            raise ValueError(f"form must be 'auto', 'joseph', 'standard' or 'sqrt'; got {form!r}")
        joseph = form != "standard"
        self._discretization = (method, noise, order)
        # exact white-noise discretisation of a new step length in microseconds (a jittered
        # stream meets one per update) instead of a matrix exponential in NumPy
        exact = method in ("expm", "analytic", "auto") and noise == "white"
        series = model_series_table(self.model) if exact else None
        self._layout = _offsets(n, m, int(cache_size), series)
        self._ws = np.zeros(self._layout["end"][0])
        self._bank = self._block("bank")
        self._bank[:] = np.nan
        self._series = None
        if series is not None:
            self._ws[WS_H_MAX] = series.h_max
            self._series = tuple(self._block(name) for name in _SERIES_BLOCKS)
            for block, coef in zip(self._series, series[:3], strict=True):
                block[:] = coef
        self._ws[0], self._ws[1], self._ws[2] = n, m, 1.0 if joseph else 0.0
        # auto: Joseph while joseph_ratio(S, R) <= JOSEPH_MAX_RATIO, then square root
        limit = JOSEPH_MAX_RATIO * joseph_scaling(r)[1] if form == "auto" else np.inf
        self._ws[WS_TRACE_LIMIT] = limit
        self._ws[_TIME] = float(initial.time)
        self._block("x")[:] = initial.mean
        self._block("p")[:] = initial.cov
        self._block("h")[:] = h
        self._block("r")[:] = r
        if measurement_noise_mean is not None:
            self._block("off")[:] = as_float_array(measurement_noise_mean, "measurement_noise_mean")
        self._m = m
        self._blocks = {name: self._block(name) for name in self._layout if name != "end"}
        self._fast = self._fast_run = None
        self._sqrt, self._auto = False, form == "auto"
        if form == "sqrt" or (form == "auto" and exceeds_joseph_limit(r, r)):
            self._to_sqrt()
        elif joseph and n <= GENERATED_MAX_STATES:
            at = self._layout
            offsets = (_TIME, at["x"][0], at["p"][0], at["h"][0], at["r"][0], at["off"][0])
            table = (
                None
                if series is None
                else tuple(v for name in _SERIES_BLOCKS for v in (at[name][0], at[name][1][0]))
            )
            bank = (at["bank"][0], int(cache_size))
            self._fast = online_kernel(n, m, offsets, table, bank)
            self._fast_run = online_run_kernel(n, m, offsets, table, bank)

    def _to_sqrt(self) -> None:
        """Continue in square-root form from the current state (for the rest of the stream)."""
        self._sqrt = True
        self._fast = self._fast_run = None
        self._blocks["fac"][:] = lower_factor(self._blocks["p"])

    def _block(self, name: str) -> FloatArray:
        pos, shape = self._layout[name]
        return self._ws[pos : pos + math.prod(shape)].reshape(shape)

    def _row(self, dt: float, t: float) -> int:
        """Bank row holding step ``dt`` to time ``t`` (discretised on first use)."""
        hit = np.flatnonzero(np.abs(self._bank[:, 0] - dt) <= STEP_MATCH_REL * abs(t))
        if hit.size:
            return int(hit[0])
        row = int(self._ws[WS_NEXT_ROW])
        self._ws[WS_NEXT_ROW] = (row + 1) % self._bank.shape[0]
        if self._series is not None:
            phi_coef, qd_coef, off_coef = self._series
            series_bank_row(self._bank, row, dt, phi_coef, qd_coef, off_coef, self._ws[WS_H_MAX])
        else:
            method, noise, order = self._discretization
            phi, qd, u = discretize_with_input(self.model, dt, method, noise=noise, order=order)
            self._bank[row] = np.concatenate([[dt], phi.ravel(), qd.ravel(), u.ravel()])
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
        if type(time) is not float:  # the compiled step takes a float (a one-line check)
            time = _time(time)
        z = measurement if type(measurement) is np.ndarray else _measurement(measurement)
        if mask is None and self._fast is not None:
            nis = self._fast(self._ws, time, z)
            if nis >= 0.0:
                return nis
            if nis == -6.0 or (nis == -2.0 and self._auto):  # Joseph loses digits / fails
                self._to_sqrt()
            elif nis != -3.0:  # -3: a step length not in the bank yet (no series table)
                self._raise(int(-nis), time, z)
        return self._update_slow(float(time), np.asarray(z, dtype=np.float64), mask)

    def update_many(self, times: ArrayLike, measurements: ArrayLike) -> StreamEstimates:
        """Apply a block of measurements ``(T, m)`` at ``times`` (T,) [s], in order.

        The same steps as calling :meth:`update` for each row (bit for bit), with the state kept
        in compiled code between rows: for replaying a recorded file before going live, or for
        blocks of a fast stream. Every component is present.

        Raises
        ------
        ValueError
            Before any step, naming the row: wrong shapes, a non-finite value, times that
            decrease or start before the filter time.
        CovarianceError
            If ``S`` is not positive definite at some row; the rows before it are applied.
        """
        t = as_float_array(times, "times", min_ndim=1)
        z = as_float_array(measurements, "measurements", min_ndim=2)
        n_rows = t.shape[0]
        if t.ndim != 1 or z.shape != (n_rows, self._m):
            raise ValueError(
                f"times must have shape (T,) and measurements (T, {self._m}); got {t.shape} "
                f"and {z.shape}"
            )
        back = np.flatnonzero(np.diff(t, prepend=self._ws[_TIME]) < 0)
        if back.size:
            k = int(back[0])
            raise ValueError(
                f"times must not decrease or start before the filter time {self.time} s; "
                f"row {k}: {t[k]}"
            )
        n = self.model.state_dim
        out = StreamEstimates(np.empty((n_rows, n)), np.empty((n_rows, n)), np.empty(n_rows))
        k = 0
        while self._fast_run is not None:
            status, k = self._fast_run(self._ws, t, z, k, *out)
            if status == 0:
                return out
            if status == 6 or (status == 2 and self._auto):  # the rest in square-root form
                self._to_sqrt()
            elif status == 3:  # a new step length: discretise, go on
                self._row(t[k] - self._ws[_TIME], t[k])
            else:
                raise CovarianceError(
                    f"innovation covariance is not positive definite at row {k} "
                    f"(t = {t[k]} s); rows 0-{k - 1} are applied"
                )
        for row in range(k, n_rows):
            out.nis[row] = self.update(t[row], z[row])
            out.mean[row] = self._blocks["x"]
            out.variance[row] = np.diagonal(self._blocks["p"])
        return out

    def _update_slow(self, t: float, z: FloatArray, mask: ArrayLike | None) -> float:
        dt = t - self._ws[_TIME]
        if not (dt >= 0.0 and math.isfinite(t)):
            self._raise(5, t, z)
        if z.shape != (self._m,):
            self._raise(4, t, z)
        present = np.ones(self._m, dtype=np.bool_) if mask is None else np.asarray(mask)
        if present.shape != (self._m,) or present.dtype != np.bool_:
            raise ValueError(f"mask must be boolean of shape ({self._m},); got {present.shape}")
        if not np.isfinite(z[present]).all():
            self._raise(1, t, z)
        n = self.model.state_dim
        phi, qd, u = np.split(self._bank[self._row(dt, t), 1:], [n * n, 2 * n * n])
        phi, qd = phi.reshape(n, n), qd.reshape(n, n)
        blk = self._blocks
        if self._sqrt:
            nis, logdet, nobs = self._sqrt_step(phi, qd, u, z, present)
        else:
            saved = (blk["x"].copy(), blk["p"].copy()) if self._auto else None
            ok, nis, logdet, nobs = kf_step(  # the generic compiled step, in the work buffer
                blk["x"], blk["p"], phi, qd, u, z, present, blk["h"], blk["r"], blk["off"],
                self._ws[2] != 0.0, blk["xp"], blk["pp"], blk["tmp"], blk["hm"], blk["rm"],
                blk["hp"], blk["s"], blk["lo"], blk["kt"], blk["nu"], blk["w"], blk["ikh"],
            )  # fmt: skip
            limit = self._ws[WS_TRACE_LIMIT]
            if saved and (not ok or _scaled_trace(blk["s"], blk["r"], present) > limit):
                blk["x"][:], blk["p"][:] = saved
                self._to_sqrt()
                nis, logdet, nobs = self._sqrt_step(phi, qd, u, z, present)
            elif not ok:
                self._raise(2, t, z)
        self._ws[3:_TIME] = nis, -0.5 * (logdet + nis + nobs * _LOG_2PI) if nobs else 0.0, nobs
        self._ws[_TIME] = t
        return float(nis)

    def _sqrt_step(
        self, phi: FloatArray, qd: FloatArray, u: FloatArray, z: FloatArray, present: BoolArray
    ) -> tuple[float, float, float]:
        """One square-root step on the work buffer; returns NIS, log det S, observed count."""
        blk = self._blocks
        lower_factor_into(qd, blk["sq"], blk["sq_tmp"])
        _, nis, logdet, nobs = sqrt_step(  # R is positive definite: the step cannot fail
            blk["x"], blk["fac"], phi, blk["sq"], u, z, present, blk["h"], blk["r"], blk["off"],
            blk["xp"], blk["pre1"], blk["pre2"], blk["rm"], blk["sr"], blk["nu"], blk["w"],
            blk["gain"],
        )  # fmt: skip
        outer_into(blk["fac"], blk["p"], self.model.state_dim)
        return nis, logdet, nobs

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


__all__ = ["OnlineFilter", "StreamEstimates"]


def _scaled_trace(s: FloatArray, r: FloatArray, present: np.ndarray) -> float:
    """``sum_a S_aa / R_aa`` over the present components (``joseph_ratio``'s numerator)."""
    return float(np.sum(np.diagonal(s)[present] / np.diagonal(r)[present]))
