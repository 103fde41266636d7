"""Sensor calibration from data: a clock offset between two sources, a radar's biases.

A GNSS receiver stamps its fixes late (its latency), while its velocity reports, or those of
an INS, carry their own times. :func:`fit_clock_offset` estimates the offset jointly with the
motion and noise parameters by maximum likelihood (:func:`.likelihood.fit_by_likelihood`): a
constant-velocity Kalman filter over both sources, with the position fixes moved to the times
they were made (``time tag - offset``), is run for every trial offset, and the offset that
makes the innovations most likely is kept, with its standard error.

A radar's constant range and azimuth biases are seen against a reference that knows where the
target was (a test vehicle's GNSS): :func:`fit_radar_bias` runs an extended Kalman filter
over both sources (the radar's range and azimuth less the trial biases) and maximises the
likelihood over the biases, the motion PSD and the three noise variances.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_times
from ..angles import wrapped
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


def fit_radar_bias(
    reference_times: ArrayLike,
    reference_positions: ArrayLike,
    radar_times: ArrayLike,
    ranges_m: ArrayLike,
    azimuths_rad: ArrayLike,
    radar_position: ArrayLike,
    *,
    accel_psd: float = 1.0,
    reference_var: float = 1.0,
    range_var: float = 1.0,
    azimuth_var: float = 1e-5,
) -> LikelihoodFit:
    """Estimate a radar's constant range and azimuth biases against a reference.

    Planar: a target seen by the radar (slant effects left out: ranges on the ground) and by a
    reference position source at its own times, in one east-north frame. The radar measures
    ``range + range_bias_m`` and ``azimuth + azimuth_bias_rad`` (clockwise from north), each
    with white noise. A constant-velocity EKF over both sources gives the log-likelihood.

    Parameters
    ----------
    reference_times, reference_positions : array_like, shapes (N,) and (N, 2)
        Time tags [s] (strictly increasing) and east, north [m] of the reference.
    radar_times, ranges_m, azimuths_rad : array_like, shape (M,)
        The radar's detections of the target [s, m, rad].
    radar_position : array_like, shape (2,)
        The radar's east, north [m].
    accel_psd, reference_var, range_var, azimuth_var : float
        Starting values [m^2/s^3, m^2, m^2, rad^2].

    Returns
    -------
    LikelihoodFit
        ``range_bias_m``, ``azimuth_bias_rad`` (signed), ``accel_psd``, ``reference_var``,
        ``range_var``, ``azimuth_var``, with standard errors.
    """
    tr = as_float_array(reference_times, "reference_times", min_ndim=1)
    zr = as_float_array(reference_positions, "reference_positions", min_ndim=2)
    tm = as_float_array(radar_times, "radar_times", min_ndim=1)
    rng = as_float_array(ranges_m, "ranges_m", min_ndim=1)
    az = as_float_array(azimuths_rad, "azimuths_rad", min_ndim=1)
    site = as_float_array(radar_position, "radar_position", min_ndim=1)
    check_times(tr, "reference_times")
    check_times(tm, "radar_times")
    if zr.shape != (tr.size, 2) or rng.shape != tm.shape or az.shape != tm.shape:
        raise ValueError(
            f"reference_positions must be (N, 2) for N times and ranges, azimuths one per radar "
            f"time; got {zr.shape} for {tr.size}, {rng.shape} and {az.shape} for {tm.size}"
        )
    if site.shape != (2,):
        raise ValueError(f"radar_position must be (east, north); got shape {site.shape}")
    if tr.size < 3 or tm.size < 3:
        raise ValueError("at least 3 reference fixes and 3 radar detections are needed")
    t = np.concatenate([tr, tm])
    order = np.argsort(t, kind="stable")
    z = np.concatenate([zr, np.stack([rng, az], -1)])[order]
    radar = np.concatenate([np.zeros(tr.size, bool), np.ones(tm.size, bool)])[order]
    t = t[order]

    def loglik(p: dict[str, float]) -> float:
        return float(
            _radar_reference_loglik(
                t, z, radar, site[0], site[1], zr[0, 0], zr[0, 1], p["range_bias_m"],
                p["azimuth_bias_rad"], p["accel_psd"], p["reference_var"], p["range_var"],
                p["azimuth_var"], PRIOR_SPEED_STD_MPS**2,
            )
        )  # fmt: skip

    positive = {"accel_psd": accel_psd, "reference_var": reference_var, "range_var": range_var}
    return fit_by_likelihood(
        loglik,
        positive | {"azimuth_var": azimuth_var},
        signed={"range_bias_m": 0.0, "azimuth_bias_rad": 0.0},
        scales={"range_bias_m": 1.0, "azimuth_bias_rad": 0.005},
    )


@numba.njit(cache=True)
def _radar_reference_loglik(  # type: ignore[no-untyped-def]
    t, z, radar, rx, ry, x0, y0, range_bias, azimuth_bias, q, ref_var, range_var, az_var,
    speed_var,
):  # fmt: skip
    """Log-likelihood of a planar constant-velocity EKF over reference fixes and radar rows.

    State ``[x, y, vx, vy]``; rows of ``z`` are ``(east, north)`` or, where ``radar``,
    ``(range, azimuth)``; the first state is at the first reference fix ``(x0, y0)``.
    """
    x = np.array([x0, y0, 0.0, 0.0])
    p = np.diag(np.array([ref_var, ref_var, speed_var, speed_var]))
    h = np.zeros((2, 4))
    nu = np.zeros(2)
    r = np.zeros((2, 2))
    phi, qd = np.eye(4), np.zeros((4, 4))  # refilled for each step's length
    total = 0.0
    prev = t[0]
    for k in range(t.size):
        dt = t[k] - prev
        prev = t[k]
        if dt > 0.0:
            phi[0, 2] = phi[1, 3] = dt
            for a in range(2):
                qd[a, a] = q * dt**3 / 3.0
                qd[a, a + 2] = qd[a + 2, a] = q * dt**2 / 2.0
                qd[a + 2, a + 2] = q * dt
            x = phi @ x
            p = phi @ p @ phi.T + qd
        h[:, :] = 0.0
        r[:, :] = 0.0
        if radar[k]:
            dx, dy = x[0] - rx, x[1] - ry
            rho2 = max(dx * dx + dy * dy, 1e-6)
            rho = math.sqrt(rho2)
            h[0, 0], h[0, 1] = dx / rho, dy / rho
            h[1, 0], h[1, 1] = dy / rho2, -dx / rho2
            nu[0] = z[k, 0] - range_bias - rho
            nu[1] = wrapped(z[k, 1] - azimuth_bias - math.atan2(dx, dy), math.pi)
            r[0, 0], r[1, 1] = range_var, az_var
        else:
            h[0, 0] = h[1, 1] = 1.0
            nu[0], nu[1] = z[k, 0] - x[0], z[k, 1] - x[1]
            r[0, 0] = r[1, 1] = ref_var
        s = h @ p @ h.T + r
        det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
        if not det > 0.0:
            return -np.inf
        s_inv = np.array([[s[1, 1], -s[0, 1]], [-s[1, 0], s[0, 0]]]) / det
        total -= 0.5 * (math.log(4.0 * math.pi**2 * det) + nu @ s_inv @ nu)
        gain = p @ h.T @ s_inv
        x = x + gain @ nu
        ikh = np.eye(4) - gain @ h
        p = ikh @ p @ ikh.T + gain @ r @ gain.T  # Joseph form
        p = 0.5 * (p + p.T)
    return total


__all__ = ["fit_clock_offset", "fit_radar_bias"]
