"""Sensor calibration from data: the clock offset between a position and a velocity source.

A GNSS receiver stamps its fixes late (its latency), while its velocity reports, or those of
an INS, carry their own times. :func:`fit_clock_offset` estimates the offset jointly with the
motion and noise parameters by maximum likelihood (:func:`.likelihood.fit_by_likelihood`): a
constant-velocity Kalman filter over both sources, with the position fixes moved to the times
they were made (``time tag - offset``), is run for every trial offset, and the offset that
makes the innovations most likely is kept, with its standard error.
"""

from __future__ import annotations

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_times
from ..filters.run import kalman_filter
from ..models.continuous import ConstantVelocity
from ..types import GaussianState
from .likelihood import LikelihoodFit, fit_by_likelihood

PRIOR_SPEED_STD_MPS = 50.0  # the prior on the first velocity: the data decide


def fit_clock_offset(
    position_times: ArrayLike,
    positions: ArrayLike,
    velocity_times: ArrayLike,
    velocities: ArrayLike,
    *,
    offset_s: float = 0.0,
    accel_psd: float = 1.0,
    position_var: float = 1.0,
    velocity_var: float = 1.0,
) -> LikelihoodFit:
    """Estimate how late the position fixes are stamped, against the velocity reports.

    Parameters
    ----------
    position_times, positions : array_like, shapes (N,) and (N, d)
        Time tags [s] (strictly increasing) and positions [m] in a local frame (d = 1-3).
    velocity_times, velocities : array_like, shapes (M,) and (M, d)
        Time tags [s] and velocities [m/s] of the other source, in the same frame.
    offset_s, accel_psd, position_var, velocity_var : float
        Starting values: the offset [s] (positive: fixes stamped after they were made), the
        white-acceleration PSD [m^2/s^3] and the noise variances [m^2], [m^2/s^2].

    Returns
    -------
    LikelihoodFit
        ``offset_s`` (signed), ``accel_psd``, ``position_var``, ``velocity_var``, with
        standard errors (``fit.interval("offset_s")``).
    """
    tp = as_float_array(position_times, "position_times", min_ndim=1)
    tv = as_float_array(velocity_times, "velocity_times", min_ndim=1)
    zp = as_float_array(positions, "positions", min_ndim=2)
    zv = as_float_array(velocities, "velocities", min_ndim=2)
    check_times(tp, "position_times")
    check_times(tv, "velocity_times")
    d = zp.shape[1]
    if zp.shape != (tp.size, d) or zv.shape != (tv.size, d) or not 1 <= d <= 3:
        raise ValueError(
            f"positions (N, d) and velocities (M, d) must match their times, d = 1-3; got "
            f"{zp.shape} for {tp.size} times and {zv.shape} for {tv.size} times"
        )
    if tp.size < 3 or tv.size < 3:
        raise ValueError("at least 3 position fixes and 3 velocity reports are needed")

    def loglik(p: dict[str, float]) -> float:
        t, z, mask = _merged(tp - p["offset_s"], zp, tv, zv)
        model = ConstantVelocity(accel_psd=p["accel_psd"], n_axes=d)
        r = np.diag([p["position_var"]] * d + [p["velocity_var"]] * d)
        prior = GaussianState(
            np.concatenate([zp[0], zv[0]]),
            np.diag([p["position_var"]] * d + [PRIOR_SPEED_STD_MPS**2] * d),
            t[0],
        )
        res = kalman_filter(t, z, model, model.state_names, r, prior, mask=mask, backend="numba")
        return float(res.info.log_likelihood.sum())

    return fit_by_likelihood(
        loglik,
        {"accel_psd": accel_psd, "position_var": position_var, "velocity_var": velocity_var},
        signed={"offset_s": offset_s},
        scales={"offset_s": 0.1},
    )


def _merged(
    tp: FloatArray, zp: FloatArray, tv: FloatArray, zv: FloatArray
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """One measurement sequence of both sources: times, ``[p, v]`` rows and their mask."""
    d = zp.shape[1]
    t, inv = np.unique(np.concatenate([tp, tv]), return_inverse=True)
    z = np.zeros((t.size, 2 * d))
    mask = np.zeros((t.size, 2 * d), dtype=bool)
    z[inv[: tp.size], :d], mask[inv[: tp.size], :d] = zp, True
    z[inv[tp.size :], d:], mask[inv[tp.size :], d:] = zv, True
    return t, z, mask


__all__ = ["fit_clock_offset"]
