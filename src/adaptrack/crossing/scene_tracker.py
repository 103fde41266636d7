"""Many-object tracker of a crossing scene: raw detections in, tracks and hazard events out.

Each track is an EKF in the coordinates of a corridor through the crossing
(:mod:`adaptrack.crossing.corridor`): state ``[u, du/dt, d2u/dt2, d]`` (constant acceleration
along the corridor with white jerk of PSD ``accel_psd``, lateral offset ``d`` a random walk),
measured in (range, azimuth, radial speed) through the lane geometry, including the
``1 + kappa d`` speed of a point off the corridor's centre on a curve. A road user gives
several detections over its body: each is a measurement of the body centre whose noise adds
the body spread along (``body_along_std_m``) and across (``body_across_std_m``).

One scan (all detections of one radar at one time) is processed as: predict every track to
the scan time; gate the detections of the tracks in that radar's view (chi-square on the
three-dimensional innovation); assign one detection per track by global nearest neighbour
(:func:`adaptrack.tracking.gnn_assign`); give every further gated detection to the track it
is closest to (the body's other reflections); update; record hits and misses (M-of-N
confirmation, deletion by coasting time: :mod:`adaptrack.tracking.lifecycle`); open tentative
tracks from the detections left over, clustered within ``cluster_radius_m``.

Stopped mode: a confirmed track slower than ``stop_speed_mps`` for ``stop_confirm_s`` is held
at zero velocity with a small position noise (its covariance stays bounded through closures of
minutes, seen or not), and leaves the mode when a detection's radial speed shows motion. A
track that has never moved faster than ``moved_speed_mps`` and further than
``moved_distance_m`` from where it opened is a *static* object (a barrier
arm, a pole, rails: zero Doppler since the start); a stopped vehicle had moved. Hazard event:
a moved track stopped within ``barrier_m`` of the crossing raises
"object stopped between the barriers".

No detection is dropped silently: every one is recorded as used by a track, opening a track,
or rejected with a reason (``ScanLog``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from .._typing import FloatArray
from ..coords.radar import wrap_to_pi
from ..tracking import (
    LifecycleRules,
    TrackBook,
    TrackStatus,
    cluster_points,
    gate_threshold,
    gnn_assign,
    mahalanobis_squared,
)
from .corridor import Corridor, site_corridors
from .sensor import RadarSpec
from .site import Site
from .tracking import _initial_point, _polar_jacobian

N_STATE = 4  # u, du/dt, d2u/dt2, d
EVENT_COLUMNS = ["time_s", "event", "track_id", "east_m", "north_m"]


@dataclass(frozen=True)
class SceneTrackerConfig:
    """Tuning of the scene tracker (units in the names)."""

    accel_psd: float = 4.0  # white jerk PSD along the corridor [m^2/s^5]
    lateral_psd: float = 0.02  # lateral random walk [m^2/s]
    stopped_psd: float = 1e-4  # position random walk while stopped [m^2/s]
    body_along_std_m: float = 1.5  # initial spread of reflections along a body, learnt per track
    spread_learning_rate: float = 0.03
    spread_limits_m: tuple[float, float] = (0.3, 3.0)
    body_across_std_m: float = 0.5
    gate_probability: float = 0.999
    cluster_radius_m: float = 3.0
    stop_speed_mps: float = 0.3
    stop_confirm_s: float = 0.5
    moving_radial_mps: float = 0.6  # a detection this fast (beyond 3 sigma) ends a stop
    moved_speed_mps: float = 0.8
    moved_distance_m: float = 3.0  # ... and has moved this far from where it was opened
    initial_speed_std_mps: float = 15.0
    merge_lateral_m: float = 1.2  # two tracks this close across (and along: the spread) ...
    merge_speed_mps: float = 2.0  # ... and this similar in speed are one body
    rules: LifecycleRules = field(default_factory=LifecycleRules)


@dataclass
class _Tracks:
    """Live tracks' filter states (rows aligned with the TrackBook)."""

    corridor: np.ndarray
    x: FloatArray
    p: FloatArray
    time_s: FloatArray
    stopped: np.ndarray
    slow_since: FloatArray
    moved: np.ndarray
    event_raised: np.ndarray
    born_u: FloatArray
    spread: FloatArray  # body spread of the reflections along the track [m]

    @classmethod
    def empty(cls) -> _Tracks:
        return cls(
            np.zeros(0, int), np.zeros((0, N_STATE)), np.zeros((0, N_STATE, N_STATE)),
            np.zeros(0), np.zeros(0, bool), np.full(0, np.nan), np.zeros(0, bool),
            np.zeros(0, bool), np.zeros(0), np.zeros(0),
        )  # fmt: skip

    def append(self, other: _Tracks) -> None:
        for name in self.__dataclass_fields__:
            setattr(self, name, np.concatenate([getattr(self, name), getattr(other, name)]))

    def keep(self, mask: np.ndarray) -> None:
        for name in self.__dataclass_fields__:
            setattr(self, name, getattr(self, name)[mask])


@dataclass
class ScanLog:
    """What became of the detections: counts by outcome (every detection is in one)."""

    updated: int = 0
    opened: int = 0
    joined_new: int = 0  # clustered into a new track's first detection
    rejected_outside_view: int = 0

    @property
    def total(self) -> int:
        """Detections accounted for."""
        return self.updated + self.opened + self.joined_new + self.rejected_outside_view


def _transition(dt: FloatArray, q: float, q_lat: float) -> tuple[FloatArray, FloatArray]:
    """Constant-acceleration (white jerk) transition and noise (T, 4, 4) for steps ``dt``."""
    n = dt.size
    f = np.zeros((n, N_STATE, N_STATE))
    f[:, 0, 0] = f[:, 1, 1] = f[:, 2, 2] = f[:, 3, 3] = 1.0
    f[:, 0, 1] = f[:, 1, 2] = dt
    f[:, 0, 2] = dt**2 / 2
    qm = np.zeros((n, N_STATE, N_STATE))
    qm[:, 0, 0] = q * dt**5 / 20
    qm[:, 0, 1] = qm[:, 1, 0] = q * dt**4 / 8
    qm[:, 0, 2] = qm[:, 2, 0] = q * dt**3 / 6
    qm[:, 1, 1] = q * dt**3 / 3
    qm[:, 1, 2] = qm[:, 2, 1] = q * dt**2 / 2
    qm[:, 2, 2] = q * dt
    qm[:, 3, 3] = q_lat * dt
    return f, qm


def _measure(
    cor: Corridor, radar: RadarSpec, x: FloatArray, spread: FloatArray, cfg: SceneTrackerConfig
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted (range, azimuth, radial speed), Jacobian (T, 3, 4) and noise (T, 3, 3)."""
    path = cor.path
    u, vu, d = x[:, 0], x[:, 1], x[:, 3]
    pos, tangent, right, kappa = path.lane_geometry(u, d)
    lever = 1.0 + kappa * d
    along = lever[:, None] * tangent
    vel = vu[:, None] * along
    zp, jp, jv = _polar_jacobian(pos, vel, radar)
    dvel_du = -(vu * lever * kappa)[:, None] * right
    dvel_dd = (vu * kappa)[:, None] * tangent
    h = np.zeros((x.shape[0], 3, N_STATE))
    h[:, :, 0] = np.einsum("tij,tj->ti", jp, along) + np.einsum("tij,tj->ti", jv, dvel_du)
    h[:, :, 1] = np.einsum("tij,tj->ti", jv, along)
    h[:, :, 3] = np.einsum("tij,tj->ti", jp, right) + np.einsum("tij,tj->ti", jv, dvel_dd)
    std = np.stack(radar.noise_std(zp[:, 0], zp[:, 1]), -1)
    r = std[:, :, None] ** 2 * np.eye(3)
    b_along = np.einsum("tij,tj->ti", jp[:, :2], tangent)
    b_across = np.einsum("tij,tj->ti", jp[:, :2], right)
    r[:, :2, :2] += (spread**2)[:, None, None] * b_along[:, :, None] * b_along[:, None, :]
    r[:, :2, :2] += cfg.body_across_std_m**2 * b_across[:, :, None] * b_across[:, None, :]
    return zp, h, r


class SceneTracker:
    """Incremental many-object tracker of one site (module docstring).

    ``step(radar, time_s, detections)`` processes one scan and returns the rows of the tracks
    at that time; ``events`` and ``log`` collect hazard events and detection outcomes.
    """

    def __init__(self, site: Site, config: SceneTrackerConfig | None = None) -> None:
        self.site = site
        self.config = config or SceneTrackerConfig()
        self.corridors = site_corridors(site.roads, site.zone_m + site.run_in_m)
        self.book = TrackBook(self.config.rules)
        self.tracks = _Tracks.empty()
        self.events: list[dict[str, object]] = []
        self.log = ScanLog()
        self._radars = {r.name: r for r in site.radars}
        self._gate = gate_threshold(3, self.config.gate_probability)
        self._last_time: dict[str, float] = {}

    # -- prediction -------------------------------------------------------------------------
    def _predict(self, time_s: float) -> None:
        tr = self.tracks
        if tr.time_s.size == 0:
            return
        dt = np.maximum(time_s - tr.time_s, 0.0)
        cfg = self.config
        f, q = _transition(dt, cfg.accel_psd, cfg.lateral_psd)
        st = tr.stopped
        if st.any():  # held at a standstill
            f[st] = np.eye(N_STATE)
            q[st] = 0.0
            q[st, 0, 0] = cfg.stopped_psd * dt[st]
            q[st, 3, 3] = cfg.stopped_psd * dt[st]
        tr.x = np.einsum("tij,tj->ti", f, tr.x)
        tr.p = f @ tr.p @ np.swapaxes(f, -1, -2) + q
        tr.time_s = np.maximum(tr.time_s, time_s)

    def _predicted_detections(self, radar: RadarSpec, rows: np.ndarray) -> tuple[FloatArray, ...]:
        zp = np.zeros((rows.size, 3))
        h = np.zeros((rows.size, 3, N_STATE))
        r = np.zeros((rows.size, 3, 3))
        for c, cor in enumerate(self.corridors):
            sel = self.tracks.corridor[rows] == c
            if sel.any():
                zp[sel], h[sel], r[sel] = _measure(
                    cor, radar, self.tracks.x[rows[sel]], self.tracks.spread[rows[sel]],
                    self.config,
                )  # fmt: skip
        s = h @ self.tracks.p[rows] @ np.swapaxes(h, -1, -2) + r
        return zp, h, r, s

    # -- update -----------------------------------------------------------------------------
    def _update(self, rows: np.ndarray, z: FloatArray, radar: RadarSpec) -> None:
        tr = self.tracks
        zp, h, r, s = self._predicted_detections(radar, rows)
        nu = z - zp
        nu[:, 1] = wrap_to_pi(nu[:, 1])
        # a detection that shows motion ends a stop (velocity freed again)
        moving = tr.stopped[rows] & (np.abs(z[:, 2]) > self.config.moving_radial_mps)
        if moving.any():
            mv = rows[moving]
            tr.stopped[mv] = False
            tr.slow_since[mv] = np.nan
            tr.p[mv, 1, 1] += 4.0
            tr.p[mv, 2, 2] += 4.0
            zp, h, r, s = self._predicted_detections(radar, rows)
            nu = z - zp
            nu[:, 1] = wrap_to_pi(nu[:, 1])
        self._learn_spread(rows, z, radar)
        pht = tr.p[rows] @ np.swapaxes(h, -1, -2)
        k = np.swapaxes(np.linalg.solve(s, np.swapaxes(pht, -1, -2)), -1, -2)
        x = tr.x[rows] + np.einsum("tij,tj->ti", k, nu)
        ikh = np.eye(N_STATE) - k @ h
        p = ikh @ tr.p[rows] @ np.swapaxes(ikh, -1, -2) + k @ r @ np.swapaxes(k, -1, -2)
        held = tr.stopped[rows]
        x[held, 1:3] = 0.0
        tr.x[rows] = x
        tr.p[rows] = 0.5 * (p + np.swapaxes(p, -1, -2))

    def _learn_spread(self, rows: np.ndarray, z: FloatArray, radar: RadarSpec) -> None:
        """Follow the spread of the reflections along each body.

        A moving average of the squared along-track residuals, less the sensor's share.
        """
        tr = self.tracks
        xy, _, horiz = _initial_point(z, radar)
        along = np.zeros(rows.size)
        for c, cor in enumerate(self.corridors):
            sel = tr.corridor[rows] == c
            if sel.any():
                pos, tangent, _, _ = cor.path.lane_geometry(tr.x[rows[sel], 0], tr.x[rows[sel], 3])
                along[sel] = np.einsum("ti,ti->t", xy[sel] - pos, tangent)
        sensor = radar.noise_std(z[:, 0], z[:, 1])
        floor = sensor[0] ** 2 + (horiz * sensor[1]) ** 2
        sample = np.maximum(along**2 - floor - tr.p[rows, 0, 0], 0.0)
        w = self.config.spread_learning_rate
        var = (1 - w) * tr.spread[rows] ** 2 + w * sample
        lo, hi = self.config.spread_limits_m
        tr.spread[rows] = np.sqrt(np.clip(var, lo**2, hi**2))

    # -- track opening ----------------------------------------------------------------------
    def _open(self, z: FloatArray, radar: RadarSpec, time_s: float) -> int:
        """Open one tentative track per cluster of detections ``z`` (n, 3); return the count."""
        xy, _, _ = _initial_point(z, radar)
        labels = cluster_points(xy, self.config.cluster_radius_m)
        n_new = int(labels.max()) + 1 if labels.size else 0
        if n_new == 0:
            return 0
        centre = np.stack([np.bincount(labels, xy[:, i]) for i in range(2)], -1).astype(float)
        centre /= np.bincount(labels)[:, None]
        first = np.array([np.flatnonzero(labels == g)[0] for g in range(n_new)])
        vr = z[first, 2]
        best_c = np.zeros(n_new, int)
        best = np.full(n_new, np.inf)
        u0 = np.zeros(n_new)
        d0 = np.zeros(n_new)
        for c, cor in enumerate(self.corridors):
            u, d = cor.path.project(centre)
            far = np.abs(d)
            better = far < best
            best_c[better], best[better], u0[better], d0[better] = (
                c,
                far[better],
                u[better],
                d[better],
            )
        x = np.zeros((n_new, N_STATE))
        p = np.zeros((n_new, N_STATE, N_STATE))
        for c, cor in enumerate(self.corridors):
            sel = best_c == c
            if not sel.any():
                continue
            pos, tangent, _, _ = cor.path.lane_geometry(u0[sel], d0[sel])
            rel = pos - np.asarray(radar.position_m)
            cos = np.einsum("ti,ti->t", rel, tangent) / np.hypot(
                np.linalg.norm(rel, axis=-1), radar.height_m
            )
            ok = np.abs(cos) > 0.3
            x[sel, 1] = np.where(ok, vr[sel] / np.where(ok, cos, 1.0), 0.0)
            sv = radar.noise_std(z[first[sel], 0], z[first[sel], 1])[2]
            p[sel, 1, 1] = np.where(
                ok, (sv / np.where(ok, np.abs(cos), 1.0)) ** 2 + 1.0,
                self.config.initial_speed_std_mps**2,
            )  # fmt: skip
        x[:, 0], x[:, 3] = u0, d0
        p[:, 0, 0] = 1.0 + self.config.body_along_std_m**2
        p[:, 2, 2] = 9.0
        p[:, 3, 3] = 1.0
        self.book.add(n_new, time_s)
        self.tracks.append(
            _Tracks(
                best_c, x, p, np.full(n_new, time_s), np.zeros(n_new, bool),
                np.full(n_new, np.nan), np.zeros(n_new, bool), np.zeros(n_new, bool), u0,
                np.full(n_new, self.config.body_along_std_m),
            )
        )  # fmt: skip
        return n_new

    # -- one scan ---------------------------------------------------------------------------
    def step(self, radar_name: str, time_s: float, z: FloatArray) -> pd.DataFrame:
        """Process the detections ``z`` (n, 3) of one radar scan; return the tracks' rows."""
        radar = self._radars.get(radar_name)
        if radar is None:
            raise ValueError(f"unknown radar {radar_name!r}; the site has {sorted(self._radars)}")
        last = self._last_time.get(radar_name, -np.inf)
        if not time_s > last:
            raise ValueError(
                f"radar {radar_name!r}: scan at {time_s} s is not after its previous scan at "
                f"{last} s (scans of a radar must be in time order, one per time)"
            )
        self._last_time[radar_name] = time_s
        z = np.asarray(z, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(z)):
            raise ValueError(f"radar {radar_name!r} at {time_s} s: a detection is not finite")
        self._predict(time_s)
        view = radar.in_view(z[:, 0], z[:, 1])
        self.log.rejected_outside_view += int((~view).sum())
        z = z[view]
        tr = self.tracks
        n_t = tr.time_s.size
        rows = np.arange(n_t)
        hit = np.zeros(n_t, dtype=bool)
        used = np.zeros(z.shape[0], dtype=bool)
        if n_t:
            zp, _h, _r, s = self._predicted_detections(radar, rows)
            seen = radar.in_view(zp[:, 0], zp[:, 1])
            rows = rows[seen]
            zp, s = zp[seen], s[seen]
            if rows.size and z.shape[0]:
                nu = z[None, :, :] - zp[:, None, :]
                nu[..., 1] = wrap_to_pi(nu[..., 1])
                d2 = mahalanobis_squared(nu, s)
                gated = d2 <= self._gate
                cost = np.where(gated, d2, np.inf)
                ti, di = gnn_assign(cost, self._gate)
                owner = np.full(z.shape[0], -1)
                owner[di] = ti
                # the body's other reflections: gated, unassigned detections join the closest
                rest = np.flatnonzero((owner < 0) & gated.any(axis=0))
                owner[rest] = np.argmin(cost[:, rest], axis=0)
                assigned = np.flatnonzero(owner >= 0)
                # sequential rounds: each track takes at most one detection per round
                order = assigned[np.argsort(d2[owner[assigned], assigned], kind="stable")]
                rnd = np.zeros(order.size, int)
                count: dict[int, int] = {}
                for j, det in enumerate(order):
                    rnd[j] = count.get(int(owner[det]), 0)
                    count[int(owner[det])] = rnd[j] + 1
                for k in range(int(rnd.max()) + 1 if rnd.size else 0):
                    dets = order[rnd == k]
                    self._update(rows[owner[dets]], z[dets], radar)
                used[assigned] = True
                hit[rows[owner[assigned]]] = True
            self.book.record(rows, hit[rows], time_s)
        self.log.updated += int(used.sum())
        left = z[~used]
        if left.shape[0]:
            n_new = self._open(left, radar, time_s)
            self.log.opened += n_new
            self.log.joined_new += left.shape[0] - n_new
            hit = np.concatenate([hit, np.ones(n_new, bool)])
        self._modes(time_s)
        self._delete(time_s)
        self._merge()
        return self.rows(time_s)

    def _merge(self) -> None:
        """Drop the younger of two tracks on one body.

        Same corridor, within the bodies' spreads along it, within ``merge_lateral_m``
        across, velocities alike (within ``merge_speed_mps`` plus three sigma).
        """
        tr = self.tracks
        n = tr.time_s.size
        if n < 2:
            return
        pts = np.stack([tr.x[:, 0] + 1e6 * tr.corridor, tr.x[:, 3]], -1)
        reach = 2.0 * float(tr.spread.max()) + 1.0
        pairs = cKDTree(pts).query_pairs(reach, output_type="ndarray")
        if pairs.size == 0:
            return
        a, b = pairs[:, 0], pairs[:, 1]
        du = np.abs(tr.x[a, 0] - tr.x[b, 0])
        dd = np.abs(tr.x[a, 3] - tr.x[b, 3])
        dv = np.abs(tr.x[a, 1] - tr.x[b, 1])
        sv = np.sqrt(tr.p[a, 1, 1] + tr.p[b, 1, 1])
        same = (
            (du < tr.spread[a] + tr.spread[b] + 0.5)
            & (dd < self.config.merge_lateral_m)
            & (dv < self.config.merge_speed_mps + 3.0 * sv)
        )
        conf = self.book.confirmed
        drop = set()
        for i, j in pairs[same]:
            older, younger = (i, j) if self.book.ids[i] < self.book.ids[j] else (j, i)
            if conf[younger] and not conf[older]:
                older, younger = younger, older
            if int(older) not in drop:
                drop.add(int(younger))
        self._drop(np.array(sorted(drop), dtype=int))

    def _modes(self, time_s: float) -> None:
        cfg = self.config
        tr = self.tracks
        conf = self.book.confirmed
        speed = np.abs(tr.x[:, 1])
        sd = np.sqrt(tr.p[:, 1, 1])
        travelled = np.abs(tr.x[:, 0] - tr.born_u)
        tr.moved |= (
            conf & (speed > cfg.moved_speed_mps) & (sd < 0.5 * speed)
            & (travelled > cfg.moved_distance_m)
        )  # fmt: skip
        slow = conf & ~tr.stopped & (speed < cfg.stop_speed_mps) & (sd < 0.5)
        tr.slow_since = np.where(
            slow, np.where(np.isnan(tr.slow_since), time_s, tr.slow_since), np.nan
        )
        enter = slow & (time_s - tr.slow_since >= cfg.stop_confirm_s)
        if enter.any():
            tr.stopped[enter] = True
            tr.x[enter, 1:3] = 0.0
            tr.p[enter, 1:3, :] = 0.0
            tr.p[enter, :, 1:3] = 0.0
        # hazard: a road user stopped between the barriers
        to_cross = np.zeros(tr.time_s.size)
        for c, cor in enumerate(self.corridors):
            sel = tr.corridor == c
            to_cross[sel] = np.abs(cor.crossing_u - tr.x[sel, 0])
        hazard = tr.stopped & tr.moved & ~tr.event_raised & (to_cross <= self.site.barrier_m)
        for i in np.flatnonzero(hazard):
            pos = self._position(np.array([i]))[0]
            self.events.append(
                {
                    "time_s": time_s,
                    "event": "stopped_between_barriers",
                    "track_id": int(self.book.ids[i]),
                    "east_m": float(pos[0]),
                    "north_m": float(pos[1]),
                }
            )
        tr.event_raised |= hazard

    def _delete(self, time_s: float) -> None:
        tr = self.tracks
        gone = self.book.expired(time_s, tr.stopped)
        # tracks that left every corridor
        out = np.zeros(tr.time_s.size, bool)
        for c, cor in enumerate(self.corridors):
            sel = tr.corridor == c
            out[sel] = (tr.x[sel, 0] < 0) | (tr.x[sel, 0] > cor.path.length_m)
        self._drop(np.union1d(gone, np.flatnonzero(out)))

    def _drop(self, rows: np.ndarray) -> None:
        """Forget the tracks in ``rows`` (book and filter states)."""
        if rows.size:
            keep = np.ones(self.tracks.time_s.size, bool)
            keep[rows] = False
            self.book.remove(rows)
            self.tracks.keep(keep)

    def _position(self, rows: np.ndarray) -> FloatArray:
        tr = self.tracks
        pos = np.zeros((rows.size, 2))
        for c, cor in enumerate(self.corridors):
            sel = tr.corridor[rows] == c
            if sel.any():
                pos[sel] = cor.path.lane_geometry(tr.x[rows[sel], 0], tr.x[rows[sel], 3])[0]
        return pos

    def status(self) -> np.ndarray:
        """Status (TrackStatus values) of every live track."""
        tr = self.tracks
        st = np.full(tr.time_s.size, int(TrackStatus.TENTATIVE))
        conf = self.book.confirmed
        coasting = conf & (tr.time_s - self.book.last_hit_s > 0.2)
        st[conf] = int(TrackStatus.CONFIRMED)
        st[coasting] = int(TrackStatus.COASTING)
        st[conf & tr.stopped] = int(TrackStatus.STOPPED)
        return st

    def rows(self, time_s: float) -> pd.DataFrame:
        """Estimates of every confirmed track at ``time_s`` (after the scan's update)."""
        tr = self.tracks
        rows = np.flatnonzero(self.book.confirmed)
        pos = np.zeros((rows.size, 2))
        speed = np.zeros(rows.size)
        pos_std = np.zeros(rows.size)
        vel = np.zeros((rows.size, 2))
        to_cross = np.zeros(rows.size)
        for c, cor in enumerate(self.corridors):
            sel = tr.corridor[rows] == c
            if not sel.any():
                continue
            x = tr.x[rows[sel]]
            p_, tangent, right, kappa = cor.path.lane_geometry(x[:, 0], x[:, 3])
            lever = 1.0 + kappa * x[:, 3]
            pos[sel] = p_
            speed[sel] = np.abs(x[:, 1] * lever)
            vel[sel] = (x[:, 1] * lever)[:, None] * tangent
            to_cross[sel] = np.abs(cor.crossing_u - x[:, 0])
            jac = np.stack([lever[:, None] * tangent, right], -1)
            sub = tr.p[rows[sel]][:, [0, 3]][:, :, [0, 3]]
            cov = jac @ sub @ np.swapaxes(jac, -1, -2)
            pos_std[sel] = np.sqrt(np.trace(cov, axis1=-2, axis2=-1))
        status = self.status()[rows]
        names = {int(s): s.name.lower() for s in TrackStatus}
        return pd.DataFrame(
            {
                "track_id": self.book.ids[rows],
                "time_s": time_s,
                "east_m": pos[:, 0],
                "north_m": pos[:, 1],
                "speed_mps": speed,
                "east_speed_mps": vel[:, 0],
                "north_speed_mps": vel[:, 1],
                "from_crossing_m": to_cross,
                "status": [
                    names[int(s)] if tr.moved[i] or s != TrackStatus.STOPPED else "static"
                    for i, s in zip(rows, status, strict=True)
                ],
                "moved": tr.moved[rows],
                "position_std_m": pos_std,
                "speed_std_mps": np.sqrt(tr.p[rows, 1, 1]),
            }
        )


def iter_scans(detections: pd.DataFrame) -> Iterator[tuple[str, float, FloatArray]]:
    """Yield the scans of a detection table in time order (radar name breaks ties).

    A scan is the detections (range_m, azimuth_rad, radial_speed_mps) of one radar at one time.
    """
    t = detections["time_s"].to_numpy()
    radar = detections["radar"].astype(str).to_numpy()
    z = detections[["range_m", "azimuth_rad", "radial_speed_mps"]].to_numpy(dtype=float)
    order = np.lexsort((radar, t))
    t, radar, z = t[order], radar[order], z[order]
    cut = np.flatnonzero((np.diff(t) != 0) | (radar[1:] != radar[:-1])) + 1
    starts = np.concatenate([[0], cut, [t.size]]) if t.size else np.zeros(1, int)
    for a, b in itertools.pairwise(starts):
        yield str(radar[a]), float(t[a]), z[a:b]


def track_scene(
    site: Site,
    detections: pd.DataFrame,
    config: SceneTrackerConfig | None = None,
    on_scan: Callable[[int, int], None] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame, ScanLog]:
    """Track a detection table scan by scan (:func:`iter_scans`).

    ``on_scan(done, total)`` is called after each scan (progress). Returns the track rows of
    every scan, the hazard events and the detection log.
    """
    tracker = SceneTracker(site, config)
    scans = list(iter_scans(detections))
    out = []
    for i, (radar, t, z) in enumerate(scans):
        out.append(tracker.step(radar, t, z))
        if on_scan is not None:
            on_scan(i + 1, len(scans))
    tracks = pd.concat(out, ignore_index=True) if out else pd.DataFrame()
    return tracks, pd.DataFrame(tracker.events, columns=EVENT_COLUMNS), tracker.log


__all__ = [
    "EVENT_COLUMNS",
    "ScanLog",
    "SceneTracker",
    "SceneTrackerConfig",
    "iter_scans",
    "track_scene",
]
