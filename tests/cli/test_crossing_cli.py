"""`adaptrack simulate` and `adaptrack track` on files, including bad input."""

import os
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.selection import Candidate, SiteTuning

IMM_PARAMS = {"accel_psd": 0.1, "jerk_psd": 3.0, "sojourn_s": 10.0}


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "adaptrack", *args],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "COLUMNS": "200"},
    )


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    proc = run(
        "simulate",
        "lx_default",
        "--out",
        str(d / "meas.csv"),
        "--truth",
        str(d / "truth.csv"),
        "--seed",
        "4",
    )
    assert proc.returncode == 0, proc.stderr
    return d


def test_simulate_then_track_meets_the_requirement(simulated):
    meas = pd.read_csv(simulated / "meas.csv")
    assert {"object_id", "radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps"} <= set(
        meas.columns
    )
    one = meas[meas.case == "B/pass_60"]
    obj = one.object_id.unique()[:2]
    sub = meas[meas.object_id.isin(obj)]
    sub.to_csv(simulated / "two.csv", index=False)
    tuned = simulated / "tuned.toml"
    imm = Candidate("imm", "road IMM (CV + CA)", IMM_PARAMS, 0.4, 10, 0.41, 0.5, "car / x")
    cv = Candidate("cv", "road EKF (CV)", {"accel_psd": 0.5}, 0.4, 10, 0.42, 0.5, "car / x")
    tuned.write_text(SiteTuning("lx_default", "tail", 0, 1, 2, (imm, cv), "imm", "test").to_toml())
    proc = run(
        "track",
        str(simulated / "two.csv"),
        "--out",
        str(simulated / "est.csv"),
        "--config",
        str(tuned),
    )
    assert proc.returncode == 0, proc.stderr
    est = pd.read_csv(simulated / "est.csv")
    truth = pd.read_csv(simulated / "truth.csv")
    for oid in obj:
        e = est[est.object_id == oid]
        tr = truth[truth.object_id == oid]
        # truth at the detection times (jitter <= 5 ms: interpolate the truth)
        east = np.interp(e.time_s, tr.time_s, tr.east_m)
        north = np.interp(e.time_s, tr.time_s, tr.north_m)
        zone = (np.interp(e.time_s, tr.time_s, tr.along_road_m) <= 150) & (
            e.time_s > e.time_s.iloc[0] + 1.0
        )
        err = np.hypot(e.east_m - east, e.north_m - north)[zone]
        assert np.sqrt(np.mean(err**2)) < 0.7


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda f: f.drop(columns=["range_m"]), r"missing column\(s\) \['range_m'\]"),
        (lambda f: f.assign(azimuth_rad=f.azimuth_rad * 180), "out of range for radians"),
        (lambda f: f.assign(radar="radar_Z"), "unknown radar 'radar_Z'"),
        (
            lambda f: f.assign(range_m=f.range_m.where(f.index != 3, np.nan)),
            "row 4, column 'range_m': empty value",
        ),
        (lambda f: f.assign(time_s=f.time_s[::-1].to_numpy()), "not strictly increasing"),
        (lambda f: f.assign(vehicle_class="tank"), "unknown class 'tank'"),
        (lambda f: f.iloc[:0], "no detections"),
    ],
)
def test_track_bad_input(simulated, change, message):
    meas = pd.read_csv(simulated / "meas.csv")
    bad = change(meas[meas.object_id == 1].reset_index(drop=True))
    path = simulated / "bad.csv"
    bad.to_csv(path, index=False)
    out = simulated / "never.csv"
    proc = run("track", str(path), "--out", str(out))
    assert proc.returncode == 1
    assert proc.stderr.startswith("error: ")
    assert re.search(message, proc.stderr), proc.stderr
    assert proc.stderr.count("\n") == 1  # one line
    assert "Traceback" not in proc.stderr
    assert not out.exists()
