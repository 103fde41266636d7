"""Truth trajectories made of manoeuvre segments, integrated exactly (1-3 axes).

A trajectory starts from a position and velocity and runs through segments, each lasting a
given time: constant velocity, constant acceleration, constant jerk, coordinated turn (a
constant turn rate in the horizontal x-y plane) and a Singer random acceleration. The
deterministic segments are evaluated in closed form at any time; the Singer segment is
sampled exactly (its exact discretisation) at the requested times, independently per run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validation import as_float_array, check_positive_scalar, check_times
from ..models.continuous import Singer
from ..models.discretize import discretize


@dataclass(frozen=True)
class Segment:
    """One manoeuvre segment.

    Attributes
    ----------
    kind : {"constant_velocity", "constant_acceleration", "constant_jerk", "coordinated_turn",
            "singer"}
    duration_s : float
        Length of the segment [s], > 0.
    accel_mps2 : tuple of float
        Acceleration per axis [m/s^2] (constant acceleration; initial value for constant jerk).
    jerk_mps3 : tuple of float
        Jerk per axis [m/s^3] (constant jerk).
    turn_rate_radps : float
        Turn rate in the x-y plane [rad/s], positive counter-clockwise (coordinated turn).
    time_constant_s, accel_std_mps2 : float
        Singer parameters of a random-acceleration segment.
    """

    kind: str
    duration_s: float
    accel_mps2: tuple[float, ...] = ()
    jerk_mps3: tuple[float, ...] = ()
    turn_rate_radps: float = 0.0
    time_constant_s: float = 1.0
    accel_std_mps2: float = 0.0

    def __post_init__(self) -> None:
        kinds = (
            "constant_velocity",
            "constant_acceleration",
            "constant_jerk",
            "coordinated_turn",
            "singer",
        )
        if self.kind not in kinds:
            raise ValueError(f"segment kind must be one of {kinds}; got {self.kind!r}")
        check_positive_scalar(self.duration_s, "duration_s")
        if self.kind == "singer":
            check_positive_scalar(self.time_constant_s, "time_constant_s")
            check_positive_scalar(self.accel_std_mps2, "accel_std_mps2", allow_zero=True)


@dataclass(frozen=True)
class TrajectorySpec:
    """Initial state and segments of a truth trajectory.

    Attributes
    ----------
    initial_position_m, initial_velocity_mps : tuple of float
        Initial position [m] and velocity [m/s], one value per axis (1-3 axes).
    segments : tuple of Segment
    """

    initial_position_m: tuple[float, ...]
    initial_velocity_mps: tuple[float, ...]
    segments: tuple[Segment, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        d = len(self.initial_position_m)
        if not 1 <= d <= 3 or len(self.initial_velocity_mps) != d:
            raise ValueError(
                "initial_position_m and initial_velocity_mps must have the same "
                f"length 1-3; got {len(self.initial_position_m)} and "
                f"{len(self.initial_velocity_mps)}"
            )
        for i, s in enumerate(self.segments):
            for name in ("accel_mps2", "jerk_mps3"):
                v = getattr(s, name)
                if v and len(v) != d:
                    raise ValueError(
                        f"segments[{i}].{name} must have {d} values (one per axis); got {len(v)}"
                    )
            if s.kind == "coordinated_turn" and d < 2:
                raise ValueError(f"segments[{i}]: a coordinated turn needs at least 2 axes")

    @property
    def n_axes(self) -> int:
        """Number of axes."""
        return len(self.initial_position_m)

    @property
    def duration_s(self) -> float:
        """Total duration of the segments [s]."""
        return float(sum(s.duration_s for s in self.segments))


@dataclass(frozen=True, eq=False)
class Truth:
    """True kinematics at the sample times: shapes (N, T) and (N, T, d)."""

    times: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray

    @property
    def state(self) -> FloatArray:
        """Positions then velocities then accelerations, shape (N, T, 3 d)."""
        return np.concatenate([self.position, self.velocity, self.acceleration], axis=-1)


def _advance(
    seg: Segment, p: FloatArray, v: FloatArray, a_in: FloatArray, tau: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Deterministic segment state after ``tau`` seconds from (p, v); tau (..., k)."""
    d = p.shape[-1]
    t = tau[..., None]
    p0, v0 = p[..., None, :], v[..., None, :]
    if seg.kind == "constant_velocity":
        return p0 + v0 * t, np.broadcast_to(v0, t.shape[:-1] + (d,)), np.zeros(t.shape[:-1] + (d,))
    if seg.kind == "constant_acceleration":
        a = np.asarray(seg.accel_mps2)
        return p0 + v0 * t + a * t**2 / 2, v0 + a * t, np.broadcast_to(a, t.shape[:-1] + (d,))
    if seg.kind == "constant_jerk":
        a = np.asarray(seg.accel_mps2) if seg.accel_mps2 else np.zeros(d)
        j = np.asarray(seg.jerk_mps3)
        return (p0 + v0 * t + a * t**2 / 2 + j * t**3 / 6, v0 + a * t + j * t**2 / 2, a + j * t)
    # coordinated turn in the x-y plane
    w = seg.turn_rate_radps
    c, s = np.cos(w * t[..., 0]), np.sin(w * t[..., 0])
    vx, vy = v0[..., 0], v0[..., 1]
    vel = np.array(np.broadcast_to(v0, t.shape[:-1] + (d,)))
    vel[..., 0], vel[..., 1] = vx * c - vy * s, vx * s + vy * c
    pos = p0 + v0 * t
    if w != 0.0:
        si = np.sin(w * t[..., 0]) / w
        ci = (1 - np.cos(w * t[..., 0])) / w
        pos = np.array(np.broadcast_to(pos, vel.shape))
        pos[..., 0] = p0[..., 0] + vx * si - vy * ci
        pos[..., 1] = p0[..., 1] + vx * ci + vy * si
    acc = np.zeros_like(vel)
    acc[..., 0], acc[..., 1] = -w * vel[..., 1], w * vel[..., 0]
    return pos, vel, acc


def simulate_truth(
    spec: TrajectorySpec,
    times: ArrayLike,
    *,
    n_runs: int = 1,
    rng: np.random.Generator | None = None,
) -> Truth:
    """Evaluate a trajectory at ``times`` for ``n_runs`` runs.

    Parameters
    ----------
    spec : TrajectorySpec
    times : array_like, shape (T,) or (n_runs, T)
        Strictly increasing sample times [s] from the trajectory start (t = 0); times after
        the last segment continue with constant velocity.
    n_runs : int
        Number of runs (only Singer segments differ between runs).
    rng : numpy.random.Generator, optional
        Required if the trajectory has a Singer segment.

    Returns
    -------
    Truth
        Shapes (n_runs, T) and (n_runs, T, d).
    """
    t = as_float_array(times, "times", min_ndim=1)
    check_times(t, "times")
    t = np.broadcast_to(t, (n_runs, t.shape[-1]))
    d = spec.n_axes
    if np.any(t < 0):
        raise ValueError("times must be >= 0 (seconds from the trajectory start)")
    needs_rng = any(s.kind == "singer" for s in spec.segments)
    if needs_rng and not isinstance(rng, np.random.Generator):
        raise TypeError(
            "rng must be a numpy.random.Generator for trajectories with Singer segments"
        )
    pos = np.empty(t.shape + (d,))
    vel = np.empty_like(pos)
    acc = np.zeros_like(pos)
    p: FloatArray = np.broadcast_to(np.asarray(spec.initial_position_m, float), (n_runs, d)).copy()
    v: FloatArray = np.broadcast_to(
        np.asarray(spec.initial_velocity_mps, float), (n_runs, d)
    ).copy()
    a: FloatArray = np.zeros((n_runs, d))
    start = 0.0
    # after the last segment the target keeps its velocity
    tail = Segment("constant_velocity", max(float(t.max()) - spec.duration_s, 0.0) + 1.0)
    segments = list(spec.segments) + [tail]
    for seg in segments:
        end = start + seg.duration_s
        inside = (t >= start) & (t < end)
        if seg.kind == "singer":
            p, v, a = _singer_segment(
                seg, p, v, a, t, start, end, inside, pos, vel, acc, cast(np.random.Generator, rng)
            )
        else:
            tau = np.where(inside, t - start, 0.0)
            sp, sv, sa = _advance(seg, p, v, a, tau)
            pos[inside], vel[inside], acc[inside] = sp[inside], sv[inside], sa[inside]
            ep, ev, ea = _advance(seg, p, v, a, np.full((n_runs, 1), seg.duration_s))
            p, v, a = ep[:, 0], ev[:, 0], ea[:, 0]
        start = end
    return Truth(t.copy(), pos, vel, acc)


def _singer_segment(
    seg: Segment,
    p: FloatArray,
    v: FloatArray,
    a: FloatArray,
    t: FloatArray,
    start: float,
    end: float,
    inside: np.ndarray,
    pos: FloatArray,
    vel: FloatArray,
    acc: FloatArray,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Sample a Singer random-acceleration segment exactly at the sample times inside it."""
    n_runs, d = p.shape
    model = Singer(time_constant_s=seg.time_constant_s, accel_std_mps2=seg.accel_std_mps2, n_axes=d)
    # acceleration starts from its stationary distribution (independent of the previous one)
    a = rng.standard_normal((n_runs, d)) * seg.accel_std_mps2
    x = np.concatenate([p, v, a], axis=-1)
    now = np.full(n_runs, start)
    for k in range(t.shape[1]):
        active = inside[:, k]
        if not active.any():
            continue
        x = _step(model, x, now, np.where(active, t[:, k], now), rng)
        now = np.where(active, t[:, k], now)
        pos[active, k], vel[active, k], acc[active, k] = (
            x[active, :d],
            x[active, d : 2 * d],
            x[active, 2 * d :],
        )
    x = _step(model, x, now, np.full(n_runs, end), rng)
    return x[:, :d], x[:, d : 2 * d], x[:, 2 * d :]


def _step(
    model: Singer, x: FloatArray, t0: FloatArray, t1: FloatArray, rng: np.random.Generator
) -> FloatArray:
    from .._linalg import matvec, psd_sqrt

    phi, qd = discretize(model, t1 - t0)
    return matvec(phi, x) + matvec(psd_sqrt(qd), rng.standard_normal(x.shape))


def segment_from_mapping(data: dict[str, object], where: str) -> Segment:
    """Build a Segment from a TOML table; ``where`` names it in error messages."""
    known = {
        "kind",
        "duration_s",
        "accel_mps2",
        "jerk_mps3",
        "turn_rate_radps",
        "turn_rate_degps",
        "time_constant_s",
        "accel_std_mps2",
    }
    unknown = set(data) - known
    if unknown:
        raise ValueError(
            f"{where}: unknown keys {sorted(unknown)}; expected some of {sorted(known)}"
        )
    kw = dict(data)
    if "turn_rate_degps" in kw:
        kw["turn_rate_radps"] = float(np.deg2rad(float(kw.pop("turn_rate_degps"))))  # type: ignore[arg-type]
    for key in ("accel_mps2", "jerk_mps3"):
        if key in kw:
            kw[key] = tuple(float(x) for x in kw[key])  # type: ignore[attr-defined]
    try:
        return Segment(**kw)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


__all__ = ["Segment", "TrajectorySpec", "Truth", "segment_from_mapping", "simulate_truth"]
