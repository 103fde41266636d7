"""Traffic-radar sensor model: noise that varies with range and angle, fields of view, P_D.

Automotive and traffic radars specify their accuracy as functions of the geometry (range
sigma growing with range, azimuth sigma growing off boresight) and see through several fields
(a wide near field and a narrow far field). A :class:`RadarSpec` holds these as
:class:`Curve` tables; the simulator draws noise with them at the true geometry, the trackers
build their measurement covariance with them at the predicted geometry, and the bound uses them
at the truth. Angles inside are radians; the site file gives degrees.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..._typing import ArrayLike, FloatArray
from ...angles import wrap
from .geometry import polar

MAX_CURVE_POINTS = 32


@dataclass(frozen=True)
class Curve:
    """A positive quantity as a piecewise-linear function of one argument.

    ``points`` are ``(argument, value)`` pairs with strictly increasing arguments; the value is
    interpolated linearly between them and held constant beyond the ends (as ``np.interp``).
    One point is a constant.

    Examples
    --------
    >>> Curve(((0.0, 0.1), (100.0, 0.3)))(np.array([-5.0, 50.0, 400.0]))
    array([0.1, 0.2, 0.3])
    """

    points: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        pts = tuple((float(x), float(y)) for x, y in self.points)
        if not 1 <= len(pts) <= MAX_CURVE_POINTS:
            raise ValueError(f"a curve needs 1 to {MAX_CURVE_POINTS} points; got {len(pts)}")
        xs = [p[0] for p in pts]
        ys = [p[1] for p in pts]
        if not all(math.isfinite(v) for v in xs + ys):
            raise ValueError(f"curve points must be finite; got {pts}")
        if any(b <= a for a, b in itertools.pairwise(xs)):
            raise ValueError(f"curve arguments must be strictly increasing; got {xs}")
        object.__setattr__(self, "points", pts)

    @classmethod
    def constant(cls, value: float) -> Curve:
        """Return a curve with the same value everywhere."""
        return cls(((0.0, float(value)),))

    @property
    def arguments(self) -> FloatArray:
        """Knot arguments (K,)."""
        return np.array([p[0] for p in self.points])

    @property
    def values(self) -> FloatArray:
        """Knot values (K,)."""
        return np.array([p[1] for p in self.points])

    def __call__(self, x: ArrayLike) -> FloatArray:
        """Value at ``x`` (any shape)."""
        return np.interp(np.asarray(x, dtype=float), self.arguments, self.values)

    def scaled(self, argument: float = 1.0, value: float = 1.0) -> Curve:
        """Return the curve with arguments and values multiplied (unit conversion)."""
        return Curve(tuple((x * argument, y * value) for x, y in self.points))


@dataclass(frozen=True)
class FieldOfView:
    """One field of a radar: slant ranges up to ``max_range_m`` within ``+-half_angle_rad``."""

    max_range_m: float
    half_angle_rad: float


@dataclass(frozen=True)
class RadarSpec:
    """A traffic radar reporting (slant range, azimuth, radial speed) detections.

    Attributes
    ----------
    name : str
    position_m : (float, float)
        East, north of the radar [m] (local frame, crossing centre at the origin).
    height_m : float
        Height above the reflection points [m].
    boresight_rad : float
        Boresight azimuth, clockwise from north [rad].
    fields : tuple of FieldOfView
        A detection needs to lie in at least one field (near/far fields of one radar).
    min_range_m : float
        Shortest slant range reported [m].
    period_s : float
        Scan period [s].
    range_std_m : Curve
        Range noise standard deviation [m] against slant range [m].
    azimuth_std_rad : Curve
        Azimuth noise standard deviation [rad] against the angle off boresight [rad, >= 0].
    radial_speed_std_mps : Curve
        Radial-speed noise standard deviation [m/s] against slant range [m].
    min_radial_speed_mps : float
        Doppler gate: no detection below this absolute radial speed [m/s].
    detection_probability : dict of str to Curve
        Probability of detection against slant range [m] per vehicle class; the key
        ``"default"`` serves classes not listed.
    azimuth_bias_rad : float
        Calibration error added to every azimuth (unknown to the trackers) [rad].
    time_jitter_s : float
        Timestamp error, uniform in ``+-time_jitter_s`` [s].
    latency_s : float
        Declared timestamp delay: a detection made at ``t`` is stamped ``t + latency_s`` [s]
        (the simulator stamps it so; the trackers take it off: :meth:`measured_at`).
    max_unambiguous_speed_mps : float or None
        Radial speeds fold at this value (None: no folding) [m/s].
    """

    name: str
    position_m: tuple[float, float]
    height_m: float
    boresight_rad: float
    fields: tuple[FieldOfView, ...]
    min_range_m: float
    period_s: float
    range_std_m: Curve
    azimuth_std_rad: Curve
    radial_speed_std_mps: Curve
    min_radial_speed_mps: float
    detection_probability: dict[str, Curve] = field(
        default_factory=lambda: {"default": Curve.constant(0.95)}
    )
    azimuth_bias_rad: float = 0.0
    time_jitter_s: float = 0.0
    max_unambiguous_speed_mps: float | None = None
    latency_s: float = 0.0

    def measured_at(self, stamped_s: ArrayLike) -> FloatArray:
        """Return when detections were made [s]: their timestamps less the latency."""
        return np.asarray(stamped_s, dtype=float) - self.latency_s

    @property
    def max_range_m(self) -> float:
        """Longest slant range of any field [m]."""
        return max(f.max_range_m for f in self.fields)

    def off_boresight(self, azimuth_rad: ArrayLike) -> FloatArray:
        """Absolute angle between an azimuth and the boresight [rad, in [0, pi]]."""
        a = np.asarray(azimuth_rad, dtype=float) - self.boresight_rad
        return np.abs(wrap(a))

    def polar(self, position: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Slant range [m] and azimuth [rad] of ground points (..., 2)."""
        rng, az, _ = polar(position, self.position_m, self.height_m)
        return rng, az

    def in_view(self, range_m: ArrayLike, azimuth_rad: ArrayLike) -> np.ndarray:
        """Whether slant ranges [m] and azimuths [rad] lie in a field of view and range gate."""
        rng = np.asarray(range_m, dtype=float)
        off = self.off_boresight(azimuth_rad)
        seen = np.zeros(np.broadcast(rng, off).shape, dtype=bool)
        for f in self.fields:
            seen |= (rng <= f.max_range_m) & (off <= f.half_angle_rad)
        return seen & (rng >= self.min_range_m)

    def covers(self, position: ArrayLike) -> np.ndarray:
        """Whether ground points (..., 2) lie in a field of view and the range gates."""
        return self.in_view(*self.polar(position))

    def noise_std(
        self, range_m: ArrayLike, azimuth_rad: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return the range [m], azimuth [rad] and radial-speed [m/s] sigmas at a geometry."""
        return (
            self.range_std_m(range_m),
            self.azimuth_std_rad(self.off_boresight(azimuth_rad)),
            self.radial_speed_std_mps(range_m),
        )

    def detection_curve(self, vehicle_class: str) -> Curve:
        """Probability of detection against slant range for a vehicle class."""
        return self.detection_probability.get(
            vehicle_class, self.detection_probability.get("default", Curve.constant(0.95))
        )

    def noise_table(self) -> tuple[FloatArray, np.ndarray]:
        """Pack the three noise curves for compiled code: (3, 2, K) knots and (3,) counts.

        Rows: range sigma against range, azimuth sigma against the angle off boresight,
        radial-speed sigma against range (see :func:`curve_tables`).
        """
        return curve_tables((self.range_std_m, self.azimuth_std_rad, self.radial_speed_std_mps))

    def kernel_row(self) -> FloatArray:
        """Geometry for compiled code (7,).

        x, y, height, boresight, min range, Doppler gate, folding speed (0: none).
        """
        return np.array(
            [*self.position_m, self.height_m, self.boresight_rad, self.min_range_m,
             self.min_radial_speed_mps, self.max_unambiguous_speed_mps or 0.0],
        )  # fmt: skip

    def field_table(self) -> FloatArray:
        """Fields of view for compiled code: (F, 2) maximum range [m], half angle [rad]."""
        return np.array([[f.max_range_m, f.half_angle_rad] for f in self.fields])


def curve_tables(curves: tuple[Curve, ...]) -> tuple[FloatArray, np.ndarray]:
    """Pack curves as (C, 2, K) arrays (arguments, values; padded) and their point counts."""
    k = max(len(c.points) for c in curves)
    table = np.zeros((len(curves), 2, k))
    counts = np.zeros(len(curves), dtype=np.int64)
    for i, c in enumerate(curves):
        n = len(c.points)
        table[i, 0, :n], table[i, 1, :n], counts[i] = c.arguments, c.values, n
    return table, counts


__all__ = ["MAX_CURVE_POINTS", "Curve", "FieldOfView", "RadarSpec", "curve_tables"]
