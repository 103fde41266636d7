"""Estimators of a crossing site as picklable callables: simulated runs of a case -> tracks.

A tracker takes the runs of one class x case
(:class:`~adaptrack.crossing.simulation.radar.CrossingRuns`) and the site, and returns
:class:`~.tracking.TrackEstimates`; :meth:`estimate` runs it on detections of a known road and
radar (a recorded file), and :func:`track_objects` on every object of an object list whose ids
are taken as truth. The Monte Carlo (:mod:`.compliance`) and the design-time selection
(:mod:`.selection`) run any mapping of names to trackers, in-process or
on a cluster (the trackers are shipped with their parameters).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..._backend import Backend
from ..._typing import BoolArray, FloatArray
from ...models.continuous import MotionModel
from ..estimators.road_filters import TrackEstimates, track_on_road, track_on_road_imm
from ..measurements_io import ObjectDetections
from ..simulation.radar import CrossingRuns
from ..site.model import Site
from ..site.road import Road
from ..site.sensor import Curve, RadarSpec
from ..site.traffic import Case, VehicleClass

Tracker = Callable[[CrossingRuns, Site, Case, VehicleClass], TrackEstimates]


@dataclass(frozen=True)
class PlanarTracker:
    """A planar tracker on the radar of the case's road.

    ``track`` is :func:`~.tracking.track_free_2d` or :func:`~.tracking.track_converted`;
    ``reads_misses``: whether it takes the class's P_D to interpret missed detections.
    """

    track: Callable[..., TrackEstimates]
    reads_misses: bool = True

    def __call__(
        self, runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass
    ) -> TrackEstimates:
        """Track the runs of one class x case."""
        radar = site.radar_for(case.road)
        kw: dict[str, object] = {"scatter_std_m": veh.scatter_std_m}
        if self.reads_misses:
            kw["detection_probability"] = radar.detection_curve(veh.name)
        times = radar.measured_at(runs.times)
        return self.track(times, runs.measurements, runs.detected, radar, **kw)


@dataclass(frozen=True)
class _RoadTrackerBase:
    """Shared call of the road trackers: runs of a case -> :meth:`estimate` on its road."""

    def estimate(
        self,
        times: FloatArray,
        z: FloatArray,
        detected: BoolArray,
        radar: RadarSpec,
        road: Road,
        scatter_std_m: float,
        detection_probability: Curve | None = None,
    ) -> TrackEstimates:
        """Track detections (N, T, 3) of ``radar`` on ``road`` (overridden).

        ``detection_probability``: the tracked class's P_D against range (default: the
        radar's ``default`` curve).
        """
        raise NotImplementedError

    def __call__(
        self, runs: CrossingRuns, site: Site, case: Case, veh: VehicleClass
    ) -> TrackEstimates:
        """Track the runs of one class x case."""
        radar = site.radar_for(case.road)
        return self.estimate(
            radar.measured_at(runs.times),
            runs.measurements,
            runs.detected,
            radar,
            site.roads[case.road],
            veh.scatter_std_m,
            radar.detection_curve(veh.name),
        )


@dataclass(frozen=True)
class RoadTracker(_RoadTrackerBase):
    """The road-constrained EKF with ``model`` along the road."""

    model: MotionModel
    backend: Backend = "auto"

    def estimate(
        self,
        times: FloatArray,
        z: FloatArray,
        detected: BoolArray,
        radar: RadarSpec,
        road: Road,
        scatter_std_m: float,
        detection_probability: Curve | None = None,
    ) -> TrackEstimates:
        """Track detections (N, T, 3) of ``radar`` on ``road`` (:func:`track_on_road`)."""
        return track_on_road(
            times, z, detected, radar, road, model=self.model, scatter_std_m=scatter_std_m,
            detection_probability=detection_probability, backend=self.backend,
        )  # fmt: skip


@dataclass(frozen=True)
class IMMTracker(_RoadTrackerBase):
    """The road IMM of ``models`` with mean sojourn times ``sojourn_s`` [s]."""

    models: tuple[MotionModel, ...]
    sojourn_s: tuple[float, ...]
    backend: Backend = "auto"

    def estimate(
        self,
        times: FloatArray,
        z: FloatArray,
        detected: BoolArray,
        radar: RadarSpec,
        road: Road,
        scatter_std_m: float,
        detection_probability: Curve | None = None,
    ) -> TrackEstimates:
        """Track detections (N, T, 3) of ``radar`` on ``road`` (:func:`track_on_road_imm`)."""
        return track_on_road_imm(
            times, z, detected, radar, road, models=self.models, sojourn_s=self.sojourn_s,
            scatter_std_m=scatter_std_m, detection_probability=detection_probability,
            backend=self.backend,
        )  # fmt: skip


def track_objects(objects: list[ObjectDetections], site: Site, estimator: Any) -> pd.DataFrame:
    """Track each object of an object list on its own with a road estimator; one table.

    ``estimator`` has :meth:`RoadTracker.estimate` (a road tracker, or the deployed one of a
    tuned configuration). Each object is one track on the road its radar watches, with the
    reflection-point scatter and detection curve of its ``vehicle_class`` (a car when none).
    Columns: ``object_id, time_s, east_m, north_m, speed_mps, speed_kmh, position_std_m``
    (the root of the position covariance's trace).
    """
    frames = []
    for obj in objects:
        radar = site.radar(obj.radar)
        user = obj.vehicle_class or "car"
        est = estimator.estimate(
            obj.times[None],
            obj.measurements[None],
            np.ones((1, obj.times.size), dtype=bool),
            radar,
            site.roads[site.road_of_radar(obj.radar)],
            site.classes[user].scatter_std_m,
            radar.detection_curve(user),
        )
        frames.append(
            pd.DataFrame(
                {
                    "object_id": obj.object_id,
                    "time_s": obj.times,
                    "east_m": est.position[0, :, 0],
                    "north_m": est.position[0, :, 1],
                    "speed_mps": est.speed[0],
                    "speed_kmh": 3.6 * est.speed[0],
                    "position_std_m": np.sqrt(np.trace(est.position_cov[0], axis1=-2, axis2=-1)),
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


__all__ = ["IMMTracker", "PlanarTracker", "RoadTracker", "Tracker"]
