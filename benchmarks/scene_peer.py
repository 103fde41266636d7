"""Stone Soup's multi-target trackers on a crossing scene's raw detections (the peers).

Three configurations of Stone Soup's parts, all on extended Kalman filters of a planar
nearly-constant-velocity model, the scene tracker's gate (chi-square, 3 dof, 0.999), a
``MultiMeasurementInitiator`` (3 associated detections confirm a track, as the scene
tracker's 3-of-4) and, per scan, the centroid of each cluster of a radar's detections (single
link within the scene tracker's ``cluster_radius_m``): one point per body. Each detection
carries its radar's (bearing, range, range rate) model at the radar's position; slant range
and rate are projected to the ground with the radar's height.

- ``moving`` (the first peer, kept for comparison): GNN with 2-D assignment; only detections
  that move (|radial speed| >= 0.3 m/s, three sigma) so zero-Doppler clutter opens no track;
  constant noise (the radar's at 50 m); tracks deleted after the scene tracker's coasting
  limit for moving tracks (1.5 s). It loses every vehicle that stops.
- ``gnn``: GNN with 2-D assignment on every detection, stopped ones included, as a crossing
  needs; each detection's noise from the site's curves at its range and azimuth, plus the
  body's scatter (the scene tracker's ``body_across_std_m``); detections beside every road
  (farther than ``max_open_offset_m`` from every corridor) dropped, as the scene tracker opens
  no track there; the scene tracker's coasting limits (a track slower than
  ``stop_speed_mps`` is kept ``max_coast_stopped_s`` or ``max_stopped_misses`` scans in a row
  unseen, a moving one ``max_coast_s``; a tentative one is dropped after ``tentative_misses``
  scans without a detection, as the scene tracker's M-of-N); a track
  that never moved faster than ``moved_speed_mps`` nor ``moved_distance_m`` from where it was
  confirmed is reported ``static`` (rails, posts: the clutter map is those tracks).
- ``jpda``: the same with Stone Soup's JPDA (``PDAHypothesiser``: the site's detection
  probability, the scene's false-alarm density in measurement space) and Gaussian-mixture
  reduction of each track's hypotheses.

Output rows have the scene tracker's columns, so all are scored by the same code.
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
PEERS = ("moving", "gnn", "jpda")
RATE_SPAN_MPS = 80.0  # the span of radial speeds for the false-alarm density (JPDA)


def stonesoup_scene(
    site: Site, detections: pd.DataFrame, variant: str = "moving", accel_psd: float = 4.0,
    false_alarms_per_scan: float = 0.5,
) -> pd.DataFrame:  # fmt: skip
    """Track ``detections`` (scene format) with Stone Soup; rows like ``track_scene``'s."""
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.deleter.base import Deleter
    from stonesoup.deleter.time import UpdateTimeDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRangeRate2D
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.array import StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.update import GaussianStateUpdate
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    if variant not in PEERS:
        raise ValueError(f"variant must be one of {PEERS}; got {variant!r}")
    cfg = SceneTrackerConfig()
    rules = cfg.rules
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(accel_psd), ConstantVelocity(accel_psd)]
    )
    predictor = ExtendedKalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement_model=None)
    gate = math.sqrt(gate_threshold(3, 0.999))
    gnn = GNNWith2DAssignment(
        DistanceHypothesiser(predictor, updater, Mahalanobis(), missed_distance=gate)
    )

    class StopAwareDeleter(Deleter):  # type: ignore[misc]
        """Delete a track unseen for the coasting limit of its speed (stopped or moving).

        A stopped track also goes after ``max_stopped_misses`` scans in a row without a
        detection (the object has left), as the scene tracker's.
        """

        def check_for_deletion(self, track, **kwargs):  # type: ignore[no-untyped-def]
            x = np.asarray(track.state_vector, dtype=float).ravel()
            stopped = np.hypot(x[1], x[3]) < cfg.stop_speed_mps
            misses = 0
            for state in reversed(track.states):
                if isinstance(state, GaussianStateUpdate):
                    break
                misses += 1
            seen = track.states[-1 - misses].timestamp if misses < len(track) else track.timestamp
            unseen = (track.timestamp - seen).total_seconds()
            if stopped:
                return unseen > rules.max_coast_stopped_s or misses > rules.max_stopped_misses
            return unseen > rules.max_coast_s

    period = max(r.period_s for r in site.radars)
    deleter = (
        UpdateTimeDeleter(timedelta(seconds=rules.max_coast_s))
        if variant == "moving"
        else StopAwareDeleter()
    )
    holding = (  # tentative tracks: dropped after the scene tracker's misses of an M-of-N
        deleter
        if variant == "moving"
        else UpdateTimeDeleter(timedelta(seconds=(rules.tentative_misses + 0.5) * period))
    )
    if variant == "jpda":
        area = sum(2 * r.fields[0].half_angle_rad * r.fields[0].max_range_m for r in site.radars)
        density = false_alarms_per_scan * len(site.radars) / (area * RATE_SPAN_MPS)
        p_d = float(site.radars[0].detection_curve("car")(np.array([50.0]))[0])
        associator = JPDA(
            PDAHypothesiser(predictor, updater, clutter_spatial_density=density,
                            prob_detect=p_d, prob_gate=0.999)
        )  # fmt: skip
    else:
        associator = gnn
    # state (north, north speed, east, east speed): bearing = atan2(east, north) = azimuth
    prior = GaussianState(np.zeros((4, 1)), np.diag([100.0**2, 15.0**2, 100.0**2, 15.0**2]))
    initiator = MultiMeasurementInitiator(
        prior, holding, gnn, updater, min_points=rules.confirm_hits,
        initiator=_polar_initiator(prior),
    )  # fmt: skip
    radars = {r.name: r for r in site.radars}

    def model(radar, slant, azimuth, ground):  # type: ignore[no-untyped-def]
        sr, sa, sv = (float(np.asarray(v).ravel()[0]) for v in radar.noise_std(slant, azimuth))
        if variant != "moving":  # the body's scatter about its centroid
            sr = math.hypot(sr, cfg.body_across_std_m)
            sa = math.hypot(sa, cfg.body_across_std_m / max(ground, 1.0))
        return CartesianToBearingRangeRate2D(
            ndim_state=4, mapping=(0, 2), velocity_mapping=(1, 3),
            noise_covar=np.diag([sa**2, sr**2, sv**2]),
            translation_offset=np.array([[radar.position_m[1]], [radar.position_m[0]]]),
        )  # fmt: skip

    fixed = {n: model(r, np.array([50.0]), np.array([r.boresight_rad]), 50.0)
             for n, r in radars.items()}  # fmt: skip
    corridors = site.corridors
    tracks: set = set()
    rows = []
    first_seen: dict[int, np.ndarray] = {}
    moved: set[int] = set()
    latency = {r.name: r.latency_s for r in site.radars}
    for name, stamp, z, _ in iter_scans(detections, latency):
        t = stamp - latency[name]  # the same declared latency as adaptrack's
        radar = radars[name]
        height = radar.height_m
        if variant == "moving":
            z = z[np.abs(z[:, 2]) >= MOVING_MPS]
        z = _centroids(z, height, cfg.cluster_radius_m)
        when = START + timedelta(seconds=float(t))
        rho = np.sqrt(np.maximum(z[:, 0] ** 2 - height**2, 0.01))
        if variant != "moving" and len(z):
            ground = np.stack([radar.position_m[0] + rho * np.sin(z[:, 1]),
                               radar.position_m[1] + rho * np.cos(z[:, 1])], -1)  # fmt: skip
            _, _, across = nearest_corridor(corridors, ground)
            keep = np.abs(across) <= cfg.max_open_offset_m
            z, rho = z[keep], rho[keep]
        dets = {
            Detection(
                np.array([[a], [g], [v * r / g]]), timestamp=when,
                measurement_model=fixed[name] if variant == "moving" else model(
                    radar, np.array([r]), np.array([a]), g),
            )
            for r, a, v, g in zip(z[:, 0], z[:, 1], z[:, 2], rho, strict=True)
        }  # fmt: skip
        hyps = associator.associate(tracks, dets, when)
        used = set()
        for track in tracks:
            hyp = hyps[track]
            if variant == "jpda":
                states, weights = [], []
                for h in hyp:
                    states.append(updater.update(h) if h else h.prediction)
                    weights.append(float(h.probability))
                    if h:
                        used.add(h.measurement)
                if any(hyp):
                    mean, covar = _mixture(
                        StateVectors([s.state_vector for s in states]),
                        np.stack([s.covar for s in states], 2),
                        weights,
                    )
                    track.append(GaussianStateUpdate(mean, covar, hyp, when))
                else:
                    track.append(states[0])
            elif hyp:
                track.append(updater.update(hyp))
                used.add(hyp.measurement)
            else:
                track.append(hyp.prediction)
        tracks -= deleter.delete_tracks(tracks)
        tracks |= initiator.initiate(dets - used, when)
        for track in tracks:
            x = np.asarray(track.state_vector, dtype=float).ravel()
            key = id(track)
            start = first_seen.setdefault(key, x[[0, 2]])
            if (
                np.hypot(x[1], x[3]) > cfg.moved_speed_mps
                and np.hypot(*(x[[0, 2]] - start)) > cfg.moved_distance_m
            ):
                moved.add(key)
            status = "confirmed" if variant == "moving" or key in moved else "static"
            rows.append((key, t, x[2], x[0], x[3], x[1], status))
    out = pd.DataFrame(
        rows,
        columns=["track_id", "time_s", "east_m", "north_m", "east_speed_mps", "north_speed_mps",
                 "status"],
    )  # fmt: skip
    out["track_id"] = pd.factorize(out["track_id"])[0] + 1
    out["speed_mps"] = np.hypot(out["east_speed_mps"], out["north_speed_mps"])
    out["from_crossing_m"] = _from_crossing(site, out[["east_m", "north_m"]].to_numpy())
    return out


def _mixture(means, covars, weights):  # type: ignore[no-untyped-def]
    """Moment-matched single Gaussian of a weighted mixture (Stone Soup's reduction)."""
    from stonesoup.functions import gm_reduce_single

    w = np.asarray(weights, dtype=float)
    return gm_reduce_single(means, covars, w / w.sum())


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
