"""Core data types: Gaussian states, per-step filter information and filter results.

All are frozen dataclasses holding read-only float64 arrays. Public construction validates
shapes and finiteness; the filters build them through a trusted path after validating their
own inputs once.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ._typing import ArrayLike, BoolArray, FloatArray
from ._validation import as_float_array, check_shape, frozen


def _trusted(cls: type, **values: Any) -> Any:
    """Build a frozen dataclass without validation (private kernels trust their inputs)."""
    obj: Any = object.__new__(cls)
    for f in fields(cls):
        object.__setattr__(obj, f.name, values[f.name] if f.name in values else f.default)
    return obj


@dataclass(frozen=True, slots=True, eq=False)
class GaussianState:
    """Gaussian belief over a state at given times.

    Parameters
    ----------
    mean : array_like, shape (..., n)
        State mean in SI units (positions [m], then velocities [m/s], then accelerations).
    cov : array_like, shape (..., n, n)
        State covariance.
    time : array_like, shape (...) or broadcastable to it
        Time of the belief [s since the run epoch].
    factor : array_like, shape (..., n, n), optional
        A factor ``S`` with ``S S^T = cov``. The square-root forms of
        :func:`adaptrack.kalman_step` and :func:`adaptrack.update` return it and continue from
        it, so a sequence of steps does not lose the digits that rounding ``cov`` to double
        precision between steps would (an ill-conditioned problem). Checked against ``cov``
        (a state made with a changed ``cov`` and the old factor is refused: pass
        ``factor=None``).

    Examples
    --------
    >>> s = GaussianState(mean=[0.0, 1.0], cov=[[1.0, 0.0], [0.0, 2.0]], time=0.0)
    >>> s.dim, s.batch_shape
    (2, ())
    """

    mean: FloatArray
    cov: FloatArray
    time: FloatArray
    factor: FloatArray | None = None

    def __post_init__(self) -> None:
        mean = as_float_array(self.mean, "mean", min_ndim=1)
        cov = as_float_array(self.cov, "cov", min_ndim=2)
        check_shape(cov, mean.shape + mean.shape[-1:], "cov", against="mean")
        time = as_float_array(self.time, "time")
        try:
            time = np.broadcast_to(time, mean.shape[:-1])
        except ValueError:
            raise ValueError(
                f"time must be broadcastable to the batch shape {mean.shape[:-1]} of mean; "
                f"got {time.shape}"
            ) from None
        for name, value in (("mean", mean), ("cov", cov), ("time", time)):
            object.__setattr__(self, name, frozen(value))
        if self.factor is not None:
            factor = as_float_array(self.factor, "factor", min_ndim=2)
            check_shape(factor, cov.shape, "factor", against="cov")
            _check_factor(factor, cov)
            object.__setattr__(self, "factor", frozen(factor))

    @property
    def dim(self) -> int:
        """State size n."""
        return int(self.mean.shape[-1])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading (batch) shape, ``()`` for a single state."""
        return tuple(self.mean.shape[:-1])

    @property
    def std(self) -> FloatArray:
        """Standard deviations, shape (..., n)."""
        return np.sqrt(np.diagonal(self.cov, axis1=-2, axis2=-1))

    def __getitem__(self, index: Any) -> GaussianState:
        """Index the batch axes (never the state axis)."""
        if not isinstance(index, tuple):
            index = (index,)
        if len(index) > len(self.batch_shape):
            raise IndexError(
                f"too many indices for the batch shape {self.batch_shape} of this GaussianState"
            )
        return _trusted(
            GaussianState,
            mean=frozen(self.mean[index]),
            cov=frozen(self.cov[index]),
            time=frozen(self.time[index]),
            factor=None if self.factor is None else frozen(self.factor[index]),
        )


FACTOR_RTOL = 1e-9  # of sigma_i sigma_j: a factor that reproduces cov to rounding


def _check_factor(factor: FloatArray, cov: FloatArray) -> None:
    """Raise ValueError unless ``factor factor^T`` equals ``cov`` to :data:`FACTOR_RTOL`."""
    d = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))
    scale = d[..., :, None] * d[..., None, :]
    off = np.abs(factor @ np.swapaxes(factor, -1, -2) - cov)
    bad = off > FACTOR_RTOL * scale + np.finfo(float).tiny
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"factor does not reproduce cov (factor factor^T differs at index {idx}); "
            "a state with a new cov needs factor=None"
        )


@dataclass(frozen=True, slots=True, eq=False)
class StepInfo:
    """Everything a measurement update derives from the prior, in one place.

    Attributes
    ----------
    innovation : ndarray, shape (..., m)
        ``z - H x_pred`` (0 where a component was missing).
    innovation_cov : ndarray, shape (..., m, m)
        ``S = H P_pred H^T + R`` (missing components decoupled with unit variance).
    nis : ndarray, shape (...)
        Normalised innovation squared ``nu^T S^-1 nu`` (chi-square with ``n_observed`` dof).
    log_likelihood : ndarray, shape (...)
        ``log N(nu; 0, S)`` over the observed components (0 when nothing was observed).
    gain : ndarray, shape (..., n, m)
        Kalman gain applied.
    n_observed : ndarray, shape (...)
        Number of measurement components used in the update.
    """

    innovation: FloatArray
    innovation_cov: FloatArray
    nis: FloatArray
    log_likelihood: FloatArray
    gain: FloatArray
    n_observed: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class FilterResult:
    """Result of a Kalman filter run over a sequence (batched over tracks).

    Index conventions: ``predicted[..., k]`` is the belief at ``times[..., k]`` before
    measurement k is used; ``filtered[..., k]`` after it. ``transition[..., k]`` and
    ``process_cov[..., k]`` map step k-1 to step k (for k = 0: from the initial state's
    time to ``times[..., 0]``; the identity and zero when they coincide), and
    ``control[..., k]`` is the known-input offset added on that step.

    Attributes
    ----------
    predicted, filtered : GaussianState
        Shapes (..., T, n) and (..., T, n, n).
    transition, process_cov : ndarray, shape (..., T, n, n)
    control : ndarray, shape (..., T, n)
    info : StepInfo
        Per step, shapes (..., T, ...).
    mask : ndarray of bool, shape (..., T, m)
        True where a measurement component was used.
    measurement_matrix : ndarray, shape (m, n)
    measurement_cov : ndarray, shape (..., m, m)
    """

    predicted: GaussianState
    filtered: GaussianState
    transition: FloatArray
    process_cov: FloatArray
    control: FloatArray
    info: StepInfo
    mask: BoolArray
    measurement_matrix: FloatArray
    measurement_cov: FloatArray

    @property
    def times(self) -> FloatArray:
        """Measurement times, shape (..., T) [s]."""
        return self.filtered.time

    @property
    def log_likelihood(self) -> FloatArray:
        """Total log-likelihood of each track's measurements, shape (...)."""
        return np.asarray(self.info.log_likelihood.sum(axis=-1))


def as_gaussian_state(value: GaussianState | ArrayLike, name: str) -> GaussianState:
    """Check that ``value`` is a GaussianState (TypeError otherwise)."""
    if not isinstance(value, GaussianState):
        raise TypeError(f"{name} must be a GaussianState; got {type(value).__name__}")
    return value


__all__ = ["FilterResult", "GaussianState", "StepInfo"]
