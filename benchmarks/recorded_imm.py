"""Recorded flights seen by simulated radars: our ML-tuned IMM-EKF against a tuned FilterPy IMM.

``python -m benchmarks.recorded_imm [--data DIR] [--scan 4.8] [--seed 1]`` reads every
``air_*.csv`` flight of ``DIR`` (default ``../shared/data``, else ``docs/data``) as truth.
Radars are placed along each flight as ``adaptrack evaluate flights`` places them (a new one
60 km ahead of the first point no radar covers, 5 km to the side; 111 km coverage; a handover
when the aircraft leaves a radar's coverage), with 30 m range, 0.08 deg azimuth and 0.1 deg
elevation noise, every ``--scan`` seconds; every stretch one radar sees is one track: the
whole flight is scored.

Leave one flight out: both estimators are tuned on the other flights and scored on it.

* ours: :func:`adaptrack.filters.imm.imm_filter` over the radar measurement model (IMM-EKF,
  constant velocity + constant acceleration, continuous-time switching), its two PSDs and its
  switching rate fitted by maximum likelihood of the plots (no truth; radar noise from the
  sensor's specification);
* FilterPy: ``IMMEstimator`` of two ``KalmanFilter`` (CV padded to the CA state) on the plots
  converted to east-north-up, each with its converted covariance, its two PSDs and switching
  probability chosen by grid search against the truth.

Prints the position RMSE of each on each held-out flight and pooled (first three scans of each
track left out), and the ratio. First the car drive (``ground_*.csv``): a 10 Hz GNSS (2 m
horizontal, 4 m vertical noise) simulated on it, both tuned on its first half and scored on
the second. Not a timing benchmark.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import adaptrack as at
from adaptrack.analysis.flights import (
    AZIMUTH_STD_RAD,
    ELEVATION_STD_RAD,
    radar_sites,
    radar_stretches,
    sub_flight,
)
from adaptrack.analysis.flights import RANGE_STD_M as RANGE_STD
from adaptrack.coords.geodetic import ecef_to_enu, geodetic_to_ecef
from adaptrack.coords.radar import polar_to_enu, polar_to_enu_cov
from adaptrack.filters.imm import imm_filter
from adaptrack.io.tables import read_flight_csv
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    PositionMeasurement,
    RadarMeasurement,
)
from adaptrack.tuning.likelihood import fit_by_likelihood
from adaptrack.tuning.position_log import read_position_log

R_POLAR = np.diag([RANGE_STD**2, AZIMUTH_STD_RAD**2, ELEVATION_STD_RAD**2])
WARM_UP = 3  # scans of each track not scored


@dataclass(frozen=True)
class Track:
    """One radar's stretch of a flight: scan times, plots, truth in that radar's frame."""

    flight: str
    times: np.ndarray
    plots: np.ndarray  # (T, 3) range [m], azimuth, elevation [rad]
    truth: np.ndarray  # (T, 3) east, north, up [m]


def flight_tracks(path: Path, scan_s: float, rng: np.random.Generator) -> list[Track]:
    """Every radar stretch of one flight (:func:`~adaptrack.analysis.flights.radar_stretches`),
    with noisy plots."""
    fl = read_flight_csv(path)
    scan = np.floor((fl.times - fl.times[0]) / scan_s)
    scans = sub_flight(fl, np.flatnonzero(np.diff(np.concatenate([[-1.0], scan])) > 0))
    tracks = []
    for site, rows in radar_stretches(scans, radar_sites(scans)):
        if rows.size < 10:
            continue
        truth = ecef_to_enu(geodetic_to_ecef(scans.lat[rows], scans.lon[rows], scans.alt[rows]),
                            *site)  # fmt: skip
        horiz = np.hypot(truth[:, 0], truth[:, 1])
        polar = np.stack(
            [np.linalg.norm(truth, axis=1), np.arctan2(truth[:, 0], truth[:, 1]),
             np.arctan2(truth[:, 2], horiz)], -1,
        )  # fmt: skip
        plots = polar + rng.standard_normal(polar.shape) * np.sqrt(np.diag(R_POLAR))
        tracks.append(Track(path.stem, scans.times[rows], plots, truth))
    return tracks


RADAR = RadarMeasurement(R_POLAR, ("range", "azimuth", "elevation"), n_axes=3)


def _priors(track: Track) -> list[at.GaussianState]:
    p0 = polar_to_enu(track.plots[0])
    c0 = polar_to_enu_cov(track.plots[0], R_POLAR)
    v_var = 150.0**2  # an aircraft's velocity, unknown at the first plot
    cv = np.zeros((6, 6))
    cv[:3, :3], cv[3:, 3:] = c0, v_var * np.eye(3)
    ca = np.zeros((9, 9))
    ca[:6, :6], ca[6:, 6:] = cv, 5.0**2 * np.eye(3)
    return [
        at.GaussianState(np.r_[p0, np.zeros(3)], cv, track.times[0]),
        at.GaussianState(np.r_[p0, np.zeros(6)], ca, track.times[0]),
    ]


def ours_run(track: Track, q_cv: float, q_ca: float, rate: float):  # type: ignore[no-untyped-def]
    """The IMM-EKF on one track."""
    models = [ConstantVelocity(q_cv, n_axes=3), ConstantAcceleration(q_ca, n_axes=3)]
    rates = [[-rate, rate], [rate, -rate]]
    return imm_filter(track.times, track.plots, models, RADAR, None, _priors(track),
                      initial_probs=[0.5, 0.5], switching_rates=rates)  # fmt: skip


def fit_ours(tracks: list[Track]) -> dict[str, float]:
    """Maximum likelihood of the plots over the training tracks (no truth)."""

    def loglik(v: dict[str, float]) -> float:
        return float(sum(ours_run(tr, v["q_cv"], v["q_ca"], v["rate"]).log_likelihood.sum()
                         for tr in tracks))  # fmt: skip

    fit = fit_by_likelihood(loglik, {"q_cv": 1.0, "q_ca": 0.1, "rate": 0.05})
    return {n: fit.value(n) for n in fit.names}


def filterpy_run(
    track: Track, q_cv: float, q_ca: float, p_switch: float, gnss: bool = False
) -> np.ndarray:
    """FilterPy's IMM on the converted plots (or GNSS fixes); positions (T, 3)."""
    from filterpy.kalman import IMMEstimator, KalmanFilter

    if gnss:
        z = track.plots
        r = np.broadcast_to(np.diag(np.square(GNSS_STD_M)), (z.shape[0], 3, 3))
        priors = car_priors(track)
    else:
        z = polar_to_enu(track.plots)
        r = polar_to_enu_cov(track.plots, R_POLAR)
        priors = _priors(track)
    order = np.array([0, 3, 6, 1, 4, 7, 2, 5, 8])  # FilterPy (x, vx, ax, y, ...) of ours
    cv, ca = ConstantVelocity(q_cv, n_axes=3), ConstantAcceleration(q_ca, n_axes=3)
    filters = []
    for prior in priors:
        kf = KalmanFilter(dim_x=9, dim_z=3)
        x, p = np.zeros(9), np.zeros((9, 9))
        x[: prior.dim], p[: prior.dim, : prior.dim] = prior.mean, prior.cov
        kf.x, kf.P = x[order], p[np.ix_(order, order)]
        kf.H = np.eye(9)[[0, 3, 6]]
        filters.append(kf)
    pi = np.array([[1 - p_switch, p_switch], [p_switch, 1 - p_switch]])
    imm = IMMEstimator(filters, np.array([0.5, 0.5]), pi)
    out = np.empty((track.times.size, 3))
    steps: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}
    for k in range(track.times.size):
        if k:
            dt = track.times[k] - track.times[k - 1]
            if dt not in steps:
                steps[dt] = [_padded(model, dt, order) for model in (cv, ca)]
            for kf, (f9, q9) in zip(filters, steps[dt], strict=True):
                kf.F, kf.Q = f9, q9
            imm.predict()
        for kf in filters:
            kf.R = r[k]
        imm.update(z[k])
        out[k] = imm.x[[0, 3, 6]]
    return out


def _padded(model, dt: float, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Transition and noise of ``model`` over ``dt`` in the 9-state CA layout, FilterPy order."""
    phi, qd = at.discretize(model, dt)
    f9, q9 = np.zeros((9, 9)), np.zeros((9, 9))
    f9[: model.state_dim, : model.state_dim] = phi
    q9[: model.state_dim, : model.state_dim] = qd
    return f9[np.ix_(order, order)], q9[np.ix_(order, order)]


def squared_errors(est: np.ndarray, track: Track) -> np.ndarray:
    return np.sum((est[WARM_UP:] - track.truth[WARM_UP:]) ** 2, axis=1)


def tune_filterpy(tracks: list[Track]) -> dict[str, float]:
    """Grid search against the truth of the training tracks."""
    best, best_mse = {}, math.inf
    for q_cv in (0.1, 0.5, 2.0, 8.0):
        for q_ca in (0.01, 0.1, 1.0, 10.0):
            for p_switch in (0.01, 0.05, 0.2):
                mse = float(np.mean(np.concatenate(
                    [squared_errors(filterpy_run(tr, q_cv, q_ca, p_switch), tr) for tr in tracks]
                )))  # fmt: skip
                if mse < best_mse:
                    best, best_mse = {"q_cv": q_cv, "q_ca": q_ca, "p_switch": p_switch}, mse
    return best


GNSS_STD_M = (2.0, 2.0, 4.0)  # simulated receiver noise, east, north, up [m]


def car_halves(path: Path, rng: np.random.Generator) -> list[Track]:
    """The car drive as truth, a 10 Hz GNSS simulated on it; its two halves in time."""
    log = read_position_log(path, "gnss")
    truth = log.enu if log.n_axes == 3 else np.c_[log.enu, np.zeros(log.times.size)]
    fixes = truth + rng.standard_normal(truth.shape) * GNSS_STD_M
    half = log.times.size // 2
    return [Track(path.stem, log.times[s], fixes[s], truth[s])
            for s in (slice(0, half), slice(half, None))]  # fmt: skip


GNSS = PositionMeasurement(np.square(GNSS_STD_M), ("x", "y", "z"))


def car_priors(track: Track) -> list[at.GaussianState]:
    v_var = 15.0**2  # a car's velocity, unknown at the first fix
    cv = np.diag(np.r_[np.square(GNSS_STD_M), [v_var] * 3])
    ca = np.diag(np.r_[np.square(GNSS_STD_M), [v_var] * 3, [3.0**2] * 3])
    return [at.GaussianState(np.r_[track.plots[0], np.zeros(3)], cv, track.times[0]),
            at.GaussianState(np.r_[track.plots[0], np.zeros(6)], ca, track.times[0])]  # fmt: skip


def car_comparison(path: Path, rng: np.random.Generator) -> None:
    """Tune on the drive's first half (ours by likelihood, FilterPy against truth), score
    the second."""
    train, test = car_halves(path, rng)

    def ours(track: Track, v: dict[str, float]):  # type: ignore[no-untyped-def]
        models = [ConstantVelocity(v["q_cv"], n_axes=3), ConstantAcceleration(v["q_ca"], n_axes=3)]
        rates = [[-v["rate"], v["rate"]], [v["rate"], -v["rate"]]]
        return imm_filter(track.times, track.plots, models, GNSS, None, car_priors(track),
                          initial_probs=[0.5, 0.5], switching_rates=rates)  # fmt: skip

    fit = fit_by_likelihood(lambda v: float(ours(train, v).log_likelihood.sum()),
                            {"q_cv": 1.0, "q_ca": 1.0, "rate": 0.1})  # fmt: skip
    ours_p = {n: fit.value(n) for n in fit.names}
    best, best_mse = {}, math.inf
    for q_cv in (0.1, 0.5, 2.0, 8.0):
        for q_ca in (0.1, 1.0, 10.0, 50.0):
            for p_switch in (0.005, 0.02, 0.1):
                mse = float(np.mean(squared_errors(
                    filterpy_run(train, q_cv, q_ca, p_switch, gnss=True), train)))  # fmt: skip
                if mse < best_mse:
                    best, best_mse = {"q_cv": q_cv, "q_ca": q_ca, "p_switch": p_switch}, mse
    ro = math.sqrt(squared_errors(ours(test, ours_p).filtered.mean[:, :3], test).mean())
    rf = math.sqrt(squared_errors(filterpy_run(test, **best, gnss=True), test).mean())
    raw = math.sqrt(squared_errors(test.plots, test).mean())
    print(f"car (second half, 10 Hz GNSS of {GNSS_STD_M} m): fixes {raw:.2f} m, ours {ro:.2f} m "
          f"({', '.join(f'{k} {v:.3g}' for k, v in ours_p.items())}), FilterPy {rf:.2f} m "
          f"({', '.join(f'{k} {v:g}' for k, v in best.items())}); ours / FilterPy "
          f"{ro / rf:.3f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=None)
    parser.add_argument("--scan", type=float, default=4.8, help="radar scan period [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--car-only", action="store_true", help="only the car drive")
    args = parser.parse_args()
    data = args.data or next(
        d for d in (Path("../shared/data"), Path("docs/data")) if list(d.glob("air_*.csv"))
    )
    rng = np.random.default_rng(args.seed)
    for car in sorted(data.glob("ground_*.csv")):
        car_comparison(car, rng)
    if args.car_only:
        return
    flights = {p.stem: flight_tracks(p, args.scan, rng) for p in sorted(data.glob("air_*.csv"))}
    for name, tracks in flights.items():
        n = sum(tr.times.size for tr in tracks)
        print(f"{name}: {len(tracks)} radar stretches, {n} scans")
    pooled = {"ours": [], "filterpy": []}
    for name, test in flights.items():
        train = [tr for other, trs in flights.items() if other != name for tr in trs]
        ours_p, fp_p = fit_ours(train), tune_filterpy(train)
        e_ours = np.concatenate(
            [squared_errors(ours_run(tr, **ours_p).filtered.mean[:, :3], tr) for tr in test]
        )
        e_fp = np.concatenate([squared_errors(filterpy_run(tr, **fp_p), tr) for tr in test])
        pooled["ours"].append(e_ours)
        pooled["filterpy"].append(e_fp)
        ro, rf = math.sqrt(e_ours.mean()), math.sqrt(e_fp.mean())
        ours_txt = ", ".join(f"{k} {v:.3g}" for k, v in ours_p.items())
        fp_txt = ", ".join(f"{k} {v:g}" for k, v in fp_p.items())
        print(
            f"held out {name}: ours {ro:.1f} m ({ours_txt}); FilterPy {rf:.1f} m ({fp_txt}); "
            f"ours / FilterPy {ro / rf:.3f}"
        )
    ro = math.sqrt(np.concatenate(pooled["ours"]).mean())
    rf = math.sqrt(np.concatenate(pooled["filterpy"]).mean())
    print(f"pooled over held-out flights: ours {ro:.1f} m, FilterPy {rf:.1f} m, "
          f"ratio {ro / rf:.3f} (ours {abs(100 * (1 - ro / rf)):.1f} % "
          f"{'lower' if ro < rf else 'higher'})")  # fmt: skip


if __name__ == "__main__":
    main()
