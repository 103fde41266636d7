"""Recorded road-user motion, replayed instead of the traffic model.

Two file layouts (CSV or Parquet), detected from the columns:

- **INTERACTION** (drone-recorded data sets): ``track_id, frame_id, timestamp_ms, agent_type,
  x, y, vx, vy, psi_rad, length, width``; positions of the box centre in the map's metric frame
  [m, m/s], ``psi_rad`` counter-clockwise from the map's x axis. Pedestrian files without
  ``psi_rad``/``length``/``width`` take the heading of the velocity and a 0.5 m x 0.5 m body.
- **generic**: ``time_s, object_id, class, x_m, y_m, length_m, width_m`` and optionally
  ``speed_mps`` with ``heading_deg`` (clockwise from north, the site's convention; both or
  neither: without them the motion is differentiated from the positions) and ``height_m``.
  Geodetic positions ``lat_deg, lon_deg`` (WGS-84) replace ``x_m, y_m``; they need an origin.

A :class:`MotionTransform` puts the file's frame onto the site's (east, north, origin at the
crossing centre): ``site = R(rotation) (p - origin)``, ``R`` turning counter-clockwise, or,
for geodetic files, the local east-north-up plane at a geodetic origin. The replay resamples
every road user at the traffic model's step (linear in position and velocity between the
recorded samples, never beyond a user's first and last sample, never across a gap longer than
``MAX_GAP_S``) and returns a :class:`~adaptrack.crossing.simulation.scene.SceneTruth` like the
traffic model's, so the radar models and the scorers take it unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ...coords.geodetic import ecef_to_enu, geodetic_to_ecef
from ...io.tables import DataFormatError, numeric_column, read_table, require_columns
from ..site.model import Site
from .faces import FaceRadar, face_returns_of
from .scene import STEP_S, SceneRecording, SceneSpec, SceneTruth, detect, symmetric_returns

INTERACTION_COLUMNS = ["track_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy"]
GENERIC_COLUMNS = ["time_s", "object_id", "class", "length_m", "width_m"]
AGENT_CLASSES = {  # INTERACTION agent_type -> the site's class names
    "car": "car",
    "truck": "truck",
    "bus": "bus",
    "truck_bus": "bus",
    "motorcycle": "motorcycle",
    "bicycle": "cyclist",
    "pedestrian": "pedestrian",
    "pedestrian/bicycle": "pedestrian",
}
WALKER_SIZE_M = 0.5  # a pedestrian record without a size: 0.5 m x 0.5 m
MAX_GAP_S = 1.0  # a user unseen longer than this is not interpolated across the gap
STILL_MPS = 0.05  # slower than this, a heading is kept from the last motion (a still body)


@dataclass(frozen=True)
class MotionTransform:
    """The file's frame onto the site's: ``site = R(rotation_deg) (p - origin_m)``.

    ``rotation_deg`` turns counter-clockwise; for geodetic files ``geodetic_origin`` is
    ``(lat_deg, lon_deg)`` of the crossing centre (the east-north plane there).
    """

    origin_m: tuple[float, float] = (0.0, 0.0)
    rotation_deg: float = 0.0
    geodetic_origin: tuple[float, float] | None = None

    def positions(self, xy: np.ndarray) -> np.ndarray:
        """Site east, north (N, 2) [m] of file positions (N, 2) [m]."""
        c, s = math.cos(math.radians(self.rotation_deg)), math.sin(math.radians(self.rotation_deg))
        p = xy - np.asarray(self.origin_m, dtype=float)
        return np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]], -1)

    def vectors(self, v: np.ndarray) -> np.ndarray:
        """Site east, north components (N, 2) of file vectors (N, 2) (rotation only)."""
        c, s = math.cos(math.radians(self.rotation_deg)), math.sin(math.radians(self.rotation_deg))
        return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], -1)


@dataclass(frozen=True, eq=False)
class RecordedMotion:
    """Samples of recorded motion in the site frame, one row per user and sample.

    ``table``: object_id, vehicle_class, time_s, east_m, north_m, east_speed_mps,
    north_speed_mps, heading_rad (clockwise from north); ``users``: object_id,
    vehicle_class, length_m, width_m, height_m (NaN: the class's).
    """

    table: pd.DataFrame
    users: pd.DataFrame
    layout: str


def read_motion(path: str | Path, transform: MotionTransform | None = None) -> RecordedMotion:
    """Read a recorded-motion file (INTERACTION or generic layout; module docstring).

    Errors name the file, row and column: missing columns, non-numbers, non-positive sizes,
    times that repeat or run backwards within one road user.
    """
    p = Path(path)
    frame = read_table(p)
    tf = transform or MotionTransform()
    if "track_id" in frame.columns:
        return _interaction(frame, p, tf)
    if "time_s" in frame.columns:
        return _generic(frame, p, tf)
    raise DataFormatError(
        f"{p}: not a motion file: needs the INTERACTION columns {INTERACTION_COLUMNS} or the "
        f"generic ones {GENERIC_COLUMNS} with x_m, y_m (or lat_deg, lon_deg); found "
        f"{list(frame.columns)}"
    )


def _interaction(frame: pd.DataFrame, p: Path, tf: MotionTransform) -> RecordedMotion:
    require_columns(frame, INTERACTION_COLUMNS, p)
    if tf.geodetic_origin is not None:
        raise DataFormatError(
            f"{p}: INTERACTION positions are metric; give an offset, not a geodetic origin"
        )
    ids = _integer_ids(frame, "track_id", p)
    t = numeric_column(frame, "timestamp_ms", p) / 1000.0
    xy = np.stack([numeric_column(frame, c, p) for c in ("x", "y")], -1)
    v = np.stack([numeric_column(frame, c, p) for c in ("vx", "vy")], -1)
    agent = frame["agent_type"].astype(str).str.strip().str.lower().to_numpy()
    unknown = ~np.isin(agent, list(AGENT_CLASSES))
    if unknown.any():
        row = int(np.argmax(unknown))
        raise DataFormatError(
            f"{p}: row {row + 1}, column 'agent_type': unknown type {agent[row]!r}; known: "
            f"{', '.join(AGENT_CLASSES)}"
        )
    cls = np.array([AGENT_CLASSES[a] for a in agent], dtype=object)
    size = {}
    for col in ("length", "width"):
        size[col] = (
            numeric_column(frame, col, p, allow_nan=True)
            if col in frame.columns
            else np.full(len(frame), np.nan)
        )
        size[col] = np.where(np.isnan(size[col]) & (cls == "pedestrian"), WALKER_SIZE_M, size[col])
    east_north = tf.positions(xy)
    vel = tf.vectors(v)
    if "psi_rad" in frame.columns:
        psi = numeric_column(frame, "psi_rad", p, allow_nan=True)
        heading = math.pi / 2 - psi - math.radians(tf.rotation_deg)
    else:
        heading = np.full(len(frame), np.nan)
    heading = np.where(np.isnan(heading), np.arctan2(vel[:, 0], vel[:, 1]), heading)
    return _assemble(p, ids, cls, t, east_north, vel, heading, size["length"], size["width"],
                     np.full(len(frame), np.nan), "interaction")  # fmt: skip


def _generic(frame: pd.DataFrame, p: Path, tf: MotionTransform) -> RecordedMotion:
    require_columns(frame, GENERIC_COLUMNS, p)
    ids = _integer_ids(frame, "object_id", p)
    t = numeric_column(frame, "time_s", p)
    if {"x_m", "y_m"} <= set(frame.columns):
        xy = np.stack([numeric_column(frame, c, p) for c in ("x_m", "y_m")], -1)
        east_north = tf.positions(xy)
    elif {"lat_deg", "lon_deg"} <= set(frame.columns):
        if tf.geodetic_origin is None:
            raise DataFormatError(
                f"{p}: geodetic positions need a geodetic origin (--origin LAT,LON)"
            )
        lat, lon = (numeric_column(frame, c, p) for c in ("lat_deg", "lon_deg"))
        ecef = geodetic_to_ecef(np.radians(lat), np.radians(lon), np.zeros(lat.size))
        lat0, lon0 = (math.radians(a) for a in tf.geodetic_origin)
        east_north = tf.positions(ecef_to_enu(ecef, lat0, lon0, 0.0)[:, :2])
    else:
        raise DataFormatError(f"{p}: needs positions x_m, y_m or lat_deg, lon_deg")
    cls = frame["class"].astype(str).str.strip().to_numpy().astype(object)
    has = {"speed_mps", "heading_deg"} & set(frame.columns)
    if len(has) == 1:
        raise DataFormatError(
            f"{p}: speed_mps and heading_deg come together; found only {has.pop()}"
        )
    if has:
        speed = numeric_column(frame, "speed_mps", p)
        heading = np.radians(numeric_column(frame, "heading_deg", p)) - math.radians(
            tf.rotation_deg
        )
        vel = speed[:, None] * np.stack([np.sin(heading), np.cos(heading)], -1)
    else:
        vel, heading = np.full((len(frame), 2), np.nan), np.full(len(frame), np.nan)
    height = numeric_column(frame, "height_m", p) if "height_m" in frame.columns else None
    return _assemble(
        p, ids, cls, t, east_north, vel, heading, numeric_column(frame, "length_m", p),
        numeric_column(frame, "width_m", p),
        np.full(len(frame), np.nan) if height is None else height, "generic",
    )  # fmt: skip


def _integer_ids(frame: pd.DataFrame, column: str, p: Path) -> np.ndarray:
    values = numeric_column(frame, column, p)
    bad = values != np.round(values)
    if bad.any():
        row = int(np.argmax(bad))
        raise DataFormatError(f"{p}: row {row + 1}, column {column!r}: not an integer id")
    return values.astype(np.int64)


def _assemble(p, ids, cls, t, xy, vel, heading, length, width, height, layout):  # type: ignore[no-untyped-def]
    for name, values in (("length", length), ("width", width)):
        bad = ~(values > 0)
        if bad.any():
            row = int(np.argmax(bad))
            raise DataFormatError(
                f"{p}: row {row + 1}: the body's {name} must be > 0 m; got {values[row]}"
            )
    bad_h = ~np.isnan(height) & ~(height > 0)
    if bad_h.any():
        row = int(np.argmax(bad_h))
        raise DataFormatError(f"{p}: row {row + 1}, column 'height_m': must be > 0 m")
    order = np.lexsort((t, ids))
    ids_o, t_o = ids[order], t[order]
    same = ids_o[1:] == ids_o[:-1]
    back = same & (np.diff(t_o) <= 0)
    if back.any():
        row = int(order[np.argmax(back) + 1])
        oid = ids_o[np.argmax(back) + 1]
        raise DataFormatError(
            f"{p}: row {row + 1}: time repeats or runs backwards for object {oid}"
        )
    xy, vel, heading = xy[order], vel[order], heading[order]
    starts = np.flatnonzero(np.concatenate([[True], ~same]))
    for a, b in zip(starts, np.append(starts[1:], ids_o.size), strict=True):
        if np.isnan(vel[a:b]).any():  # differentiate the positions (one sample: at rest)
            for k in range(2):
                vel[a:b, k] = np.gradient(xy[a:b, k], t_o[a:b]) if b - a > 1 else 0.0
            heading[a:b] = np.arctan2(vel[a:b, 0], vel[a:b, 1])
        still = np.hypot(vel[a:b, 0], vel[a:b, 1]) < STILL_MPS
        h = heading[a:b]
        for k in range(1, h.size):  # a still body keeps the heading it had
            if still[k] and not still[k - 1]:
                h[k] = h[k - 1]
    table = pd.DataFrame(
        {
            "object_id": ids_o,
            "vehicle_class": cls[order],
            "time_s": t_o,
            "east_m": xy[:, 0],
            "north_m": xy[:, 1],
            "east_speed_mps": vel[:, 0],
            "north_speed_mps": vel[:, 1],
            "heading_rad": np.mod(heading, 2 * math.pi),
        }
    )
    first = table.groupby("object_id", sort=True).head(1).index
    users = pd.DataFrame(
        {
            "object_id": ids_o[first],
            "vehicle_class": cls[order][first],
            "length_m": np.asarray(length)[order][first],
            "width_m": np.asarray(width)[order][first],
            "height_m": np.asarray(height)[order][first],
        }
    )
    return RecordedMotion(table, users.reset_index(drop=True), layout)


def replay_truth(motion: RecordedMotion, site: Site, start_s: float | None = None) -> SceneTruth:
    """Resample recorded motion on the traffic model's step; the scene truth of a replay.

    Time 0 of the replay is ``start_s`` of the file (default: its first sample). Users keep
    the file's ids. ``to_crossing_m`` is the distance from the crossing centre, positive
    while the user approaches it; ``in_zone`` is within ``site.zone_m`` of the centre.
    """
    tab = motion.table
    t0 = float(tab["time_s"].min()) if start_s is None else start_s
    parts = []
    for oid, g in tab.groupby("object_id", sort=True):
        t = g["time_s"].to_numpy() - t0
        k = np.arange(math.ceil(t[0] / STEP_S - 1e-9), math.floor(t[-1] / STEP_S + 1e-9) + 1)
        grid = k * STEP_S
        grid = grid[grid >= 0.0]
        if grid.size == 0:
            continue
        j = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 1)
        nxt = np.minimum(j + 1, t.size - 1)
        gap = t[nxt] - t[j]
        keep = (gap <= MAX_GAP_S) | (np.abs(grid - t[j]) < 1e-9)
        grid, j, nxt = grid[keep], j[keep], nxt[keep]
        w = np.where(t[nxt] > t[j], (grid - t[j]) / np.maximum(t[nxt] - t[j], 1e-12), 0.0)

        def lerp(col: str, j=j, nxt=nxt, w=w, g=g) -> np.ndarray:  # type: ignore[no-untyped-def]
            a = g[col].to_numpy()
            return a[j] + w * (a[nxt] - a[j])

        hd = g["heading_rad"].to_numpy()
        dh = np.angle(np.exp(1j * (hd[nxt] - hd[j])))
        parts.append(
            pd.DataFrame(
                {
                    "object_id": oid,
                    "vehicle_class": g["vehicle_class"].iloc[0],
                    "time_s": grid,
                    "east_m": lerp("east_m"),
                    "north_m": lerp("north_m"),
                    "east_speed_mps": lerp("east_speed_mps"),
                    "north_speed_mps": lerp("north_speed_mps"),
                    "heading_rad": np.mod(hd[j] + w * dh, 2 * math.pi),
                }
            )
        )
    cols = ["object_id", "vehicle_class", "time_s", "east_m", "north_m", "east_speed_mps",
            "north_speed_mps", "heading_rad"]  # fmt: skip
    table = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=cols)
    ve, vn = table["east_speed_mps"].to_numpy(float), table["north_speed_mps"].to_numpy(float)
    e, n = table["east_m"].to_numpy(float), table["north_m"].to_numpy(float)
    dist = np.hypot(e, n)
    approaching = e * ve + n * vn < 0.0
    table["speed_mps"] = np.hypot(ve, vn)
    table["to_crossing_m"] = np.where(approaching, dist, -dist)
    table["in_zone"] = dist <= site.zone_m
    table = table.sort_values(["time_s", "object_id"], kind="stable", ignore_index=True)
    first = table.groupby("object_id", sort=True)["time_s"].min()
    users = motion.users[motion.users["object_id"].isin(first.index)].copy()
    users["arrival_s"] = users["object_id"].map(first).to_numpy()
    return SceneTruth(
        table,
        users.reset_index(drop=True),
        np.zeros((0, 2)),
        pd.DataFrame({"object_id": [], "stop_time_s": []}),
        pd.DataFrame({"object_id": [], "cross_time_s": []}),
    )


def replay_spec(site: Site, duration_s: float) -> SceneSpec:
    """Return the scene settings of a replay.

    The site's clutter, multipath and occlusion keys of ``[scene]``; flows, mix, closures and
    stalls are the recording's, so none are drawn.
    """
    data = site.source.get("scene", {})
    keep = ("false_alarms_per_scan", "multipath_probability", "multipath_extra_m", "occlusion",
            "stationary_detections")  # fmt: skip
    clutter = tuple(tuple(p) for p in data.get("static_clutter_m", []))
    return SceneSpec(duration_s=duration_s, closure_s=0.0, static_clutter_m=clutter,
                     **{k: data[k] for k in keep if k in data})  # fmt: skip


def simulate_replay(
    site: Site,
    motion: RecordedMotion,
    seed: int,
    radar: FaceRadar | None = None,
    *,
    start_s: float | None = None,
    duration_s: float | None = None,
) -> SceneRecording:
    """Simulate the detections of every site radar watching recorded motion.

    ``radar``: the face model's kind (None: the scene's symmetric reflections); the replay
    runs from ``start_s`` of the file for ``duration_s`` (default: to its last sample).
    """
    truth = replay_truth(motion, site, start_s)
    end = float(truth.table["time_s"].max()) + STEP_S if len(truth.table) else 0.0
    duration = end if duration_s is None else min(duration_s, end)
    if not duration > 0:
        raise ValueError("the recording holds no motion after the replay's start")
    if duration < end:
        keep = truth.table["time_s"] < duration
        truth = replace(truth, table=truth.table[keep].reset_index(drop=True))
    spec = replay_spec(site, duration)
    returns = symmetric_returns if radar is None else face_returns_of(radar)
    det, src = detect(site, spec, truth, np.random.default_rng(seed), returns)
    return SceneRecording(truth, det, src, spec)


__all__ = [
    "MotionTransform",
    "RecordedMotion",
    "read_motion",
    "replay_spec",
    "replay_truth",
    "simulate_replay",
]
