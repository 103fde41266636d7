"""`adaptrack fit` and `adaptrack filter` on a GNSS log, and their errors."""

import numpy as np
import pandas as pd
import pytest

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
