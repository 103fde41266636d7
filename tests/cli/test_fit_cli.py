"""`adaptrack fit` and `adaptrack filter` on a GNSS log, and their errors."""

import numpy as np
import pandas as pd
import pytest

from adaptrack._progress import FIRST_RUN_NOTE
from tests.cv_truth import cv_states
from tests.tuning.test_position_log import N, gnss_log


def test_fit_and_filter_commands_end_to_end(tmp_path, cli):
    gnss_log(tmp_path / "log.csv", seed=6)
    code, out, err = cli(
        "fit", tmp_path / "log.csv", "--measurement", "gnss", "--out", tmp_path / "fit.toml"
    )
    assert code == 0, err
    assert "q_horizontal" in out and "columns not used: speed_kmh" in err
    code, out, err = cli(
        "filter", tmp_path / "log.csv", "--config", tmp_path / "fit.toml", "--smooth", "--out",
        tmp_path / "est.csv",
    )  # fmt: skip
    assert code == 0, err
    assert "innovations: mean NIS" in out and "consistent" in out  # simulated as fitted
    est = pd.read_csv(tmp_path / "est.csv")
    assert len(est) == N
    assert {"time_s", "east_m", "velocity_up_mps", "east_std_m", "cov_e_n", "lat_deg",
            "lon_deg", "alt_m"} <= set(est.columns)  # fmt: skip
    assert np.all(np.isfinite(est.to_numpy()))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.drop(columns="lon_deg"), "lon_deg"),
        (lambda f: f.iloc[[0, 2, 1, *range(3, len(f))]], "row 3, column 'time_s': unsorted"),
        (lambda f: f.assign(lat_deg=f.lat_deg.where(f.index != 7, np.nan)), "row 8"),
    ],
)
def test_bad_logs_get_one_line_errors(tmp_path, cli, edit, message):
    gnss_log(tmp_path / "log.csv")
    edit(pd.read_csv(tmp_path / "log.csv")).to_csv(tmp_path / "bad.csv", index=False)
    code, _, err = cli(
        "fit", tmp_path / "bad.csv", "--measurement", "gnss", "--out", tmp_path / "fit.toml"
    )
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "fit.toml").exists()


def test_filter_refuses_a_config_that_is_not_a_fit(tmp_path, cli):
    gnss_log(tmp_path / "log.csv")
    (tmp_path / "c.toml").write_text('[fit]\nmeasurement = "gnss"\nmodel = "cv"\naxes = 3\n')
    code, _, err = cli(
        "filter", tmp_path / "log.csv", "--config", tmp_path / "c.toml", "--out", tmp_path / "e.csv"
    )
    assert code == 1 and "incomplete [fit] table" in err


def test_filter_refuses_a_log_of_other_axes_than_the_fit(tmp_path, cli):
    gnss_log(tmp_path / "log.csv")
    code, _, err = cli(
        "fit", tmp_path / "log.csv", "--measurement", "gnss", "--out", tmp_path / "fit.toml"
    )
    assert code == 0, err
    pd.read_csv(tmp_path / "log.csv").drop(columns="alt_m").to_csv(
        tmp_path / "flat.csv", index=False
    )
    code, _, err = cli(
        "filter", tmp_path / "flat.csv", "--config", tmp_path / "fit.toml", "--out",
        tmp_path / "e.csv",
    )  # fmt: skip
    assert code == 1 and "the fit is 3-D; the log has 2 axes" in err, err
    assert not (tmp_path / "e.csv").exists()


def _late_fixes_log(path, late_s=0.12, seed=9):
    """A planar GNSS log whose fixes are stamped ``late_s`` late against the velocity reports
    of the same rows: a constant-velocity truth on a 20 ms grid (its own closed form), fixes
    (0.3 m noise) and velocities (0.1 m/s) at 10 Hz, converted to geodetic by pymap3d."""
    import pymap3d

    rng = np.random.default_rng(seed)
    fine, q, n = 0.02, 1.0, 6000  # 120 s
    states = cv_states(rng, [[0.0, 6.0], [0.0, 2.0]], fine, q, n)
    step, shift = 5, round(late_s / fine)  # rows every 0.1 s; fixes made 0.12 s before
    rows = np.arange(shift, n, step)
    pos = states[rows - shift, :, 0] + rng.normal(0.0, 0.3, (rows.size, 2))
    vel = states[rows, :, 1] + rng.normal(0.0, 0.1, (rows.size, 2))
    lat, lon, _ = pymap3d.enu2geodetic(pos[:, 0], pos[:, 1], 0.0, 47.0, 8.0, 400.0)
    pd.DataFrame(
        {"time_s": fine * rows, "lat_deg": lat, "lon_deg": lon, "velocity_east_mps": vel[:, 0],
         "velocity_north_mps": vel[:, 1]}
    ).to_csv(path, index=False)  # fmt: skip


def test_fit_finds_how_late_the_fixes_are_and_filter_corrects_their_times(tmp_path, cli):
    """Fixes stamped 120 ms late: ``fit --clock-offset`` finds it within 3 standard errors;
    ``filter`` writes when each fix was made."""
    import tomllib

    _late_fixes_log(tmp_path / "log.csv")
    code, out, err = cli(
        "fit", tmp_path / "log.csv", "--measurement", "gnss", "--clock-offset", "--out",
        tmp_path / "fit.toml",
    )  # fmt: skip
    assert code == 0, err
    assert "clock offset_s" in out and "columns not used" not in err
    clock = tomllib.loads((tmp_path / "fit.toml").read_text())["fit"]["clock"]["offset_s"]
    assert abs(clock["value"] - 0.12) < 3 * clock["std_error"] < 0.03, clock
    code, _, err = cli(
        "filter", tmp_path / "log.csv", "--config", tmp_path / "fit.toml", "--out",
        tmp_path / "est.csv",
    )  # fmt: skip
    assert code == 0, err
    est = pd.read_csv(tmp_path / "est.csv")
    made = est["time_s"] - est["corrected_time_s"]
    np.testing.assert_allclose(made, clock["value"], atol=1e-6)  # CSV keeps 10 digits


def test_a_clock_offset_needs_velocity_reports(tmp_path, cli):
    gnss_log(tmp_path / "log.csv")
    code, _, err = cli(
        "fit", tmp_path / "log.csv", "--measurement", "gnss", "--clock-offset", "--out",
        tmp_path / "fit.toml",
    )  # fmt: skip
    assert code == 1 and "needs the log's velocity reports" in err, err


def test_fit_and_filter_a_radar_plot_list(tmp_path, cli):
    """`fit --measurement radar3d` then `filter --smooth`: metres east/north/up of the radar,
    closer to the truth than the plots themselves."""
    from tests.tuning.test_radar_log import radar_plot_list

    truth = radar_plot_list(tmp_path / "plots.csv", seed=4, n=200)
    code, out, err = cli(
        "fit", tmp_path / "plots.csv", "--measurement", "radar3d", "--out", tmp_path / "fit.toml"
    )
    assert code == 0, err
    assert "r_range_rate" in out and "columns not used: snr_db" in err
    code, out, err = cli(
        "filter", tmp_path / "plots.csv", "--config", tmp_path / "fit.toml", "--smooth", "--out",
        tmp_path / "est.csv",
    )  # fmt: skip
    assert code == 0, err
    assert "innovations: mean NIS" in out
    est = pd.read_csv(tmp_path / "est.csv")
    assert {"east_m", "north_m", "up_m", "velocity_east_mps", "cov_e_n"} <= set(est.columns)
    plots = pd.read_csv(tmp_path / "plots.csv")
    az, el = np.radians(plots.azimuth_deg), np.radians(plots.elevation_deg)
    raw = (
        plots.range_m.to_numpy()[:, None]
        * np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]
    )
    est_pos = est[["east_m", "north_m", "up_m"]].to_numpy()
    err_est = np.sqrt(np.mean(np.sum((est_pos - truth[:, :3]) ** 2, axis=1)))
    err_raw = np.sqrt(np.mean(np.sum((raw - truth[:, :3]) ** 2, axis=1)))
    assert err_est < 0.6 * err_raw, (err_est, err_raw)
    pd.read_csv(tmp_path / "plots.csv").drop(columns="range_rate_mps").to_csv(
        tmp_path / "no_rate.csv", index=False
    )
    code, _, err = cli(
        "filter", tmp_path / "no_rate.csv", "--config", tmp_path / "fit.toml", "--out",
        tmp_path / "e2.csv",
    )  # fmt: skip
    assert code == 0, err  # a fit with range-rate filters plots without it
    pd.read_csv(tmp_path / "plots.csv").drop(columns="elevation_deg").to_csv(
        tmp_path / "flat.csv", index=False
    )
    code, _, err = cli(
        "fit", tmp_path / "flat.csv", "--measurement", "radar3d", "--out", tmp_path / "f2.toml"
    )
    assert code == 1 and "elevation_deg" in err and len(err.strip().splitlines()) == 1, err


def test_fit_and_filter_a_coordinated_turn(tmp_path, cli):
    """`--model ct`: the turn PSD in the fit, the turn rate and its sigma in the estimates."""
    from tests.tuning.test_position_log import turning_drive

    t, _pos, _rate, meas = turning_drive(7)
    pd.DataFrame({"time_s": t, "east_m": meas[:, 0], "north_m": meas[:, 1]}).to_csv(
        tmp_path / "drive.csv", index=False
    )
    code, out, err = cli(
        "fit", tmp_path / "drive.csv", "--measurement", "position", "--model", "ct", "--out",
        tmp_path / "fit.toml",
    )  # fmt: skip
    assert code == 0, err
    assert "q_turn" in out and 'model = "ct"' in (tmp_path / "fit.toml").read_text()
    assert "hardly constrains" not in err  # the bends determine the turn PSD
    code, out, err = cli(
        "filter", tmp_path / "drive.csv", "--config", tmp_path / "fit.toml", "--out",
        tmp_path / "est.csv",
    )  # fmt: skip
    assert code == 0, err
    est = pd.read_csv(tmp_path / "est.csv")
    assert {"turn_rate_radps", "turn_rate_std_radps", "velocity_east_mps"} <= set(est.columns)
    bend = (est.time_s > 18) & (est.time_s <= 25)
    assert est.turn_rate_radps[bend].mean() > 0.1  # a left bend of pi / 20 rad/s
    code, _, err = cli(
        "fit", tmp_path / "drive.csv", "--measurement", "position", "--model", "turn",
        "--out", tmp_path / "f2.toml",
    )  # fmt: skip
    assert code != 0 and "cv, ca, ct" in err


def test_parameters_the_log_does_not_determine_are_pointed_out(tmp_path, cli):
    """A turn model fitted to a drive without bends (white acceleration): the turn PSD is
    left undetermined (its interval spans orders of magnitude, or there is none) and `fit`
    says so; the white acceleration's PSD and the noise it determines, and does not flag."""
    rng = np.random.default_rng(8)
    states = cv_states(rng, [[0.0, 12.0], [0.0, 0.5]], 0.1, 0.5, 600)
    meas = states[:, :, 0] + rng.normal(0.0, 1.5, (600, 2))
    pd.DataFrame({"time_s": 0.1 * np.arange(1, 601), "east_m": meas[:, 0],
                  "north_m": meas[:, 1]}).to_csv(tmp_path / "drive.csv", index=False)  # fmt: skip
    code, _, err = cli(
        "fit", tmp_path / "drive.csv", "--measurement", "position", "--model", "ct",
        "--out", tmp_path / "fit.toml",
    )  # fmt: skip
    assert code == 0, err
    notes = [line for line in err.splitlines() if line.startswith("note:")]
    notes = [line for line in notes if not line.startswith(FIRST_RUN_NOTE[:30])]  # cold cache
    assert len(notes) == 1 and notes[0].startswith("note: q_turn"), err


@pytest.mark.parametrize(
    ("model", "announced"), [("cv", None), ("ct", "about 1 min"), ("cv+ct", "about 2 min")]
)
def test_a_first_fit_says_it_compiles_only_the_kernel_its_model_runs(
    tmp_path, cli, monkeypatch, model, announced
):
    """Only the kernel the model runs is missing from the cache: the EKF's and the IMM's are
    announced with their own compile times; the Kalman filter's (seconds) is not."""
    from adaptrack import _progress
    from adaptrack.cli import fit as cli_fit
    from adaptrack.tuning.log_fit import compiled_kernel

    gnss_log(tmp_path / "log.csv")
    log = cli_fit._read(tmp_path / "log.csv", "gnss")
    missing = compiled_kernel(log, model)
    monkeypatch.setattr(_progress, "kernels_cached", lambda kernel, package: kernel != missing)

    def no_fit(*args):
        raise ValueError("not fitted in this test")

    monkeypatch.setattr(cli_fit, "fit_motion", no_fit)
    code, _, err = cli("fit", tmp_path / "log.csv", "--measurement", "gnss", "--model", model,
                       "--out", tmp_path / "fit.toml")  # fmt: skip
    assert code != 0 and "not fitted in this test" in err
    notes = [line for line in err.splitlines() if line.startswith(FIRST_RUN_NOTE[:30])]
    assert [announced in n for n in notes] == ([] if announced is None else [True]), err


def test_a_rough_likelihood_is_one_note_naming_its_parameters():
    from adaptrack.cli.fit import _fit_notes
    from adaptrack.tuning.likelihood import LikelihoodFit

    cov = np.diag([np.nan, 0.01])
    fit = LikelihoodFit(("q_turn", "r"), np.array([0.3, 2.0]), cov, 0.0, True, "", (), ("q_turn",))
    (note,) = _fit_notes(fit)
    assert note.startswith("the likelihood is rough in q_turn") and "no standard error" in note


def test_fit_and_filter_an_imm_of_cv_and_the_coordinated_turn(tmp_path, cli):
    """`--model cv+ct`: both models' PSDs and the switching rate by maximum likelihood; the
    estimates (filtered and IMM-smoothed) with each model's probability, the turn model's
    higher in the bends than on the straights; smoothing brings the positions nearer the
    truth than the fixes."""
    from tests.tuning.test_position_log import turning_drive

    t, pos, _rate, meas = turning_drive(9)
    pd.DataFrame({"time_s": t, "east_m": meas[:, 0], "north_m": meas[:, 1]}).to_csv(
        tmp_path / "drive.csv", index=False
    )
    code, out, err = cli(
        "fit", tmp_path / "drive.csv", "--measurement", "position", "--model", "cv+ct",
        "--out", tmp_path / "fit.toml",
    )  # fmt: skip
    assert code == 0, err
    for name in ("q_horizontal", "q_ct_horizontal", "q_turn", "switch_rate", "r_horizontal"):
        assert name in out
    for smooth in ((), ("--smooth",)):
        code, out, err = cli(
            "filter", tmp_path / "drive.csv", "--config", tmp_path / "fit.toml", *smooth,
            "--out", tmp_path / "est.csv",
        )  # fmt: skip
        assert code == 0, err
        assert "not checked" in out  # an IMM has no single innovation sequence
        est = pd.read_csv(tmp_path / "est.csv")
        p = est[["probability_cv", "probability_ct"]].to_numpy()
        assert np.allclose(p.sum(axis=1), 1.0)
        bends = ((t > 17) & (t <= 25)) | ((t > 42) & (t <= 50))
        straight = (t > 30) & (t <= 38)
        assert est.probability_ct[bends].mean() > est.probability_ct[straight].mean() + 0.2
    raw = np.sqrt(np.mean(np.sum((meas - pos) ** 2, axis=1)))
    smoothed = np.sqrt(np.mean(np.sum((est[["east_m", "north_m"]].to_numpy() - pos) ** 2, 1)))
    assert smoothed < 0.6 * raw, (smoothed, raw)


def test_filter_refit_online_writes_the_causal_refitted_estimates(tmp_path, cli):
    """The CLI's refitted run is MotionFit.filter_online's; its first estimates, before any
    refit, are the plain filter's."""
    from adaptrack._toml import load_toml
    from adaptrack.io.position_log import read_position_log
    from adaptrack.tuning.log_fit import fit_from_toml

    gnss_log(tmp_path / "log.csv", seed=8)
    code, _, err = cli(
        "fit", tmp_path / "log.csv", "--measurement", "gnss", "--out", tmp_path / "fit.toml"
    )
    assert code == 0, err
    code, out, err = cli(
        "filter", tmp_path / "log.csv", "--config", tmp_path / "fit.toml", "--refit-online",
        "--out", tmp_path / "est.csv",
    )  # fmt: skip
    assert code == 0, err
    assert "refitted 4 times" in out, out  # 4 parameters: after 80, 160, 320, 640 of 1200
    est = pd.read_csv(tmp_path / "est.csv")
    fit, _ = fit_from_toml(load_toml(tmp_path / "fit.toml"), "fit.toml")
    log = read_position_log(tmp_path / "log.csv", "gnss")
    mean, cov, online = fit.filter_online(log)
    np.testing.assert_allclose(est[["east_m", "north_m", "up_m"]].to_numpy(), mean[:, :3],
                               atol=1e-6)  # fmt: skip
    plain, _ = fit.filter(log)
    np.testing.assert_array_equal(mean[:80], plain[:80])
    assert not np.allclose(mean[80:], plain[80:])
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert len(online.fits) == 4


def test_filter_refit_online_refuses_smoothing(tmp_path, cli):
    gnss_log(tmp_path / "log.csv")
    (tmp_path / "c.toml").write_text("")
    code, _, err = cli(
        "filter", tmp_path / "log.csv", "--config", tmp_path / "c.toml", "--refit-online",
        "--smooth", "--out", tmp_path / "e.csv",
    )  # fmt: skip
    assert code == 2 and "does not take --smooth" in err
