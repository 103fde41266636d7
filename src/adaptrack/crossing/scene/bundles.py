"""The named bundles the scene tracker's kernels take, and the layouts of their packed rows.

The track table (:class:`TrackRows`), the settings (:class:`Settings`), the site
(:class:`SiteTables`), one radar of a scan (:class:`RadarView`), what is kept per radar
(:class:`RadarState`) and the confirmed-track output (:class:`RowBuffer`): NamedTuples of arrays
and numbers, which numba passes by value and reads by name. The scan counters' columns are
:data:`LOG_FIELDS` (indices ``LOG_*``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

LOG_FIELDS = ("updated", "opened", "joined_new", "rejected_outside_view", "off_road")
LOG_UPDATED, LOG_OPENED, LOG_JOINED_NEW, LOG_OUTSIDE_VIEW, LOG_OFF_ROAD = range(len(LOG_FIELDS))
BIAS_WEIGHT, BIAS_SUM, BIAS_SAMPLES = range(3)  # a radar's alignment sums (RadarState.bias_stats)


class TrackRows(NamedTuple):
    """Live tracks, one row each: the track book's columns, then the filter's."""

    ids: np.ndarray
    history: np.ndarray
    confirmed: np.ndarray
    misses: np.ndarray
    last_hit_s: np.ndarray
    born_s: np.ndarray
    corridor: np.ndarray
    x: np.ndarray
    p: np.ndarray
    time_s: np.ndarray
    stopped: np.ndarray
    slow_since: np.ndarray
    moved: np.ndarray
    event_raised: np.ndarray
    line_event_raised: np.ndarray
    anchor_u: np.ndarray
    spread: np.ndarray
    along_m2: np.ndarray
    along_m4: np.ndarray
    direction: np.ndarray
    miss_run: np.ndarray
    occluded: np.ndarray
    doppler_seen_s: np.ndarray
    detection_d: np.ndarray
    sensor_id: np.ndarray
    clutter_views: np.ndarray


class Settings(NamedTuple):
    """The tracker's settings as the loop reads them (``SceneTrackerConfig`` and its rules)."""

    accel_psd: float
    lateral_psd: float
    stopped_psd: float
    body_along_std_m: float
    body_across_std_m: float
    start_speed_max_mps: float
    body_extent_gate: bool
    occlusion_gate: bool
    passing_gate: bool
    beside_m: float
    shadow_spread_m: float
    gate: float
    clutter_gate: float
    sensor_id_bonus: float
    clutter_age_s: float
    moving_radial_mps: float
    spread_learning_rate: float
    shape_learning_rate: float
    spread_lo_m: float
    spread_hi_m: float
    estimate_azimuth_bias: bool
    bias_forget: float
    bias_gate_m: float
    bias_min_samples: float
    confirm_speed_var: float
    window_mask: int
    confirm_hits: int
    cluster_radius_m: float
    max_open_offset_m: float
    initial_speed_var: float
    moved_speed_mps: float
    moving_speed_std_mps: float
    moved_distance_m: float
    stop_speed_mps: float
    stop_exit_sigmas: float
    stop_confirm_s: float
    stop_seen_s: float
    stationary_detections: bool
    same_object_m: float
    stop_decel_mps2: float
    split_kurtosis: float
    split_min_half_gap_m: float
    tentative_misses: int
    max_tentative_s: float
    max_coast_s: float
    max_coast_stopped_s: float
    max_coast_hidden_s: float
    max_position_std_m: float
    max_stopped_misses: int
    merge_lateral_m: float
    merge_speed_mps: float
    merge_parts_speed_mps: float
    absorb_young_static: bool
    merge_settled_s: float
    merge_settled_lateral_m: float
    coasting_s: float
    status_codes: np.ndarray  # confirmed, coasting, stopped, static, tentative


class SiteTables(NamedTuple):
    """The site for compiled code: corridors, crossing, radars and the controller's warnings.

    Radars are rows: geometry (R, 7), noise curves (R, 3, 2, K) and counts (R, 3), fields of
    view (R, F, 2) with their counts (R,), detection-probability curves (R, 1, 2, K) and counts
    (R, 1), latency (R,) [s].
    """

    roads: np.ndarray
    bounds: np.ndarray
    crossing_u: np.ndarray
    length_m: np.ndarray
    half_lane_m: np.ndarray
    barrier_m: float
    stop_line_m: float
    warning_starts: np.ndarray
    warning_ends: np.ndarray
    radar: np.ndarray
    noise_tab: np.ndarray
    noise_cnt: np.ndarray
    fields: np.ndarray
    field_count: np.ndarray
    pd_tab: np.ndarray
    pd_cnt: np.ndarray
    latency_s: np.ndarray


class RadarView(NamedTuple):
    """One radar as a scan's kernels read it: its row of :attr:`SiteTables.radar` and curves.

    ``radar`` (7,) (:data:`adaptrack.crossing.site.geometry.RADAR_FIELDS`), noise curves
    ``noise_tab`` (3, 2, K) and counts ``noise_cnt`` (3,), ``fields`` (F, 2) max range and half
    angle of the fields of view in use, detection-probability curve ``pd_tab`` (1, 2, K) and
    ``pd_cnt`` (1,).
    """

    radar: np.ndarray
    noise_tab: np.ndarray
    noise_cnt: np.ndarray
    fields: np.ndarray
    pd_tab: np.ndarray
    pd_cnt: np.ndarray


class RadarState(NamedTuple):
    """What the tracker keeps per radar.

    The last scan's timestamp [s], the azimuth bias taken off [rad] and the running sums of
    the alignment that estimates it (R, 3).
    """

    last_stamp_s: np.ndarray
    azimuth_bias_rad: np.ndarray
    bias_stats: np.ndarray


class RowBuffer(NamedTuple):
    """Confirmed tracks after each scan, a column each (the columns of ``SceneTracker.rows``).

    Status as codes (``scene.tracker.STATUS_NAMES``); sigmas of position and speed.
    """

    track_id: np.ndarray
    time_s: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    speed_mps: np.ndarray
    east_speed_mps: np.ndarray
    north_speed_mps: np.ndarray
    from_crossing_m: np.ndarray
    status: np.ndarray
    moved: np.ndarray
    position_std_m: np.ndarray
    speed_std_mps: np.ndarray


def empty_rows(capacity: int) -> RowBuffer:
    """Return a row buffer with room for ``capacity`` rows."""
    kinds = {"track_id": np.int64, "status": np.int64, "moved": bool}
    return RowBuffer(*(np.zeros(capacity, kinds.get(name, float)) for name in RowBuffer._fields))
