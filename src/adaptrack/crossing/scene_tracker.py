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
three-dimensional innovation; a detection on another road user's body that lies beyond a
track's own body end along the lane costs that track its excess, ``body_extent_gate``, and
a stopped road user's track pays it for any detection beyond its body's end; in a
standing queue, a track hidden behind a nearer stopped road user is seen, if at all, over
its own body: a detection in the occluder's gate beyond it is the occluder's,
``occlusion_gate``);
assign one detection per track by global nearest neighbour
(:func:`adaptrack.tracking.gnn_assign`; a static object that has stood longer than
``clutter_age_s`` keeps the detections in its own tight gate: learnt clutter such as a rail);
give every further gated detection to the track most likely to have made it (the body's
other reflections; least ``d2 + ln det S``); update (a body reaching out of the radar's field
of view is measured at the centre of its part in view); apply what a miss tells (the Doppler
gate hides slow vehicles; a miss behind a nearer track tells nothing,
unless it lies within that track's own body: a duplicate); record hits and misses
(M-of-N confirmation once the speed sigma is below ``confirm_speed_std_mps``, deletion by
coasting time or, for a stopped track, by misses in a row: :mod:`adaptrack.tracking.lifecycle`);
open tentative tracks from the detections left over, clustered within ``cluster_radius_m``;
split a stopped track whose reflections come from two bodies of a queue
(:meth:`SceneTracker._split`); merge two tracks on one body (two moving parts of one long
vehicle among them; a young static object whose body overlaps a stopped road user's,
``absorb_young_static``). The per-track arithmetic runs compiled (:mod:`._scene_kernels`):
a scan's gating and its update are one call each (``associate_scan``, ``apply_scan``),
around the global assignment when a detection lies in two tracks' gates.

Stopped mode: a confirmed track slower than ``stop_speed_mps`` for ``stop_confirm_s`` (a
speed estimate within ``stop_exit_sigmas`` sigmas above it does not restart the count: the
noise of a vehicle creeping to a halt; and, where the radars report stationary objects,
``stationary_detections``, detected within ``stop_seen_s``: a track that loses its
detections is not taken for stopped) is held at zero velocity with a small position noise
(its covariance stays bounded through closures of minutes, seen or not), and leaves the mode
when a detection's radial speed shows motion along its direction of travel (a stopped
track's gate allows a start-up speed in that direction). A track that has never moved faster
than ``moved_speed_mps`` (with a speed sigma below ``moving_speed_std_mps``: not the first
guess of a folding radar's track) and further than ``moved_distance_m`` from where it was
confirmed (not where it opened: a first detection mixed with a ghost or another body's
reflection is metres off) is a *static* object (a barrier arm, a pole, rails: zero Doppler
since the start); a stopped vehicle had moved. Hazard event: a moved track stopped on the
carriageway (both lanes) within ``barrier_m`` of the crossing raises "object stopped between
the barriers" (a reflection of a barrier post beside the road is not in the way). Given the
controller's warning intervals (lights flashing, barriers down), a confirmed track
approaching the stop line that would need more than ``stop_decel_mps2`` to stop its front
there raises "vehicle will not stop before the stop line", with its lead time (distance to
the line over speed).

Sensor effects: each radar's declared latency is taken off its timestamps; radial speeds of a
folding radar are unfolded (:func:`._ekf_kernels.doppler_usable`); a constant azimuth bias of
each radar can be estimated from the offsets across the lane of the detections of tracks
faster than 6 m/s against the centre of the lane they drive in (vehicles keep to their lane on
average; ``estimate_azimuth_bias``, ``bias_*`` settings) and taken off the radar's next scans
(``azimuth_bias_rad``). It is opt-in: in a 10-minute scene with queues the near-field radar at
the crossing settles at -0.17 deg where there is none (the roadside radars within 0.03 deg).

No detection is dropped silently: every one is recorded as used by a track, opening a track,
or rejected with a reason (``ScanLog``).
"""

from __future__ import annotations

import bisect
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .._toml import load_toml
from .._typing import FloatArray
from ..tracking import (
    LifecycleRules,
    TrackBook,
    TrackStatus,
    gate_threshold,
    gnn_assign,
)
from ._scene_kernels import (
    BODY_HALF_SPREADS,
    apply_scan,
    associate_scan,
    confirmed_rows,
    detections_in_view,
    mode_changes,
    open_tracks,
    planar_rows,
    predict_tracks,
    retired_rows,
    split_rows,
)
from .corridor import Corridor, site_corridors
from .sensor import curve_tables
from .site import Site

N_STATE = 4  # u, du/dt, d2u/dt2, d
STATIC = len(TrackStatus)  # status code of a stopped object that never moved
STATUS_NAMES = (*(s.name.lower() for s in TrackStatus), "static")  # by status code
COASTING_S = 0.2  # a confirmed track without a detection for longer is coasting [s]
_STATUS_CODES = np.array(
    [TrackStatus.CONFIRMED, TrackStatus.COASTING, TrackStatus.STOPPED, STATIC], np.int64
)  # confirmed_rows' codes
ROW_COLUMNS = (
    "track_id", "time_s", "east_m", "north_m", "speed_mps", "east_speed_mps", "north_speed_mps",
    "from_crossing_m", "status", "moved", "position_std_m", "speed_std_mps",
)  # fmt: skip
EVENT_COLUMNS = ["time_s", "event", "track_id", "east_m", "north_m", "lead_s"]


@dataclass(frozen=True)
class SceneTrackerConfig:
    """Tuning of the scene tracker (units in the names)."""

    accel_psd: float = 4.0  # white jerk PSD along the corridor [m^2/s^5]
    lateral_psd: float = 0.02  # lateral random walk [m^2/s]
    stopped_psd: float = 1e-4  # position random walk while stopped [m^2/s]
    body_along_std_m: float = 1.5  # initial body spread along; learnt per track as it moves
    spread_learning_rate: float = 0.03
    spread_limits_m: tuple[float, float] = (0.3, 3.0)
    shape_learning_rate: float = 0.01  # moments of the reflections along a body ...
    split_kurtosis: float = 1.8  # ... a stopped track's below this are two bodies ...
    split_min_half_gap_m: float = 2.0  # ... this far either side of it (a queue)
    body_across_std_m: float = 0.5
    body_extent_gate: bool = True  # a detection beyond the body's end along the lane costs more
    occlusion_gate: bool = True  # a track hidden in a queue takes none of its occluder's
    absorb_young_static: bool = True  # a new static object on a stopped body is its reflection
    gate_probability: float = 0.999
    clutter_gate_probability: float = 0.99  # a static object's own detections (reserved) ...
    clutter_age_s: float = 300.0  # ... once it has stood longer than any closure
    cluster_radius_m: float = 3.0
    stop_speed_mps: float = 0.3  # a track this slow is slowing to a stop ...
    stop_exit_sigmas: float = 2.0  # ... stays slowing unless this many sigmas faster ...
    stop_confirm_s: float = 0.5  # ... and stops after this
    same_object_m: float = 2.5  # a stop this near an alarmed stopped track is its object
    moving_radial_mps: float = 0.3  # a detection this fast (beyond 3 sigma) ends a stop
    start_speed_max_mps: float = 3.0  # a stopped vehicle's gate allows starting up to this
    passing_gate: bool = True  # ... but not on a detection of a road user passing beside it
    moved_speed_mps: float = 0.8
    moving_speed_std_mps: float = 1.0  # ... known this well (not a first guess) ...
    moved_distance_m: float = 3.0  # ... and has moved this far from where it was confirmed
    initial_speed_std_mps: float = 15.0
    confirm_speed_std_mps: float = 3.0  # a track is confirmed once its speed is known this well
    merge_lateral_m: float = 1.2  # two tracks this close across (and along: the spread) ...
    merge_speed_mps: float = 1.0  # ... and this similar in speed are one body
    merge_parts_speed_mps: float = 4.0  # two faster road users whose bodies overlap: one
    merge_settled_s: float = 10.0  # a road user followed this long is not merged into ...
    merge_settled_lateral_m: float = 0.5  # ... a track this far beside it (side by side)
    stop_decel_mps2: float = 4.0  # a driver is expected to stop for the lights at this
    stationary_detections: bool = True  # the radars report stopped objects at zero Doppler
    stop_seen_s: float = 0.3  # ... so a stop counts only while detections show it
    sensor_id_bonus: float = 0.0  # chi-square units off a detection with a track's sensor id
    estimate_azimuth_bias: bool = False  # align each radar's azimuths to the lanes (opt-in)
    bias_memory: float = 20000.0  # detections the alignment remembers (forgetting 1 - 1/this)
    bias_min_samples: float = 300.0  # ... before it is applied
    bias_gate_m: float = 2.0  # detections further across from the lane centre are left out
    rules: LifecycleRules = field(default_factory=LifecycleRules)

    def __post_init__(self) -> None:
        """Reject settings no tracker can run on, naming the field (NaN included)."""
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "rules" or isinstance(value, bool):
                continue
            if f.name == "spread_limits_m":
                lo, hi = value
                if not 0 < lo <= hi < np.inf:
                    raise ValueError(
                        "SceneTrackerConfig.spread_limits_m must be 0 < low <= high < inf; "
                        f"got {value}"
                    )
                continue
            if f.name in _PROBABILITIES:
                ok, want = 0 < value < 1, "in (0, 1)"
            elif f.name in _RATES:
                ok, want = 0 < value <= 1, "in (0, 1]"
            elif f.name == "bias_memory":
                ok, want = 1 <= value, ">= 1"
            elif f.name in _POSITIVE:
                ok, want = 0 < value, "> 0"
            else:
                ok, want = 0 <= value, ">= 0"
            if ok and f.name not in _NO_LIMIT:
                ok, want = value < np.inf, f"{want} and finite"
            if not ok:
                raise ValueError(f"SceneTrackerConfig.{f.name} must be {want}; got {value}")


_PROBABILITIES = ("gate_probability", "clutter_gate_probability")
_RATES = ("spread_learning_rate", "shape_learning_rate")
_POSITIVE = (
    "accel_psd", "body_along_std_m", "body_across_std_m", "cluster_radius_m",
    "initial_speed_std_mps", "confirm_speed_std_mps", "moving_speed_std_mps",
    "stop_decel_mps2",
)  # fmt: skip
_NO_LIMIT = (  # inf: no limit
    "merge_parts_speed_mps", "merge_settled_s", "clutter_age_s", "stop_seen_s",
    "bias_min_samples", "stop_confirm_s", "moved_distance_m",
)  # fmt: skip


def load_scene_config(path: str | Path) -> SceneTrackerConfig:
    """Scene-tracker settings of a TOML file's ``[scene_tracker]`` table (defaults without it).

    Keys are :class:`SceneTrackerConfig` fields; ``[scene_tracker.rules]`` holds
    :class:`~adaptrack.tracking.LifecycleRules` fields. A ``tuned.toml`` of ``adaptrack
    tune`` may carry the table next to its road-estimator selection. Errors name the file and
    the key.
    """
    table = load_toml(Path(path)).get("scene_tracker", {})
    rules = table.pop("rules", {}) if isinstance(table, dict) else None
    if not isinstance(table, dict) or not isinstance(rules, dict):
        raise ValueError(f"{path}: [scene_tracker] and [scene_tracker.rules] must be tables")
    for given, cls in ((table, SceneTrackerConfig), (rules, LifecycleRules)):
        known = {f.name for f in fields(cls)} - {"rules"}
        unknown = sorted(set(given) - known)
        if unknown:
            raise ValueError(f"{path}: unknown {cls.__name__} setting(s) {unknown}; known: "
                             f"{sorted(known)}")  # fmt: skip
        defaults = cls()
        for key, value in given.items():
            want = type(getattr(defaults, key))
            number = isinstance(value, int | float) and not isinstance(value, bool)
            ok = isinstance(value, bool) if want is bool else (
                number if want in (int, float) else isinstance(value, list)
            )  # fmt: skip
            if not ok:
                raise ValueError(f"{path}: {cls.__name__} setting {key!r}: expected a "
                                 f"{want.__name__}; got {value!r}")  # fmt: skip
    settings: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in table.items()}
    try:
        return SceneTrackerConfig(**settings, rules=LifecycleRules(**rules))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: [scene_tracker]: {exc}") from None


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
    line_event_raised: np.ndarray  # "will not stop before the stop line" raised
    anchor_u: FloatArray  # where along the corridor it was confirmed (opened, until then)
    spread: FloatArray  # body spread of the reflections along the track [m]
    along_m2: FloatArray  # moving 2nd and 4th moments of the along-track residual [m^2, m^4]
    along_m4: FloatArray
    direction: FloatArray  # +1 / -1: direction of travel along u once known, else 0
    miss_run: FloatArray  # probability of the current run of misses for a moving target
    occluded: np.ndarray  # hidden behind a nearer track at its last scan without a detection
    doppler_seen_s: FloatArray  # last hit whose radial speed measured the speed [s] (-inf)
    detection_d: FloatArray  # its own detections' offset across (moving average) [m], NaN
    sensor_id: np.ndarray  # (T, radars) the object id each radar last reported for it (-1 none)

    @classmethod
    def opened(
        cls,
        corridor: np.ndarray,
        x: FloatArray,
        p: FloatArray,
        time_s: float,
        spread_m: float,
        sensor_id: np.ndarray,
    ) -> _Tracks:
        """Return new tracks on ``corridor`` rows with states ``x``, ``p`` at ``time_s``.

        ``sensor_id`` (n, radars): the sensor's object ids they start with (-1: none).
        """
        n = corridor.size
        no = np.zeros(n, bool)
        m2, m4 = _one_body_moments(spread_m)
        return cls(
            corridor, x, p, np.full(n, time_s), stopped=no, slow_since=np.full(n, np.nan),
            moved=no.copy(), event_raised=no.copy(), line_event_raised=no.copy(),
            anchor_u=x[:, 0].copy(),
            spread=np.full(n, spread_m), along_m2=np.full(n, m2), along_m4=np.full(n, m4),
            direction=np.zeros(n), miss_run=np.ones(n),
            occluded=no.copy(), doppler_seen_s=np.full(n, -np.inf),
            detection_d=np.full(n, np.nan), sensor_id=sensor_id,
        )  # fmt: skip

    @classmethod
    def empty(cls, n_radars: int) -> _Tracks:
        """Return no track (sensor ids kept for ``n_radars`` radars)."""
        return cls.opened(
            np.zeros(0, int), np.zeros((0, N_STATE)), np.zeros((0, N_STATE, N_STATE)), 0.0, 0.0,
            np.zeros((0, n_radars), np.int64),
        )  # fmt: skip

    @property
    def static(self) -> np.ndarray:
        """Stopped objects that never moved (clutter: a post, a rail), bool per track."""
        return self.stopped & ~self.moved

    def taken(self, rows: np.ndarray) -> _Tracks:
        """Return a copy of the tracks in ``rows``."""
        return _Tracks(**{name: getattr(self, name)[rows] for name in self.__dataclass_fields__})

    def place(self, rows: np.ndarray | slice, u: FloatArray, spread: FloatArray) -> None:
        """Move stopped ``rows`` to ``u`` along their corridor with a new body ``spread`` [m].

        Their position sigma grows by half a metre; the reflection moments restart at one
        body's (Gaussian).
        """
        self.x[rows, 0] = self.anchor_u[rows] = u
        self.p[rows, 0, 0] += 0.25
        self.spread[rows] = spread
        self.along_m2[rows], self.along_m4[rows] = _one_body_moments(spread)

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


class SceneTracker:
    """Incremental many-object tracker of one site (module docstring).

    ``step(radar, time_s, detections)`` processes one scan; ``rows(time_s)`` (or the arrays
    of ``columns``) gives the confirmed tracks after it; ``events`` and ``log`` collect hazard
    events and detection outcomes.
    """

    def __init__(
        self,
        site: Site,
        config: SceneTrackerConfig | None = None,
        warnings: FloatArray | None = None,
    ) -> None:
        self.site = site
        self.config = config or SceneTrackerConfig()
        # the controller's warning intervals (K, 2) [s]: lights flashing or barriers down
        self._warning_starts, self._warning_ends = _merged_intervals(
            np.asarray([] if warnings is None else warnings, float).reshape(-1, 2)
        )
        self.corridors = site_corridors(site.roads, site.zone_m + site.run_in_m)
        self.book = TrackBook(self.config.rules)
        self.tracks = _Tracks.empty(len(site.radars))
        self.events: list[dict[str, object]] = []
        self.log = ScanLog()
        self._radars = {r.name: r for r in site.radars}
        self._radar_index = {r.name: i for i, r in enumerate(site.radars)}
        self._radar_tables = {
            r.name: (
                r.kernel_row(), *r.noise_table(), r.field_table(),
                *curve_tables((r.detection_curve("default"),)),
            )
            for r in site.radars
        }  # fmt: skip
        self._roads, self._bounds = _corridor_tables(self.corridors)
        self._crossing_u = np.array([c.crossing_u for c in self.corridors])
        self._length_m = np.array([c.path.length_m for c in self.corridors])
        self._gate = gate_threshold(3, self.config.gate_probability)
        self._clutter_gate = gate_threshold(3, self.config.clutter_gate_probability)
        self._last_time: dict[str, float] = {}
        self._half_lane = np.array([0.5 * site.roads[c.first].lane_width_m for c in self.corridors])
        # two road users this far apart across the lane [m] stand side by side (two spreads)
        self._beside_m = BODY_HALF_SPREADS * self.config.body_across_std_m
        self.azimuth_bias_rad = {r.name: 0.0 for r in site.radars}  # estimated, taken off
        self._bias_stats = {r.name: np.zeros(3) for r in site.radars}
        self.last_scan_s = -np.inf  # when the last scan was made (timestamp less latency) [s]
        self.outside_view = np.zeros(0, bool)  # the last scan's detections outside every field

    # -- track opening ----------------------------------------------------------------------
    def _open(self, z: FloatArray, ids: np.ndarray, radar_name: str, time_s: float) -> int:
        """Open one tentative track per cluster of detections ``z`` (n, 3); return the count.

        Each starts with the sensor object id (``ids`` (n,), -1: none) of its first detection.
        """
        radar_row, noise_tab, noise_cnt = self._radar_tables[radar_name][:3]
        cfg = self.config
        corridor, x, p, _, first = open_tracks(
            z, radar_row, noise_tab, noise_cnt, self._roads, self._bounds,
            cfg.cluster_radius_m, cfg.initial_speed_std_mps**2, cfg.body_along_std_m**2,
        )  # fmt: skip
        n_new = corridor.size
        if n_new:
            self.book.add(n_new, time_s)
            sensor_id = np.full((n_new, len(self._radars)), -1, np.int64)
            sensor_id[:, self._radar_index[radar_name]] = ids[first]
            self.tracks.append(
                _Tracks.opened(corridor, x, p, time_s, cfg.body_along_std_m, sensor_id)
            )
        return n_new

    # -- one scan ---------------------------------------------------------------------------
    def previous_scan_s(self, radar_name: str) -> float:
        """Timestamp of the radar's last scan processed [s] (-inf before its first)."""
        return self._last_time.get(radar_name, -np.inf)

    def step(
        self, radar_name: str, time_s: float, z: FloatArray, ids: np.ndarray | None = None
    ) -> None:
        """Process the detections ``z`` (n, 3) of one radar scan stamped ``time_s``.

        The scan was made at ``time_s`` less the radar's declared latency
        (:attr:`last_scan_s` after the call; see :meth:`rows`). ``ids`` (n,): the sensor's
        object ids of an object-list radar (integers >= 0; -1: none). They are hints, not
        truth: a detection with the id that radar last gave a track costs
        ``sensor_id_bonus`` less in the assignment, within the same gate.
        """
        radar = self._radars.get(radar_name)
        if radar is None:
            raise ValueError(f"unknown radar {radar_name!r}; the site has {sorted(self._radars)}")
        last = self._last_time.get(radar_name, -np.inf)
        if not time_s > last:
            raise ValueError(
                f"radar {radar_name!r}: scan at {time_s} s is not after its previous scan at "
                f"{last} s (scans of a radar must be in time order, one per time)"
            )
        z = np.asarray(z, dtype=float).reshape(-1, 3)
        if not np.isfinite(z).all():
            raise ValueError(f"radar {radar_name!r} at {time_s} s: a detection is not finite")
        ids = _sensor_ids(ids, z.shape[0], radar_name, time_s)
        self._last_time[radar_name] = time_s
        time_s = float(radar.measured_at(time_s))
        self.last_scan_s = time_s
        cfg = self.config
        bias = self.azimuth_bias_rad[radar_name]
        if bias:
            z = z.copy()
            z[:, 1] = (z[:, 1] - bias + np.pi) % (2 * np.pi) - np.pi
        tr = self.tracks
        predict_tracks(
            tr.x, tr.p, tr.time_s, tr.stopped, tr.direction, time_s,
            cfg.accel_psd, cfg.lateral_psd, cfg.stopped_psd,
        )  # fmt: skip
        radar_row, noise_tab, noise_cnt, fields, pd_tab, pd_cnt = self._radar_tables[radar_name]
        view = detections_in_view(z, radar_row, fields)
        self.outside_view = ~view
        n_out = int(np.count_nonzero(self.outside_view))
        if n_out:
            self.log.rejected_outside_view += n_out
            z = z[view]
            ids = ids[view]
        r_col = self._radar_index[radar_name]
        used = np.zeros(z.shape[0], dtype=bool)
        if tr.time_s.size:
            book = self.book
            seen, d2, logdet, simple, ti, di = associate_scan(
                tr.x, tr.p, tr.spread, tr.stopped, tr.moved, book.confirmed, self._clutter(),
                tr.direction, tr.corridor, tr.sensor_id[:, r_col], self._roads, self._bounds,
                radar_row, noise_tab, noise_cnt, fields, cfg.body_across_std_m,
                cfg.start_speed_max_mps, cfg.body_extent_gate, cfg.occlusion_gate,
                cfg.passing_gate, self._beside_m, self._gate,
                self._clutter_gate, cfg.sensor_id_bonus, z, ids,
            )  # fmt: skip
            if not simple:
                ti, di = gnn_assign(np.where(d2 <= self._gate, d2, np.inf), self._gate)
            stats = self._bias_stats[radar_name]
            used = apply_scan(
                time_s, seen, d2, logdet, self._gate, ti, di, z, ids, r_col, tr.x, tr.p,
                tr.spread, tr.along_m2, tr.along_m4, tr.stopped, tr.moved, tr.direction,
                tr.slow_since, tr.corridor, tr.miss_run, tr.occluded, tr.anchor_u,
                tr.doppler_seen_s, tr.detection_d, tr.sensor_id, book.history, book.misses,
                book.last_hit_s, book.confirmed, self._roads, self._bounds, radar_row, noise_tab,
                noise_cnt,
                fields, pd_tab, pd_cnt, cfg.body_across_std_m, cfg.moving_radial_mps,
                cfg.start_speed_max_mps**2, cfg.spread_learning_rate, cfg.shape_learning_rate,
                *cfg.spread_limits_m, cfg.estimate_azimuth_bias, self._half_lane, bias, stats,
                1.0 - 1.0 / cfg.bias_memory, cfg.bias_gate_m, cfg.confirm_speed_std_mps**2,
                (1 << book.rules.confirm_window) - 1, book.rules.confirm_hits,
            )  # fmt: skip
            if stats[2] >= cfg.bias_min_samples:
                self.azimuth_bias_rad[radar_name] = float(stats[1] / stats[0])
        self.log.updated += int(np.count_nonzero(used))
        left = z[~used]
        if left.shape[0]:
            n_new = self._open(left, ids[~used], radar_name, time_s)
            self.log.opened += n_new
            self.log.joined_new += left.shape[0] - n_new
        self._modes(time_s)
        self._split(time_s)
        self._retire(time_s)

    def _clutter(self) -> np.ndarray:
        """Return the static objects older than ``clutter_age_s`` (bool per track).

        Barrier posts, rails: their detections are their own (:func:`.reserve_clutter`); a
        young one may be a vehicle waiting at a closure.
        """
        tr = self.tracks
        return tr.static & (tr.time_s - self.book.born_s >= self.config.clutter_age_s)

    def _split(self, time_s: float) -> None:
        """Split a stopped track holding two queued bodies (:func:`._scene_kernels.split_rows`).

        Only road users that moved (static clutter stays whole: a rail reflects all along the
        crossing). The part towards the crossing keeps the track's identity, the other becomes
        a new confirmed stopped road user; each is placed at its cluster with that spread
        (within the limits) and half a metre more position sigma (:meth:`_Tracks.place`).
        """
        cfg = self.config
        tr = self.tracks
        rows, half, body = split_rows(
            tr.stopped, tr.moved, tr.along_m2, tr.along_m4, cfg.split_kurtosis,
            cfg.split_min_half_gap_m,
        )  # fmt: skip
        if rows.size == 0:
            return
        towards = np.where(self._crossing_u[tr.corridor[rows]] >= tr.x[rows, 0], 1.0, -1.0)
        u = tr.x[rows, 0]
        spread = np.clip(body, *cfg.spread_limits_m)
        rear = tr.taken(rows)
        tr.place(rows, u + towards * half, spread)
        rear.place(slice(None), u - towards * half, spread)
        self.book.add_copies(rows, time_s)
        tr.append(rear)

    def _modes(self, time_s: float) -> None:
        """Update moving and stopped modes (:func:`._scene_kernels.mode_changes`); raise events."""
        cfg = self.config
        tr = self.tracks
        hazard, on_road = mode_changes(
            time_s, tr.x, tr.p, tr.corridor, self.book.confirmed, self.book.last_hit_s,
            tr.anchor_u, tr.stopped, tr.moved, tr.direction, tr.slow_since, tr.event_raised,
            tr.doppler_seen_s, self._crossing_u, self._half_lane, self.site.barrier_m,
            cfg.moved_speed_mps, cfg.moving_speed_std_mps, cfg.moved_distance_m,
            cfg.stop_speed_mps, cfg.stop_exit_sigmas, cfg.stop_confirm_s,
            cfg.stop_seen_s if cfg.stationary_detections else np.inf,
        )  # fmt: skip
        if hazard.any():
            rows = self._new_objects(np.flatnonzero(hazard))
            self._raise("stopped_between_barriers", rows, time_s)
        if self._warning(time_s):
            self._stop_line_events(time_s, on_road)

    def _new_objects(self, rows: np.ndarray) -> np.ndarray:
        """Keep the hazard ``rows`` that are not an object already alarmed: one object, one alarm.

        A track stopped within ``same_object_m`` (half a car's length) of a stopped track whose
        alarm is raised stands on that object's body (e.g. a track from the other lane that
        took a stopped car's reflections); it raises no second alarm now, and may later if
        the other track is gone. Not one whose own detections lie beside that track, on its
        corridor ``BODY_HALF_SPREADS`` spreads across (``body_across_std_m``) or more: another
        road user stands there (a motorcycle beside a car queued between the barriers). Where
        the detections lie, not the track's state: a duplicate's state may stand beside the
        body whose reflections it takes.
        """
        if rows.size == 0:
            return rows
        tr = self.tracks
        alarmed = np.setdiff1d(np.flatnonzero(tr.event_raised & tr.stopped), rows)
        if alarmed.size == 0:
            return rows
        new = self._planar(rows)["position"]
        old = self._planar(alarmed)["position"]
        near = (
            np.linalg.norm(new[:, None, :] - old[None, :, :], axis=-1) < self.config.same_object_m
        )
        across = np.abs(tr.detection_d[rows][:, None] - tr.x[alarmed, 3][None, :])
        beside = (tr.corridor[rows][:, None] == tr.corridor[alarmed][None, :]) & (
            across >= self._beside_m
        )  # NaN (no detection yet): not beside
        same = (near & ~beside).any(axis=1)
        tr.event_raised[rows[same]] = False
        return rows[~same]

    def _warning(self, time_s: float) -> bool:
        """Whether the crossing's lights flash or its barriers are down at ``time_s``."""
        k = bisect.bisect_right(self._warning_starts, time_s) - 1
        return k >= 0 and time_s < self._warning_ends[k]

    def _stop_line_events(self, time_s: float, on_road: np.ndarray) -> None:
        """Raise "will not stop before the stop line" for tracks that cannot stop there.

        A moving confirmed road user on the carriageway, detected within ``stop_seen_s``,
        first in its lane (one who follows another stops behind it), whose front needs more
        than ``stop_decel_mps2`` to stop at the line even at the low end of its speed's 90 %
        interval; its lead is the time to reach the line. ``on_road``: tracks on the
        carriageway (bool per track).
        """
        cfg = self.config
        tr = self.tracks
        ahead = self._crossing_u[tr.corridor] - tr.x[:, 0]  # towards the crossing: sign(ahead)
        speed = tr.x[:, 1] * np.sign(ahead)  # > 0 approaching
        front = np.sqrt(3.0) * tr.spread  # half a uniform body of that spread
        to_line = np.abs(ahead) - self.site.stop_line_m - front
        cand = (
            self.book.confirmed & tr.moved & ~tr.stopped & ~tr.line_event_raised & on_road
            & (speed > 0.5) & (to_line > -front)
        )  # fmt: skip
        seen = time_s - self.book.last_hit_s <= cfg.stop_seen_s
        slow_bound = speed - 1.645 * np.sqrt(tr.p[:, 1, 1])  # the speed is at least this (95 %)
        cant = (
            cand & seen & (slow_bound > np.sqrt(2.0 * cfg.stop_decel_mps2 * np.maximum(to_line, 0)))
        )
        road_user = self.book.confirmed & ~tr.static
        for i in np.flatnonzero(cant):  # one who follows a road user stops behind it
            ahead_i = (tr.x[:, 0] - tr.x[i, 0]) * np.sign(ahead[i])
            lane = np.abs(tr.x[:, 3] - tr.x[i, 3]) < self._half_lane[tr.corridor[i]]
            cant[i] = not np.any(
                road_user & (tr.corridor == tr.corridor[i]) & lane & (ahead_i > 0)
                & (np.sign(ahead) == np.sign(ahead[i]))
            )  # fmt: skip
        rows = np.flatnonzero(cant)
        self._raise(
            "will_not_stop_before_stop_line", rows, time_s,
            np.maximum(to_line[rows], 0.0) / speed[rows],
        )  # fmt: skip
        tr.line_event_raised |= cant

    def _raise(
        self, event: str, rows: np.ndarray, time_s: float, lead_s: FloatArray | None = None
    ) -> None:
        """Record ``event`` for the tracks in ``rows`` (with its lead time [s] if predicted)."""
        if rows.size == 0:
            return
        pos = self._planar(rows)["position"]
        for k, i in enumerate(rows):
            self.events.append(
                {
                    "time_s": time_s,
                    "event": event,
                    "track_id": int(self.book.ids[i]),
                    "east_m": float(pos[k, 0]),
                    "north_m": float(pos[k, 1]),
                    "lead_s": float(lead_s[k]) if lead_s is not None else np.nan,
                }
            )

    def _retire(self, time_s: float) -> None:
        """Delete the tracks that expired or left their corridor, then merge the rest.

        Of two tracks on one body the younger goes: same corridor, within the bodies'
        spreads along it (or, moving faster than ``merge_parts_speed_mps``, with overlapping
        bodies: two parts of one long vehicle), within ``merge_lateral_m`` across, velocities
        alike (within ``merge_speed_mps`` plus three sigma), both static objects or neither
        (:func:`._scene_kernels.retired_rows`). A road user followed longer than
        ``merge_settled_s`` stays when the other is more than ``merge_settled_lateral_m``
        beside it (two road users side by side, e.g. a motorcycle filtering past a queue).
        """
        tr = self.tracks
        book = self.book
        cfg = self.config
        r = cfg.rules
        dead = retired_rows(
            time_s, tr.time_s, tr.x, tr.p, tr.corridor, self._length_m, tr.spread, tr.stopped,
            tr.moved, tr.occluded, book.ids, book.confirmed, book.misses, book.born_s,
            book.last_hit_s, cfg.stationary_detections, r.tentative_misses, r.max_tentative_s,
            r.max_coast_s, r.max_coast_stopped_s, r.max_coast_hidden_s, r.max_position_std_m,
            r.max_stopped_misses, cfg.merge_lateral_m, cfg.merge_speed_mps,
            cfg.merge_parts_speed_mps, cfg.clutter_age_s, cfg.absorb_young_static,
            cfg.merge_settled_s, cfg.merge_settled_lateral_m,
        )  # fmt: skip
        if dead.any():
            self._drop(np.flatnonzero(dead))

    def _drop(self, rows: np.ndarray) -> None:
        """Forget the tracks in ``rows`` (book and filter states)."""
        if rows.size:
            keep = np.ones(self.tracks.time_s.size, bool)
            keep[rows] = False
            self.book.remove(rows)
            self.tracks.keep(keep)

    def _planar(self, rows: np.ndarray) -> dict[str, FloatArray]:
        """Planar position, velocity, position sigma and distance to the crossing of rows."""
        tr = self.tracks
        n = rows.size
        out: dict[str, FloatArray] = {
            "position": np.zeros((n, 2)),
            "velocity": np.zeros((n, 2)),
            "position_std": np.zeros(n),
            "to_crossing": np.zeros(n),
        }
        planar_rows(
            tr.x[rows], tr.p[rows], tr.corridor[rows], self._roads, self._bounds,
            self._crossing_u, *out.values(),
        )  # fmt: skip
        return out

    def snapshot(self, time_s: float) -> _Snapshot:
        """Return the confirmed tracks' states at ``time_s`` (:meth:`rows` before geometry)."""
        tr = self.tracks
        rows, status = confirmed_rows(
            self.book.confirmed, tr.time_s, self.book.last_hit_s, tr.stopped, tr.moved,
            COASTING_S, _STATUS_CODES,
        )  # fmt: skip
        return _Snapshot(
            self.book.ids[rows], np.full(rows.size, time_s), tr.x[rows], tr.p[rows],
            tr.corridor[rows], status, tr.moved[rows],
        )  # fmt: skip

    def table(self, snapshots: list[_Snapshot]) -> dict[str, np.ndarray]:
        """Columns of :meth:`rows` for several snapshots at once (one planar conversion)."""
        parts = [np.concatenate([getattr(s, f) for s in snapshots]) for f in _SNAPSHOT_FIELDS]
        ids, times, x, p, corridor, status, moved = (
            parts if snapshots else (np.zeros(0, np.int64), np.zeros(0), np.zeros((0, N_STATE)),
                                     np.zeros((0, N_STATE, N_STATE)), np.zeros(0, np.int64),
                                     np.zeros(0, np.int64), np.zeros(0, bool))
        )  # fmt: skip
        n = ids.size
        pos, vel, pos_std, to_cross = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(n), np.zeros(n)
        planar_rows(
            x, p, corridor, self._roads, self._bounds, self._crossing_u, pos, vel, pos_std,
            to_cross,
        )  # fmt: skip
        return {
            "track_id": ids,
            "time_s": times,
            "east_m": pos[:, 0],
            "north_m": pos[:, 1],
            "speed_mps": np.hypot(vel[:, 0], vel[:, 1]),
            "east_speed_mps": vel[:, 0],
            "north_speed_mps": vel[:, 1],
            "from_crossing_m": to_cross,
            "status": status,
            "moved": moved,
            "position_std_m": pos_std,
            "speed_std_mps": np.sqrt(p[:, 1, 1]),
        }

    def columns(self, time_s: float) -> dict[str, np.ndarray]:
        """Columns of :meth:`rows` (arrays, one entry per confirmed track)."""
        return self.table([self.snapshot(time_s)])

    def rows(self, time_s: float) -> pd.DataFrame:
        """Estimates of every confirmed track at ``time_s`` (after the scan's update).

        ``status`` is tentative / confirmed / coasting / stopped, or static for a stopped
        object that never moved (clutter).
        """
        return _frame([self.columns(time_s)])


@dataclass(frozen=True)
class _Snapshot:
    """Confirmed tracks at one time.

    Ids, time [s], states and covariances, corridor rows, status codes, whether each moved.
    """

    track_id: np.ndarray
    time_s: FloatArray
    x: FloatArray
    p: FloatArray
    corridor: np.ndarray
    status: np.ndarray
    moved: np.ndarray


_SNAPSHOT_FIELDS = tuple(f.name for f in fields(_Snapshot))


def _frame(columns: list[dict[str, np.ndarray]]) -> pd.DataFrame:
    """One table of track rows from the columns of several scans (status named)."""
    names = np.array(STATUS_NAMES)
    keys = list(columns[0]) if columns else list(ROW_COLUMNS)
    table: dict[str, np.ndarray] = {
        k: np.concatenate([c[k] for c in columns]) if columns else np.zeros(0) for k in keys
    }
    table["status"] = names[np.asarray(table["status"], dtype=int)]
    return pd.DataFrame(table)


def _sensor_ids(ids: np.ndarray | None, n: int, radar_name: str, time_s: float) -> np.ndarray:
    """Return the sensor object ids of a scan's ``n`` detections as int64 (-1s for ``None``)."""
    if ids is None:
        return np.full(n, -1, np.int64)
    raw = np.asarray(ids)
    if raw.dtype == np.int64 and raw.shape == (n,) and raw.min(initial=-1) >= -1:
        return raw  # already valid (as iter_scans yields them)
    if raw.shape != (n,) or not np.issubdtype(raw.dtype, np.integer) or np.any(raw < -1):
        raise ValueError(
            f"radar {radar_name!r} at {time_s} s: sensor ids must be {n} integers >= -1 "
            f"(one per detection); got shape {raw.shape} dtype {raw.dtype}"
        )
    return raw.astype(np.int64)


def _one_body_moments(spread_m: FloatArray | float) -> tuple[FloatArray | float, ...]:
    """Second and fourth moments [m^2, m^4] of one body's reflections (Gaussian, that spread)."""
    return spread_m**2, 3.0 * spread_m**4


def _merged_intervals(intervals: FloatArray) -> tuple[list[float], list[float]]:
    """Return the starts and ends of the union of half-open intervals (K, 2), in time order."""
    starts: list[float] = []
    ends: list[float] = []
    for a, b in sorted(map(tuple, intervals.tolist())):
        if starts and a <= ends[-1]:
            ends[-1] = max(ends[-1], b)
        elif b > a:
            starts.append(a)
            ends.append(b)
    return starts, ends


def _corridor_tables(corridors: list[Corridor]) -> tuple[FloatArray, np.ndarray]:
    """Corridor centrelines packed as one (5, S) table and each one's column range (C, 2)."""
    paths = [c.path for c in corridors]
    table = np.concatenate(
        [np.stack([p.s, p.xy[:, 0], p.xy[:, 1], p.heading, p.curvature]) for p in paths], axis=1
    )
    stops = np.cumsum([p.s.size for p in paths])
    return table, np.stack([stops - [p.s.size for p in paths], stops], -1).astype(np.int64)


def iter_scans(
    detections: pd.DataFrame, latency_s: dict[str, float] | None = None
) -> Iterator[tuple[str, float, FloatArray, np.ndarray]]:
    """Yield the scans of a detection table in time order (radar name breaks ties).

    A scan is the detections (range_m, azimuth_rad, radial_speed_mps) of one radar at one
    timestamp, with their sensor object ids (the ``object_id`` column of an object list; -1
    without it). With radars' ``latency_s``, the order is that of the times the scans were
    made (timestamps less latency); the timestamps are yielded.
    """
    t = detections["time_s"].to_numpy()
    radar = detections["radar"].astype(str).to_numpy()
    z = detections[["range_m", "azimuth_rad", "radial_speed_mps"]].to_numpy(dtype=float)
    ids = (
        detections["object_id"].to_numpy(dtype=np.int64)
        if "object_id" in detections.columns
        else np.full(t.size, -1, np.int64)
    )
    made = t - pd.Series(radar).map(latency_s or {}).fillna(0.0).to_numpy()
    order = np.lexsort((radar, made))
    t, radar, z, ids = t[order], radar[order], z[order], ids[order]
    cut = np.flatnonzero((np.diff(t) != 0) | (radar[1:] != radar[:-1])) + 1
    starts = np.concatenate([[0], cut, [t.size]]) if t.size else np.zeros(1, int)
    for a, b in itertools.pairwise(starts):
        yield str(radar[a]), float(t[a]), z[a:b], ids[a:b]


def track_scene(
    site: Site,
    detections: pd.DataFrame,
    config: SceneTrackerConfig | None = None,
    on_scan: Callable[[int, int], None] | None = None,
    warnings: FloatArray | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame, ScanLog]:
    """Track a detection table scan by scan (:func:`iter_scans`).

    An ``object_id`` column (a radar object list) gives the sensor's ids as association hints
    (:meth:`SceneTracker.step`).

    ``on_scan(done, total)`` is called after each scan (progress); ``warnings`` (K, 2): when
    the crossing's lights flash or its barriers are down [s] (none: no stop-line prediction).
    Returns the track rows of every scan, the hazard events and the detection log.
    """
    tracker = SceneTracker(site, config, warnings)
    scans = list(iter_scans(detections, {r.name: r.latency_s for r in site.radars}))
    out = []
    for i, (radar, t, z, ids) in enumerate(scans):
        tracker.step(radar, t, z, ids)
        out.append(tracker.snapshot(tracker.last_scan_s))
        if on_scan is not None:
            on_scan(i + 1, len(scans))
    table = _frame([tracker.table(out)])
    return table, pd.DataFrame(tracker.events, columns=EVENT_COLUMNS), tracker.log


__all__ = [
    "EVENT_COLUMNS",
    "STATUS_NAMES",
    "ScanLog",
    "SceneTracker",
    "SceneTrackerConfig",
    "iter_scans",
    "load_scene_config",
    "track_scene",
]
