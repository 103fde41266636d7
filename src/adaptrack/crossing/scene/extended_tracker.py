"""A scene tracker of free 2-D motion with box extents and existence probabilities.

Where :mod:`.tracker` follows road users along the site's corridors with hand-set rules,
this one takes its behaviour from three models:

- **Motion**: a nearly-coordinated turn in the plane (:class:`~adaptrack.models.turn.
  CoordinatedTurn`, state ``x, y, vx, vy, omega``), so turns, lane changes, U-turns and
  pedestrians crossing anywhere are followed; the site's lanes enter only as a prior on a
  new track's direction of motion (along the nearest lane, either way, within
  ``lane_prior_m``; while a train is due, on the rails, their axis instead where it explains
  the new group's mean radial speed better), never as a path a track must keep.
- **Extent**: each track is a box (length, width, heading: the velocity's direction once the
  speed is known, else the last one or the lane's). A radar's reflections of it lie on the
  faces it sees (:func:`.box_view.face_moments`): a detection is predicted at the visible
  faces' mean, with their spread, so the estimate is the box centre whichever faces reflect.
  The detections a track takes in a scan (each to the track that explains it best, within a
  chi-square gate over position and radial speed) update it as one measurement: their mean
  ground point and mean radial speed, the radial speed carrying the turn rate through the
  points' lever arms. Length and width follow the detections' spread along and across
  (moment matching, rate ``extent_learning_rate``) where a scan gives three or more.
- **Existence**: every track carries the probability that an object stands behind it
  (:mod:`adaptrack.tracking.existence`): a scan that should have seen it and did not lowers
  it, a detection raises it by its likelihood against the clutter density that each radar's
  :class:`~adaptrack.tracking.clutter_map.ClutterMap` learns online from the detections no
  track explains, and by its detection count (negative binomial, rate learnt per track,
  radar and range, against a clutter group's). The P_D of a scan is learnt per radar and
  range (the declared curve as the prior), times the share of the track's reflection point
  in view, less its share hidden behind nearer tracks in 3-D from the antenna's height. A
  group of unexplained detections (single link within ``cluster_gap_m``) opens a track at
  the birth / (birth + clutter) share. A track is reported once its existence reaches
  ``report_existence`` and its speed is known to ``report_speed_std_mps`` (along its
  velocity; the worst axis when slower than 1 m/s), and while it stays above
  ``keep_existence``, kept through standstills and occlusions of any length while it is not
  contradicted, and dropped below ``drop_existence`` or once its position is known worse
  than ``lost_position_std_m``.

Two tracks whose boxes overlap and whose velocities agree within ``same_body_sigmas`` (and a
rigid body's turn) follow one body: the younger is dropped. With the empty site's background
(:mod:`.background`) a stationary detection on a known reflector is the reflector's unless a
track explains it better or an object is found standing on it. After every scan the
crossing's clear / not-clear state is updated from every track as likely as a reported one
(:mod:`.occupancy`), and each reported track gets a class with its probability
(:mod:`.road_user_class`). Every detection is accounted for (:class:`ExtendedLog`). Status:
confirmed (detected within ``COASTING_S``), coasting, or stopped (slower than
``stopped_speed_mps``); ``moved`` once faster than ``moved_speed_mps``.
This class is the NumPy reference, one scan per call; :func:`track_scene_extended` runs the
same computation compiled, many scans per call (:mod:`.extended_loop`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from ..._typing import FloatArray
from ...models.turn import CoordinatedTurn
from ...tracking import cluster_points, gate_threshold
from ...tracking.clutter_map import ClutterMap
from ...tracking.existence import after_hit, after_miss, at_birth, count_ratio, survive
from ..site.model import Site
from ..site.sensor import RadarSpec, curve_tables
from .background import BackgroundMap
from .box_view import face_moments
from .detection_table import check_detection_table
from .extended_loop import (
    CFG_FIELDS,
    N_ROW_F,
    ROW_F_FIELDS,
    TRACK_ARRAYS,
    lane_grid,
    run_scans,
)
from .occupancy import (
    AREA_CELL_M,
    EVENT_CLEAR,
    EVENT_NOT_CLEAR,
    TRAIN_ALIGN_DEG,
    TRAIN_SPEED_MPS,
    ClearanceMonitor,
)
from .road_user_class import class_names, class_probabilities
from .tracker import EVENT_COLUMNS, ROW_COLUMNS, STATUS_NAMES, scan_arrays

N_STATE = 5  # x, y, vx, vy, omega
BACKGROUND = -2  # owner of a detection the background explains
EXTENT_FLOOR_M = 0.3  # what a box's learnt length and width stay uncertain by, at best [m]
OBJECT_REACH_M = 1.0  # an object beside a reflector spreads its detections over this radius
COASTING_S = 0.2  # a reported track without a detection for longer is coasting [s]
_CONFIRMED, _COASTING, _STOPPED = (
    STATUS_NAMES.index(s) for s in ("confirmed", "coasting", "stopped")
)


@dataclass(frozen=True)
class ExtendedTrackerConfig:
    """Settings of :class:`ExtendedTracker`; each is a model parameter (units in the names)."""

    accel_psd: float = 2.0  # white acceleration PSD, each axis [m^2/s^3]
    turn_psd: float = 0.05  # turn-rate random walk PSD [rad^2/s^3]
    gate_probability: float = 0.9999  # a detection of a track falls in its gate this often
    shape_model_std_m: float = 0.25  # the box model's own error on a scan's mean point [m]
    body_doppler_std_mps: float = 0.3  # radial-speed scatter over a body (wheels, limbs) [m/s]
    birth_density: float = 1e-7  # new objects per m^2 per scan
    clutter_prior_density: float = 1e-5  # unexplained detection groups per m^2 per scan ...
    clutter_doppler_span_mps: float = 80.0  # ... spread evenly over this radial-speed span
    clutter_cell_m: float = 5.0
    clutter_memory_scans: float = 20000.0
    lifetime_s: float = 3600.0  # mean time an object stays in the scene [s]
    report_existence: float = 0.99  # a track is first reported at this existence ...
    report_speed_std_mps: float = 1.0  # ... once its velocity is known this well (each axis) ...
    keep_existence: float = 0.5  # ... and kept reported while more likely than not
    drop_existence: float = 1e-4
    lost_position_std_m: float = 5.0
    cluster_gap_m: float = 1.5  # a body's detections lie closer than this to a neighbour [m]
    lane_prior_m: float = 6.0  # a new track this near a lane's centreline moves along it ...
    lane_speed_std_mps: float = 12.0  # ... with this speed sigma along and ...
    lane_across_std_mps: float = 1.0  # ... this across [m/s]; elsewhere:
    initial_speed_std_mps: float = 8.0  # sigma of each velocity component [m/s]
    initial_turn_std_radps: float = 0.3
    prior_length_m: float = 4.5  # a new track's box (a car) ...
    prior_width_m: float = 1.8
    prior_length_std_m: float = 2.5  # ... and how little that is known (its class)
    prior_width_std_m: float = 0.5
    min_extent_m: float = 0.3
    max_extent_m: float = 20.0
    extent_learning_rate: float = 0.05
    count_shape: float = 2.0  # gamma shape of a body's detection rate (its RCS fluctuation)
    count_learning_rate: float = 0.1  # a track's detections per scan, moving average
    body_height_m: float = 1.5  # an occluder's height [m] (the antenna sees over it)
    antenna_height_m: float | None = None  # above the road (None: the radar's height_m + 0.5)
    same_body_sigmas: float = 3.0
    background_alarm_nats: float = 16.0  # an object stands on a reflector (CUSUM threshold)
    stopped_speed_mps: float = 0.5
    moved_speed_mps: float = 1.0

    def __post_init__(self) -> None:
        """Reject settings no tracker can run on, naming the field."""
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if f.name in (
                "gate_probability",
                "report_existence",
                "keep_existence",
                "drop_existence",
            ):
                ok, want = 0 < value < 1, "in (0, 1)"
            elif f.name in ("extent_learning_rate", "count_learning_rate"):
                ok, want = 0 < value <= 1, "in (0, 1]"
            else:
                ok, want = 0 < value < np.inf, "finite and > 0"
            if not ok:
                raise ValueError(f"ExtendedTrackerConfig.{f.name} must be {want}; got {value}")
        if not self.drop_existence < self.keep_existence <= self.report_existence:
            raise ValueError(
                "ExtendedTrackerConfig: drop_existence < keep_existence <= "
                "report_existence is required"
            )


@dataclass
class ExtendedLog:
    """What became of the detections: counts by outcome (every detection is in one)."""

    updated: int = 0
    opened: int = 0
    joined_new: int = 0
    rejected_outside_view: int = 0
    background: int = 0  # stationary, on a reflector of the empty site's background map

    @property
    def total(self) -> int:
        """Detections accounted for."""
        return (self.updated + self.opened + self.joined_new + self.rejected_outside_view
                + self.background)  # fmt: skip


_TRACK_FIELDS = (
    "track_id", "x", "p", "time_s", "existence", "heading_rad", "extent", "extent_var",
    "born_s", "last_hit_s", "hits", "moved", "reported", "rate", "top_speed_mps",
)  # fmt: skip


class ExtendedTracker:
    """Incremental tracker of one site (module docstring).

    ``step`` processes a scan; ``last_columns`` (or ``columns(time_s)``) holds the reported
    tracks after it, ``clearance.events`` the crossing's events and ``log`` the detections'
    outcomes.
    """

    def __init__(
        self,
        site: Site,
        config: ExtendedTrackerConfig | None = None,
        background: BackgroundMap | None = None,
        train_intervals: FloatArray | None = None,
    ) -> None:
        self.site = site
        self.background = background
        self.clearance = ClearanceMonitor(site, train_intervals)
        n_reflectors = 0 if background is None else background.reflector_rate.size
        self._reflector_cusum = np.zeros(n_reflectors)  # object-on-reflector test [nats]
        self._reflectors_of = {
            r.name: background.reflectors_seen_by(r.name) if background is not None
            else np.zeros(0, np.int64)
            for r in site.radars
        }  # fmt: skip
        self.config = cfg = config or ExtendedTrackerConfig()
        self.motion = CoordinatedTurn(accel_psd=cfg.accel_psd, turn_psd=cfg.turn_psd)
        self.log = ExtendedLog()
        self._radars = {r.name: r for r in site.radars}
        self._last_stamp = dict.fromkeys(self._radars, -np.inf)
        self._clutter = {
            name: ClutterMap(cfg.clutter_prior_density, cfg.clutter_cell_m,
                             cfg.clutter_memory_scans)
            for name in self._radars
        }  # fmt: skip
        self._gate = gate_threshold(3, cfg.gate_probability)
        self._next_id = 1
        self._radar_index = {name: k for k, name in enumerate(self._radars)}
        self._counts = {name: _Counts() for name in self._radars}
        self._t = _empty_tracks(len(self._radars))
        self.last_columns = self.columns(-np.inf)  # the reported tracks after the last scan
        lanes = [(c.path.xy, c.path.heading) for c in site.corridors]
        self._lane_xy = np.concatenate([xy for xy, _ in lanes]) if lanes else np.zeros((0, 2))
        # corridor headings are azimuths (clockwise from north): as a direction (east, north)
        az = np.concatenate([h for _, h in lanes]) if lanes else np.zeros(0)
        self._lane_dir = np.stack([np.sin(az), np.cos(az)], -1)
        self._lane_tree = cKDTree(self._lane_xy) if len(self._lane_xy) else None

    # -- one scan -------------------------------------------------------------------------
    def step(self, radar_name: str, time_s: float, z: FloatArray) -> None:
        """Process the detections ``z`` (n, 3: range m, azimuth rad, radial speed m/s) of a scan."""
        radar = self._radars.get(radar_name)
        if radar is None:
            raise ValueError(f"unknown radar {radar_name!r}; the site has {sorted(self._radars)}")
        if not time_s > self._last_stamp[radar_name]:
            raise ValueError(
                f"radar {radar_name!r}: scan at {time_s} s is not after its previous scan at "
                f"{self._last_stamp[radar_name]} s"
            )
        z = np.asarray(z, float)
        if z.size == 0:
            z = z.reshape(0, 3)
        if z.ndim != 2 or z.shape[1] != 3:
            raise ValueError(
                f"radar {radar_name!r} at {time_s} s: detections must be (n, 3) (range_m, "
                f"azimuth_rad, radial_speed_mps); got shape {z.shape}"
            )
        if not np.isfinite(z).all():
            raise ValueError(f"radar {radar_name!r} at {time_s} s: a detection is not finite")
        self._last_stamp[radar_name] = time_s
        t_scan = float(radar.measured_at(time_s))
        cfg, t = self.config, self._t
        self._predict(t_scan)
        in_field = radar.in_view(z[:, 0], z[:, 1])
        self.log.rejected_outside_view += int((~in_field).sum())
        z = z[in_field]
        g, g_cov, a, v_var = _ground_points(radar, z)
        n_t = t["x"].shape[0]
        owner = np.full(z.shape[0], -1)
        cost = np.zeros((n_t, z.shape[0]))
        offset, spread = self._faces(radar)
        share = self._view_share(radar, offset, spread)
        seen = share > 0
        if n_t and z.shape[0]:
            cost = self._point_costs(radar, g, g_cov, a, v_var, z[:, 2], offset, spread)
            cost[~seen] = np.inf
            best = np.argmin(cost, axis=0)
            ok = np.isfinite(cost[best, np.arange(z.shape[0])])
            owner[ok] = best[ok]
        if self.background is not None and z.shape[0]:
            explained = self._background_explains(radar, g, z[:, 2], owner, cost,
                                                  self._counts[radar_name])  # fmt: skip
            owner[explained] = BACKGROUND
        hit = np.zeros(n_t, bool)
        pd, clear = self._detection_probability(radar, seen)
        pd = pd * share
        # P_D is learnt from the tracks surely there, wholly in view and hidden by none
        learns = (t["existence"] >= cfg.report_existence) & t["reported"] & (share >= 1.0) & clear
        clutter = self._clutter[radar_name]
        r_index = self._radar_index[radar_name]
        counts = self._counts[radar_name]
        for i in np.unique(owner[owner >= 0]):
            mine = owner == i
            ratio = self._update(i, radar, g[mine], g_cov[mine], a[mine], v_var[mine],
                                 z[mine, 2], offset[i], spread[i], clutter)  # fmt: skip
            n_mine = int(mine.sum())
            rate = t["rate"][i, r_index]
            ground = _ground_range(t["x"][i, :2], radar)
            with np.errstate(over="ignore"):  # an infinite ratio: surely an object (after_hit)
                ratio *= count_ratio(n_mine, counts.rate_at(ground) if np.isnan(rate) else rate,
                                     cfg.count_shape, counts.clutter_mean)  # fmt: skip
            t["rate"][i, r_index] = n_mine if np.isnan(rate) else rate + cfg.count_learning_rate * (
                n_mine - rate)  # fmt: skip
            if t["reported"][i]:
                counts.learn_object(n_mine, ground, cfg.count_learning_rate)
            t["existence"][i] = after_hit(t["existence"][i], pd[i], ratio)
            t["last_hit_s"][i] = t_scan
            t["hits"][i] += 1
            hit[i] = True
        self.log.updated += int((owner >= 0).sum())
        self.log.background += int((owner == BACKGROUND).sum())
        missed = seen & ~hit
        for i in np.flatnonzero(learns):
            counts.learn_detection(_ground_range(t["x"][i, :2], radar), bool(hit[i]))
        t["existence"][missed] = after_miss(t["existence"][missed], pd[missed])
        self._births(radar, t_scan, np.flatnonzero(owner == -1), g, g_cov, a, v_var, z[:, 2])
        self._prune()
        self.last_columns = self.columns(t_scan)
        # occupancy needs an object's presence and place, not its speed: every track as
        # likely as a reported one, reported or not yet
        t = self._t
        present = (t["existence"] >= cfg.report_existence) | (
            t["reported"] & (t["existence"] >= cfg.keep_existence)
        )
        rows = np.flatnonzero(present)
        self.clearance.update(t_scan, t["track_id"][rows], t["x"][rows, :2], t["x"][rows, 2:4],
                              t["heading_rad"][rows], t["extent"][rows, 0],
                              t["extent"][rows, 1])  # fmt: skip

    def _births(self, radar, t_scan, left, g, g_cov, a, v_var, vr):  # type: ignore[no-untyped-def]
        """Open a track on each group of the scan's unexplained detections ``left``.

        Its existence: the birth / (birth + clutter) share at the group's centre, times the
        odds of its detection count; the groups are counted in the radar's clutter map.
        """
        cfg = self.config
        clutter, counts = self._clutter[radar.name], self._counts[radar.name]
        groups = cluster_points(g[left], cfg.cluster_gap_m) if left.size else np.zeros(0, int)
        labels = np.unique(groups)
        centres = np.array([g[left[groups == k]].mean(axis=0) for k in labels]).reshape(-1, 2)
        density = clutter.density(centres) / cfg.clutter_doppler_span_mps
        birth = cfg.birth_density / cfg.clutter_doppler_span_mps
        for k, centre, centre_density in zip(labels, centres, density, strict=True):
            rows = left[groups == k]
            r0 = float(at_birth(birth, centre_density))
            rate = counts.rate_at(_ground_range(centre, radar))
            odds = (
                r0
                / (1.0 - r0)
                * float(count_ratio(rows.size, rate, cfg.count_shape, counts.clutter_mean))
            )
            self._open(radar, t_scan, g[rows], g_cov[rows], a[rows], v_var[rows], vr[rows],
                       odds / (1.0 + odds))  # fmt: skip
            counts.learn_clutter(rows.size, cfg.count_learning_rate)
            self.log.opened += 1
            self.log.joined_new += rows.size - 1
        clutter.end_scan(centres)

    def _predict(self, t_scan: float) -> None:
        """Predict every track to the scan time (motion and survival)."""
        t = self._t
        if not t["x"].shape[0]:
            return
        dt = np.maximum(t_scan - t["time_s"], 0.0)
        x, f = self.motion.propagate(t["x"], dt)
        p = f @ t["p"] @ np.swapaxes(f, -1, -2) + self.motion.process_cov(dt)
        t["x"], t["p"] = x, 0.5 * (p + np.swapaxes(p, -1, -2))
        t["time_s"] = np.full(dt.shape, t_scan)
        t["existence"] = survive(t["existence"], dt, self.config.lifetime_s)
        speed = np.hypot(x[:, 2], x[:, 3])
        speed_var = np.einsum("ni,nij,nj->n", _unit(x[:, 2:4]), p[:, 2:4, 2:4], _unit(x[:, 2:4]))
        known = speed > 2.0 * np.sqrt(speed_var) + 0.3
        t["heading_rad"] = np.where(known, np.arctan2(x[:, 3], x[:, 2]), t["heading_rad"])

    def _view_share(self, radar: RadarSpec, offset: FloatArray, spread: FloatArray) -> FloatArray:
        """Each track's probability of lying in the radar's view (0 to 1).

        The share of five points in view: the predicted reflection point and two sigmas
        either way along the axes of its covariance (the track's and the faces' spread).
        """
        x, p = self._t["x"], self._t["p"]
        if not x.shape[0]:
            return np.zeros(0)
        centre = x[:, :2] + offset
        cov = p[:, :2, :2] + spread
        values, vectors = np.linalg.eigh(cov)
        reach = 2.0 * np.sqrt(np.maximum(values, 0.0))[:, None, :] * vectors  # (T, 2, 2)
        points = [centre] + [centre + sign * reach[:, :, k] for k in (0, 1) for sign in (1, -1)]
        return np.mean([np.asarray(radar.covers(q), float) for q in points], axis=0)

    def _detection_probability(
        self, radar: RadarSpec, seen: np.ndarray
    ) -> tuple[FloatArray, np.ndarray]:
        """Each track's P_D in this scan, and whether nothing hides it (bool each).

        The P_D at its range learnt from this radar's tracks (:class:`_Counts`; the radar's
        declared curve as the prior), less the share of it hidden behind nearer tracks.
        """
        t, cfg = self._t, self.config
        xy = t["x"][:, :2]
        rng, az = radar.polar(xy)
        declared = radar.detection_curve("default")(rng)
        counts = self._counts[radar.name]
        ground_m = np.hypot(*(xy - np.asarray(radar.position_m)).T) if len(xy) else np.zeros(0)
        learnt = np.array([counts.pd_at(g, p) for g, p in zip(ground_m, declared, strict=True)])
        pd = np.where(seen, learnt, 0.0)
        antenna = _antenna_height(radar, cfg)
        rel = xy - np.asarray(radar.position_m)
        ground = np.linalg.norm(rel, axis=1)
        half = np.arctan2(0.5 * np.hypot(t["extent"][:, 0], t["extent"][:, 1]),
                          np.maximum(ground, 1e-6))  # fmt: skip
        hidden = np.zeros(xy.shape[0])
        idx = np.flatnonzero(seen)
        for i in idx:
            for j in idx:
                if ground[j] >= ground[i] or j == i:
                    continue
                lap = half[i] + half[j] - abs(math.remainder(az[i] - az[j], 2 * math.pi))
                if lap <= 0:
                    continue
                share = min(lap / (2 * half[i]), 1.0)
                # the sight line over the occluder's top meets the ground-standing body at
                # this height: below it is hidden
                line = antenna - (antenna - cfg.body_height_m) * ground[i] / max(ground[j], 1e-6)
                depth = float(np.clip(line / cfg.body_height_m, 0.0, 1.0))
                hidden[i] = max(hidden[i], share * depth)
        return pd * (1.0 - hidden), hidden == 0.0

    def _faces(self, radar: RadarSpec) -> tuple[FloatArray, FloatArray]:
        """Each track's face offset (T, 2) and spread (T, 2, 2) seen from the radar."""
        t = self._t
        return face_moments(t["x"][:, :2], t["heading_rad"], t["extent"][:, 0],
                            t["extent"][:, 1], np.asarray(radar.position_m))  # fmt: skip

    def _point_costs(self, radar, g, g_cov, a, v_var, vr, offset, spread):  # type: ignore[no-untyped-def]
        """Return chi-square plus log-determinant per track and detection (T, n); inf: no gate."""
        t, cfg = self._t, self.config
        x, p = t["x"], t["p"]
        e = g[None, :, :] - (x[:, None, :2] + offset[:, None, :])
        s = (
            p[:, None, :2, :2]
            + spread[:, None]
            + g_cov[None]
            + cfg.shape_model_std_m**2 * np.eye(2)
        )
        det = s[..., 0, 0] * s[..., 1, 1] - s[..., 0, 1] ** 2
        d2 = (s[..., 1, 1] * e[..., 0] ** 2 - 2 * s[..., 0, 1] * e[..., 0] * e[..., 1]
              + s[..., 0, 0] * e[..., 1] ** 2) / det  # fmt: skip
        lever = g[None, :, :] - x[:, None, :2]
        predicted = np.einsum(
            "nj,tnj->tn",
            a,
            x[:, None, 2:4] + x[:, None, 4:5] * np.stack([-lever[..., 1], lever[..., 0]], -1),
        )
        dv = _unfold(vr[None, :] - predicted, radar)
        sv = (
            np.einsum("nj,tjk,nk->tn", a, p[:, 2:4, 2:4], a)
            + v_var[None]
            + cfg.body_doppler_std_mps**2
        )
        chi = d2 + dv**2 / sv
        return np.where(chi <= self._gate, chi + np.log(det * sv), np.inf)

    def _update(self, i, radar, g, g_cov, a, v_var, vr, offset, spread, clutter):  # type: ignore[no-untyped-def]
        """Update track ``i`` with its detections of a scan; return their likelihood ratio."""
        t, cfg = self._t, self.config
        x, p = t["x"][i], t["p"][i]
        n = g.shape[0]
        lever = g - x[:2]
        arm = np.stack([-lever[:, 1], lever[:, 0]], -1)
        h = np.zeros((3, N_STATE))
        h[0, 0] = h[1, 1] = 1.0
        h[2, 2:4] = a.mean(axis=0)
        h[2, 4] = np.einsum("nj,nj->n", a, arm).mean()
        predicted = np.array([x[0] + offset[0], x[1] + offset[1], h[2] @ x])
        zbar = np.array([*g.mean(axis=0), vr.mean()])
        r = np.zeros((3, 3))
        r[:2, :2] = g_cov.sum(axis=0) / n**2 + spread / n + cfg.shape_model_std_m**2 * np.eye(2)
        r[2, 2] = v_var.mean() / n + cfg.body_doppler_std_mps**2
        innov = zbar - predicted
        innov[2] = _unfold(innov[2], radar)
        s = h @ p @ h.T + r
        s_inv = np.linalg.inv(s)
        k = p @ h.T @ s_inv
        t["x"][i] = x + k @ innov
        ikh = np.eye(N_STATE) - k @ h
        post = ikh @ p @ ikh.T + k @ r @ k.T  # Joseph form
        t["p"][i] = 0.5 * (post + post.T)
        if n >= 3:
            self._learn_extent(i, g, g_cov, np.asarray(radar.position_m))
        speed = math.hypot(t["x"][i, 2], t["x"][i, 3])
        known = t["p"][i, 2, 2] + t["p"][i, 3, 3] < 1.0
        t["moved"][i] |= speed > cfg.moved_speed_mps and known
        if known and t["reported"][i]:
            t["top_speed_mps"][i] = max(t["top_speed_mps"][i], speed)
        density = clutter.density(zbar[None, :2])[0] / cfg.clutter_doppler_span_mps
        g_z = math.exp(-0.5 * innov @ s_inv @ innov) / math.sqrt((2 * math.pi) ** 3
                                                                 * np.linalg.det(s))  # fmt: skip
        return g_z / density

    def _learn_extent(self, i, g, g_cov, radar_xy):  # type: ignore[no-untyped-def]
        """Move the box's length and width towards the detections' spread along and across."""
        t, cfg = self._t, self.config
        h = t["heading_rad"][i]
        axes = np.array([[math.cos(h), math.sin(h)], [-math.sin(h), math.cos(h)]])
        local = (g - g.mean(axis=0)) @ axes.T
        noise = np.einsum("ai,nij,aj->a", axes, g_cov, axes) / g.shape[0]
        observed = np.maximum(local.var(axis=0, ddof=1) - noise, 0.0)
        _, model_cov = face_moments(t["x"][i : i + 1, :2], np.array([h]),
                                    t["extent"][i : i + 1, 0], t["extent"][i : i + 1, 1],
                                    radar_xy)  # fmt: skip
        expected = np.einsum("ai,ij,aj->a", axes, model_cov[0], axes)
        rate = cfg.extent_learning_rate
        for k in (0, 1):
            # an axis is learnt where a face along it is in view: its reflections' variance
            # is then that of a uniform spread over the face, proportional to its square
            size = t["extent"][i, k]
            if expected[k] >= 0.25 * size**2 / 12.0:
                square = size**2 * (1.0 + rate * (observed[k] / expected[k] - 1.0))
                t["extent"][i, k] = min(max(math.sqrt(max(square, 0.0)), cfg.min_extent_m),
                                        cfg.max_extent_m)  # fmt: skip
                # the prior's weight in the moving average decays by 1 - rate a step
                t["extent_var"][i, k] = (1.0 - rate) * t["extent_var"][i, k] + rate * (
                    EXTENT_FLOOR_M**2)  # fmt: skip

    def _open(self, radar, t_scan, g, g_cov, a, v_var, vr, existence):  # type: ignore[no-untyped-def]
        """Open a track on a group of unexplained detections (lane prior on its motion)."""
        cfg = self.config
        centre = g.mean(axis=0)
        direction = None
        if self._lane_tree is not None:
            dist, k = self._lane_tree.query(centre)
            if dist <= cfg.lane_prior_m:
                direction = self._lane_dir[k]
        n = g.shape[0]
        if self.clearance.train_due(t_scan) and self.clearance.area.on_rails(centre):
            # a train is due: the rails are a lane too, taken where they explain the radial
            # speeds better than the road's lane
            rails = np.asarray(self.site.rails.direction, float)
            noise = v_var.mean() / n + cfg.body_doppler_std_mps**2
            fit = [self._lane_fit(d, a.mean(axis=0), vr.mean(), noise)
                   for d in (rails, direction) if d is not None]  # fmt: skip
            if direction is None or fit[0] > fit[1]:
                direction = rails
        heading = math.atan2(direction[1], direction[0]) if direction is not None else math.atan2(
            *(np.asarray(radar.position_m) - centre)[::-1])  # fmt: skip
        length, width = cfg.prior_length_m, cfg.prior_width_m
        length_sd, width_sd = cfg.prior_length_std_m, cfg.prior_width_std_m
        offset, spread = face_moments(centre[None], np.array([heading]), np.array([length]),
                                      np.array([width]),
                                      np.asarray(radar.position_m))  # fmt: skip
        x = np.zeros(N_STATE)
        x[:2] = centre - offset[0]
        p = np.zeros((N_STATE, N_STATE))
        p[:2, :2] = g_cov.sum(axis=0) / n**2 + spread[0] + cfg.shape_model_std_m**2 * np.eye(2)
        if direction is not None:
            p[2:4, 2:4] = self._lane_velocity_cov(direction)
        else:
            p[2:4, 2:4] = cfg.initial_speed_std_mps**2 * np.eye(2)
        p[4, 4] = cfg.initial_turn_std_radps**2
        # the radial speeds: a one-dimensional update of the velocity
        h = np.zeros(N_STATE)
        h[2:4] = a.mean(axis=0)
        s = h @ p @ h + v_var.mean() / n + cfg.body_doppler_std_mps**2
        k = p @ h / s
        x = x + k * (vr.mean() - h @ x)
        p = p - np.outer(k, k) * s
        speed = math.hypot(x[2], x[3])
        if speed > 1.0:
            heading = math.atan2(x[3], x[2])
        new = {
            "track_id": np.array([self._next_id]), "x": x[None], "p": 0.5 * (p + p.T)[None],
            "time_s": np.array([t_scan]), "existence": np.array([existence]),
            "heading_rad": np.array([heading]), "born_s": np.array([t_scan]),
            "extent": np.array([[length, width]]),
            "extent_var": np.array([[length_sd**2, width_sd**2]]),
            "last_hit_s": np.array([t_scan]), "hits": np.array([1]),
            "moved": np.array([False]), "reported": np.array([False]),
            "rate": np.full((1, len(self._radars)), np.nan), "top_speed_mps": np.zeros(1),
        }  # fmt: skip
        self._next_id += 1
        for name in _TRACK_FIELDS:
            self._t[name] = np.concatenate([self._t[name], new[name]])

    def _lane_velocity_cov(self, direction: FloatArray) -> FloatArray:
        """Return a new track's velocity covariance (2, 2) [m^2/s^2] along a lane (unit vector)."""
        cfg = self.config
        along = np.outer(direction, direction)
        return cfg.lane_speed_std_mps**2 * along + cfg.lane_across_std_mps**2 * (np.eye(2) - along)

    def _lane_fit(self, direction: FloatArray, los: FloatArray, vr: float, noise: float) -> float:
        """Log-likelihood of a group's mean radial speed under a lane prior along ``direction``.

        ``vr`` [m/s] along the mean line of sight ``los``; the prior velocity has mean zero.
        """
        var = float(los @ self._lane_velocity_cov(direction) @ los) + noise
        return -0.5 * (vr**2 / var + math.log(var))

    def _prune(self) -> None:
        """Drop tracks gone (existence), lost (position sigma) or duplicating another's body."""
        t, cfg = self._t, self.config
        if not t["x"].shape[0]:
            return
        t["reported"] |= (t["existence"] >= cfg.report_existence) & (
            _speed_variance(t["x"], t["p"]) <= cfg.report_speed_std_mps**2
        )
        pos_std = np.sqrt(t["p"][:, 0, 0] + t["p"][:, 1, 1])
        keep = (t["existence"] >= cfg.drop_existence) & (pos_std <= cfg.lost_position_std_m)
        keep &= ~self._duplicates()
        for name in _TRACK_FIELDS:
            t[name] = t[name][keep]

    def _duplicates(self) -> np.ndarray:
        """Tracks whose box overlaps an older track's, moving alike (bool per track).

        Two bodies cannot overlap: two such tracks follow one body (parts of a long vehicle,
        the far end of a lorry opening a track of its own). Their velocities agree within
        ``same_body_sigmas`` of both estimates and of a rigid body's turn (turn rate times
        length). The older keeps its identity; the younger is dropped.
        """
        t, cfg = self._t, self.config
        x = t["x"]
        n = x.shape[0]
        out = np.zeros(n, bool)
        if n < 2:
            return out
        length, width = t["extent"][:, 0], t["extent"][:, 1]
        reach = float(length.max())
        pairs = cKDTree(x[:, :2]).query_pairs(reach, output_type="ndarray")
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]  # in order: i, then j
        for i, j in pairs.tolist():
            older, younger = (i, j) if t["born_s"][i] <= t["born_s"][j] else (j, i)
            if out[older] or out[younger]:
                continue
            h = t["heading_rad"][older]
            axis = np.array([math.cos(h), math.sin(h)])
            d = x[younger, :2] - x[older, :2]
            along, across = d @ axis, -d[0] * axis[1] + d[1] * axis[0]
            half_o, half_y = 0.5 * length[older], 0.5 * length[younger]
            if (abs(along) >= half_o + half_y
                    or abs(across) >= 0.5 * (width[older] + width[younger])):  # fmt: skip
                continue
            dv = x[younger, 2:4] - x[older, 2:4]
            turn = (abs(x[older, 4]) * 2.0 * max(half_o, half_y)) ** 2 + cfg.body_doppler_std_mps**2
            sv = t["p"][younger, 2:4, 2:4] + t["p"][older, 2:4, 2:4] + turn * np.eye(2)
            if dv @ np.linalg.solve(sv, dv) > cfg.same_body_sigmas**2:
                continue
            out[younger] = True
        return out

    def _background_explains(self, radar, g, vr, owner, cost, counts):  # type: ignore[no-untyped-def]
        """Stationary detections that a reflector of the background explains (bool each).

        A detection on a reflector's cells is the reflector's where the reflector's density
        (its detections' Gaussian scatter times its rate, spread evenly over +- the static
        speed) exceeds its best track's, unless an object stands on the reflector. That is
        tested per reflector by a CUSUM of the log-likelihood ratio of each scan's detections
        there, object beside the reflector (rate ``m``, the radar's object rate, its points
        spread over ``OBJECT_REACH_M``) against the reflector alone; at
        ``background_alarm_nats`` the reflector's detections go to the tracks again, until
        the sum falls back (it is capped at twice the threshold).
        """
        bg, cfg = self.background, self.config
        assert bg is not None
        span = bg.static_speed_mps
        reflector = bg.reflector_of(radar.name, g)
        still = (np.abs(vr) <= span) & (reflector >= 0)
        own = bg.density(reflector, g)
        for k in self._reflectors_of[radar.name]:
            here = still & (reflector == k)
            m = max(counts.rate_at(_ground_range(bg.reflector_mean[k], radar)), 0.5)
            beside = m / (math.pi * OBJECT_REACH_M**2)
            llr = float(np.log1p(beside / np.maximum(own[here], 1e-300)).sum()) - m
            self._reflector_cusum[k] = min(max(self._reflector_cusum[k] + llr, 0.0),
                                           2.0 * cfg.background_alarm_nats)  # fmt: skip
        free = np.ones(g.shape[0], bool)
        on = reflector >= 0
        free[on] = self._reflector_cusum[reflector[on]] < cfg.background_alarm_nats
        track = np.zeros(g.shape[0])
        mine = owner >= 0
        if mine.any():
            track[mine] = np.exp(-0.5 * cost[owner[mine], np.flatnonzero(mine)]) / (
                2 * math.pi) ** 1.5  # fmt: skip
        return still & free & (own / (2.0 * span) > track)

    # -- output ---------------------------------------------------------------------------
    def columns(self, time_s: float) -> dict[str, np.ndarray]:
        """Return the reported tracks at ``time_s`` (after the scan): the track table's columns."""
        t, cfg = self._t, self.config
        rows = np.flatnonzero(t["reported"] & (t["existence"] >= cfg.keep_existence))
        x, p = t["x"][rows], t["p"][rows]
        speed = np.hypot(x[:, 2], x[:, 3])
        u = _unit(x[:, 2:4])
        status = np.where(
            speed < cfg.stopped_speed_mps, _STOPPED,
            np.where(time_s - t["last_hit_s"][rows] > COASTING_S, _COASTING, _CONFIRMED),
        )  # fmt: skip
        names, chance = class_names(class_probabilities(
            t["extent"][rows, 0], t["extent_var"][rows, 0], t["extent"][rows, 1],
            t["extent_var"][rows, 1],
            t["top_speed_mps"][rows],
        ))  # fmt: skip
        return {
            "track_id": t["track_id"][rows], "time_s": np.full(rows.size, time_s),
            "east_m": x[:, 0], "north_m": x[:, 1], "speed_mps": speed,
            "east_speed_mps": x[:, 2], "north_speed_mps": x[:, 3],
            "from_crossing_m": np.hypot(x[:, 0], x[:, 1]), "status": status,
            "moved": t["moved"][rows],
            "position_std_m": np.sqrt(p[:, 0, 0] + p[:, 1, 1]),
            "speed_std_mps": np.sqrt(np.einsum("ni,nij,nj->n", u, p[:, 2:4, 2:4], u)),
            "existence": t["existence"][rows], "length_m": t["extent"][rows, 0],
            "width_m": t["extent"][rows, 1],
            "heading_rad": t["heading_rad"][rows], "class": names,
            "class_probability": chance,
        }  # fmt: skip


EXTRA_COLUMNS = ("existence", "length_m", "width_m", "heading_rad", "class",
                 "class_probability")  # fmt: skip


@dataclass
class _Counts:
    """A radar's detections per group: of a reported object by range (mean), of clutter (mean).

    A body's count falls with range (its echo power) and varies with its aspect; the mean per
    ``RANGE_BIN_M`` of ground range is learnt from the reported tracks' hits, and so is the
    detection probability (the share of scans that detect a track surely there, in view and
    hidden by none).
    """

    object_rate: FloatArray = field(default_factory=lambda: np.ones(RANGE_BINS))
    clutter_mean: float = 1.1
    pd_hits: FloatArray = field(default_factory=lambda: np.zeros(RANGE_BINS))
    pd_chances: FloatArray = field(default_factory=lambda: np.zeros(RANGE_BINS))

    def pd_at(self, ground_m: float, declared: float) -> float:
        """P_D at this ground range: hits over chances, the declared P_D worth ``PD_PRIOR``."""
        k = min(int(ground_m / RANGE_BIN_M), RANGE_BINS - 1)
        return float((self.pd_hits[k] + PD_PRIOR * declared) / (self.pd_chances[k] + PD_PRIOR))

    def learn_detection(self, ground_m: float, hit: bool) -> None:
        """Count a chance of detecting an object at this range, forgetting over ``PD_MEMORY``."""
        k = min(int(ground_m / RANGE_BIN_M), RANGE_BINS - 1)
        keep = 1.0 - 1.0 / PD_MEMORY
        self.pd_hits[k] = keep * self.pd_hits[k] + float(hit)
        self.pd_chances[k] = keep * self.pd_chances[k] + 1.0

    def rate_at(self, ground_m: float) -> float:
        """Mean detections of an object at this ground range [m]."""
        return float(self.object_rate[min(int(ground_m / RANGE_BIN_M), RANGE_BINS - 1)])

    def learn_object(self, n: int, ground_m: float, rate: float) -> None:
        """Move the mean count at this range towards ``n`` (a track's ``rate``, shared)."""
        k = min(int(ground_m / RANGE_BIN_M), RANGE_BINS - 1)
        self.object_rate[k] += rate * RADAR_SHARE * (n - self.object_rate[k])

    def learn_clutter(self, n: int, rate: float) -> None:
        """Move a clutter group's mean count towards ``n`` (at least 1.01: mostly singles)."""
        step = rate * RADAR_SHARE * (n - self.clutter_mean)
        self.clutter_mean = max(self.clutter_mean + step, 1.01)


RANGE_BIN_M = 10.0
RANGE_BINS = 40
RADAR_SHARE = 0.1  # a radar's mean counts learn at this share of a track's learning rate
PD_PRIOR = 20.0  # scans the declared P_D is worth against the learnt one
PD_MEMORY = 2000.0  # scans the learnt P_D remembers


def _empty_tracks(n_radars: int) -> dict[str, np.ndarray]:
    kinds = {"track_id": np.int64, "hits": np.int64, "moved": bool, "reported": bool}
    out = {name: np.zeros(0, kinds.get(name, float)) for name in _TRACK_FIELDS}
    out["rate"] = np.zeros((0, n_radars))
    out["extent"], out["extent_var"] = np.zeros((0, 2)), np.zeros((0, 2))
    out["x"], out["p"] = np.zeros((0, N_STATE)), np.zeros((0, N_STATE, N_STATE))
    return out


def _speed_variance(x: FloatArray, p: FloatArray) -> FloatArray:
    """Variance of the speed [m^2/s^2]: along the velocity, or its worst axis when slow."""
    v_cov = p[:, 2:4, 2:4]
    u = _unit(x[:, 2:4])
    along = np.einsum("ni,nij,nj->n", u, v_cov, u)
    worst = np.linalg.eigvalsh(v_cov)[:, -1] if len(x) else np.zeros(0)
    return np.where(np.hypot(x[:, 2], x[:, 3]) > 1.0, along, worst)


def _unit(v: FloatArray) -> FloatArray:
    """Return the unit vectors of the rows of ``v`` (a zero row gives east)."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, v / np.maximum(norm, 1e-9), np.array([1.0, 0.0]))


def _antenna_height(radar: RadarSpec, cfg: ExtendedTrackerConfig) -> float:
    """Return the antenna's height above the road [m]."""
    return cfg.antenna_height_m if cfg.antenna_height_m is not None else radar.height_m + 0.5


def _ground_range(xy: FloatArray, radar: RadarSpec) -> float:
    """Return the ground distance [m] from the radar to a point (2,)."""
    return float(np.hypot(*(np.asarray(xy) - radar.position_m)))


def _unfold(dv: FloatArray, radar: RadarSpec) -> FloatArray:
    """Radial-speed residuals folded into +-v_max of a folding radar (else unchanged)."""
    v_max = radar.max_unambiguous_speed_mps
    if not v_max:
        return dv
    return (np.asarray(dv) + v_max) % (2 * v_max) - v_max


def _ground_points(radar: RadarSpec, z: FloatArray):  # type: ignore[no-untyped-def]
    """Ground points (n, 2), their covariance (n, 2, 2), radial-speed directions (n, 2), variance.

    The radial speed of a ground point moving at ``v`` is ``a . v`` (``a``: the horizontal
    unit vector towards it times the cosine of the depression angle).
    """
    rng, az = z[:, 0], z[:, 1]
    rho = np.sqrt(np.maximum(rng**2 - radar.height_m**2, 0.01))
    s, c = np.sin(az), np.cos(az)
    g = np.asarray(radar.position_m) + np.stack([rho * s, rho * c], -1)
    sr, sa, sv = radar.noise_std(rng, az)
    d_range = (rng / rho)[:, None] * np.stack([s, c], -1)
    d_az = rho[:, None] * np.stack([c, -s], -1)
    cov = (sr**2)[:, None, None] * d_range[:, :, None] * d_range[:, None, :] + (sa**2)[
        :, None, None
    ] * d_az[:, :, None] * d_az[:, None, :]
    a = (rho / rng)[:, None] * np.stack([s, c], -1)
    return g, cov, a, np.broadcast_to(np.asarray(sv, float) ** 2, rng.shape).copy()


def track_scene_extended(
    site: Site,
    detections: pd.DataFrame,
    config: ExtendedTrackerConfig | None = None,
    on_scan: Callable[[int, int], None] | None = None,
    background: BackgroundMap | None = None,
    train_intervals: FloatArray | None = None,
    reference: bool = False,
) -> tuple[pd.DataFrame, pd.DataFrame, ExtendedLog]:
    """Track a detection table scan by scan; return the reported tracks of every scan and the log.

    Columns as :func:`.tracker.track_scene`'s (``status`` named; ``from_crossing_m`` is the
    straight distance from the crossing centre, the track not being tied to a road) and
    :data:`EXTRA_COLUMNS`; the events are :mod:`.occupancy`'s. ``background``: the empty
    site's reflectors (:mod:`.background`); ``train_intervals`` (K, 2): when the controller
    has a train due [s]. The scans run in the compiled loop (:mod:`.extended_loop`, many
    scans per call); ``reference=True`` runs :class:`ExtendedTracker` one scan per call
    instead (the NumPy reference it equals).
    """
    check_detection_table(detections)
    tracker = ExtendedTracker(site, config, background, train_intervals)
    names, radar, stamps, starts, z, _ = scan_arrays(
        detections, {r.name: r.latency_s for r in site.radars}
    )
    unknown = sorted(set(names) - set(tracker._radars))
    if unknown:
        raise ValueError(f"unknown radar {unknown[0]!r}; the site has {sorted(tracker._radars)}")
    if not reference:
        return _track_compiled(tracker, names, radar, stamps, starts, z, on_scan)
    out: list[dict[str, np.ndarray]] = []
    n_scans = stamps.size
    for k in range(n_scans):
        tracker.step(names[radar[k]], float(stamps[k]), z[starts[k] : starts[k + 1]])
        out.append(tracker.last_columns)
        if on_scan is not None and (k + 1) % 1000 == 0:
            on_scan(k + 1, n_scans)
    keys = [*ROW_COLUMNS, *EXTRA_COLUMNS]
    table = {k: np.concatenate([o[k] for o in out]) if out else np.zeros(0) for k in keys}
    return (_track_frame(table), pd.DataFrame(tracker.clearance.events, columns=EVENT_COLUMNS),
            tracker.log)  # fmt: skip


def _track_frame(table: dict[str, np.ndarray]) -> pd.DataFrame:
    """Return the track table of the columns ``table`` (``status`` as named categories)."""
    frame = pd.DataFrame({k: table[k] for k in [*ROW_COLUMNS, *EXTRA_COLUMNS]})
    frame["status"] = pd.Categorical.from_codes(
        frame["status"].astype(int), categories=STATUS_NAMES
    )
    return frame


SCANS_PER_CALL = 2000  # scans per compiled call (progress between calls)


def _track_compiled(  # type: ignore[no-untyped-def]
    tracker: ExtendedTracker, names, radar, stamps, starts, z, on_scan
) -> tuple[pd.DataFrame, pd.DataFrame, ExtendedLog]:
    """Run the scans through :func:`.extended_loop.run_scans` from ``tracker``'s initial state."""
    site_index = [tracker._radar_index[name] for name in names]
    scan_radar = np.asarray(site_index, np.int64)[radar] if radar.size else np.zeros(0, np.int64)
    specs = list(tracker._radars.values())
    latency = np.array([r.latency_s for r in specs])
    scan_time = stamps - latency[scan_radar] if stamps.size else np.zeros(0)
    arrays = _CompiledState(tracker)
    n_scans, k = stamps.size, 0
    rows = arrays.rows(n_scans)
    while k < n_scans:
        stop = min(k + SCANS_PER_CALL, n_scans)
        reached = run_scans(k, stop, scan_radar, scan_time, starts, z, arrays.tracks,
                            arrays.state, arrays.log, arrays.radars, arrays.learnt,
                            arrays.clutter, arrays.background, arrays.has_background,
                            arrays.scene, arrays.cfg, *rows)  # fmt: skip
        if reached < stop:
            need = int(starts[reached + 1] - starts[reached])
            arrays.grow(need)
            rows = arrays.grow_rows(rows, need)
        elif on_scan is not None:
            on_scan(stop, n_scans)
        k = reached
    return arrays.result(rows)


class _CompiledState:
    """The arrays of :mod:`.extended_loop` built from a new tracker, and the result from them."""

    def __init__(self, tracker: ExtendedTracker) -> None:
        cfg = tracker.config
        specs = list(tracker._radars.values())
        values = {f.name: getattr(cfg, f.name) for f in fields(cfg)}
        values.update(
            gate=tracker._gate, extent_floor_m=EXTENT_FLOOR_M, object_reach_m=OBJECT_REACH_M,
            coasting_s=COASTING_S, range_bin_m=RANGE_BIN_M, radar_share=RADAR_SHARE,
            pd_prior=PD_PRIOR, pd_memory=PD_MEMORY,
            clutter_prior_scans=next(iter(tracker._clutter.values())).prior_scans,
            area_cell_m=AREA_CELL_M,
        )  # fmt: skip
        self.cfg = np.array([float(values[name]) for name in CFG_FIELDS])
        n_r = len(specs)
        n_f = max(len(r.fields) for r in specs)
        fields_table = np.zeros((n_r, n_f, 2))
        for i, r in enumerate(specs):
            fields_table[i, : len(r.fields)] = r.field_table()
        noise = [r.noise_table() for r in specs]
        pd_curves = [curve_tables((r.detection_curve("default"),)) for r in specs]
        k_noise = max(t.shape[-1] for t, _ in noise)
        k_pd = max(t.shape[-1] for t, _ in pd_curves)
        noise_table = np.zeros((n_r, 3, 2, k_noise))
        pd_table = np.zeros((n_r, 1, 2, k_pd))
        for i in range(n_r):
            noise_table[i, :, :, : noise[i][0].shape[-1]] = noise[i][0]
            pd_table[i, :, :, : pd_curves[i][0].shape[-1]] = pd_curves[i][0]
        self.radars = (
            np.array([r.kernel_row() for r in specs]),
            fields_table,
            np.array([len(r.fields) for r in specs], np.int64),
            noise_table,
            np.array([n for _, n in noise], np.int64),
            pd_table,
            np.array([n for _, n in pd_curves], np.int64),
            np.array([_antenna_height(r, cfg) for r in specs]),
        )
        counts = [tracker._counts[r.name] for r in specs]
        self.learnt = (
            np.array([c.object_rate for c in counts]),
            np.array([c.clutter_mean for c in counts]),
            np.array([c.pd_hits for c in counts]),
            np.array([c.pd_chances for c in counts]),
        )
        cell = cfg.clutter_cell_m
        first = np.array([np.floor((np.asarray(r.position_m) - r.max_range_m) / cell) - 1
                          for r in specs]).astype(np.int64)  # fmt: skip
        span = max(math.ceil(2 * r.max_range_m / cell) + 3 for r in specs)
        self.clutter = (np.zeros((n_r, span, span)), np.zeros((n_r, span, span), np.int64),
                        first, np.zeros(n_r, np.int64))  # fmt: skip
        self.has_background = tracker.background is not None
        self.background = _background_arrays(tracker, specs)
        area = tracker.clearance.area
        rails = area.rails
        rails_row = (
            np.array([0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0]) if rails is None else np.array([
                *rails.centre_m, *rails.direction,
                area.rails_half_width_m,
                TRAIN_SPEED_MPS, math.tan(math.radians(TRAIN_ALIGN_DEG)),
            ])
        )  # fmt: skip
        self.scene = (
            np.ascontiguousarray(tracker._lane_xy, dtype=float),
            np.ascontiguousarray(tracker._lane_dir, dtype=float),
            np.ascontiguousarray(area.inside), np.asarray(area.origin, float),
            np.ascontiguousarray(tracker.clearance.trains, dtype=float), rails_row,
            lane_grid(tracker._lane_xy, cfg.lane_prior_m),
        )  # fmt: skip
        self.state = np.array([0, tracker._next_id, -1, 0, 0, 0], np.int64)
        self.log = np.zeros(5, np.int64)
        self.tracks = tuple(tracker._t[name] for name in TRACK_ARRAYS)
        self.grow(64)

    def grow(self, need: int) -> None:
        """Make room for ``need`` more tracks than held (doubling)."""
        held = int(self.state[0])
        size = self.tracks[0].shape[0]
        if held + need <= size and size:
            return
        new = max(2 * size, held + need, 64)
        grown = []
        for arr in self.tracks:
            out = np.zeros((new, *arr.shape[1:]), arr.dtype)
            out[:held] = arr[:held]
            grown.append(out)
        self.tracks = tuple(grown)

    def rows(self, n_scans: int) -> tuple[FloatArray, np.ndarray, FloatArray]:
        """Output arrays for a first guess of the rows (8 a scan) and events."""
        size = max(8 * n_scans, 1024)
        return np.zeros((size, N_ROW_F)), np.zeros((size, 3), np.int64), np.zeros((1024, 5))

    def grow_rows(self, rows, need: int):  # type: ignore[no-untyped-def]
        """Double the output arrays that could run out in the next scan."""
        rows_f, rows_i, events = rows
        held, written, n_events = (int(v) for v in self.state[[0, 3, 4]])
        if written + held + need > rows_f.shape[0]:
            size = 2 * rows_f.shape[0] + held + need
            rows_f = np.concatenate([rows_f, np.zeros((size - rows_f.shape[0], N_ROW_F))])
            rows_i = np.concatenate([rows_i, np.zeros((size - rows_i.shape[0], 3), np.int64)])
        if n_events + 1 > events.shape[0]:
            events = np.concatenate([events, np.zeros(events.shape)])
        return rows_f, rows_i, events

    def result(self, rows) -> tuple[pd.DataFrame, pd.DataFrame, ExtendedLog]:  # type: ignore[no-untyped-def]
        """Return the track table, the events and the log of the run."""
        rows_f, rows_i, events = rows
        n_rows, n_events = int(self.state[3]), int(self.state[4])
        f = dict(zip(ROW_F_FIELDS, rows_f[:n_rows].T, strict=True))
        status_codes = np.array([_CONFIRMED, _COASTING, _STOPPED], np.int64)
        names, chance = class_names(class_probabilities(
            f["length_m"], f["length_var"], f["width_m"], f["width_var"], f["top_speed_mps"]
        ))  # fmt: skip
        table = {
            "track_id": rows_i[:n_rows, 0], "time_s": f["time_s"], "east_m": f["east_m"],
            "north_m": f["north_m"], "speed_mps": f["speed_mps"],
            "east_speed_mps": f["east_speed_mps"], "north_speed_mps": f["north_speed_mps"],
            "from_crossing_m": np.hypot(f["east_m"], f["north_m"]),
            "status": status_codes[rows_i[:n_rows, 1]], "moved": rows_i[:n_rows, 2] > 0,
            "position_std_m": f["position_std_m"], "speed_std_mps": f["speed_std_mps"],
            "existence": f["existence"], "length_m": f["length_m"], "width_m": f["width_m"],
            "heading_rad": f["heading_rad"], "class": names, "class_probability": chance,
        }  # fmt: skip
        ev = events[:n_events]
        kinds = np.array([EVENT_NOT_CLEAR, EVENT_CLEAR], dtype=object)
        event_frame = pd.DataFrame({
            "time_s": ev[:, 0], "event": kinds[ev[:, 1].astype(int)],
            "track_id": ev[:, 2].astype(np.int64), "east_m": ev[:, 3], "north_m": ev[:, 4],
            "lead_s": np.full(n_events, np.nan),
        }, columns=EVENT_COLUMNS)  # fmt: skip
        log = ExtendedLog(*(int(v) for v in self.log))
        return _track_frame(table), event_frame, log


def _background_arrays(tracker: ExtendedTracker, specs: list[RadarSpec]) -> tuple[object, ...]:
    """Return the background map's arrays for :mod:`.extended_loop` (empty without a map)."""
    bg = tracker.background
    n_r = len(specs)
    if bg is None:
        return (np.zeros((n_r, 1, 1), np.int64), np.zeros(2), 1.0, 0.5, np.zeros((0, 2)),
                np.zeros((0, 2, 2)), np.zeros(0), np.zeros((n_r, 1), np.int64),
                np.zeros(n_r, np.int64), tracker._reflector_cusum)  # fmt: skip
    regions = np.zeros((n_r, *bg.regions.shape[1:]), np.int64)
    seen = [tracker._reflectors_of[r.name] for r in specs]
    seen_by = np.zeros((n_r, max(1, max(s.size for s in seen))), np.int64)
    for i, r in enumerate(specs):
        if r.name in bg.radars:
            regions[i] = bg.regions[bg.radars.index(r.name)]
        seen_by[i, : seen[i].size] = seen[i]
    return (regions, np.asarray(bg.origin_m, float), float(bg.cell_m),
            float(bg.static_speed_mps), np.ascontiguousarray(bg.reflector_mean, dtype=float),
            np.ascontiguousarray(bg.reflector_cov, dtype=float),
            np.ascontiguousarray(bg.reflector_rate, dtype=float), seen_by,
            np.array([s.size for s in seen], np.int64), tracker._reflector_cusum)  # fmt: skip


__all__ = ["EXTRA_COLUMNS", "ExtendedLog", "ExtendedTracker", "ExtendedTrackerConfig",
           "track_scene_extended"]  # fmt: skip
