"""Radar detections of vehicles on a crossing approach, as a traffic radar reports them.

Per scan (period ``T``, timestamps jittered by up to ``time_jitter_s``) a detection gives
slant range, azimuth (clockwise from north, with the radar's calibration bias) and radial
speed (positive receding), with Gaussian noise whose standard deviations are the radar's
curves at the true geometry (range and radial-speed sigma against range, azimuth sigma against
the angle off boresight). Effects that decide accuracy in practice are simulated: the
reflection point wanders along the body (``N(0, sigma_b^2)`` about the front face, ``sigma_b``
the class's scatter), the vehicle drives off the lane centre (a constant offset per run, the
vehicle kept inside its lane), detections are lost with probability ``1 - P_D(class, range)``,
outside every field of view and below the Doppler gate (a vehicle stopped at the barrier
vanishes); radial speed optionally folds at ``+-max_unambiguous_speed_mps``. Truth is the
front reference point at the lane offset; the case's profile is its distance along its own
lane (on a curve that differs from the centreline's by the factor ``1 + kappa (w/2 + d)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._typing import BoolArray, FloatArray
from ..site.model import Site
from ..site.road import Road
from ..site.sensor import RadarSpec, curve_tables
from ..site.traffic import Case, VehicleClass, along_road_profile, case_duration, random_profiles
from .radar_kernel import detections_kernel


@dataclass(frozen=True, eq=False)
class CrossingRuns:
    """Monte-Carlo runs of one case: truth and detections, shapes (N, T[, k])."""

    times: FloatArray  # reported detection times [s]
    true_times: FloatArray  # true scan times [s]
    measurements: FloatArray  # (N, T, 3): range [m], azimuth [rad], radial speed [m/s]
    detected: BoolArray  # (N, T)
    position: FloatArray  # (N, T, 2) true reference point [m]
    velocity: FloatArray  # (N, T, 2) [m/s]
    speed: FloatArray  # (N, T) [m/s]
    along_road_m: FloatArray  # (N, T) true s of the front [m]
    lateral_offset_m: FloatArray  # (N,)


def scan_count(
    radar: RadarSpec, vehicle: VehicleClass, case: Case, start_m: float, stop_line_m: float
) -> int:
    """Radar scans of one approach of ``case`` (the length T of its runs)."""
    return int(case_duration(case, vehicle, start_m, stop_line_m) / radar.period_s) + 1


def simulate_case(
    road: Road,
    radar: RadarSpec,
    vehicle: VehicleClass,
    case: Case,
    *,
    n_runs: int,
    rng: np.random.Generator,
    start_m: float,
    stop_line_m: float,
    lateral_offset_std_m: float,
) -> CrossingRuns:
    """Simulate ``n_runs`` approaches of one vehicle class in one case."""
    n = scan_count(radar, vehicle, case, start_m, stop_line_m)
    t_true = radar.period_s * np.arange(n)
    if case.kind == "random":
        on_road, v, _ = random_profiles(case, vehicle, start_m, t_true, n_runs, rng)
    else:  # one profile for every run
        on_road, v, _ = along_road_profile(case, vehicle, start_m, stop_line_m, t_true)
        v = np.broadcast_to(v, (n_runs, n))
    half = max(0.5 * (road.lane_width_m - vehicle.width_m), 0.0)  # the vehicle stays in lane
    offset = np.clip(rng.normal(0.0, lateral_offset_std_m, n_runs), -half, half)
    # the profile is the vehicle's own distance along its lane: on a curve the lane point runs
    # (1 + kappa (w/2 + d)) times as far as the centreline
    s = road.centreline_at(on_road, offset)
    pos = road.lane_point(s, offset[:, None])
    direction = road.inbound_direction(s)
    vel = v[..., None] * direction
    # reflection point: along the body about the front face
    scatter = rng.normal(0.0, vehicle.scatter_std_m, (n_runs, n))
    noise = rng.standard_normal((n_runs, n, 3))  # scaled by the noise curves in the kernel
    draw = rng.uniform(size=(n_runs, n))
    jitter = rng.uniform(-radar.time_jitter_s, radar.time_jitter_s, (n_runs, n))
    radar_arr = np.array(
        [
            *radar.position_m,
            radar.height_m,
            radar.azimuth_bias_rad,
            radar.boresight_rad,
            radar.min_range_m,
            radar.min_radial_speed_mps,
            radar.max_unambiguous_speed_mps or 0.0,
        ]
    )
    meas = np.empty((n_runs, n, 3))
    detected = np.empty((n_runs, n), dtype=bool)
    detections_kernel(
        pos,
        direction,
        v,
        scatter,
        noise,
        draw,
        radar_arr,
        radar.field_table(),
        *radar.noise_table(),
        *curve_tables((radar.detection_curve(vehicle.name),)),
        meas,
        detected,
    )
    return CrossingRuns(
        t_true + jitter + radar.latency_s,
        np.broadcast_to(t_true, (n_runs, n)).copy(),
        meas,
        detected,
        pos,
        vel,
        np.array(v),
        np.array(s),
        offset,
    )


def site_scan_count(site: Site, case: Case, vehicle: VehicleClass) -> int:
    """:func:`scan_count` with the site's geometry and radar."""
    return scan_count(
        site.radar_for(case.road), vehicle, case, site.zone_m + site.run_in_m, site.stop_line_m
    )


def simulate_site_case(
    site: Site, case: Case, vehicle: VehicleClass, *, n_runs: int, rng: np.random.Generator
) -> CrossingRuns:
    """:func:`simulate_case` with the site's geometry, radar and traffic settings."""
    return simulate_case(
        site.roads[case.road],
        site.radar_for(case.road),
        vehicle,
        case,
        n_runs=n_runs,
        rng=rng,
        start_m=site.zone_m + site.run_in_m,
        stop_line_m=site.stop_line_m,
        lateral_offset_std_m=site.lateral_offset_std_m,
    )


__all__ = [
    "CrossingRuns",
    "scan_count",
    "simulate_case",
    "simulate_site_case",
    "site_scan_count",
]
