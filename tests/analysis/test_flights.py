"""Real-flight navigation evaluation and the `smooth` / `evaluate flights` commands."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from adaptrack.analysis.flights import evaluate_flight, simulate_flight_measurements
from adaptrack.io import DataFormatError, read_flight_csv

DATA = Path(__file__).parents[1] / "regression" / "data"
REGA = DATA / "air_1hz_REGA1_helicopter_zurich_20190524.csv"
AFR = DATA / "air_1hz_AFR26TR_arrival_CDG_20211007_first300.csv"


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "adaptrack", *args],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "COLUMNS": "200"},
    )


def test_triple_node_lsq_beats_position_only_on_a_real_flight():
    # REGA1 has exact time tags (truth error ~3 m); AFR26TR's 1 s snapshot tags put a ~50 m
    # along-track error floor under every method, which hides the differences
    for seed in (0, 1, 2):
        rows = {r.method: r for r in evaluate_flight(read_flight_csv(REGA), seed=seed)}
        assert set(rows) == {"lsq_triple", "lsq_position", "kf", "rts"}
        assert rows["lsq_triple"].position_rmse_m <= rows["lsq_position"].position_rmse_m
        assert rows["lsq_triple"].velocity_rmse_mps <= rows["lsq_position"].velocity_rmse_mps
        assert rows["rts"].position_rmse_m <= rows["kf"].position_rmse_m
        for r in rows.values():
            assert 0 < r.position_rmse_m < 100 and r.n_scored > 60


def write_measurements(tmp_path):
    m = simulate_flight_measurements(read_flight_csv(REGA), seed=1)
    from adaptrack.coords import enu_to_polar

    polar = enu_to_polar(m.nodes.radar_position)
    radar = pd.DataFrame(
        {
            "time_s": m.nodes.radar_times,
            "range_m": polar[:, 0],
            "azimuth_deg": np.degrees(polar[:, 1]),
            "elevation_deg": np.degrees(polar[:, 2]),
        }
    )
    vel = pd.DataFrame(
        {
            "time_s": m.nodes.velocity_times,
            "velocity_east_mps": m.nodes.velocity[:, 0],
            "velocity_north_mps": m.nodes.velocity[:, 1],
            "velocity_up_mps": m.nodes.velocity[:, 2],
        }
    )
    frame = pd.concat([radar, vel]).sort_values("time_s", kind="stable")
    path = tmp_path / "meas.csv"
    frame.to_csv(path, index=False)
    site = m.site
    return path, f"{np.degrees(site[0])},{np.degrees(site[1])},{site[2]}"


@pytest.mark.parametrize("method", ["lsq", "rts"])
def test_smooth_cli_writes_enu_and_ecef_with_covariance(tmp_path, method):
    path, site = write_measurements(tmp_path)
    out = tmp_path / "est.csv"
    proc = run("smooth", str(path), "--site", site, "--method", method, "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    est = pd.read_csv(out)
    for col in (
        "time_s",
        "east_m",
        "velocity_up_mps",
        "ecef_x_m",
        "ecef_vz_mps",
        "east_std_m",
        "ecef_x_std_m",
        "cov_e_n",
    ):
        assert col in est.columns
    assert np.all(est["east_std_m"].dropna() > 0)
    # ECEF positions are consistent with ENU (site at the ellipsoid): |ecef| ~ Earth radius
    r = np.linalg.norm(est[["ecef_x_m", "ecef_y_m", "ecef_z_m"]].dropna().to_numpy(), axis=1)
    assert np.all((r > 6.3e6) & (r < 6.4e6))


def test_smooth_cli_bad_input(tmp_path):
    path, site = write_measurements(tmp_path)
    frame = pd.read_csv(path)
    bad = frame.rename(columns={"azimuth_deg": "azimuth_rad"})
    bad.to_csv(tmp_path / "rad.csv", index=False)
    proc = run("smooth", str(tmp_path / "rad.csv"), "--site", site, "--out", str(tmp_path / "o"))
    assert proc.returncode == 1
    assert "out of range for radians" in proc.stderr and "degrees given?" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()
    frame.assign(azimuth_rad=0.1).to_csv(tmp_path / "mixed.csv", index=False)
    proc = run("smooth", str(tmp_path / "mixed.csv"), "--site", site, "--out", str(tmp_path / "o"))
    assert proc.returncode == 1 and "mixed units" in proc.stderr
    frame.drop(columns=["range_m"]).to_csv(tmp_path / "norange.csv", index=False)
    proc = run(
        "smooth", str(tmp_path / "norange.csv"), "--site", site, "--out", str(tmp_path / "o")
    )
    assert proc.returncode == 1 and "missing column 'range_m'" in proc.stderr
    proc = run("smooth", str(path), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2  # missing --site: usage error
    proc = run(
        "smooth",
        str(path),
        "--site",
        site,
        "--degree",
        "9",
        "--window",
        "5",
        "--out",
        str(tmp_path / "o"),
    )
    assert proc.returncode == 0  # windows with too few nodes give NaN rows, reported
    assert pd.read_csv(tmp_path / "o")["east_m"].isna().any()


def test_evaluate_flights_cli(tmp_path):
    out = tmp_path / "fl.json"
    proc = run("evaluate", "flights", str(REGA), str(AFR), "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(out.read_text())["rows"]
    assert {r["method"] for r in rows} == {"lsq_triple", "lsq_position", "kf", "rts"}
    assert {r["flight"] for r in rows} == {REGA.stem, AFR.stem}
    assert all({"position_rmse_m", "velocity_rmse_mps"} <= set(r) for r in rows)
    for path in (REGA, AFR):  # a table each, titled with the flight's whole name
        assert f"{path.stem}: navigation smoothing" in proc.stdout
    proc = run("evaluate", "flights")
    assert proc.returncode == 1 and "needs at least one flight CSV" in proc.stderr


def test_flight_reader_errors(tmp_path):
    frame = pd.read_csv(REGA)
    frame.drop(columns=["track_deg"]).to_csv(tmp_path / "a.csv", index=False)
    with pytest.raises(DataFormatError, match=r"missing column\(s\) \['track_deg'\]"):
        read_flight_csv(tmp_path / "a.csv")
    f2 = frame.copy()
    f2.loc[5, "t_s"] = f2.loc[4, "t_s"]
    f2.to_csv(tmp_path / "b.csv", index=False)
    with pytest.raises(DataFormatError, match="row 6, column 't_s': duplicate time"):
        read_flight_csv(tmp_path / "b.csv")
    f3 = frame.copy()
    f3["lat_deg"] = np.radians(f3["lat_deg"]) * 1000
    f3.to_csv(tmp_path / "c.csv", index=False)
    with pytest.raises(DataFormatError, match="latitude/longitude out of range"):
        read_flight_csv(tmp_path / "c.csv")


def test_unknown_columns_of_a_measurement_file_are_reported(tmp_path):
    from adaptrack.io.navigation import read_navigation_measurements
    from adaptrack.io.tables import DataFormatError

    path, _ = write_measurements(tmp_path)
    frame = pd.read_csv(path)
    stds = {"range_std_m": 30.0, "azimuth_std_rad": 1e-3, "elevation_std_rad": 1e-3,
            "velocity_std_mps": 1.0}  # fmt: skip
    read_navigation_measurements(path, **stds)  # the file as written is read
    frame.assign(snr_db=1.0).to_csv(tmp_path / "snr.csv", index=False)
    with pytest.raises(DataFormatError, match=r"unknown column\(s\) \['snr_db'\]"):
        read_navigation_measurements(tmp_path / "snr.csv", **stds)
    frame.assign(range_rate_mps=1.0).to_csv(tmp_path / "rr.csv", index=False)
    with pytest.raises(DataFormatError, match="read as a record"):
        read_navigation_measurements(tmp_path / "rr.csv", **stds)


def write_radar_record(tmp_path, seed=2):
    """The helicopter seen by a radar that measures range-rate (0.2 m/s), every 1 s: the
    range-rate from the recorded velocity projected on the line of sight."""
    m = simulate_flight_measurements(read_flight_csv(REGA), seed=seed, scan_s=1.0)
    rng = np.random.default_rng(seed)
    pos, vel = m.truth_position[m.radar_index], m.truth_velocity[m.radar_index]
    ok = np.all(np.isfinite(vel), axis=1)
    pos, vel, t = pos[ok], vel[ok], m.truth_times[m.radar_index][ok]
    r = np.linalg.norm(pos, axis=1)
    frame = pd.DataFrame({
        "time_s": t,
        "range_m": r + rng.normal(0, 30.0, r.size),
        "azimuth_deg": np.degrees(np.arctan2(pos[:, 0], pos[:, 1]) + rng.normal(0, 1.4e-3, r.size)),
        "elevation_deg": np.degrees(np.arctan2(pos[:, 2], np.hypot(pos[:, 0], pos[:, 1]))
                                    + rng.normal(0, 1.7e-3, r.size)),
        "range_rate_mps": np.einsum("ij,ij->i", pos, vel) / r + rng.normal(0, 0.2, r.size),
    })  # fmt: skip
    frame.to_csv(tmp_path / "record.csv", index=False)
    site = m.site
    return (
        tmp_path / "record.csv",
        f"{np.degrees(site[0])},{np.degrees(site[1])},{site[2]}",
        pos,
        vel,
    )


@pytest.mark.parametrize("method", ["lsq", "rts"])
def test_smooth_uses_a_measured_range_rate(tmp_path, method):
    """With range_rate_mps the radar's record is smoothed whole (triple nodes or the EKF):
    velocity closer to the truth than the same samples without their range-rates.

    Sliding fits (lsq) each at its best window of 10, 20 and 30 s (measured on this record):
    triple nodes carry so much more per window that 10 s is best (velocity 2.5 m/s; 20 s: 3.8,
    the quadratic no longer follows the turns); position nodes alone need 20 s (3.6 m/s).
    """
    path, site, _, vel = write_radar_record(tmp_path)
    pd.read_csv(path).drop(columns="range_rate_mps").to_csv(tmp_path / "plain.csv", index=False)
    errors = {}
    for name in ("record", "plain"):
        out = tmp_path / f"{name}_est.csv"
        window = "10" if name == "record" else "20"
        proc = run("smooth", str(tmp_path / f"{name}.csv"), "--site", site, "--method", method,
                   "--range-rate-std-mps", "0.2", "--azimuth-std-deg", "0.08",
                   "--elevation-std-deg", "0.1", "--window", window, "--out", str(out))  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        est = pd.read_csv(out)
        ok = np.isfinite(est["east_m"]).to_numpy()
        assert ok[5:-5].all()
        v = est[["velocity_east_mps", "velocity_north_mps", "velocity_up_mps"]].to_numpy()
        errors[name] = np.sqrt(np.mean(np.sum((v[ok] - vel[ok]) ** 2, axis=1)))
    assert "range-rate used" in proc.stdout or name == "plain"
    assert errors["record"] < 0.9 * errors["plain"], errors


def straight_flight(length_km=500.0, speed=200.0, alt=9000.0):
    """A synthetic airliner on a straight line (east in the tangent plane at its start) at
    constant speed; each fix's velocity in its own east-north-up frame, by pymap3d."""
    import pymap3d

    from adaptrack.io.tables import Flight

    t = np.arange(0.0, length_km * 1e3 / speed, 1.0)
    lat, lon, h = pymap3d.enu2geodetic(speed * t, 0.0 * t, alt + 0 * t, 45.0, 2.0, 0.0)
    ecef_v = pymap3d.enu2uvw(speed, 0.0, 0.0, 45.0, 2.0)
    vel = np.stack(pymap3d.uvw2enu(*ecef_v, lat, lon), -1)
    return Flight("straight", t, np.radians(lat), np.radians(lon), h, vel)


def test_radars_cover_a_long_flight_and_every_scan_is_scored():
    """500 km: several radars, every fix within 111 km of its stretch's radar, handovers only
    when leaving coverage, and every scan scored by every method."""
    from adaptrack.analysis.flights import (
        MAX_RANGE_M,
        radar_sites,
        radar_stretches,
    )
    from adaptrack.coords.geodetic import ecef_to_enu, geodetic_to_ecef

    fl = straight_flight()
    sites = radar_sites(fl)
    assert 2 <= len(sites) <= 5
    stretches = radar_stretches(fl, sites)
    assert np.concatenate([rows for _, rows in stretches]).tolist() == list(range(fl.times.size))
    ecef = geodetic_to_ecef(fl.lat, fl.lon, fl.alt)
    for site, rows in stretches:
        local = ecef_to_enu(ecef[rows], *site)
        assert np.linalg.norm(local, axis=1).max() <= MAX_RANGE_M
        assert np.hypot(local[:, 0], local[:, 1]).min() > 4000.0  # never right overhead
    rows = evaluate_flight(fl, seed=3, scans_s=(4.8,))
    for r in rows:
        assert r.n_scored >= r.n_scans - 2 and r.n_radars == len(stretches), r
        assert r.position_rmse_m < 150.0, r


def test_velocity_reports_carry_their_quantisation_and_lag():
    from adaptrack.analysis.flights import (
        GROUNDSPEED_STEP_MPS,
        VELOCITY_LAG_STD_S,
        VELOCITY_STD_MPS,
        velocity_report_cov,
    )

    t = np.arange(10.0)
    steady = np.tile([0.0, 100.0, 0.0], (10, 1))  # due north
    cov = velocity_report_cov(steady, t)
    assert cov[5, 1, 1] == pytest.approx(VELOCITY_STD_MPS**2 + GROUNDSPEED_STEP_MPS**2 / 12)
    assert cov[5, 0, 0] == pytest.approx(VELOCITY_STD_MPS**2)
    turning = steady + np.c_[3.0 * t, 0 * t, 0 * t]  # 3 m/s^2 east
    extra = velocity_report_cov(turning, t)[5, 0, 0] - VELOCITY_STD_MPS**2
    assert extra == pytest.approx((VELOCITY_LAG_STD_S * 3.0) ** 2, rel=1e-3)


def test_a_radar_record_with_bad_rows_is_named(tmp_path):
    from adaptrack.io.navigation import read_radar_record
    from adaptrack.io.tables import DataFormatError

    path, _, _, _ = write_radar_record(tmp_path)
    frame = pd.read_csv(path)
    cases = [
        (frame.drop(columns="range_rate_mps"), "range_rate_mps"),
        (frame.assign(velocity_east_mps=1.0, velocity_north_mps=1.0, velocity_up_mps=0.0),
         "velocity rows of a second source"),
        (frame.assign(range_m=frame.range_m.where(frame.index != 4, np.nan)),
         "row 5, column 'range_m'"),
        (frame.iloc[[0, 2, 1, *range(3, len(frame))]], "row 3, column 'time_s': unsorted"),
        (frame.assign(range_rate_mps=frame.range_rate_mps.where(frame.index != 6, np.inf)),
         "row 7"),
        (frame.iloc[:1], "at least 2 plots"),
    ]  # fmt: skip
    for bad, message in cases:
        bad.to_csv(tmp_path / "bad.csv", index=False)
        with pytest.raises(DataFormatError, match=message):
            read_radar_record(tmp_path / "bad.csv")
