"""Recorded flights seen by simulated radars, and a car's GNSS: our ML-tuned IMMs against a
truth-tuned FilterPy IMM.

``python -m benchmarks.recorded_imm [--data DIR] [--scan 4.8] [--seed 1] [--models cv+ca,cv+ct]
[--car-only]`` reads every ``air_*.csv`` flight of ``DIR`` (default ``../shared/data``, else
``docs/data``) as truth. Radars are placed along each flight as ``adaptrack evaluate flights``
places them (a new one 60 km ahead of the first point no radar covers, 5 km to the side; 111
km coverage; a handover when the aircraft leaves a radar's coverage), with 30 m range, 0.08
deg azimuth and 0.1 deg elevation noise, every ``--scan`` seconds; every stretch one radar
sees is one track: the whole flight is scored.

Leave one flight out: every estimator is tuned on the other flights and scored on it.

* ours: :func:`adaptrack.filters.imm.imm_filter` over the radar measurement model (IMM-EKF,
  continuous-time switching, the compiled kernel) of constant velocity with constant
  acceleration (``cv+ca``) or with the coordinated turn (``cv+ct``), horizontal and vertical
  PSDs apart; PSDs and switching rate fitted by maximum likelihood of the plots (no truth;
  radar noise from the sensor's specification);
* ours refitted online: the same IMM starting from that fit, its parameters refitted causally
  by maximum likelihood of the held-out recording's own plots received so far
  (:func:`adaptrack.tuning.causal.refit_online`; no truth, each estimate from earlier plots
  only);
* FilterPy: ``IMMEstimator`` of two ``KalmanFilter`` (CV padded to the CA state) on the plots
  converted to east-north-up, each with its converted covariance; its two PSDs and switching
  probability chosen by grid search against the truth, on the isotropic grid (one PSD per
  model for all axes) and then, around its best, with the vertical PSDs apart (``split``).

Offline, for a recording (not causal): our IMM smoother (:func:`adaptrack.smoothers.imm_smooth`)
of the same fitted IMMs, against FilterPy's Kalman filter and RTS smoother (``batch_filter``,
``rts_smoother``; FilterPy has no IMM smoother) of one model, CV or CA, whose PSD and vertical
fraction are chosen by grid search against the truth.

``--oracle`` instead prints, for our IMMs, the RMSE when tuned against the truth of the very
data they are scored on: a bound on any tuning of that IMM (same plots, same seed); and, for
the car, the best causal linear filter of the last 20, 40 or 80 fixes trained by least
squares against the truth of the first half (:func:`linear_filter_rmse`).

Prints the position RMSE of each on each held-out flight and pooled (first three scans of each
track left out), and the ratios. First the car drive (``ground_*.csv``): a 10 Hz GNSS (2 m
horizontal, 4 m vertical noise) simulated on it, every estimator tuned on its first half and
scored on the second. Not a timing benchmark (about half an hour, most of it FilterPy's grids).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import adaptrack as at
from adaptrack.analysis.flights import (
    AZIMUTH_STD_RAD,
    ELEVATION_STD_RAD,
    radar_sites,
    radar_stretches,
    scan_rows,
    sub_flight,
)
from adaptrack.analysis.flights import RANGE_STD_M as RANGE_STD
from adaptrack.coords.geodetic import ecef_to_enu, geodetic_to_ecef
from adaptrack.coords.radar import polar_to_enu, polar_to_enu_cov
from adaptrack.filters.imm import IMMResult, imm_filter
from adaptrack.io.position_log import read_position_log
from adaptrack.io.tables import read_flight_csv
from adaptrack.models import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    PositionMeasurement,
    RadarMeasurement,
    filterpy_order,
)
from adaptrack.smoothers import imm_smooth
from adaptrack.tuning.causal import refit_online
from adaptrack.tuning.likelihood import fit_by_likelihood

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
    scans = sub_flight(fl, scan_rows(fl.times, scan_s))
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


MODEL_SETS = ("cv+ca", "cv+ct")
START = {  # starting values of the maximum-likelihood fit: PSDs, switching rate [1/s]
    ("cv+ca", False): {"q_cv_h": 1.0, "q_cv_v": 0.01, "q_ca_h": 0.1, "q_ca_v": 0.001, "rate": 0.05},
    ("cv+ct", False): {"q_cv_h": 0.5, "q_cv_v": 0.01, "q_ct": 0.5, "q_w": 1e-5, "q_ct_v": 0.01,
                       "rate": 0.05},
    ("cv+ca", True): {"q_cv_h": 1.0, "q_cv_v": 0.1, "q_ca_h": 1.0, "q_ca_v": 0.1, "rate": 0.1},
    ("cv+ct", True): {"q_cv_h": 0.5, "q_cv_v": 0.1, "q_ct": 0.5, "q_w": 1e-3, "q_ct_v": 0.1,
                      "rate": 0.1},
}  # fmt: skip
TURN_STD = {False: 0.05, True: 0.3}  # prior turn-rate sigma [rad/s]: aircraft, car


def ours_models(kind: str, v: Mapping[str, float]) -> list[Any]:
    """CV with CA or with the coordinated turn; horizontal and vertical PSDs apart."""
    cv = ConstantVelocity((v["q_cv_h"], v["q_cv_h"], v["q_cv_v"]), n_axes=3)
    if kind == "cv+ca":
        return [cv, ConstantAcceleration((v["q_ca_h"], v["q_ca_h"], v["q_ca_v"]), n_axes=3)]
    return [cv, CoordinatedTurn(v["q_ct"], v["q_w"], v["q_ct_v"], n_axes=3)]


def ours_run(track: Track, kind: str, v: Mapping[str, float], gnss: bool = False) -> IMMResult:
    """Our IMM (``kind`` of :data:`MODEL_SETS`) on one track's radar plots (IMM-EKF) or
    GNSS fixes, with the parameters ``v`` (PSDs, switching ``rate`` [1/s])."""
    rates = _switching(v)
    sensor, priors = (GNSS, car_priors(track)) if gnss else (RADAR, _priors(track))
    if kind == "cv+ct":
        ct = np.zeros((7, 7))
        ct[:6, :6], ct[6, 6] = priors[0].cov, TURN_STD[gnss] ** 2
        priors = [priors[0], at.GaussianState(np.r_[priors[0].mean, 0.0], ct, priors[0].time)]
    return imm_filter(track.times, track.plots, ours_models(kind, v), sensor, None, priors,
                      initial_probs=[0.5, 0.5], switching_rates=rates,
                      backend="numba")  # fmt: skip


def fit_ours(tracks: list[Track], kind: str, gnss: bool = False) -> dict[str, float]:
    """Maximum likelihood of the plots (or fixes) over the training tracks (no truth)."""

    def loglik(v: dict[str, float]) -> float:
        return float(sum(ours_run(tr, kind, v, gnss).log_likelihood.sum() for tr in tracks))

    fit = fit_by_likelihood(loglik, START[kind, gnss])
    return {n: fit.value(n) for n in fit.names}


def ours_online(
    tracks: list[Track], kind: str, start: Mapping[str, float], gnss: bool = False
) -> list[np.ndarray]:
    """Our IMM on a recording's tracks in time order, its parameters refitted causally by
    maximum likelihood of the plots received so far (:func:`refit_online`), starting at
    ``start``; positions (T, 3) of each track."""

    def run(times: np.ndarray, plots: np.ndarray, v: dict[str, float]) -> tuple[Any, Any]:
        res = ours_run(Track(tracks[0].flight, times, plots, plots), kind, v, gnss)  # no truth
        return res.log_likelihood, res.filtered.mean[:, :3]

    return refit_online([(tr.times, tr.plots) for tr in tracks], run, start).estimates


def filterpy_run(
    track: Track,
    q_cv: float | tuple[float, ...],
    q_ca: float | tuple[float, ...],
    p_switch: float,
    gnss: bool = False,
) -> np.ndarray:
    """FilterPy's IMM on the converted plots (or GNSS fixes); positions (T, 3)."""
    from filterpy.kalman import IMMEstimator, KalmanFilter

    z, r, priors = _filterpy_inputs(track, gnss)
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


def _filterpy_inputs(
    track: Track, gnss: bool
) -> tuple[np.ndarray, np.ndarray, list[at.GaussianState]]:
    """FilterPy's measurements, their covariances and the priors (CV, CA) of one track: the
    plots converted to east-north-up with the converted covariance, or the GNSS fixes."""
    if gnss:
        z = track.plots
        r = np.broadcast_to(np.diag(np.square(GNSS_STD_M)), (z.shape[0], 3, 3))
        return z, r, car_priors(track)
    return polar_to_enu(track.plots), polar_to_enu_cov(track.plots, R_POLAR), _priors(track)


def _padded(model, dt: float, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Transition and noise of ``model`` over ``dt`` in the 9-state CA layout, FilterPy order."""
    phi, qd = at.discretize(model, dt)
    f9, q9 = np.zeros((9, 9)), np.zeros((9, 9))
    f9[: model.state_dim, : model.state_dim] = phi
    q9[: model.state_dim, : model.state_dim] = qd
    return f9[np.ix_(order, order)], q9[np.ix_(order, order)]


def _switching(v: Mapping[str, float]) -> list[list[float]]:
    """The two modes' switching rate matrix [1/s] of the parameters ``v``."""
    return [[-v["rate"], v["rate"]], [v["rate"], -v["rate"]]]


def ours_smoothed(run: IMMResult, kind: str, v: Mapping[str, float]) -> np.ndarray:
    """Our IMM smoother (:func:`adaptrack.smoothers.imm_smooth`) of a run of :func:`ours_run`
    with the same ``kind`` and parameters ``v``; positions (T, 3)."""
    smoothed = imm_smooth(run, ours_models(kind, v), switching_rates=_switching(v))
    return smoothed.smoothed.mean[:, :3]


def filterpy_smoothed(
    track: Track, kind: str, q: tuple[float, ...], gnss: bool = False
) -> np.ndarray:
    """FilterPy's Kalman filter and RTS smoother (``batch_filter``, ``rts_smoother``) of one
    model (``kind`` "cv" or "ca", PSDs ``q`` east, north, up) on the converted plots (or GNSS
    fixes); positions (T, 3)."""
    from filterpy.kalman import KalmanFilter

    z, r, priors = _filterpy_inputs(track, gnss)
    model = (ConstantVelocity if kind == "cv" else ConstantAcceleration)(q, n_axes=3)
    prior = priors[0 if kind == "cv" else 1]
    n = model.state_dim
    fp = np.argsort(filterpy_order(model))  # FilterPy's layout: x = ours[fp]
    kf = KalmanFilter(dim_x=n, dim_z=3)
    kf.x, kf.P = prior.mean[fp], prior.cov[np.ix_(fp, fp)]
    kf.H = np.eye(n)[[0, n // 3, 2 * n // 3]]
    fs, qs = [np.eye(n)], [np.zeros((n, n))]  # the prior is at the first plot's time
    for dt in np.diff(track.times):
        phi, qd = at.discretize(model, dt)
        fs.append(phi[np.ix_(fp, fp)])
        qs.append(qd[np.ix_(fp, fp)])
    means, covs, _, _ = kf.batch_filter(z, Fs=fs, Qs=qs, Rs=list(r))
    smoothed, _, _, _ = kf.rts_smoother(means, covs, Fs=fs, Qs=qs)
    return smoothed[:, [0, n // 3, 2 * n // 3]]


def tune_filterpy_smoother(
    tracks: list[Track], grids: Mapping[str, tuple[float, ...]], gnss: bool = False
) -> FilterPyParams:
    """Grid search against the truth of the training tracks: model (CV or CA), its PSD and
    the vertical PSD as a fraction of it (:data:`VERTICAL_FACTORS`)."""

    def mse(v: FilterPyParams) -> float:
        errs = [squared_errors(filterpy_smoothed(tr, **v, gnss=gnss), tr) for tr in tracks]
        return float(np.mean(np.concatenate(errs)))

    grid = [{"kind": kind, "q": (q, q, q * f)}
            for kind, qs in grids.items() for q in qs for f in VERTICAL_FACTORS]  # fmt: skip
    return min(grid, key=mse)


def squared_errors(est: np.ndarray, track: Track) -> np.ndarray:
    return np.sum((est[WARM_UP:] - track.truth[WARM_UP:]) ** 2, axis=1)


FilterPyParams = dict[str, Any]
VERTICAL_FACTORS = (1.0, 1e-1, 1e-2, 1e-3, 1e-4)  # vertical PSD / horizontal, searched


def tune_filterpy(
    tracks: list[Track], q_cvs: tuple[float, ...], q_cas: tuple[float, ...],
    p_switches: tuple[float, ...], gnss: bool = False,
) -> tuple[FilterPyParams, FilterPyParams]:  # fmt: skip
    """Grid search against the truth of the training tracks.

    First the isotropic grid (one PSD per model for all axes); then, around its best, the
    vertical PSDs of both models as fractions of the horizontal ones. Returns both bests.
    """

    def mse(v: FilterPyParams) -> float:
        errs = [squared_errors(filterpy_run(tr, **v, gnss=gnss), tr) for tr in tracks]
        return float(np.mean(np.concatenate(errs)))

    grid = [{"q_cv": a, "q_ca": b, "p_switch": c}
            for a in q_cvs for b in q_cas for c in p_switches]  # fmt: skip
    iso = min(grid, key=mse)
    split = [{"q_cv": (iso["q_cv"],) * 2 + (iso["q_cv"] * f,),
              "q_ca": (iso["q_ca"],) * 2 + (iso["q_ca"] * g,), "p_switch": iso["p_switch"]}
             for f in VERTICAL_FACTORS for g in VERTICAL_FACTORS]  # fmt: skip
    return iso, min(split, key=mse)


def describe(params: Mapping[str, Any]) -> str:
    """``name value`` pairs, tuples shown as horizontal / vertical."""

    def one(v: Any) -> str:
        if isinstance(v, str):
            return v
        return f"{v[0]:.3g}/{v[2]:.3g}" if isinstance(v, tuple) else f"{v:.3g}"

    return ", ".join(f"{k} {one(v)}" for k, v in params.items())


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


FILTERPY = ("isotropic", "split")  # FilterPy's grids (tune_filterpy)
OFFLINE = "RTS smoother"  # FilterPy's best smoother of one model (tune_filterpy_smoother)
CAR_GRIDS = {"cv": (0.1, 0.5, 2.0, 8.0), "ca": (0.1, 1.0, 10.0, 50.0)}  # PSDs searched
FLIGHT_GRIDS = {"cv": (0.1, 0.5, 2.0, 8.0), "ca": (0.01, 0.1, 1.0, 10.0)}


def report(
    name: str, sq: dict[str, list[np.ndarray]], params: dict[str, Any], kinds: list[str]
) -> None:
    """Print each of our model sets and each FilterPy grid, with the ratios."""
    r = {k: math.sqrt(float(np.concatenate(v).mean())) for k, v in sq.items()}
    print(name)
    for kind in kinds:
        print(f"  ours, IMM {kind}: {r[kind]:.2f} m ({describe(params[kind])})"
              if kind in params else f"  ours, IMM {kind}: {r[kind]:.2f} m")  # fmt: skip
    for kind in kinds:
        print(f"  ours, IMM {kind} refitted online (causal): {r[f'{kind} online']:.2f} m")
    for label in FILTERPY:
        rows = [*kinds, *(f"{k} online" for k in kinds)]
        ratios = ", ".join(f"{k} {r[k] / r[label]:.3f}" for k in rows)
        extra = f" ({describe(params[label])})" if label in params else ""
        print(f"  FilterPy, {label} grid: {r[label]:.2f} m{extra}; ours / FilterPy: {ratios}")
    if OFFLINE not in r:
        return
    for kind in kinds:
        print(f"  offline, ours IMM {kind} smoothed: {r[f'{kind} smoothed']:.2f} m")
    ratios = ", ".join(f"{k} {r[f'{k} smoothed'] / r[OFFLINE]:.3f}" for k in kinds)
    extra = f" ({describe(params[OFFLINE])})" if OFFLINE in params else ""
    print(f"  offline, FilterPy {OFFLINE}: {r[OFFLINE]:.2f} m{extra}; ours / FilterPy: {ratios}")


def car_comparison(path: Path, rng: np.random.Generator, kinds: list[str]) -> None:
    """Tune on the drive's first half (ours by likelihood, FilterPy against truth), score
    the second."""
    train, test = car_halves(path, rng)
    params: dict[str, Any] = {kind: fit_ours([train], kind, gnss=True) for kind in kinds}
    fp = tune_filterpy([train], CAR_GRIDS["cv"], CAR_GRIDS["ca"], (0.005, 0.02, 0.1), gnss=True)
    params |= dict(zip(FILTERPY, fp, strict=True))
    params[OFFLINE] = tune_filterpy_smoother([train], CAR_GRIDS, gnss=True)
    runs = {kind: ours_run(test, kind, params[kind], True) for kind in kinds}
    sq = {kind: [squared_errors(runs[kind].filtered.mean[:, :3], test)] for kind in kinds}
    for kind in kinds:  # the drive in time order: refits from the first half on
        online = ours_online([train, test], kind, params[kind], gnss=True)[1]
        sq[f"{kind} online"] = [squared_errors(online, test)]
    for label in FILTERPY:
        sq[label] = [squared_errors(filterpy_run(test, **params[label], gnss=True), test)]
    for kind in kinds:
        sq[f"{kind} smoothed"] = [squared_errors(ours_smoothed(runs[kind], kind, params[kind]),
                                                 test)]  # fmt: skip
    sq[OFFLINE] = [squared_errors(filterpy_smoothed(test, **params[OFFLINE], gnss=True), test)]
    raw = rmse([test], lambda tr: tr.plots)
    report(f"car (second half, 10 Hz GNSS of {GNSS_STD_M} m; fixes {raw:.2f} m)", sq, params,
           kinds)  # fmt: skip


def oracle_rmse(tracks: list[Track], kind: str, start: Mapping[str, float], gnss: bool) -> float:
    """Position RMSE [m] of our IMM with its parameters tuned against the truth of the very
    ``tracks`` it is scored on (Nelder-Mead in log space from ``start``): a bound on what
    any tuning of this IMM can reach on them, not a tuning anyone could do."""
    from scipy.optimize import minimize

    names = list(start)

    def mse(log_values: np.ndarray) -> float:
        v = dict(zip(names, np.exp(log_values).tolist(), strict=True))
        try:
            sq = [squared_errors(ours_run(tr, kind, v, gnss).filtered.mean[:, :3], tr)
                  for tr in tracks]  # fmt: skip
        except ValueError:  # parameters the filter cannot run with
            return math.inf
        value = float(np.concatenate(sq).mean())
        return value if math.isfinite(value) else math.inf

    x0 = np.log([start[n] for n in names])
    best = minimize(mse, x0, method="Nelder-Mead", options={"maxfev": 400 * len(names)})
    return math.sqrt(min(best.fun, mse(x0)))


def linear_filter_rmse(train: Track, test: Track, taps: int) -> float:
    """Position RMSE [m] on ``test`` of the best causal linear filter of the last ``taps``
    fixes, per axis, its weights fitted by least squares against the truth of ``train``:
    a peer stronger than any fixed Kalman filter tuned on ``train`` (whose steady state is
    such a filter), up to the fixes' irregular spacing, which it ignores."""

    def lagged(z: np.ndarray) -> np.ndarray:  # row k: fixes k + taps - 1, ..., k
        return np.stack([z[taps - 1 - j : z.size - j] for j in range(taps)], axis=1)

    sq = np.zeros(test.times.size - taps + 1)
    for axis in range(3):
        weights = np.linalg.lstsq(lagged(train.plots[:, axis]), train.truth[taps - 1 :, axis],
                                  rcond=None)[0]  # fmt: skip
        sq += (lagged(test.plots[:, axis]) @ weights - test.truth[taps - 1 :, axis]) ** 2
    return math.sqrt(float(sq.mean()))


LINEAR_TAPS = (20, 40, 80)  # lengths of the linear filters of linear_filter_rmse [fixes]


def oracle_bounds(data: Path, scan_s: float, rng: np.random.Generator, kinds: list[str]) -> None:
    """Print each oracle bound (:func:`oracle_rmse`) next to the likelihood fit it starts
    from (car: fitted on the first half; flights: on the other flights), same plots as the
    comparison."""
    for car in sorted(data.glob("ground_*.csv")):
        train, test = car_halves(car, rng)
        for kind in kinds:
            fit = fit_ours([train], kind, gnss=True)
            fitted = rmse(
                [test], lambda tr, k=kind, v=fit: ours_run(tr, k, v, True).filtered.mean[:, :3]
            )
            print(f"car, second half, IMM {kind}: fitted {fitted:.3f} m, "
                  f"oracle {oracle_rmse([test], kind, fit, True):.3f} m")  # fmt: skip
        for taps in LINEAR_TAPS:
            print(
                f"car, second half, best causal linear filter of {taps} fixes (trained "
                f"against the first half's truth): {linear_filter_rmse(train, test, taps):.3f} m"
            )
    flights = {p.stem: flight_tracks(p, scan_s, rng) for p in sorted(data.glob("air_*.csv"))}
    for kind in kinds:
        sq_fit: list[np.ndarray] = []
        sq_oracle = 0.0
        for name, test in flights.items():
            train = [tr for other, trs in flights.items() if other != name for tr in trs]
            fit = fit_ours(train, kind)
            errs = [squared_errors(ours_run(tr, kind, fit).filtered.mean[:, :3], tr) for tr in test]
            sq_fit.extend(errs)
            bound = oracle_rmse(test, kind, fit, False)
            sq_oracle += bound**2 * sum(e.size for e in errs)
            fitted = math.sqrt(np.concatenate(errs).mean())
            print(f"{name}, IMM {kind}: fitted on the others {fitted:.2f} m, oracle {bound:.2f} m")
        n = sum(e.size for e in sq_fit)
        fitted = math.sqrt(np.concatenate(sq_fit).mean())
        print(f"flights pooled, IMM {kind}: fitted {fitted:.2f} m, "
              f"oracle {math.sqrt(sq_oracle / n):.2f} m")  # fmt: skip


def rmse(tracks: list[Track], estimate: Any) -> float:
    """Position RMSE [m] of ``estimate(track)`` over ``tracks`` pooled."""
    return math.sqrt(
        float(np.concatenate([squared_errors(estimate(tr), tr) for tr in tracks]).mean())
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=None)
    parser.add_argument("--scan", type=float, default=4.8, help="radar scan period [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--car-only", action="store_true", help="only the car drive")
    parser.add_argument(
        "--oracle",
        action="store_true",
        help="instead: our IMMs tuned against the truth they are scored on (a bound)",
    )
    parser.add_argument(
        "--models",
        default=",".join(MODEL_SETS),
        help="our IMMs, comma-separated: cv+ca, cv+ct",
    )
    args = parser.parse_args()
    data = args.data or next(
        d for d in (Path("../shared/data"), Path("docs/data")) if list(d.glob("air_*.csv"))
    )
    kinds = args.models.split(",")
    if not set(kinds) <= set(MODEL_SETS):
        parser.error(f"--models takes {', '.join(MODEL_SETS)}")
    rng = np.random.default_rng(args.seed)
    if args.oracle:
        oracle_bounds(data, args.scan, rng, kinds)
        return
    for car in sorted(data.glob("ground_*.csv")):
        car_comparison(car, rng, kinds)
    if args.car_only:
        return
    flights = {p.stem: flight_tracks(p, args.scan, rng) for p in sorted(data.glob("air_*.csv"))}
    for name, tracks in flights.items():
        n = sum(tr.times.size for tr in tracks)
        print(f"{name}: {len(tracks)} radar stretches, {n} scans")
    labels = [*kinds, *(f"{k} online" for k in kinds), *FILTERPY,
              *(f"{k} smoothed" for k in kinds), OFFLINE]  # fmt: skip
    pooled: dict[str, list[np.ndarray]] = {k: [] for k in labels}
    for name, test in flights.items():
        train = [tr for other, trs in flights.items() if other != name for tr in trs]
        params: dict[str, Any] = {kind: fit_ours(train, kind) for kind in kinds}
        grids = tune_filterpy(train, FLIGHT_GRIDS["cv"], FLIGHT_GRIDS["ca"], (0.01, 0.05, 0.2))
        params |= dict(zip(FILTERPY, grids, strict=True))
        params[OFFLINE] = tune_filterpy_smoother(train, FLIGHT_GRIDS)
        runs = {kind: [ours_run(tr, kind, params[kind]) for tr in test] for kind in kinds}
        sq = {
            kind: [squared_errors(run.filtered.mean[:, :3], tr)
                   for run, tr in zip(runs[kind], test, strict=True)]
            for kind in kinds
        }  # fmt: skip
        for kind in kinds:
            sq[f"{kind} online"] = [
                squared_errors(est, tr)
                for est, tr in zip(ours_online(test, kind, params[kind]), test, strict=True)
            ]
        for label in FILTERPY:
            sq[label] = [squared_errors(filterpy_run(tr, **params[label]), tr) for tr in test]
        for kind in kinds:
            sq[f"{kind} smoothed"] = [
                squared_errors(ours_smoothed(run, kind, params[kind]), tr)
                for run, tr in zip(runs[kind], test, strict=True)
            ]
        sq[OFFLINE] = [squared_errors(filterpy_smoothed(tr, **params[OFFLINE]), tr) for tr in test]
        for k, v in sq.items():
            pooled[k].extend(v)
        report(f"held out {name}", sq, params, kinds)
    report("pooled over the held-out flights", pooled, {}, kinds)


if __name__ == "__main__":
    main()
