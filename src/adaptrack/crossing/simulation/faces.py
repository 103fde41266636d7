"""Radar returns from the faces of road users' boxes: what a real radar sees of them.

Written from the physics with its own geometry (no helper shared with the trackers):

- each road user is a box of its length, width and height (``CLASS_HEIGHT_M`` unless the
  motion gives one) standing on the road with its heading;
- the antenna stands ``mount_height_m`` above the road (default: the radar's ``height_m``,
  which the site gives above the reflection points, plus ``REFLECTION_HEIGHT_M``); it sees a
  vertical face when it lies outside the face's plane, and the roof when it is above it;
- reflections fall on the visible faces with probability proportional to the face's area
  projected on the line of sight (a roof at grazing sight reflects ``ROOF_GAIN`` of that),
  uniformly over the face, between ``SIDE_HEIGHTS`` of the body's height on a side face;
- a reflection is lost when the segment from the antenna to it passes through another box
  (occlusion in 3-D from the antenna height); each is detected with the site's
  ``P_D(class, range)``; the radial speed is the body's velocity along the line of sight,
  walkers' and riders' limbs adding ``LIMB_DOPPLER_FRACTION`` of their speed at random.

Three radar kinds (:class:`FaceRadar`):

- ``object``: one return per road user and scan, at the centroid of ``OBJECT_SAMPLES``
  visible reflections (an ARS408-style object list: the reported point lies on the near
  faces, not at the body centre);
- ``cluster``: a few returns per road user, ``cluster_points_per_m`` of visible extent,
  1 to ``cluster_max_points``;
- ``cloud``: tens of returns per body (a TI mmWave or 4-D imaging radar): a negative-binomial
  count of mean ``cloud_points_per_m2`` per square metre of projected visible area (within
  ``cloud_full_range_m``; falling as ``1/r^2`` beyond) and shape ``cloud_count_shape`` (the
  scan-to-scan fluctuation of the radar cross-section), with measured elevations (noise
  ``elevation_std_deg``) and radial speeds quantised to ``doppler_step_mps``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numba
import numpy as np

from ..._typing import FloatArray
from ..site.sensor import RadarSpec
from .scene import BodyReturns, ScanStates, SceneSpec

RadarKind = Literal["object", "cluster", "cloud"]
RADAR_KINDS: tuple[str, ...] = ("object", "cluster", "cloud")
CLASS_HEIGHT_M = {  # a box's height when the motion gives none [m]
    "car": 1.5,
    "truck": 3.5,
    "bus": 3.2,
    "motorcycle": 1.4,
    "pedestrian": 1.75,
    "cyclist": 1.7,
}
DEFAULT_HEIGHT_M = 1.5  # a class not listed
REFLECTION_HEIGHT_M = 0.5  # the site's radar height_m is above a reflection point this high
SIDE_HEIGHTS = (0.15, 0.85)  # reflections on a side face span these fractions of the height
ROOF_GAIN = 0.3  # a roof reflects this much of its projected area (grazing sight)
OBJECT_SAMPLES = 12  # reflections averaged into an object-list return
LIMB_DOPPLER_FRACTION = 0.3  # walkers and riders: limb speed spread, a fraction of the speed
LIMBED = ("pedestrian", "cyclist")
FACES = 5  # front, rear, right, left, roof


@dataclass(frozen=True)
class FaceRadar:
    """The face model's radar kind and its parameters (module docstring).

    The point cloud's density and count shape are fitted (rounded) to a real 77 GHz TI
    AWR1843 recording of a person walking by ``python -m benchmarks.point_cloud_stats
    DATA_DIR``, which checks them on a person running and an e-scooter passing; the
    elevation noise is a prior (the recording's vertical spread, 0.34 m, lies below the
    model's body alone, 0.39 m, so it does not identify it).
    """

    kind: RadarKind = "cluster"
    mount_height_m: float | None = None
    cluster_points_per_m: float = 0.6
    cluster_max_points: int = 4
    cloud_points_per_m2: float = 18.0
    cloud_count_shape: float = 2.0
    cloud_full_range_m: float = 10.0
    elevation_std_deg: float = 6.0
    doppler_step_mps: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in RADAR_KINDS:
            raise ValueError(
                f"radar kind must be one of {', '.join(RADAR_KINDS)}; got {self.kind!r}"
            )
        positive = ("cluster_points_per_m", "cloud_points_per_m2", "cloud_count_shape",
                    "cloud_full_range_m")  # fmt: skip
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"face radar: {name} must be > 0; got {getattr(self, name)}")
        if self.cluster_max_points < 1 or self.elevation_std_deg < 0:
            raise ValueError("face radar: cluster_max_points >= 1 and elevation_std_deg >= 0")
        if self.doppler_step_mps is not None and not self.doppler_step_mps > 0:
            raise ValueError("face radar: doppler_step_mps must be > 0 (or None)")

    @classmethod
    def of_kind(cls, kind: str) -> FaceRadar:
        """Return the defaults of a kind (a point cloud quantises Doppler in 0.44 m/s steps)."""
        radar = cls(kind=kind)  # type: ignore[arg-type]
        return replace(radar, doppler_step_mps=0.44) if kind == "cloud" else radar

    def antenna_height(self, radar: RadarSpec) -> float:
        """Antenna height above the road [m]."""
        if self.mount_height_m is not None:
            return self.mount_height_m
        return radar.height_m + REFLECTION_HEIGHT_M


def box_heights(st: ScanStates) -> FloatArray:
    """Box height per row [m]: the motion's, else the class's."""
    by_class = np.array([CLASS_HEIGHT_M.get(str(c), DEFAULT_HEIGHT_M) for c in st.vehicle_class])
    return np.where(np.isnan(st.height), by_class, st.height)


def face_frames(
    centre: FloatArray, forward: FloatArray, length: FloatArray, width: FloatArray,
    height: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """Return each box's five faces: centre, outward normal, two half-extent vectors.

    Each (N, 5, 3) [m]; faces in the order front, rear, right, left, roof.
    """
    n = centre.shape[0]
    f = np.concatenate([forward, np.zeros((n, 1))], -1)
    r = np.stack([forward[:, 1], -forward[:, 0], np.zeros(n)], -1)  # right of the heading
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    c = np.concatenate([centre, 0.5 * height[:, None]], -1)
    hl, hw, hh = (0.5 * a[:, None] for a in (length, width, height))
    normal = np.stack([f, -f, r, -r, up], 1)
    mid = np.stack([c + hl * f, c - hl * f, c + hw * r, c - hw * r, c + hh * up], 1)
    span_a = np.stack([hw * r, hw * r, hl * f, hl * f, hl * f], 1)
    span_b = np.stack([hh * up, hh * up, hh * up, hh * up, hw * r], 1)
    return mid, normal, span_a, span_b


def visible_weights(
    antenna: FloatArray, mid: FloatArray, normal: FloatArray, span_a: FloatArray,
    span_b: FloatArray,
) -> FloatArray:  # fmt: skip
    """Return each face's area projected on the line of sight from the antenna (N, 5) [m^2].

    Zero for a face the antenna is behind; the roof's is scaled by ``ROOF_GAIN``.
    """
    sight = antenna[None, None, :] - mid
    dist = np.linalg.norm(sight, axis=-1)
    cos = np.einsum("nfk,nfk->nf", sight, normal) / np.maximum(dist, 1e-9)
    area = 4.0 * np.linalg.norm(span_a, axis=-1) * np.linalg.norm(span_b, axis=-1)
    w = np.where(cos > 0.0, area * cos, 0.0)
    w[:, 4] *= ROOF_GAIN
    return w


def draw_points(
    rows: np.ndarray, weights: FloatArray, mid: FloatArray, span_a: FloatArray,
    span_b: FloatArray, rng: np.random.Generator,
) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
    """Draw reflection points (K, 3) on the visible faces of ``rows`` (K,), and their faces.

    A point's face is drawn by the faces' weights, its place uniformly over the face.
    """
    w = weights[rows]
    cum = np.cumsum(w, axis=1)
    pick = (rng.uniform(size=rows.size) * cum[:, -1])[:, None]
    face = np.minimum((cum < pick).sum(axis=1), FACES - 1)
    a = rng.uniform(-1.0, 1.0, rows.size)
    b = rng.uniform(-1.0, 1.0, rows.size)
    lo, hi = SIDE_HEIGHTS
    side = face < 4
    b = np.where(side, (lo + (hi - lo) * 0.5 * (b + 1.0)) * 2.0 - 1.0, b)  # side: lo..hi of H
    point = mid[rows, face] + a[:, None] * span_a[rows, face] + b[:, None] * span_b[rows, face]
    return point, face


@numba.njit(cache=True)
def occluded_points(antenna, point, owner, scan_of, centre, forward, half, height):  # type: ignore[no-untyped-def]
    """Whether the segment antenna -> point (K, 3) passes through another box of its scan.

    Boxes (N,): ``centre`` (N, 2), unit ``forward`` (N, 2), half length and width ``half``
    (N, 2), ``height`` (N,); ``owner`` (K,) the box of each point, ``scan_of`` (N,) per box.
    Slab test in each box's own frame.
    """
    out = np.zeros(point.shape[0], dtype=np.bool_)
    order = np.argsort(scan_of, kind="mergesort")
    first = np.searchsorted(scan_of[order], scan_of)
    last = np.searchsorted(scan_of[order], scan_of, side="right")
    for k in range(point.shape[0]):
        i = owner[k]
        d = (point[k, 0] - antenna[0], point[k, 1] - antenna[1], point[k, 2] - antenna[2])
        for m in range(first[i], last[i]):
            j = order[m]
            if j == i:
                continue
            fx, fy = forward[j, 0], forward[j, 1]
            ox, oy = antenna[0] - centre[j, 0], antenna[1] - centre[j, 1]
            o = (ox * fx + oy * fy, ox * fy - oy * fx, antenna[2] - 0.5 * height[j])
            v = (d[0] * fx + d[1] * fy, d[0] * fy - d[1] * fx, d[2])
            ext = (half[j, 0], half[j, 1], 0.5 * height[j])
            t0, t1 = 0.0, 1.0 - 1e-9
            hit = True
            for ax in range(3):
                if abs(v[ax]) < 1e-12:
                    if abs(o[ax]) > ext[ax]:
                        hit = False
                        break
                    continue
                ta = (-ext[ax] - o[ax]) / v[ax]
                tb = (ext[ax] - o[ax]) / v[ax]
                if ta > tb:
                    ta, tb = tb, ta
                t0 = max(t0, ta)
                t1 = min(t1, tb)
                if t0 > t1:
                    hit = False
                    break
            if hit:
                out[k] = True
                break
    return out


def face_returns_of(face_radar: FaceRadar):  # type: ignore[no-untyped-def]
    """Return the reflection model of :func:`~adaptrack.crossing.simulation.scene.detect`."""

    def returns(
        radar: RadarSpec, spec: SceneSpec, st: ScanStates, rng: np.random.Generator
    ) -> BodyReturns:
        return face_returns(face_radar, radar, spec, st, rng)

    return returns


def face_returns(
    fr: FaceRadar, radar: RadarSpec, spec: SceneSpec, st: ScanStates, rng: np.random.Generator
) -> BodyReturns:
    """Reflections of the road users' boxes in one radar's scans (module docstring)."""
    h_ant = fr.antenna_height(radar)
    antenna = np.array([radar.position_m[0], radar.position_m[1], h_ant])
    height = box_heights(st)
    mid, normal, span_a, span_b = face_frames(st.centre, st.forward, st.length, st.width, height)
    weights = visible_weights(antenna, mid, normal, span_a, span_b)
    extent = np.sqrt(weights.sum(axis=1))  # a length scale of what is seen [m]
    ground = st.centre - antenna[:2]
    dist = np.hypot(ground[:, 0], ground[:, 1])
    if fr.kind == "object":
        count = np.full(st.centre.shape[0], OBJECT_SAMPLES)
    elif fr.kind == "cluster":
        draw = rng.uniform(0.6, 1.4, dist.size)
        count = np.clip(np.rint(fr.cluster_points_per_m * extent * draw), 1, fr.cluster_max_points)
        count = count.astype(np.int64)
    else:
        fall = np.minimum(1.0, (fr.cloud_full_range_m / np.maximum(dist, 1e-3)) ** 2)
        mean = fr.cloud_points_per_m2 * weights.sum(axis=1) * fall
        shape = fr.cloud_count_shape
        count = rng.poisson(rng.gamma(shape, mean / shape)).astype(np.int64)
    reach = max(f.max_range_m for f in radar.fields) + 20.0
    count = np.where((weights.sum(axis=1) > 0) & (dist < reach), count, 0)
    rows = np.repeat(np.arange(count.size), count)
    point, _ = draw_points(rows, weights, mid, span_a, span_b, rng)
    half = 0.5 * np.stack([st.length, st.width], -1)
    hidden = (
        occluded_points(
            antenna, point, rows, st.scan_of.astype(np.int64), st.centre, st.forward, half, height
        )
        if (spec.occlusion and rows.size)
        else np.zeros(rows.size, bool)
    )
    vel = st.velocity[rows]
    if fr.kind == "object":  # one return per user: the centroid of what it sees
        keep = ~hidden
        n_seen = np.bincount(rows[keep], minlength=count.size)
        sums = np.stack([np.bincount(rows[keep], point[keep, k], minlength=count.size)
                         for k in range(3)], -1)  # fmt: skip
        seen_rows = np.flatnonzero(n_seen > 0)
        point = sums[seen_rows] / n_seen[seen_rows, None]
        rows, hidden, vel = seen_rows, np.zeros(seen_rows.size, bool), st.velocity[seen_rows]
    rel = point - antenna
    slant = np.sqrt((rel**2).sum(axis=1))
    azimuth = np.arctan2(rel[:, 0], rel[:, 1])
    elevation = np.arcsin(np.clip(rel[:, 2] / np.maximum(slant, 1e-9), -1.0, 1.0))
    radial = (rel[:, 0] * vel[:, 0] + rel[:, 1] * vel[:, 1]) / np.maximum(slant, 1e-9)
    limbs = np.isin(st.vehicle_class[rows].astype(str), LIMBED)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    radial = radial + limbs * LIMB_DOPPLER_FRACTION * speed * rng.standard_normal(rows.size)
    p_d = np.empty(rows.size)
    cls = st.vehicle_class[rows].astype(str)
    for c in np.unique(cls):
        m = cls == c
        p_d[m] = radar.detection_curve(str(c))(slant[m])
    seen = ~hidden & _in_fields(radar, slant, azimuth) & (rng.uniform(size=rows.size) < p_d)
    if not spec.stationary_detections:
        seen &= np.abs(radial) >= radar.min_radial_speed_mps
    elev = None
    if fr.kind == "cloud":
        elev = elevation[seen] + math.radians(fr.elevation_std_deg) * rng.standard_normal(
            seen.sum()
        )
    return BodyReturns(
        st.scan_of[rows[seen]], slant[seen], azimuth[seen], radial[seen],
        st.object_id[rows[seen]], elev, fr.doppler_step_mps,
    )  # fmt: skip


def _in_fields(radar: RadarSpec, slant: FloatArray, azimuth: FloatArray) -> np.ndarray:
    """Whether returns lie in one of the radar's fields and beyond its shortest range."""
    off = np.abs(np.angle(np.exp(1j * (azimuth - radar.boresight_rad))))
    inside = np.zeros(slant.size, bool)
    for f in radar.fields:
        inside |= (slant <= f.max_range_m) & (off <= f.half_angle_rad)
    return inside & (slant >= radar.min_range_m)


__all__ = [
    "CLASS_HEIGHT_M",
    "RADAR_KINDS",
    "FaceRadar",
    "RadarKind",
    "box_heights",
    "draw_points",
    "face_frames",
    "face_returns",
    "face_returns_of",
    "occluded_points",
    "visible_weights",
]
