"""Real-flight evaluation of navigation smoothing (spec D; ``adaptrack evaluate flights``).

A recorded ADS-B trajectory is the truth. A radar at a site near the track measures range,
azimuth and elevation every ``scan_s`` within 60 nmi of the site (DOMAIN 7(b): sigma 30 m,
0.08 deg; elevation sigma 0.1 deg is this evaluation's assumption for a 3-D radar); a
second, unsynchronised source measures the velocity (sigma 1 m/s per axis) at other epochs.
The radar detections are
converted to ENU with their Jacobian covariance. Methods, all scored at the radar epochs:

* ``lsq_position``: sliding-window polynomial least squares on the position nodes;
* ``lsq_triple``: the same with the velocity nodes of the second source (nodes of several
  orders at asynchronous times, spec D.6);
* ``kf`` / ``rts``: a 3-axis Singer Kalman filter over both sources (component masks) and its
  RTS smoother.

Caveats of the truth (the data's README): the altitude is barometric (used consistently as
the vertical coordinate here); AFR26TR has 1 s snapshot time tags (tens of metres of
along-track truth error); the ADS-B velocity lags the position by up to about 1 s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..coords.geodetic import (
    ecef_to_enu,
    ecef_to_geodetic,
    enu_to_ecef,
    enu_to_ecef_rotation,
    geodetic_to_ecef,
)
from ..coords.radar import enu_to_polar, polar_to_enu, polar_to_enu_cov
from ..filters.ekf import ekf_filter
from ..filters.run import kalman_filter
from ..io.navigation import NavigationNodes, RadarRecord
from ..io.tables import Flight
from ..models.continuous import Singer
from ..models.measurement import RadarMeasurement
from ..smoothers.batch_ls import smooth_polynomial
from ..smoothers.rts import rts_smooth
from ..smoothers.triple_nodes import radar_triple_nodes, smooth_triple_nodes
from ..types import GaussianState

RANGE_STD_M = 30.0
AZIMUTH_STD_RAD = math.radians(0.08)
ELEVATION_STD_RAD = math.radians(0.1)
VELOCITY_STD_MPS = 1.0
MAX_RANGE_M = 111_120.0  # 60 nmi, terminal surveillance radar coverage (DOMAIN 4)
SITE_AHEAD_M, SITE_SIDE_M = 60_000.0, 5_000.0  # a new radar: this far along, this far aside
GROUNDSPEED_STEP_MPS = 0.5144  # ADS-B reports: 1 kt steps
VERTICAL_RATE_STEP_MPS = 0.3251  # 64 ft/min steps
VELOCITY_LAG_STD_S = 0.5  # the velocity reports lag the positions by up to about 1 s


@dataclass(frozen=True)
class FlightRow:
    """RMSE of one method on one flight."""

    flight: str
    method: str
    scan_s: float
    position_rmse_m: float
    velocity_rmse_mps: float
    n_scored: int
    n_scans: int = 0  # radar scans of the whole flight
    n_radars: int = 1  # radars (stretches) the flight was seen by


@dataclass(frozen=True, eq=False)
class FlightMeasurements:
    """Simulated measurements of a flight in the ENU frame of the radar site, with truth."""

    site: tuple[float, float, float]
    truth_times: FloatArray
    truth_position: FloatArray
    truth_velocity: FloatArray
    radar_index: np.ndarray
    nodes: NavigationNodes


def radar_sites(flight: Flight) -> list[tuple[float, float, float]]:
    """Radar sites along a flight until every fix is within :data:`MAX_RANGE_M` of one.

    From the first fix no radar covers, the next radar stands :data:`SITE_AHEAD_M` further
    along the track (the last fix within that distance), :data:`SITE_SIDE_M` to its right,
    on the ellipsoid (so that no radar looks straight up at the track). Latitude,
    longitude [rad], height [m].
    """
    origin = (float(flight.lat[0]), float(flight.lon[0]), 0.0)
    ecef = geodetic_to_ecef(flight.lat, flight.lon, flight.alt)
    p = ecef_to_enu(ecef, *origin)
    sites: list[tuple[float, float, float]] = []
    covered = np.zeros(flight.times.size, dtype=bool)
    while not covered.all():
        first = int(np.argmax(~covered))
        near = np.linalg.norm(p[:, :2] - p[first, :2], axis=1) <= SITE_AHEAD_M
        j = int(np.flatnonzero(near & (np.arange(p.shape[0]) >= first)).max())
        heading = p[min(j + 1, p.shape[0] - 1), :2] - p[max(j - 1, 0), :2]
        side = np.array([heading[1], -heading[0]]) / max(float(np.linalg.norm(heading)), 1e-9)
        at_site = np.r_[p[j, :2] + SITE_SIDE_M * side, 0.0]
        lat, lon, _ = ecef_to_geodetic(enu_to_ecef(at_site, *origin))
        sites.append((float(lat), float(lon), 0.0))
        covered |= np.linalg.norm(ecef_to_enu(ecef, *sites[-1]), axis=1) <= MAX_RANGE_M
    return sites


def radar_stretches(
    flight: Flight, sites: list[tuple[float, float, float]]
) -> list[tuple[tuple[float, float, float], np.ndarray]]:
    """Split a flight's fixes between radars: (site, fix indices) per contiguous stretch.

    A fix stays with the current radar while that radar covers it (a handover only when the
    aircraft leaves its coverage, to the nearest radar), so stretches are long.
    """
    ecef = geodetic_to_ecef(flight.lat, flight.lon, flight.alt)
    dist = np.stack([np.linalg.norm(ecef_to_enu(ecef, *s), axis=1) for s in sites])
    owner = np.empty(flight.times.size, dtype=int)
    current = int(np.argmin(dist[:, 0]))
    for k in range(flight.times.size):
        if dist[current, k] > MAX_RANGE_M:
            current = int(np.argmin(dist[:, k]))
        owner[k] = current
    cuts = np.flatnonzero(np.diff(owner)) + 1
    return [(sites[owner[part[0]]], part) for part in np.split(np.arange(owner.size), cuts)]


def sub_flight(flight: Flight, rows: np.ndarray) -> Flight:
    """Return the fixes ``rows`` of a flight."""
    return Flight(flight.name, flight.times[rows], flight.lat[rows], flight.lon[rows],
                  flight.alt[rows], flight.velocity_enu[rows])  # fmt: skip


def velocity_report_cov(velocity_enu: FloatArray, times: FloatArray) -> FloatArray:
    """Covariance (n, 3, 3) of velocity reports against the true velocity [m^2/s^2].

    The simulated sensor's :data:`VELOCITY_STD_MPS` plus the reports' own errors (ADS-B):
    groundspeed steps along the track and vertical-rate steps (uniform, ``step^2 / 12``),
    and their lag behind the positions (:data:`VELOCITY_LAG_STD_S` times the acceleration,
    from the reports' own differences).
    """
    n = velocity_enu.shape[0]
    accel = np.zeros((n, 3))
    ok = np.all(np.isfinite(velocity_enu), axis=1)
    if ok.sum() >= 2:
        accel[ok] = np.gradient(velocity_enu[ok], times[ok], axis=0)
    horiz = velocity_enu[:, :2] / np.maximum(np.linalg.norm(velocity_enu[:, :2], axis=1),
                                             1e-9)[:, None]  # fmt: skip
    along = np.zeros((n, 3))
    along[:, :2] = np.nan_to_num(horiz)
    cov = np.broadcast_to(VELOCITY_STD_MPS**2 * np.eye(3), (n, 3, 3)).copy()
    cov += GROUNDSPEED_STEP_MPS**2 / 12 * along[:, :, None] * along[:, None, :]
    cov[:, 2, 2] += VERTICAL_RATE_STEP_MPS**2 / 12
    lag = VELOCITY_LAG_STD_S * np.nan_to_num(accel)
    return cov + lag[:, :, None] * lag[:, None, :]


def radar_site(flight: Flight) -> tuple[float, float, float]:
    """Place the radar about 11 km south of the track's mean position, on the ellipsoid.

    Returns latitude [rad], longitude [rad], height [m].
    """
    return (float(np.mean(flight.lat) - math.radians(0.1)), float(np.mean(flight.lon)), 0.0)


def scan_rows(times: FloatArray, scan_s: float) -> np.ndarray:
    """Return the fixes a radar scanning every ``scan_s`` [s] from ``times[0]`` reports.

    The first fix of each scan period (indices into ``times``).
    """
    scan = np.floor((times - times[0]) / scan_s)
    return np.flatnonzero(np.diff(np.concatenate([[-1.0], scan])) > 0)


def simulate_flight_measurements(
    flight: Flight,
    *,
    seed: int = 0,
    scan_s: float = 4.8,
    site: tuple[float, float, float] | None = None,
) -> FlightMeasurements:
    """Radar detections every ``scan_s`` and asynchronous velocity measurements in between."""
    rng = np.random.default_rng(seed)
    site = radar_site(flight) if site is None else site
    pos = ecef_to_enu(geodetic_to_ecef(flight.lat, flight.lon, flight.alt), *site)
    # velocities are given in each fix's own local frame: rotate them into the site's frame
    rot_fix = enu_to_ecef_rotation(flight.lat, flight.lon)
    rot_site = enu_to_ecef_rotation(site[0], site[1])
    vel = np.einsum("ji,njk,nk->ni", rot_site, rot_fix, flight.velocity_enu)
    radar_idx = scan_rows(flight.times, scan_s)
    in_cover = np.linalg.norm(pos[radar_idx], axis=-1) <= MAX_RANGE_M
    if in_cover.sum() < 10:
        raise ValueError(
            f"flight {flight.name}: fewer than 10 radar scans within "
            f"{MAX_RANGE_M / 1e3:.0f} km of the radar site"
        )
    radar_idx = radar_idx[in_cover]
    rows = np.arange(flight.times.size)
    vel_idx = rows[(rows % 2 == 1) & np.all(np.isfinite(vel), axis=-1)]
    polar = enu_to_polar(pos[radar_idx])
    noise = rng.standard_normal(polar.shape) * [RANGE_STD_M, AZIMUTH_STD_RAD, ELEVATION_STD_RAD]
    meas = polar + noise
    cov = polar_to_enu_cov(
        meas, np.diag([RANGE_STD_M**2, AZIMUTH_STD_RAD**2, ELEVATION_STD_RAD**2])
    )
    vmeas = vel[vel_idx] + rng.standard_normal((vel_idx.size, 3)) * VELOCITY_STD_MPS
    in_span = (flight.times[vel_idx] >= flight.times[radar_idx[0]]) & (
        flight.times[vel_idx] <= flight.times[radar_idx[-1]]
    )  # velocity reports only while the radar sees the aircraft
    vel_idx, vmeas = vel_idx[in_span], vmeas[in_span]
    nodes = NavigationNodes(
        flight.times[radar_idx],
        polar_to_enu(meas),
        cov,
        flight.times[vel_idx],
        vmeas,
        velocity_report_cov(vel, flight.times)[vel_idx],
    )
    return FlightMeasurements(site, flight.times, pos, vel, radar_idx, nodes)


def _squared_errors(est: GaussianState, m: FlightMeasurements) -> tuple[FloatArray, FloatArray]:
    """Squared position and velocity errors at the radar scans (NaN estimates left out)."""
    idx = m.radar_index
    ep = np.sum((est.mean[:, :3] - m.truth_position[idx]) ** 2, -1)
    ev = np.sum((est.mean[:, 3:6] - m.truth_velocity[idx]) ** 2, -1)
    return ep[np.isfinite(ep)], ev[np.isfinite(ev)]


def smooth_lsq(
    nodes: NavigationNodes, *, use_velocity: bool = True, degree: int = 2, window_s: float = 20.0
) -> GaussianState:
    """Sliding-window polynomial LSQ at the radar epochs: ``[p, v, a]`` (K, 9) in ENU."""
    t_r = nodes.radar_times
    times, orders = [t_r], [np.zeros(t_r.size, int)]
    values, covs = [nodes.radar_position], [nodes.radar_cov]
    if use_velocity:
        times.append(nodes.velocity_times)
        orders.append(np.ones(nodes.velocity_times.size, int))
        values.append(nodes.velocity)
        covs.append(nodes.velocity_cov)
    return smooth_polynomial(
        np.concatenate(times),
        np.concatenate(orders),
        np.concatenate(values),
        np.concatenate(covs),
        t_r,
        degree=degree,
        window_s=window_s,
        insufficient="nan",
    )


def smooth_kalman(nodes: NavigationNodes, model: Singer, *, smooth: bool = True) -> GaussianState:
    """Singer KF (or RTS smoother) over both sources; ``[p, v, a]`` at the radar epochs.

    The filter starts at the first radar detection (its prior position); velocity nodes before
    it cannot initialise a track and are not used.
    """
    keep = nodes.velocity_times >= nodes.radar_times[0]
    t_vel = nodes.velocity_times[keep]
    # one measurement per distinct epoch; a radar and a velocity node at the same time merge
    t, inv = np.unique(np.concatenate([nodes.radar_times, t_vel]), return_inverse=True)
    ir, iv = inv[: nodes.radar_times.size], inv[nodes.radar_times.size :]
    n = t.size
    z = np.full((n, 6), np.nan)
    mask = np.zeros((n, 6), dtype=bool)
    r = np.broadcast_to(np.eye(6), (n, 6, 6)).copy()
    z[ir, :3] = nodes.radar_position
    r[ir, :3, :3] = nodes.radar_cov
    mask[ir, :3] = True
    z[iv, 3:] = nodes.velocity[keep]
    r[iv, 3:, 3:] = nodes.velocity_cov[keep]
    mask[iv, 3:] = True
    p0 = np.diag([RANGE_STD_M**2] * 3 + [300.0**2] * 3 + [10.0**2] * 3)
    p0[:3, :3] = nodes.radar_cov[0]
    prior = GaussianState(np.concatenate([nodes.radar_position[0], np.zeros(6)]), p0, t[0])
    h = np.hstack([np.eye(6), np.zeros((6, 3))])
    res = kalman_filter(t, z, model, h, r, prior, mask=mask)
    est = rts_smooth(res) if smooth else res.filtered
    return GaussianState(est.mean[ir], est.cov[ir], t[ir])


@dataclass(frozen=True)
class RadarSigmas:
    """A radar's noise sigmas.

    Range [m], azimuth, elevation [rad], range-rate [m/s], range acceleration [m/s^2].
    """

    range_m: float
    azimuth_rad: float
    elevation_rad: float
    range_rate_mps: float
    range_accel_mps2: float


def smooth_record_lsq(
    record: RadarRecord, sigmas: RadarSigmas, *, degree: int = 2, window_s: float = 20.0
) -> GaussianState:
    """Sliding polynomial LSQ of a radar record's triple nodes (spec D.2, D.6), at its epochs."""
    nodes = radar_triple_nodes(
        record.times, *record.polar.T, range_std_m=sigmas.range_m,
        azimuth_std_rad=sigmas.azimuth_rad, elevation_std_rad=sigmas.elevation_rad,
        range_rate=record.range_rate, range_rate_std_mps=sigmas.range_rate_mps,
        range_accel=record.range_accel,
        range_accel_std_mps2=None if record.range_accel is None else sigmas.range_accel_mps2,
    )  # fmt: skip
    return smooth_triple_nodes(nodes, record.times, degree=degree, window_s=window_s)


def smooth_record_kalman(
    record: RadarRecord, sigmas: RadarSigmas, model: Singer, *, smooth: bool = True
) -> GaussianState:
    """EKF over range, azimuth, elevation and range-rate (and its RTS smoother), Singer model."""
    radar = RadarMeasurement(
        np.array([sigmas.range_m, sigmas.azimuth_rad, sigmas.elevation_rad,
                  sigmas.range_rate_mps]) ** 2,
        ("range", "azimuth", "elevation", "range_rate"), n_axes=3,
    )  # fmt: skip
    first = record.polar[0]
    p0 = np.diag([RANGE_STD_M**2] * 3 + [300.0**2] * 3 + [10.0**2] * 3)
    p0[:3, :3] = polar_to_enu_cov(first, np.diag(radar.noise_cov.diagonal()[:3]))
    prior = GaussianState(np.r_[polar_to_enu(first), np.zeros(6)], p0, record.times[0])
    z = np.c_[record.polar, record.range_rate]
    res = ekf_filter(record.times, z, model, radar, prior)
    return rts_smooth(res) if smooth else res.filtered


METHODS = ("lsq_triple", "lsq_position", "kf", "rts")


def evaluate_flight(
    flight: Flight,
    *,
    seed: int = 0,
    scans_s: tuple[float, ...] = (4.8, 1.0),
    degree: int = 2,
    window_s: float = 20.0,
) -> list[FlightRow]:
    """RMSE of ``lsq_triple``, ``lsq_position``, ``kf`` and ``rts`` over a whole flight.

    Radars stand along the flight (:func:`radar_sites`); each stretch one radar sees is a
    track of its own (:func:`radar_stretches`), and the rows pool every scan of every
    stretch (a stretch of fewer than 10 scans cannot be smoothed: counted, not scored).
    One set of rows per radar scan period (default: the ASR-11's 4.8 s and a 1 s variant).
    """
    model = Singer(time_constant_s=20.0, accel_std_mps2=2.0, n_axes=3)
    stretches = radar_stretches(flight, radar_sites(flight))
    rows = []
    for scan in scans_s:
        errors: dict[str, list[tuple[FloatArray, FloatArray]]] = {k: [] for k in METHODS}
        n_scans = 0
        for k, (site, fixes) in enumerate(stretches):
            part = sub_flight(flight, fixes)
            n_scans += scan_rows(part.times, scan).size
            try:
                m = simulate_flight_measurements(part, seed=seed + k, scan_s=scan, site=site)
            except ValueError:  # fewer than 10 scans in this stretch
                continue
            estimates = {
                "lsq_triple": smooth_lsq(m.nodes, use_velocity=True, degree=degree,
                                         window_s=window_s),
                "lsq_position": smooth_lsq(m.nodes, use_velocity=False, degree=degree,
                                           window_s=window_s),
                "kf": smooth_kalman(m.nodes, model, smooth=False),
                "rts": smooth_kalman(m.nodes, model, smooth=True),
            }  # fmt: skip
            for name, est in estimates.items():
                errors[name].append(_squared_errors(est, m))
        for name in METHODS:
            ep = np.concatenate([e[0] for e in errors[name]] or [np.zeros(0)])
            ev = np.concatenate([e[1] for e in errors[name]] or [np.zeros(0)])
            rows.append(FlightRow(
                flight.name, name, scan, math.sqrt(float(np.mean(ep))) if ep.size else math.nan,
                math.sqrt(float(np.mean(ev))) if ev.size else math.nan, int(ep.size), n_scans,
                len(stretches),
            ))  # fmt: skip
    return rows


__all__ = [
    "FlightMeasurements",
    "FlightRow",
    "evaluate_flight",
    "radar_site",
    "radar_sites",
    "radar_stretches",
    "scan_rows",
    "simulate_flight_measurements",
    "smooth_kalman",
    "smooth_lsq",
]
