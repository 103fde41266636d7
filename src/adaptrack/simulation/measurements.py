"""Simulated measurements of a truth trajectory.

Cartesian position (optionally velocity) measurements with Gaussian noise, or a 2-D radar's
range and azimuth (azimuth clockwise from north, +y) converted to Cartesian positions with
the Jacobian covariance of the conversion (one covariance per detection). Missed detections
are an explicit mask, never dropped rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray
from .._validation import check_positive_scalar
from .segments import Truth


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measurements ready for a linear filter.

    Attributes
    ----------
    times : ndarray, shape (N, T)
        Measurement times [s].
    values : ndarray, shape (N, T, m)
        Measured positions [m] (then velocities [m/s]); NaN where not detected.
    cov : ndarray, shape (m, m) or (N, T, m, m)
        Measurement noise covariance.
    mask : ndarray of bool, shape (N, T)
        True where a detection exists.
    """

    times: FloatArray
    values: FloatArray
    cov: FloatArray
    mask: BoolArray

    @property
    def dim(self) -> int:
        """Measurement size m."""
        return int(self.values.shape[-1])


def _detections(shape: tuple[int, ...], prob: float, rng: np.random.Generator) -> BoolArray:
    """Draw the detection mask; the first two epochs are detections (track initiation)."""
    if prob >= 1.0:
        return np.ones(shape, dtype=bool)
    mask = rng.uniform(size=shape) < prob
    mask[..., :2] = True
    return mask


def simulate_cartesian(
    truth: Truth,
    position_std_m: float,
    *,
    rng: np.random.Generator,
    velocity_std_mps: float | None = None,
    detection_probability: float = 1.0,
) -> Measurements:
    """Positions (and velocities) plus independent Gaussian noise of the given RMS per axis."""
    s_p = check_positive_scalar(position_std_m, "position_std_m")
    pd = check_positive_scalar(detection_probability, "detection_probability")
    parts, stds = [truth.position], [s_p] * truth.position.shape[-1]
    if velocity_std_mps is not None:
        s_v = check_positive_scalar(velocity_std_mps, "velocity_std_mps")
        parts.append(truth.velocity)
        stds += [s_v] * truth.velocity.shape[-1]
    clean = np.concatenate(parts, axis=-1)
    values = clean + rng.standard_normal(clean.shape) * np.asarray(stds)
    mask = _detections(truth.times.shape, pd, rng)
    values = np.where(mask[..., None], values, np.nan)
    return Measurements(truth.times, values, np.diag(np.square(stds)), mask)


def simulate_polar_2d(
    truth: Truth,
    range_std_m: float,
    azimuth_std_rad: float,
    *,
    rng: np.random.Generator,
    sensor_xy_m: tuple[float, float] = (0.0, 0.0),
    detection_probability: float = 1.0,
) -> Measurements:
    """Range and azimuth of a 2-D radar, converted to x-y positions with their covariance.

    Azimuth is clockwise from north (+y): ``x = r sin(az)``, ``y = r cos(az)``. The covariance
    of each converted position is ``J diag(s_r^2, s_az^2) J^T`` with the Jacobian at the
    measured ``(r, az)``.
    """
    s_r = check_positive_scalar(range_std_m, "range_std_m")
    s_a = check_positive_scalar(azimuth_std_rad, "azimuth_std_rad")
    pd = check_positive_scalar(detection_probability, "detection_probability")
    rel = truth.position[..., :2] - np.asarray(sensor_xy_m)
    rng_m = np.hypot(rel[..., 0], rel[..., 1]) + s_r * rng.standard_normal(rel.shape[:-1])
    az = np.arctan2(rel[..., 0], rel[..., 1]) + s_a * rng.standard_normal(rel.shape[:-1])
    sa, ca = np.sin(az), np.cos(az)
    xy = np.stack([rng_m * sa, rng_m * ca], axis=-1) + np.asarray(sensor_xy_m)
    jac = np.stack([np.stack([sa, rng_m * ca], -1), np.stack([ca, -rng_m * sa], -1)], -2)
    cov = jac @ np.diag([s_r**2, s_a**2]) @ np.swapaxes(jac, -1, -2)
    mask = _detections(truth.times.shape, pd, rng)
    return Measurements(truth.times, np.where(mask[..., None], xy, np.nan), cov, mask)


__all__ = ["Measurements", "simulate_cartesian", "simulate_polar_2d"]
