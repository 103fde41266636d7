"""A radar plot list: read, fit by maximum likelihood without truth, filter."""

import numpy as np
import pandas as pd
import pymap3d
import pytest

from adaptrack.io.radar_plots import read_radar_log
from adaptrack.tuning.log_fit import fit_motion
from tests.cv_truth import cv_states

Q_H, Q_V = 0.8, 0.05  # white-acceleration PSDs of the truth [m^2/s^3]
SIGMAS = {"range_m": 8.0, "azimuth_deg": 0.06, "elevation_deg": 0.08, "range_rate_mps": 0.4}


def radar_plot_list(path, seed=1, n=300, dt=1.0):
    """A 3-D CV target seen by a radar at the origin: plots by pymap3d (azimuth, elevation,
    slant range) and the range-rate as the range's derivative along the truth's velocity;
    Gaussian noise of SIGMAS. Returns the truth (n, 6): east, north, up, velocities."""
    rng = np.random.default_rng(seed)
    start = [[4000.0, -40.0], [9000.0, -60.0], [800.0, 2.0]]
    h = cv_states(rng, [row for row in start[:2]], dt, Q_H, n)
    v = cv_states(rng, [start[2]], dt, Q_V, n)
    pos = np.c_[h[:, 0, 0], h[:, 1, 0], v[:, 0, 0]]
    vel = np.c_[h[:, 0, 1], h[:, 1, 1], v[:, 0, 1]]
    az, el, rng_m = pymap3d.enu2aer(*pos.T, deg=True)
    rate = np.einsum("ij,ij->i", pos, vel) / rng_m
    frame = pd.DataFrame(
        {"time_s": dt * np.arange(1, n + 1), "range_m": rng_m, "azimuth_deg": az,
         "elevation_deg": el, "range_rate_mps": rate, "snr_db": 20.0}
    )  # fmt: skip
    for col, sigma in SIGMAS.items():
        frame[col] += rng.normal(0, sigma, n)
    frame.to_csv(path, index=False)
    return np.c_[pos, vel]


@pytest.mark.statistical
def test_fit_recovers_the_noise_and_motion_of_a_3d_radar_log(tmp_path):
    """Every parameter within 3.3 standard errors of the truth (8 at once: < 1 % false
    failure if the standard errors are right)."""
    radar_plot_list(tmp_path / "plots.csv")
    log = read_radar_log(tmp_path / "plots.csv", "radar3d")
    assert log.components == ("range", "azimuth", "elevation", "range_rate")
    assert log.unused == ("snr_db",)
    fit = fit_motion(log, "cv")
    truth = {
        "q_horizontal": Q_H, "q_vertical": Q_V, "r_range": SIGMAS["range_m"] ** 2,
        "r_azimuth": np.radians(SIGMAS["azimuth_deg"]) ** 2,
        "r_elevation": np.radians(SIGMAS["elevation_deg"]) ** 2,
        "r_range_rate": SIGMAS["range_rate_mps"] ** 2,
    }  # fmt: skip
    assert set(fit.fit.names) == set(truth)
    for name, value in truth.items():
        z = (np.log(fit.fit.value(name)) - np.log(value)) / (
            fit.fit.std_error(name) / fit.fit.value(name)
        )
        assert abs(z) < 3.3, (name, fit.fit.value(name), value, fit.fit.std_error(name))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.iloc[:0], "at least 2 plots"),
        (lambda f: f.assign(range_m=f.range_m.where(f.index != 3, 1e300)),
         r"row 4, column 'range_m': 1e\+300 m is not a radar range"),
        (lambda f: f.assign(range_m=f.range_m.where(f.index != 5, -1.0)),
         "row 6, column 'range_m'"),
        (lambda f: f.assign(range_rate_mps=f.range_rate_mps.where(f.index != 2, 3e8)),
         "row 3, column 'range_rate_mps'"),
    ],
)  # fmt: skip
def test_implausible_plot_lists_are_named(tmp_path, edit, message):
    from adaptrack.io.tables import DataFormatError

    radar_plot_list(tmp_path / "plots.csv", n=20)
    edit(pd.read_csv(tmp_path / "plots.csv")).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(DataFormatError, match=message):
        read_radar_log(tmp_path / "bad.csv", "radar3d")
