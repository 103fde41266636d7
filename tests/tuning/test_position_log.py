"""A recorded position log: maximum-likelihood fit, filter, geodetic output, the CLI."""

import numpy as np
import pandas as pd
import pymap3d
import pytest

import adaptrack as at
from adaptrack.io.position_log import estimates_table, read_position_log
from adaptrack.tuning.log_fit import fit_motion

DT, N = 0.1, 1200
Q_H, Q_V, R_H, R_V = 2.0, 0.05, 0.25, 1.0  # [m^2/s^3], [m^2]
ORIGIN = (48.2, 16.37, 180.0)  # deg, deg, m


def _cv_track(rng, q, n_axes, speed):
    """Constant-velocity truth per axis from its own closed-form transition (exact Q)."""
    phi = np.array([[1.0, DT], [0.0, 1.0]])
    chol = np.linalg.cholesky(q * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]]))
    out = np.zeros((N, n_axes))
    for a in range(n_axes):
        s = np.array([0.0, speed[a]])
        for k in range(N):
            s = phi @ s + chol @ rng.standard_normal(2)
            out[k, a] = s[0]
    return out


def gnss_log(path, seed=3):
    """A GNSS log simulated in ENU and converted to geodetic by pymap3d (independent)."""
    rng = np.random.default_rng(seed)
    enu = np.concatenate(
        [_cv_track(rng, Q_H, 2, (8.0, 3.0)), _cv_track(rng, Q_V, 1, (0.0,))], axis=-1
    )
    meas = enu + rng.normal(0.0, 1.0, enu.shape) * np.sqrt([R_H, R_H, R_V])
    lat, lon, alt = pymap3d.enu2geodetic(*meas.T, *ORIGIN)
    frame = pd.DataFrame(
        {"time_s": DT * np.arange(N), "lat_deg": lat, "lon_deg": lon, "alt_m": alt,
         "speed_kmh": 0.0}
    )  # fmt: skip
    frame.to_csv(path, index=False)
    return enu, meas


@pytest.mark.statistical
def test_a_simulated_gnss_log_gives_back_its_noise_and_motion(tmp_path):
    """Each parameter within 3 standard errors of the simulation's (one seed; the fit's own
    log-scale errors, tested for coverage in test_likelihood), and the smoothed positions
    nearer the truth than the fixes."""
    truth, meas = gnss_log(tmp_path / "log.csv")
    log = read_position_log(tmp_path / "log.csv", "gnss")
    assert log.unused == ("speed_kmh",) and log.n_axes == 3
    fit = fit_motion(log, "cv").fit
    assert fit.converged, fit.message
    for name, value in {"q_horizontal": Q_H, "q_vertical": Q_V, "r_horizontal": R_H,
                        "r_vertical": R_V}.items():  # fmt: skip
        z = np.log(fit.value(name) / value) / (fit.std_error(name) / fit.value(name))
        assert abs(z) < 3, (name, fit.value(name), value)
    # east-north-up at the first fix (within millimetres of the simulation's frame moved
    # there, over a few hundred metres): smoothing beats the fixes against the truth
    assert np.abs(log.enu - (meas - meas[0])).max() < 0.01
    mean, _ = fit_motion(log, "cv").filter(log, smooth=True)
    smoothed = np.sqrt(np.mean((mean[:, :3] - (truth - meas[0])) ** 2, axis=0))
    raw = np.sqrt(np.mean((log.enu - (truth - meas[0])) ** 2, axis=0))
    assert np.all(smoothed < 0.7 * raw), (smoothed, raw)


def test_filtered_estimates_convert_back_to_the_geodetic_fixes_frame(tmp_path):
    """lat/lon/alt of the estimates equal pymap3d's conversion of their east-north-up (1 mm)
    at the log's first fix; the position covariance columns are the filter's."""
    gnss_log(tmp_path / "log.csv", seed=4)
    log = read_position_log(tmp_path / "log.csv", "gnss")
    fitted = fit_motion(log, "cv")
    mean, cov = fitted.filter(log, smooth=True)
    table = estimates_table(log, mean, cov)
    first = pd.read_csv(tmp_path / "log.csv").iloc[0]
    lat, lon, alt = pymap3d.enu2geodetic(
        table["east_m"], table["north_m"], table["up_m"], first.lat_deg, first.lon_deg,
        first.alt_m,
    )  # fmt: skip
    east_err = np.deg2rad(table["lon_deg"] - lon) * 6.4e6 * np.cos(np.deg2rad(lat))
    north_err = np.deg2rad(table["lat_deg"] - lat) * 6.4e6
    assert np.abs(east_err).max() < 1e-3 and np.abs(north_err).max() < 1e-3
    assert np.abs(table["alt_m"] - alt).max() < 1e-3
    assert np.allclose(table["north_std_m"] ** 2, cov[:, 1, 1])
    assert np.allclose(table["cov_e_u"], cov[:, 0, 2])


def test_a_planar_local_log_is_fitted_in_two_axes(tmp_path):
    rng = np.random.default_rng(5)
    track = _cv_track(rng, Q_H, 2, (5.0, -2.0))
    meas = track + rng.normal(0.0, np.sqrt(R_H), track.shape)
    pd.DataFrame({"t_s": DT * np.arange(N), "east_m": meas[:, 0], "north_m": meas[:, 1]}).to_csv(
        tmp_path / "p.csv", index=False
    )
    log = read_position_log(tmp_path / "p.csv", "position")
    fitted = fit_motion(log, "cv")
    assert set(fitted.fit.names) == {"q_horizontal", "r_horizontal"}
    mean, _ = fitted.filter(log)
    filt = np.sqrt(np.mean(np.sum((mean[:, :2] - track) ** 2, axis=1)))
    raw = np.sqrt(np.mean(np.sum((meas - track) ** 2, axis=1)))
    assert filt < 0.8 * raw, (filt, raw)


def turning_drive(seed):
    """A car at 12 m/s: straight, a 90 deg left bend over 10 s, straight, a right bend;
    positions integrated at 1 ms from the heading (independent of the model's closed form)."""
    rng = np.random.default_rng(seed)
    fine = np.arange(0.0, 60.0, 0.001)
    rate = np.where((fine > 15) & (fine <= 25), np.pi / 20, 0.0)
    rate -= np.where((fine > 40) & (fine <= 50), np.pi / 20, 0.0)
    heading = np.cumsum(rate) * 0.001
    pos = np.cumsum(12.0 * np.c_[np.cos(heading), np.sin(heading)], axis=0) * 0.001
    idx = np.arange(0, fine.size, 100)
    meas = pos[idx] + rng.normal(0.0, 1.5, (idx.size, 2))
    return fine[idx], pos[idx], rate[idx], meas


def test_the_coordinated_turn_fits_a_drive_with_bends_better_than_cv(tmp_path):
    """On bends, the CT model's likelihood is higher (by far more than its one extra
    parameter), its filtered positions nearer the truth, and its turn rate follows the bend."""
    t, pos, rate, meas = turning_drive(6)
    pd.DataFrame({"time_s": t, "east_m": meas[:, 0], "north_m": meas[:, 1]}).to_csv(
        tmp_path / "bends.csv", index=False
    )
    log = read_position_log(tmp_path / "bends.csv", "position")
    ct, cv = fit_motion(log, "ct"), fit_motion(log, "cv")
    assert set(ct.fit.names) == {"q_horizontal", "q_turn", "r_horizontal"}
    assert ct.fit.log_likelihood > cv.fit.log_likelihood + 10
    rmse = {}
    for name, fitted in (("ct", ct), ("cv", cv)):
        mean, cov = fitted.filter(log)
        rmse[name] = np.sqrt(np.mean(np.sum((mean[:, :2] - pos) ** 2, axis=1)))
    assert rmse["ct"] < 0.9 * rmse["cv"], rmse
    mean, cov = ct.filter(log)
    table = estimates_table(log, mean, cov, turn_rate=True)
    bend = (t > 18) & (t <= 25)
    true_rate = rate[bend].mean()  # pi / 20 rad/s
    assert abs(table["turn_rate_radps"][bend].mean() - true_rate) < 0.1 * true_rate
    assert np.all(table["turn_rate_std_radps"] > 0)


@pytest.mark.parametrize(
    ("layout", "model", "values"),
    [
        ("position", "ct", {"q_horizontal": 2.0, "q_turn": 1e-3, "r_horizontal": 2.0}),
        ("radar2d", "cv", {"q_horizontal": 0.5, "r_range": 50.0, "r_azimuth": 1e-6,
                           "r_range_rate": 0.2}),
        ("radar3d", "ca", {"q_horizontal": 0.1, "q_vertical": 0.01, "r_range": 60.0,
                           "r_azimuth": 2e-6, "r_elevation": 3e-6, "r_range_rate": 0.1}),
        ("radar3d", "ct", {"q_horizontal": 0.7, "q_vertical": 0.05, "q_turn": 1e-4,
                           "r_range": 70.0, "r_azimuth": 1e-6, "r_elevation": 2e-6,
                           "r_range_rate": 0.3}),
    ],
)  # fmt: skip
def test_the_fit_s_compiled_likelihood_is_the_ekf_s(tmp_path, layout, model, values):
    """The fit's log-likelihood (the compiled filter) equals the sum over the NumPy EKF's
    steps (``ekf_filter(backend="numpy")``), at parameters away from the fit's maximum."""
    from adaptrack.io.radar_plots import read_radar_log
    from adaptrack.tuning.log_fit import _inputs, _log_likelihood, _measured
    from tests.tuning.test_radar_log import radar_plot_list

    if layout == "position":
        t, _, _, meas = turning_drive(2)
        pd.DataFrame({"time_s": t, "east_m": meas[:, 0], "north_m": meas[:, 1]}).to_csv(
            tmp_path / "log.csv", index=False
        )
        log = read_position_log(tmp_path / "log.csv", "position")
    else:
        radar_plot_list(tmp_path / "log.csv", n=120)
        frame = pd.read_csv(tmp_path / "log.csv")
        if layout == "radar2d":
            frame = frame.drop(columns=["elevation_deg", "snr_db"])
        frame.to_csv(tmp_path / "log.csv", index=False)
        log = read_radar_log(tmp_path / "log.csv", layout)
    (motion,), sensor, (prior,) = _inputs(log, model, values)
    ref = at.ekf_filter(log.times, _measured(log), motion, sensor, prior, backend="numpy")
    ekf = float(ref.info.log_likelihood.sum())
    assert _log_likelihood(log, model, values) == pytest.approx(ekf, rel=1e-9, abs=1e-6)


def test_an_imm_fit_starts_from_the_cv_fit_and_finds_the_noise(tmp_path):
    """A target at 200 m/s seen with 20 m noise (white acceleration, PSD 0.5): from the
    default start (r = 1 m^2) the IMM's likelihood is too rough for the optimiser, which
    stopped at r = 2.7 m^2 and a log-likelihood 90,000 below the CV fit's. Started from the
    CV fit, the IMM (which holds CV as its quiet model) is at least as likely as CV, and its
    noise variance within 15 % (3 standard errors) of the truth's 400 m^2."""
    from tests.cv_truth import cv_states

    rng = np.random.default_rng(5)
    n = 900
    states = cv_states(rng, [[0.0, 200.0], [0.0, -30.0]], 1.0, 0.5, n)
    meas = states[:, :, 0] + rng.normal(0.0, 20.0, (n, 2))
    pd.DataFrame({"time_s": np.arange(1.0, n + 1), "east_m": meas[:, 0],
                  "north_m": meas[:, 1]}).to_csv(tmp_path / "fast.csv", index=False)  # fmt: skip
    log = read_position_log(tmp_path / "fast.csv", "position")
    cv, imm = fit_motion(log, "cv"), fit_motion(log, "cv+ca")
    assert imm.fit.log_likelihood > cv.fit.log_likelihood - 2.0
    assert imm.fit.value("r_horizontal") == pytest.approx(400.0, rel=0.15)
    assert imm.fit.rough == ()


@pytest.mark.parametrize("model", ["cv", "ct", "cv+ct"])
def test_compiled_kernel_names_the_kernel_the_fit_runs(tmp_path, monkeypatch, model):
    """Each compiled kernel is replaced by one that raises its own name: the fit's first
    evaluation raises the name `compiled_kernel` gives (none: the Kalman filter's)."""
    from adaptrack.filters import _ekf_kernel, _imm_kernel
    from adaptrack.tuning.log_fit import compiled_kernel

    for module, name in ((_ekf_kernel, "ekf_kernel"), (_imm_kernel, "imm_kernel")):
        label = f"{module.__name__.rsplit('.', 1)[1]}.{name}"

        def named(*args, label=label):
            raise RuntimeError(label)

        monkeypatch.setattr(module, name, named)
    gnss_log(tmp_path / "log.csv")
    log = read_position_log(tmp_path / "log.csv", "gnss")
    expected = compiled_kernel(log, model)
    if expected is None:
        assert fit_motion(log, model).fit.converged
    else:
        with pytest.raises(RuntimeError) as info:
            fit_motion(log, model)
        assert str(info.value) == expected
