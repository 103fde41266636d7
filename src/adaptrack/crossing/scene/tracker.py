"""Many-object tracker of a crossing scene: raw detections in, tracks and hazard events out.

Each track is an EKF in the coordinates of a corridor through the crossing
(:mod:`adaptrack.crossing.site.corridor`): state ``[u, du/dt, d2u/dt2, d]`` (constant acceleration
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
``clutter_age_s`` keeps the detections in its own tight gate: learnt clutter such as a rail,
which is frozen from then on, neither predicted nor updated, its view of each radar stored);
give every further gated detection to the track most likely to have made it (the body's
other reflections; least ``d2 + ln det S``); update (a body reaching out of the radar's field
of view is measured at the centre of its part in view); apply what a miss tells (the Doppler
gate hides slow vehicles; a miss behind a nearer track tells nothing,
unless it lies within that track's own body: a duplicate, or the nearer track is a static
object shorter than ``shadow_spread_m``: a post; a tentative track's miss behind a
moving body shorter than ``shadow_spread_m`` that it moves with counts against its
confirmation: the radar sees over a car, and what is seen rarely there, moving with the car,
is its multipath ghost); record hits and misses
(M-of-N confirmation once the speed sigma is below ``confirm_speed_std_mps``, deletion by
coasting time or, for a stopped track, by misses in a row: :mod:`adaptrack.tracking.lifecycle`);
open tentative tracks from the detections left over, clustered within ``cluster_radius_m``
(a body farther than ``max_open_offset_m`` across from every corridor opens none: it is
beside every road of the site, counted as ``off_road``);
split a stopped track whose reflections come from two bodies of a queue
(:meth:`SceneTracker._split`); merge two tracks on one body (two moving parts of one long
vehicle among them; a young static object whose body overlaps a stopped road user's,
``absorb_young_static``). All of it runs compiled: the per-scan kernels of
the stage modules of :mod:`adaptrack.crossing.scene` inside one loop over scans
(:mod:`.scan_loop`), so that a run of scans is one call (:func:`track_scene`) and a single scan too
(:meth:`SceneTracker.step`); the global assignment of a scan where a detection lies in two
tracks' gates is SciPy's, called from the loop.

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
folding radar are unfolded (:func:`..estimators.kernels.doppler_usable`); a constant azimuth bias of
each radar can be estimated from the offsets across the lane of the detections of tracks
faster than 6 m/s against the centre of the lane they drive in (vehicles keep to their lane on
average; ``estimate_azimuth_bias``, ``bias_*`` settings) and taken off the radar's next scans
(``azimuth_bias_rad``). It is opt-in: in a 10-minute scene with queues the near-field radar at
the crossing settles at -0.17 deg where there is none (the roadside radars within 0.03 deg).

No detection is dropped silently: every one is recorded as used by a track, opening a track,
or rejected with a reason (``ScanLog``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..._toml import load_toml
from ..._typing import FloatArray
from ...tracking import LifecycleRules, TrackBook, TrackStatus, gate_threshold
from ..site.corridor import Corridor
from ..site.model import Site
from ..site.sensor import curve_tables
from .body import BODY_HALF_SPREADS
from .bundles import (
    LOG_FIELDS,
    RadarState,
    RowBuffer,
    Settings,
    SiteTables,
    TrackRows,
    empty_rows,
)
from .gate import CLUTTER_VIEW
from .scan_loop import EVENT_FIELDS, EVENT_NAMES, new_row, run_scans, with_room, write_rows

N_STATE = 4  # u, du/dt, d2u/dt2, d
STATIC = len(TrackStatus)  # status code of a stopped object that never moved
STATUS_NAMES = (*(s.name.lower() for s in TrackStatus), "static")  # by status code
COASTING_S = 0.2  # a confirmed track without a detection for longer is coasting [s]
_STATUS_CODES = np.array(
    [
        TrackStatus.CONFIRMED,
        TrackStatus.COASTING,
        TrackStatus.STOPPED,
        STATIC,
        TrackStatus.TENTATIVE,
    ],
    np.int64,
)  # confirmed_rows' codes
ROW_COLUMNS = RowBuffer._fields  # the columns of a track table
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
    shadow_spread_m: float = 1.4  # a moving body this long (spread) hides a new track behind it
    # (a shorter one, a car, does not: the radar on its pole sees over it; 0: every body hides);
    # a static object shorter than this (a post, a barrier arm) hides no track at all
    absorb_young_static: bool = True  # a new static object on a stopped body is its reflection
    gate_probability: float = 0.999
    clutter_gate_probability: float = 0.99  # a static object's own detections (reserved) ...
    clutter_age_s: float = 300.0  # ... once it has stood longer than any closure
    cluster_radius_m: float = 3.0
    max_open_offset_m: float = 15.0  # a body farther across from every corridor opens no track
    # (beside every road of the site: a field, a car park; a false alarm there)
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
    "stop_decel_mps2", "max_open_offset_m",
)  # fmt: skip
_NO_LIMIT = (  # inf: no limit
    "merge_parts_speed_mps", "merge_settled_s", "clutter_age_s", "stop_seen_s",
    "bias_min_samples", "stop_confirm_s", "moved_distance_m", "shadow_spread_m",
    "max_open_offset_m",
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
    clutter_views: FloatArray  # (T, radars, CLUTTER_VIEW) a learnt clutter's gate, per radar

    @classmethod
    def opened(
        cls,
        corridor: np.ndarray,
        x: FloatArray,
        p: FloatArray,
        time_s: float,
        spread_m: float,
        n_radars: int,
    ) -> _Tracks:
        """Return new tentative tracks on ``corridor`` rows with states ``x``, ``p`` at ``time_s``.

        Written as the scan loop opens a track (:func:`.scan_loop.new_row`: body ``spread_m``
        [m], no sensor object id from any of the ``n_radars`` radars).
        """
        n = corridor.size
        rows = with_room(_track_rows(TrackBook(LifecycleRules()), cls.empty(n_radars)), 0, n)
        for g in range(n):
            new_row(rows, g, 0, time_s, corridor[g], x[g], p[g], spread_m, 0, -1)
        return cls(**{name: getattr(rows, name)[:n] for name in cls.__dataclass_fields__})

    @classmethod
    def empty(cls, n_radars: int) -> _Tracks:
        """Return no track (sensor ids kept for ``n_radars`` radars)."""
        real, no = np.zeros(0), np.zeros(0, bool)
        return cls(
            corridor=np.zeros(0, np.int64), x=np.zeros((0, N_STATE)),
            p=np.zeros((0, N_STATE, N_STATE)), time_s=real, stopped=no, slow_since=real,
            moved=no, event_raised=no, line_event_raised=no, anchor_u=real, spread=real,
            along_m2=real, along_m4=real, direction=real, miss_run=real, occluded=no,
            doppler_seen_s=real, detection_d=real, sensor_id=np.zeros((0, n_radars), np.int64),
            clutter_views=np.zeros((0, n_radars, CLUTTER_VIEW)),
        )  # fmt: skip

    @property
    def static(self) -> np.ndarray:
        """Stopped objects that never moved (clutter: a post, a rail), bool per track."""
        return self.stopped & ~self.moved

    def append(self, other: _Tracks) -> None:
        """Add the tracks of ``other`` after these."""
        for name in self.__dataclass_fields__:
            setattr(self, name, np.concatenate([getattr(self, name), getattr(other, name)]))


@dataclass
class ScanLog:
    """What became of the detections: counts by outcome (every detection is in one)."""

    updated: int = 0
    opened: int = 0
    joined_new: int = 0  # clustered into a new track's first detection
    rejected_outside_view: int = 0
    off_road: int = 0  # left over beside every road (``max_open_offset_m``): no track opened

    @property
    def total(self) -> int:
        """Detections accounted for."""
        return (
            self.updated + self.opened + self.joined_new + self.rejected_outside_view
            + self.off_road
        )  # fmt: skip


class SceneTracker:
    """Incremental many-object tracker of one site (module docstring).

    ``step(radar, time_s, detections)`` processes one scan; ``rows(time_s)`` (or the arrays
    of ``columns``) gives the confirmed tracks after it; ``events`` and ``log`` collect hazard
    events and detection outcomes. :func:`track_scene` processes many scans in one compiled call
    (:func:`.scan_loop.run_scans`), as :func:`track_scene` does.
    """

    def __init__(
        self,
        site: Site,
        config: SceneTrackerConfig | None = None,
        warnings: FloatArray | None = None,
    ) -> None:
        self.site = site
        self.config = config or SceneTrackerConfig()
        self.corridors = site.corridors
        self.book = TrackBook(self.config.rules)
        self.tracks = _Tracks.empty(len(site.radars))
        self.events: list[dict[str, object]] = []
        self.log = ScanLog()
        self._radar_index = {r.name: i for i, r in enumerate(site.radars)}
        self._tables = _site_tables(site, self.corridors, warnings)
        self._settings = _loop_settings(self.config)
        n_radars = len(site.radars)
        self._radar_state = RadarState(
            np.full(n_radars, -np.inf), np.zeros(n_radars), np.zeros((n_radars, 3))
        )
        self.last_scan_s = -np.inf  # when the last scan was made (timestamp less latency) [s]
        self.outside_view = np.zeros(0, bool)  # the last scan's detections outside every field

    @property
    def azimuth_bias_rad(self) -> dict[str, float]:
        """Each radar's estimated azimuth bias, taken off its scans [rad] (0 until known)."""
        return {name: float(self._radar_state.azimuth_bias_rad[k])
                for name, k in self._radar_index.items()}  # fmt: skip

    def previous_scan_s(self, radar_name: str) -> float:
        """Timestamp of the radar's last scan processed [s] (-inf before its first)."""
        return float(self._radar_state.last_stamp_s[self._radar_index[radar_name]])

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
        r = self._radar(radar_name)
        last = self._radar_state.last_stamp_s[r]
        if not time_s > last:
            raise ValueError(
                f"radar {radar_name!r}: scan at {time_s} s is not after its previous scan at "
                f"{last} s (scans of a radar must be in time order, one per time)"
            )
        z = np.asarray(z, dtype=float).reshape(-1, 3)
        if not np.isfinite(z).all():
            raise ValueError(f"radar {radar_name!r} at {time_s} s: a detection is not finite")
        ids = _sensor_ids(ids, z.shape[0], radar_name, time_s)
        self._run(np.array([r]), np.array([float(time_s)]), np.array([0, z.shape[0]]), z, ids)

    def _run(
        self,
        radar_rows: np.ndarray,
        stamps_s: FloatArray,
        starts: np.ndarray,
        z: FloatArray,
        ids: np.ndarray,
        rows_out: RowBuffer | None = None,
        n_out: int = 0,
    ) -> tuple[RowBuffer | None, int]:
        """Process checked scans in order (their arrays as :func:`scan_arrays` gives them).

        Scan ``k`` is ``z[starts[k]:starts[k+1]]`` with sensor ``ids``, of radar row
        ``radar_rows[k]`` (the site's order), stamped ``stamps_s[k]``; stamps of one radar
        must increase. With ``rows_out`` (:func:`.scan_loop.empty_rows`, ``n_out`` rows
        used), the confirmed tracks after every scan are appended to it; returns the buffer
        (grown if it was full) and its rows used.
        """
        if len(radar_rows) == 0:
            return rows_out, n_out
        book, tr = self.book, self.tracks
        log = np.array([getattr(self.log, name) for name in LOG_FIELDS], np.int64)
        outside = np.zeros(z.shape[0], bool)
        record = rows_out is not None
        t, n, book.next_id, events, n_events, out, n_out = run_scans(
            self._rows(), book.ids.size, book.next_id, self._settings, self._tables,
            self._radar_state, log, z, ids, np.asarray(starts, np.int64),
            np.asarray(radar_rows, np.int64), np.asarray(stamps_s, float), outside,
            np.zeros((0, EVENT_FIELDS)), 0, record, rows_out if record else empty_rows(0),
            n_out,
        )  # fmt: skip
        for name, column in zip(TrackRows._fields, t, strict=True):
            setattr(book if name in _BOOK_COLUMNS else tr, name, column[:n])
        for name, count in zip(LOG_FIELDS, log.tolist(), strict=True):
            setattr(self.log, name, count)
        self.events.extend(_event_records(events[:n_events]))
        k = radar_rows[-1]
        self.last_scan_s = float(stamps_s[-1] - self._tables.latency_s[k])
        self.outside_view = outside[starts[-2] :]
        return (out if record else None), n_out

    def _rows(self) -> TrackRows:
        """Return the track book's and the filter's columns (the arrays themselves, not copies)."""
        return _track_rows(self.book, self.tracks)

    def _radar(self, radar_name: str) -> int:
        """Return the site's row of a radar; an unknown name is an error."""
        r = self._radar_index.get(radar_name)
        if r is None:
            raise ValueError(
                f"unknown radar {radar_name!r}; the site has {sorted(self._radar_index)}"
            )
        return r

    def columns(self, time_s: float) -> dict[str, np.ndarray]:
        """Columns of :meth:`rows` (arrays, one entry per confirmed track)."""
        out, n_out = write_rows(
            self._rows(),
            self.book.ids.size,
            float(time_s),
            self._settings,
            self._tables,
            empty_rows(0),
            0,
        )
        return _columns(out, n_out)

    def rows(self, time_s: float) -> pd.DataFrame:
        """Estimates of every confirmed track at ``time_s`` (after the scan's update).

        ``status`` is tentative / confirmed / coasting / stopped, or static for a stopped
        object that never moved (clutter).
        """
        return _frame([self.columns(time_s)])


_BOOK_COLUMNS = ("ids", "history", "confirmed", "misses", "last_hit_s", "born_s")


def _columns(out: RowBuffer, n: int) -> dict[str, np.ndarray]:
    """Columns of :meth:`SceneTracker.rows` from a row buffer's first ``n`` rows (views)."""
    return {name: column[:n] for name, column in zip(RowBuffer._fields, out, strict=True)}


def _event_records(events: FloatArray) -> list[dict[str, object]]:
    """Event dicts (``EVENT_COLUMNS``) of an event buffer's rows."""
    return [
        {"time_s": float(t), "event": EVENT_NAMES[int(code)], "track_id": int(track),
         "east_m": float(east), "north_m": float(north), "lead_s": float(lead)}
        for t, code, track, east, north, lead in events.tolist()
    ]  # fmt: skip


def _loop_settings(cfg: SceneTrackerConfig) -> Settings:
    """Return the compiled loop's view of the settings (gates as chi-square thresholds).

    Fields named as in the config or its rules are theirs; the others are derived here.
    """
    r = cfg.rules
    derived: dict[str, Any] = {
        # two road users this far apart across the lane [m] stand side by side (two spreads)
        "beside_m": BODY_HALF_SPREADS * cfg.body_across_std_m,
        "gate": gate_threshold(3, cfg.gate_probability),
        "clutter_gate": gate_threshold(3, cfg.clutter_gate_probability),
        "spread_lo_m": cfg.spread_limits_m[0],
        "spread_hi_m": cfg.spread_limits_m[1],
        "bias_forget": 1.0 - 1.0 / cfg.bias_memory,
        "confirm_speed_var": cfg.confirm_speed_std_mps**2,
        "window_mask": (1 << r.confirm_window) - 1,
        "initial_speed_var": cfg.initial_speed_std_mps**2,
        "coasting_s": COASTING_S,
        "status_codes": _STATUS_CODES,
    }
    named: dict[str, Any] = {f.name: getattr(r, f.name) for f in fields(r)}
    named.update({f.name: getattr(cfg, f.name) for f in fields(cfg) if f.name != "rules"})
    return Settings(**{k: derived[k] if k in derived else named[k] for k in Settings._fields})


def _site_tables(site: Site, corridors: list[Corridor], warnings: FloatArray | None) -> SiteTables:
    """Return the site for the compiled loop; ``warnings`` (K, 2): the controller's intervals."""
    radars = site.radars
    starts, ends = _merged_intervals(
        np.asarray([] if warnings is None else warnings, float).reshape(-1, 2)
    )
    roads, bounds = _corridor_tables(corridors)
    noise_tab, noise_cnt = curve_tables(tuple(
        c for r in radars for c in (r.range_std_m, r.azimuth_std_rad, r.radial_speed_std_mps)
    ))  # fmt: skip
    pd_tab, pd_cnt = curve_tables(tuple(r.detection_curve("default") for r in radars))
    field_count = np.array([len(r.fields) for r in radars], np.int64)
    fields = np.zeros((len(radars), int(field_count.max()), 2))
    for k, r in enumerate(radars):
        fields[k, : field_count[k]] = r.field_table()
    n = len(radars)
    return SiteTables(
        roads=roads, bounds=bounds,
        crossing_u=np.array([c.crossing_u for c in corridors]),
        length_m=np.array([c.path.length_m for c in corridors]),
        half_lane_m=np.array([0.5 * site.roads[c.first].lane_width_m for c in corridors]),
        barrier_m=float(site.barrier_m), stop_line_m=float(site.stop_line_m),
        warning_starts=np.array(starts, float), warning_ends=np.array(ends, float),
        radar=np.stack([r.kernel_row() for r in radars]),
        noise_tab=noise_tab.reshape(n, 3, 2, -1), noise_cnt=noise_cnt.reshape(n, 3),
        fields=fields, field_count=field_count,
        pd_tab=pd_tab.reshape(n, 1, 2, -1), pd_cnt=pd_cnt.reshape(n, 1),
        latency_s=np.array([r.latency_s for r in radars], float),
    )  # fmt: skip


def _frame(columns: list[dict[str, np.ndarray]]) -> pd.DataFrame:
    """One table of track rows from the columns of several scans (status named, categorical)."""
    keys = list(columns[0]) if columns else list(ROW_COLUMNS)
    table: dict[str, Any] = {
        k: (columns[0][k] if len(columns) == 1 else np.concatenate([c[k] for c in columns]))
        if columns else np.zeros(0, np.int64 if k == "status" else float)
        for k in keys
    }  # fmt: skip
    table["status"] = pd.Categorical.from_codes(table["status"], categories=STATUS_NAMES)
    return pd.DataFrame(table, copy=False)  # the columns are the buffer's, not copied


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


def _track_rows(book: TrackBook, tracks: _Tracks) -> TrackRows:
    """Return the track book's and the filter's columns as the loop's rows (not copies)."""
    return TrackRows(**{
        name: getattr(book if name in _BOOK_COLUMNS else tracks, name) for name in TrackRows._fields
    })  # fmt: skip


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


def scan_arrays(
    detections: pd.DataFrame, latency_s: dict[str, float] | None = None
) -> tuple[list[str], np.ndarray, FloatArray, np.ndarray, FloatArray, np.ndarray]:
    """Split a detection table into scans in time order (radar name breaks ties).

    A scan is the detections (range_m, azimuth_rad, radial_speed_mps) of one radar at one
    timestamp, with their sensor object ids (the ``object_id`` column of an object list; -1
    without it). With radars' ``latency_s``, the order is that of the times the scans were
    made (timestamps less latency). Returns the radar names (sorted), each scan's radar (its
    index in them) and timestamp [s], the scans' start rows (S + 1,) in the sorted
    detections ``z`` (N, 3) and their ``ids`` (N,).
    """
    t = detections["time_s"].to_numpy(dtype=float)
    codes, uniques = pd.factorize(detections["radar"])
    names, rank = np.unique(np.array([str(u) for u in uniques], dtype=object), return_inverse=True)
    codes = rank[codes] if t.size else codes
    z = detections[["range_m", "azimuth_rad", "radial_speed_mps"]].to_numpy(dtype=float)
    ids = (
        detections["object_id"].to_numpy(dtype=np.int64)
        if "object_id" in detections.columns
        else np.full(t.size, -1, np.int64)
    )
    latency = np.array([(latency_s or {}).get(name, 0.0) for name in names], float)
    order = np.lexsort((codes, t - latency[codes]))
    t, codes, z, ids = t[order], codes[order], z[order], ids[order]
    cut = np.flatnonzero((np.diff(t) != 0) | (codes[1:] != codes[:-1])) + 1
    starts = np.concatenate([[0], cut, [t.size]] if t.size else [[0]]).astype(np.int64)
    return list(names), codes[starts[:-1]], t[starts[:-1]], starts, z, ids


def iter_scans(
    detections: pd.DataFrame, latency_s: dict[str, float] | None = None
) -> Iterator[tuple[str, float, FloatArray, np.ndarray]]:
    """Yield the scans of :func:`scan_arrays`: radar name, timestamp [s], detections, ids."""
    names, radar, stamps, starts, z, ids = scan_arrays(detections, latency_s)
    for k, (a, b) in enumerate(itertools.pairwise(starts)):
        yield names[radar[k]], float(stamps[k]), z[a:b], ids[a:b]


SCANS_PER_CALL = 4096  # scans per compiled call of track_scene (progress between calls)
ROWS_PER_SCAN = 16  # track rows reserved per scan (untouched memory costs nothing; it grows)


def track_scene(
    site: Site,
    detections: pd.DataFrame,
    config: SceneTrackerConfig | None = None,
    on_scan: Callable[[int, int], None] | None = None,
    warnings: FloatArray | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame, ScanLog]:
    """Track a detection table scan by scan (:func:`scan_arrays`), compiled.

    An ``object_id`` column (a radar object list) gives the sensor's ids as association hints
    (:meth:`SceneTracker.step`). A radar the site does not have, or a detection that is not
    finite, is an error naming the scan.

    ``on_scan(done, total)`` is called after each run of scans (progress); ``warnings`` (K, 2):
    when the crossing's lights flash or its barriers are down [s] (none: no stop-line
    prediction). Returns the track rows of every scan, the hazard events and the detection log.
    """
    tracker = SceneTracker(site, config, warnings)
    names, radar, stamps, starts, z, ids = scan_arrays(
        detections, {r.name: r.latency_s for r in site.radars}
    )
    rows = np.array([tracker._radar(name) for name in names], np.int64)[radar]
    for bad, what in ((~np.isfinite(z).all(axis=1), "a detection is not finite"),
                      (ids < -1, "sensor ids must be integers >= -1")):  # fmt: skip
        if bad.any():
            k = int(np.searchsorted(starts, np.flatnonzero(bad)[0], side="right")) - 1
            raise ValueError(f"radar {names[radar[k]]!r} at {stamps[k]} s: {what}")
    n_scans = stamps.size
    out: RowBuffer | None = empty_rows(ROWS_PER_SCAN * n_scans)
    n_out = 0
    for a in range(0, n_scans, SCANS_PER_CALL):
        b = min(a + SCANS_PER_CALL, n_scans)
        out, n_out = tracker._run(
            rows[a:b], stamps[a:b], starts[a : b + 1] - starts[a], z[starts[a] : starts[b]],
            ids[starts[a] : starts[b]], out, n_out,
        )  # fmt: skip
        if on_scan is not None:
            on_scan(b, n_scans)
    assert out is not None
    table = _frame([_columns(out, n_out)])
    return table, pd.DataFrame(tracker.events, columns=EVENT_COLUMNS), tracker.log


__all__ = [
    "EVENT_COLUMNS",
    "STATUS_NAMES",
    "ScanLog",
    "SceneTracker",
    "SceneTrackerConfig",
    "iter_scans",
    "load_scene_config",
    "scan_arrays",
    "track_scene",
]
