"""Mode stage of a scan: moving, stopped and static, and the hazards they raise."""

from __future__ import annotations

import math

import numba
import numpy as np

from .body import N_STATE


@numba.njit(cache=True)
def mode_changes(time_s, t, site, cfg):  # type: ignore[no-untyped-def]
    """Update the moving / stopped modes after a scan in place (``SceneTracker._modes``).

    A confirmed track whose speed is known (sigma below half of it and below
    ``moving_speed_std``) to exceed ``moved_speed`` gets its ``direction``; it has ``moved``
    once also ``moved_distance`` from ``anchor_u``. One slower than ``stop_speed`` (sigma
    below 0.5 m/s, detected within ``seen_s``; inf: not required) is slowing to a stop; it
    stays so while its speed is not significantly above (``stop_exit_sigmas`` sigmas) and
    after ``stop_confirm_s`` is ``stopped`` (speed and acceleration zeroed with their
    covariance). Returns the hazard rows (a moved track stopped on the carriageway within
    ``barrier_m`` of the crossing, its standstill shown by a Doppler-measuring detection
    within ``seen_s`` (``doppler_seen_s``), raised once: ``event_raised`` set) and which
    tracks are on the carriageway (bool each). A stop that only misses and radial speeds
    blind to the lane (across the line of sight) suggest raises nothing yet.
    Bundles: ``t`` (the track rows, :class:`~.bundles.TrackRows`), ``site`` (the site,
    :class:`~.bundles.SiteTables`), ``cfg`` (the settings, :class:`~.bundles.Settings`); a setting
    named here is the field of ``cfg``.
    """
    x, p, corridor, confirmed, last_hit_s = t.x, t.p, t.corridor, t.confirmed, t.last_hit_s
    anchor_u, stopped, moved, direction = t.anchor_u, t.stopped, t.moved, t.direction
    slow_since, event_raised, doppler_seen_s = t.slow_since, t.event_raised, t.doppler_seen_s
    crossing_u, half_lane, barrier_m = site.crossing_u, site.half_lane_m, site.barrier_m
    moved_speed, moving_speed_std = cfg.moved_speed_mps, cfg.moving_speed_std_mps
    moved_distance, stop_speed = cfg.moved_distance_m, cfg.stop_speed_mps
    stop_exit_sigmas, stop_confirm_s = cfg.stop_exit_sigmas, cfg.stop_confirm_s
    seen_s = cfg.stop_seen_s if cfg.stationary_detections else np.inf
    n = x.shape[0]
    hazard = np.zeros(n, dtype=np.bool_)
    on_road = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        speed = abs(x[i, 1])
        sd = math.sqrt(p[i, 1, 1])
        if confirmed[i]:
            if speed > moved_speed and sd < 0.5 * speed and sd < moving_speed_std:
                direction[i] = 1.0 if x[i, 1] > 0.0 else -1.0
                if abs(x[i, 0] - anchor_u[i]) > moved_distance:
                    moved[i] = True
        limit = stop_speed if math.isnan(slow_since[i]) else stop_speed + stop_exit_sigmas * sd
        slow = (
            confirmed[i] and not stopped[i] and speed < limit and sd < 0.5
            and time_s - last_hit_s[i] <= seen_s
        )  # fmt: skip
        if not slow:
            slow_since[i] = np.nan
        elif math.isnan(slow_since[i]):
            slow_since[i] = time_s
        if slow and time_s - slow_since[i] >= stop_confirm_s:
            stopped[i] = True
            x[i, 1] = x[i, 2] = 0.0
            for a in range(1, 3):
                for b in range(N_STATE):
                    p[i, a, b] = p[i, b, a] = 0.0
        on_road[i] = abs(x[i, 3]) <= 2.0 * half_lane[corridor[i]]
        to_cross = abs(crossing_u[corridor[i]] - x[i, 0])
        shown = time_s - doppler_seen_s[i] <= seen_s
        if stopped[i] and moved[i] and on_road[i] and to_cross <= barrier_m and shown:
            hazard[i] = not event_raised[i]
            event_raised[i] = True
    return hazard, on_road
