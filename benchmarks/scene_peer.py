"""Stone Soup's multi-target tracker on a crossing scene's raw detections (the peer).

GNN with 2-D assignment (``GNNWith2DAssignment``), a Mahalanobis ``DistanceHypothesiser``
with the scene tracker's gate (chi-square, 3 dof, 0.999), extended Kalman filters on a planar
nearly-constant-velocity model, a ``MultiMeasurementInitiator`` (3 associated detections
confirm a track, as the scene tracker's 3-of-4) and an ``UpdateTimeDeleter`` at the scene
tracker's coasting limit. Each detection carries its radar's (bearing, range, range rate)
model at the radar's position; slant range and rate are projected to the ground with the
radar's height. As a moving-target tracker it is given the detections that move
(|radial speed| >= 0.3 m/s, three sigma): zero-Doppler clutter would otherwise become tracks;
as a point-target tracker, the centroid of each cluster of a scan's detections (single link
within the scene tracker's ``cluster_radius_m``), one per vehicle body.
Its output rows have the scene tracker's columns, so both are scored by the same code.
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta

import numpy as np
import pandas as pd

from adaptrack.crossing.scene.tracker import SceneTrackerConfig, iter_scans
from adaptrack.crossing.site.corridor import nearest_corridor
from adaptrack.crossing.site.model import Site
from adaptrack.tracking import cluster_points, gate_threshold

MOVING_MPS = 0.3
START = datetime(2026, 1, 1)


def stonesoup_scene(site: Site, detections: pd.DataFrame, accel_psd: float = 4.0) -> pd.DataFrame:
    """Track ``detections`` (scene format) with Stone Soup; rows like ``track_scene``'s."""
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.deleter.time import UpdateTimeDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRangeRate2D
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    cfg = SceneTrackerConfig()
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(accel_psd), ConstantVelocity(accel_psd)]
    )
    predictor = ExtendedKalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement_model=None)
    hypothesiser = DistanceHypothesiser(
        predictor, updater, Mahalanobis(), missed_distance=math.sqrt(gate_threshold(3, 0.999))
    )
    associator = GNNWith2DAssignment(hypothesiser)
    deleter = UpdateTimeDeleter(timedelta(seconds=cfg.rules.max_coast_s))
    # state (north, north speed, east, east speed): bearing = atan2(east, north) = azimuth
    prior = GaussianState(np.zeros((4, 1)), np.diag([100.0**2, 15.0**2, 100.0**2, 15.0**2]))
    initiator = MultiMeasurementInitiator(
        prior, deleter, associator, updater, min_points=cfg.rules.confirm_hits,
        initiator=_polar_initiator(prior),
    )  # fmt: skip
    models = {}
    for r in site.radars:
        sr = float(r.range_std_m(np.array([50.0]))[0])
        sa = float(r.azimuth_std_rad(np.array([0.0]))[0])
        sv = float(r.radial_speed_std_mps(np.array([50.0]))[0])
        models[r.name] = (
            CartesianToBearingRangeRate2D(
                ndim_state=4, mapping=(0, 2), velocity_mapping=(1, 3),
                noise_covar=np.diag([sa**2, sr**2, sv**2]),
                translation_offset=np.array([[r.position_m[1]], [r.position_m[0]]]),
            ),
            r.height_m,
        )  # fmt: skip
    tracks: set = set()
    rows = []
    latency = {r.name: r.latency_s for r in site.radars}
    for radar, stamp, z, _ in iter_scans(detections, latency):
        t = stamp - latency[radar]  # the same declared latency as adaptrack's
        model, height = models[radar]
        z = _centroids(z[np.abs(z[:, 2]) >= MOVING_MPS], height, cfg.cluster_radius_m)
        when = START + timedelta(seconds=float(t))
        rho = np.sqrt(np.maximum(z[:, 0] ** 2 - height**2, 0.01))
        dets = {
            Detection(np.array([[a], [g], [v * r / g]]), timestamp=when, measurement_model=model)
            for r, a, v, g in zip(z[:, 0], z[:, 1], z[:, 2], rho, strict=True)
        }
        hyps = associator.associate(tracks, dets, when)
        used = set()
        for track in tracks:
            hyp = hyps[track]
            if hyp:
                track.append(updater.update(hyp))
                used.add(hyp.measurement)
            else:
                track.append(hyp.prediction)
        tracks -= deleter.delete_tracks(tracks)
        tracks |= initiator.initiate(dets - used, when)
        for track in tracks:
            x = np.asarray(track.state_vector, dtype=float).ravel()
            rows.append((id(track), t, x[2], x[0], x[3], x[1]))
    out = pd.DataFrame(
        rows,
        columns=["track_id", "time_s", "east_m", "north_m", "east_speed_mps", "north_speed_mps"],
    )
    out["track_id"] = pd.factorize(out["track_id"])[0] + 1
    out["speed_mps"] = np.hypot(out["east_speed_mps"], out["north_speed_mps"])
    out["from_crossing_m"] = _from_crossing(site, out[["east_m", "north_m"]].to_numpy())
    out["status"] = "confirmed"
    return out


def _centroids(z: np.ndarray, height_m: float, radius_m: float) -> np.ndarray:
    """Mean (range, azimuth, radial speed) of each cluster of detections on the ground."""
    if len(z) < 2:
        return z
    rho = np.sqrt(np.maximum(z[:, 0] ** 2 - height_m**2, 0.01))
    xy = np.stack([rho * np.sin(z[:, 1]), rho * np.cos(z[:, 1])], -1)
    labels = cluster_points(xy, radius_m)
    n = labels.max() + 1
    count = np.bincount(labels, minlength=n)
    mean_xy = np.stack([np.bincount(labels, xy[:, i], n) for i in range(2)], -1) / count[:, None]
    g = np.hypot(mean_xy[:, 0], mean_xy[:, 1])
    vr = np.bincount(labels, z[:, 2], n) / count
    return np.stack([np.hypot(g, height_m), np.arctan2(mean_xy[:, 0], mean_xy[:, 1]), vr], -1)


def _polar_initiator(prior):  # type: ignore[no-untyped-def]
    """A Stone Soup initiator opening a track at a (bearing, range, range rate) detection.

    Position from bearing and range (covariance through the Jacobian), velocity along the
    line of sight from the range rate, the prior's speed variance across it.
    """
    from stonesoup.base import Property
    from stonesoup.initiator.base import GaussianInitiator
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate

    class PolarInitiator(GaussianInitiator):  # type: ignore[misc]
        prior_state: object = Property(doc="prior (its speed variance is used)")

        def initiate(self, detections, timestamp, **kwargs):  # type: ignore[no-untyped-def]
            tracks = set()
            for det in detections:
                model = det.measurement_model
                a, r, v = np.asarray(det.state_vector, dtype=float).ravel()
                off = np.asarray(model.translation_offset, dtype=float).ravel()
                c, s_ = math.cos(a), math.sin(a)
                x = np.array([[off[0] + r * c], [v * c], [off[1] + r * s_], [v * s_]])
                var = np.diag(model.covar())
                jac = np.array([[-r * s_, c], [r * c, s_]])  # (north, east) by (bearing, range)
                pos = jac @ np.diag(var[:2]) @ jac.T
                speed_var = float(self.prior_state.covar[1, 1])
                p = np.zeros((4, 4))
                p[np.ix_([0, 2], [0, 2])] = pos
                los = np.array([c, s_])
                vel = var[2] * np.outer(los, los) + speed_var * np.outer([-s_, c], [-s_, c])
                p[np.ix_([1, 3], [1, 3])] = vel
                tracks.add(
                    Track([
                        GaussianStateUpdate(
                            x, p, hypothesis=SingleHypothesis(None, det),
                            timestamp=det.timestamp,
                        )
                    ])
                )  # fmt: skip
            return tracks

    return PolarInitiator(prior_state=prior)


def _from_crossing(site: Site, xy: np.ndarray) -> np.ndarray:
    """Distance along the nearest corridor to the crossing centre [m]."""
    corridors = site.corridors
    index, u, _ = nearest_corridor(corridors, xy)
    return np.abs(np.array([c.crossing_u for c in corridors])[index] - u)
