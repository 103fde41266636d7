"""How fast the extended tracker tells that the crossing is not clear, and how often it is wrong.

Seeded trials on a site, each replayed through the face radar (the simulator's own geometry):

- ``placed``: an object (``OBJECT_BOX``, seed 001's smallest: 0.5 x 0.5 x 1.0 m) appears
  standing at a random point between the barriers with no approach (a fallen load);
- ``stalled``: a car drives in at ``approach_kmh`` and stops between the barriers at a random
  point of the area;

the delay runs from when the object first stands in the area (placed: its appearance; stalled:
its box first touching the area, an event up to ``EARLY_S`` before counting as its own) to the
first ``crossing_not_clear`` event (negative: raised as the car's estimated box arrived). The
background map is learnt first from ``background_s`` of the empty site (a different seed).
``clear_run``
counts the false ``crossing_not_clear`` events over a span with no object in the area, and
``traffic_run`` those of a scene with traffic and trains (the site's ``[scene]``; a train at
every closure on a site with rails), told apart by the simulator's own truth: a raise is
false when no road user (trains aside: the controller's known occupant) is within
``NEAR_M`` of the area between the barriers from ``EARLY_S`` before it to ``EARLY_S`` after,
the area taken as ``barrier_m`` of the crossing along the user's corridor plus half its
length.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..scene.background import BackgroundMap, learn_background
from ..scene.extended_tracker import track_scene_extended
from ..scene.occupancy import AREA_CELL_M, EVENT_NOT_CLEAR, CrossingArea
from ..simulation.faces import FaceRadar, face_returns_of
from ..simulation.motion import read_motion, simulate_replay
from ..simulation.scene import Trains, scene_spec, simulate_scene
from ..site.model import Site

OBJECT_BOX = (0.5, 0.5, 1.0)  # length, width, height [m]
EARLY_S = 1.0  # a stalled car's event up to this before its box touches the area is its own
NEAR_M = 3.0  # a raise for a road user this near the area [m] is early, not false
FAR_AWAY_M = 5000.0  # where the empty site's only "road user" stands (out of every view)


@dataclass(frozen=True)
class ClearanceTrial:
    """One trial: what stood where, and when the tracker said so (NaN: never)."""

    kind: str
    seed: int
    east_m: float
    north_m: float
    delay_s: float
    false_events: int  # crossing_not_clear raised before the object stood in the area


def _replay(site: Site, motion: pd.DataFrame, seed: int, radar: FaceRadar):  # type: ignore[no-untyped-def]
    """Return the detections of motion given as a generic trajectory table."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "motion.csv"
        motion.to_csv(path, index=False)
        return simulate_replay(site, read_motion(path), seed=seed, radar=radar)


def _far_away(duration_s: float) -> pd.DataFrame:
    """Return a pedestrian out of every radar's view: the replay's stand-in for "nobody"."""
    t = np.arange(0.0, duration_s + 1e-9, 0.1)
    return pd.DataFrame({"time_s": t, "object_id": 999, "class": "pedestrian",
                         "x_m": FAR_AWAY_M, "y_m": FAR_AWAY_M, "length_m": 0.5,
                         "width_m": 0.5, "height_m": 1.7, "speed_mps": 0.0,
                         "heading_deg": 0.0})  # fmt: skip


def empty_background(site: Site, radar: FaceRadar, seconds: float, seed: int) -> BackgroundMap:
    """Learn the background from ``seconds`` of the empty site."""
    return learn_background(site, _replay(site, _far_away(seconds), seed, radar).detections)


def _area_point(area: CrossingArea, rng: np.random.Generator) -> tuple[float, float]:
    cells = np.argwhere(area.inside)
    i, j = cells[rng.integers(len(cells))]
    east, north = area.origin + (np.array([i, j]) + rng.uniform(size=2)) * AREA_CELL_M
    return float(east), float(north)


def _placed(point: tuple[float, float], start_s: float, duration_s: float) -> pd.DataFrame:
    t = np.arange(start_s, duration_s + 1e-9, 0.1)
    length, width, height = OBJECT_BOX
    return pd.DataFrame({"time_s": t, "object_id": 1, "class": "object", "x_m": point[0],
                         "y_m": point[1], "length_m": length, "width_m": width,
                         "height_m": height, "speed_mps": 0.0, "heading_deg": 0.0})  # fmt: skip


def _stalled(site: Site, point: tuple[float, float], approach_kmh: float, decel_mps2: float,
             duration_s: float) -> pd.DataFrame:  # fmt: skip
    """Return a car driving along the corridor nearest to ``point`` and stopping there."""
    corridor = min(site.corridors, key=lambda c: float(np.abs(c.path.project(np.array(point))[1])))
    u_stop, d = (float(v) for v in corridor.path.project(np.array(point)))
    v0 = approach_kmh / 3.6
    braking = v0**2 / (2 * decel_mps2)
    t = np.arange(0.0, duration_s + 1e-9, 0.1)
    t_brake = max(u_stop - braking - 60.0, 0.0) / v0  # start 60 m + braking before the stop
    u0 = u_stop - braking - v0 * t_brake
    tb = np.clip(t - t_brake, 0.0, v0 / decel_mps2)
    u = np.where(t < t_brake, u0 + v0 * t, u0 + v0 * t_brake + v0 * tb - 0.5 * decel_mps2 * tb**2)
    speed = np.where(t < t_brake, v0, v0 - decel_mps2 * tb)
    xy = corridor.path.lane_point(u, d)
    heading = np.interp(u, corridor.path.s, corridor.path.heading)
    return pd.DataFrame({"time_s": t, "object_id": 1, "class": "car", "x_m": xy[:, 0],
                         "y_m": xy[:, 1], "length_m": 4.5, "width_m": 1.8, "height_m": 1.5,
                         "speed_mps": speed,
                         "heading_deg": np.degrees(heading) % 360.0})  # fmt: skip


def clearance_trials(
    site: Site,
    kind: str,
    seeds: range,
    *,
    radar: FaceRadar | None = None,
    duration_s: float = 20.0,
    placed_at_s: float = 10.0,
    approach_kmh: float = 40.0,
    decel_mps2: float = 3.0,
    background_s: float = 60.0,
) -> list[ClearanceTrial]:
    """Run trials of ``kind`` (``placed`` or ``stalled``), one per seed (module docstring)."""
    if kind not in ("placed", "stalled"):
        raise ValueError(f"kind must be 'placed' or 'stalled'; got {kind!r}")
    radar = radar or FaceRadar.of_kind("cluster")
    background = empty_background(site, radar, background_s, seed=10_000)
    area = CrossingArea(site)
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        point = _area_point(area, rng)
        if kind == "placed":
            motion, since = _placed(point, placed_at_s, duration_s), placed_at_s
        else:
            motion = _stalled(site, point, approach_kmh, decel_mps2, duration_s)
            inside = area.touches(
                motion[["x_m", "y_m"]].to_numpy(),
                np.radians(90.0 - motion["heading_deg"].to_numpy()),
                4.5,
                1.8,
            )
            since = float(motion["time_s"].iloc[int(np.argmax(inside))]) if inside.any() else np.nan
        rec = _replay(site, pd.concat([motion, _far_away(duration_s)]), seed, radar)
        _, events, _ = track_scene_extended(site, rec.detections, background=background)
        raised = events.loc[events["event"] == EVENT_NOT_CLEAR, "time_s"].to_numpy()
        # a moving car's estimated box may touch the area a little before its true one
        early = EARLY_S if kind == "stalled" else 0.05
        after = raised[raised >= since - early]
        out.append(ClearanceTrial(kind, seed, point[0], point[1],
                                  float(after[0] - since) if after.size else np.nan,
                                  int((raised < since - early).sum())))  # fmt: skip
    return out


def clear_run(site: Site, seconds: float, seed: int, radar: FaceRadar | None = None) -> int:
    """Count false ``crossing_not_clear`` events over ``seconds`` of the empty site.

    The background is learnt from another seed.
    """
    radar = radar or FaceRadar.of_kind("cluster")
    background = empty_background(site, radar, 60.0, seed=10_000)
    rec = _replay(site, _far_away(seconds), seed, radar)
    _, events, _ = track_scene_extended(site, rec.detections, background=background)
    return int((events["event"] == EVENT_NOT_CLEAR).sum())


@dataclass(frozen=True)
class TrafficRun:
    """The ``crossing_not_clear`` raises of a scene with traffic, and its trains.

    Each raise had a road user in the area, one near it (within ``NEAR_M``), or none (false).
    """

    seconds: float
    raised: int
    in_area: int
    near: int
    false: int
    trains: int
    false_times_s: tuple[float, ...]


def traffic_run(
    site: Site, seconds: float, seed: int, radar: FaceRadar | None = None
) -> TrafficRun:
    """Track ``seconds`` of the site's scene with trains; sort the "not clear" raises.

    The background is learnt from 60 s of the empty site (another seed); the tracker is told
    the warning intervals as the times a train is due.
    """
    if not (np.isfinite(seconds) and seconds > 0):
        raise ValueError(f"traffic_run: seconds must be finite and > 0; got {seconds}")
    radar = radar or FaceRadar.of_kind("cluster")
    spec = scene_spec(site, duration_s=seconds)
    if spec.trains is None and site.rails is not None:
        spec = scene_spec(site, duration_s=seconds, trains=Trains())
    rec = simulate_scene(site, spec, seed, face_returns_of(radar))
    background = empty_background(site, radar, 60.0, seed=10_000 + seed)
    _, events, _ = track_scene_extended(site, rec.detections, background=background,
                                        train_intervals=spec.warnings())  # fmt: skip
    raised = np.sort(events.loc[events["event"] == EVENT_NOT_CLEAR, "time_s"].to_numpy())
    truth, users = rec.truth.table, rec.truth.users
    truth = truth[truth["vehicle_class"] != "train"].sort_values("time_s", kind="stable")
    length = truth["object_id"].map(users.set_index("object_id")["length_m"]).to_numpy()
    barrier = max([site.barrier_m, *site.barriers.values()])
    beyond = np.abs(truth["to_crossing_m"].to_numpy()) - barrier - 0.5 * length  # [m]
    beyond = np.where(np.isfinite(beyond), beyond, np.inf)
    t = truth["time_s"].to_numpy()
    lo, hi = np.searchsorted(t, raised - EARLY_S), np.searchsorted(t, raised + EARLY_S, "right")
    kinds = []
    for a, b in zip(lo, hi, strict=True):
        gap = float(beyond[a:b].min()) if b > a else np.inf
        kinds.append("in" if gap <= 0 else "near" if gap <= NEAR_M else "false")
    kinds_a = np.array(kinds, dtype=object)
    return TrafficRun(seconds, len(raised), int((kinds_a == "in").sum()),
                      int((kinds_a == "near").sum()), int((kinds_a == "false").sum()),
                      len(spec.closures()) if spec.trains is not None else 0,
                      tuple(float(x) for x in raised[kinds_a == "false"]))  # fmt: skip


__all__ = [
    "OBJECT_BOX",
    "ClearanceTrial",
    "TrafficRun",
    "clear_run",
    "clearance_trials",
    "empty_background",
    "traffic_run",
]
