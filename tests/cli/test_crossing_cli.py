"""`adaptrack simulate` and `adaptrack track` on files, including bad input."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.studies.selection import Candidate, SiteTuning, load_tuning

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
        "--ids",
        "truth",
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
    proc = run("track", str(path), "--site", "lx_default", "--out", str(out), "--ids", "truth")
    assert proc.returncode == 1
    assert proc.stderr.startswith("error: ")
    assert re.search(message, proc.stderr), proc.stderr
    assert proc.stderr.count("\n") == 1  # one line
    assert "Traceback" not in proc.stderr
    assert not out.exists()


EXAMPLE_SITE = Path(__file__).parents[2] / "examples" / "sites" / "rural_crossing.toml"


@pytest.fixture(scope="module")
def demo_on_a_site_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    proc = run(
        "demo", "--site", str(EXAMPLE_SITE), "--runs", "3", "--training-runs", "1",
        "--validation-runs", "2", "--workers", "1", "--seed", "5", "--out", str(out),
        "--scene-seconds", "30",
    )  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    verdict = summary["test"]["summary"][summary["deployed"]]["verdict"]
    assert proc.returncode == {"pass": 0, "fail": 4, "undecided": 5}[verdict], proc.stderr[-3000:]
    assert proc.stdout.count("VERDICT: rural_crossing ") == 1
    return out, proc.stdout


def test_demo_on_a_site_file_reports_the_family_and_the_validation_table(demo_on_a_site_file):
    out, stdout = demo_on_a_site_file
    summary = json.loads((out / "summary.json").read_text())
    deployed = summary["deployed"]
    assert "candidates on 2 validation runs" in stdout and deployed in stdout
    assert {c["family"] for c in summary["selection"]["candidates"]} == {
        "cv", "ca", "singer", "m1", "m2", "imm",
    }  # fmt: skip
    tuned = (out / "tuned.toml").read_text()
    assert 'family = "' in tuned and "[candidates.imm.parameters]" in tuned
    html = (out / "report.html").read_text()
    assert "rural_crossing" in html and "id='candidates'" in html and "north_east: 0.0-" in html
    # a site it was not developed on has its own mixed traffic in the report
    assert summary["mixed_traffic"]["stall_road"] in ("north_east", "south_west")
    assert "id='mixed-classes'" in html
    # the summary carries the site: the report re-renders for a site given as a file
    again = out / "again.html"
    proc = run("report", str(out / "summary.json"), "--out", str(again))
    assert proc.returncode == 0, proc.stderr
    assert "id='candidates'" in again.read_text() and "rural_crossing" in again.read_text()
    # and track uses the deployed estimator of tuned.toml
    assert load_tuning(out / "tuned.toml").winner.label == deployed


def test_tune_writes_the_selection(tmp_path):
    out = tmp_path / "tuned.toml"
    proc = run(
        "tune", str(EXAMPLE_SITE), "--out", str(out), "--families", "cv,ca",
        "--training-runs", "1", "--validation-runs", "2", "--workers", "1",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert {c.family for c in load_tuning(out).candidates} == {"cv", "ca"}
    bad = run("tune", str(EXAMPLE_SITE), "--out", str(out), "--families", "kalman")
    assert bad.returncode == 2 and "unknown ['kalman']" in bad.stderr


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("min_radial_speed_mps", "min_radial_speed"), "unknown key"),
        (lambda t: t.replace("decel_mps2 = 9.0", "decel_mps2 = 12.0"), "less than or equal to 10"),
        (lambda t: t.replace('road = "south_west"', 'road = "south"', 1), "unknown road 'south'"),
    ],
)
def test_demo_bad_site_file_is_one_line(tmp_path, edit, message):
    site = tmp_path / "site.toml"
    site.write_text(edit(EXAMPLE_SITE.read_text()))
    proc = run("demo", "--site", str(site), "--out", str(tmp_path / "out"), "--workers", "1")
    assert proc.returncode == 1 and proc.stderr.startswith("error: ")
    assert re.search(message, proc.stderr) and proc.stderr.count("\n") == 1, proc.stderr
    assert not (tmp_path / "out").exists()


def test_scene_simulate_then_track_with_the_controllers_warnings(tmp_path):
    """Raw detections of a mixed-traffic scene through the CLI, with the warning intervals."""
    det, truth, warn = tmp_path / "det.csv", tmp_path / "truth.csv", tmp_path / "warn.csv"
    proc = run(
        "simulate", "lx_default", "--scene", "--duration", "320", "--seed", "2",
        "--out", str(det), "--truth", str(truth), "--warnings", str(warn),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    intervals = pd.read_csv(warn)
    assert list(intervals.columns) == ["start_s", "end_s"]
    np.testing.assert_allclose(intervals.to_numpy(), [[292.0, 420.0]])  # 8 s of lights
    out = tmp_path / "tracks.csv"
    track = ("track", str(det), "--site", "lx_default", "--out", str(out), "--warnings")
    proc = run(*track, str(warn))
    assert proc.returncode == 0, proc.stderr
    events = pd.read_csv(tmp_path / "tracks.events.csv")
    assert list(events.columns) == ["time_s", "event", "track_id", "east_m", "north_m", "lead_s"]
    assert pd.read_csv(out)["track_id"].nunique() > 5
    # scored against the truth the simulation wrote: the tracks lie on the road users
    proc = run("score", str(out), "--truth", str(truth), "--site", "lx_default", "--json",
               str(tmp_path / "score.json"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    score = json.loads((tmp_path / "score.json").read_text())
    assert score["gospa_localisation_m2"] < 0.5 and len(score["classes"]) >= 2
    # a warnings file that is not one: a one-line error naming the row
    bad = tmp_path / "bad.csv"
    bad.write_text("start_s,end_s\n10,5\n")
    proc = run(*track, str(bad))
    assert proc.returncode != 0
    assert "row 1: start_s must be before end_s" in proc.stderr
    assert "Traceback" not in proc.stderr


def _hand_made_scene(tmp_path):
    """Two cars in the zone at 0, 0.5 and 1 s; one track 1 m east of the first, none of the
    second, and a static track (not a road user). Per epoch GOSPA^2 (c = 5 m, p = 2) is
    1 (localisation) + 12.5 (the missed car: c^2 / 2)."""
    times = [0.0, 0.5, 1.0]
    truth = pd.DataFrame(
        [(oid, "car", t, 0.0, y + 10.0 * t, 10.0, True)
         for t in times for oid, y in ((1, 10.0), (2, -40.0))],
        columns=["object_id", "vehicle_class", "time_s", "east_m", "north_m", "speed_mps",
                 "in_zone"],
    )  # fmt: skip
    tracks = pd.DataFrame(
        [(tid, t, x, y, s, 0.0, s, 20.0, status)
         for t in times for tid, x, y, s, status in ((7, 1.0, 10.0 + 10.0 * t, 10.0, "confirmed"),
                                                     (9, 30.0, 5.0, 0.0, "static"))],
        columns=["track_id", "time_s", "east_m", "north_m", "speed_mps", "east_speed_mps",
                 "north_speed_mps", "from_crossing_m", "status"],
    )  # fmt: skip
    truth.to_csv(tmp_path / "truth.csv", index=False)
    tracks.to_csv(tmp_path / "tracks.csv", index=False)
    return truth, tracks


def test_score_a_hand_made_scene_with_a_known_answer(tmp_path):
    _hand_made_scene(tmp_path)
    out = tmp_path / "score.json"
    proc = run("score", str(tmp_path / "tracks.csv"), "--truth", str(tmp_path / "truth.csv"),
               "--site", "lx_default", "--json", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    score = json.loads(out.read_text())
    assert score["epochs"] == 3
    assert score["gospa_mean_m"] == pytest.approx(np.sqrt(13.5))
    assert score["gospa_localisation_m2"] == pytest.approx(1.0)
    assert score["gospa_missed_m2"] == pytest.approx(12.5)
    assert score["gospa_false_m2"] == 0.0  # the static track is no road user
    assert score["id_switches"] == 0
    (car,) = score["classes"]
    assert car["class"] == "car" and car["vehicles"] == 1 and car["epochs"] == 3
    assert car["position_rms_m"] == pytest.approx(1.0) and car["coverage"] == pytest.approx(0.5)
    assert "identity switches 0" in proc.stdout
    assert score["false_tracks"] == 0  # the static track is not reported
    assert score["confirm_delays_s"] == [0.0] and score["never_confirmed"] == 1


def test_false_tracks_and_the_time_to_confirm():
    """A car in the zone from 0 s, tracked from 1 s; a confirmed track 50 m from it at 1 and
    1.5 s: one false track, a time to confirm of 1 s. A tentative track (a new one on an
    established body) is not a reported road user."""
    from adaptrack.crossing.studies.scene_metrics import TRACK_COLUMNS, TRUTH_COLUMNS, score_scene

    times = [0.0, 0.5, 1.0, 1.5]
    truth = pd.DataFrame([(1, "car", t, 0.0, 10.0 + 10.0 * t, 10.0, True) for t in times],
                         columns=TRUTH_COLUMNS)  # fmt: skip
    tracks = pd.DataFrame(
        [(tid, t, x, 10.0 + 10.0 * t, 10.0, 0.0, 10.0, 20.0, "confirmed")
         for t in times[2:] for tid, x in ((7, 0.5), (11, 50.0))],
        columns=TRACK_COLUMNS,
    )  # fmt: skip
    score = score_scene(truth, tracks, 200.0)
    assert score.false_tracks == 1 and score.never_confirmed == 0
    tentative = tracks.assign(track_id=13, east_m=-50.0, status="tentative")
    both = score_scene(truth, pd.concat([tracks, tentative]), 200.0)
    assert both.false_tracks == 1 and both.gospa_false == score.gospa_false
    np.testing.assert_allclose(score.confirm_delays_s, [1.0])
    assert score.hours == pytest.approx(1.5 / 3600)


@pytest.mark.parametrize(
    ("which", "edit", "message"),
    [
        ("truth", lambda f: f.drop(columns="in_zone"), "missing column(s) ['in_zone']"),
        ("truth", lambda f: f.assign(east_m=f.east_m.where(f.index != 2, np.nan)),
         "row 3, column 'east_m'"),
        ("truth", lambda f: f.assign(in_zone=f.in_zone.astype(object).where(f.index != 1, "maybe")),
         "row 2, column 'in_zone': 'maybe' is not true or false"),
        ("tracks", lambda f: f.drop(columns="status"), "missing column(s) ['status']"),
    ],
)  # fmt: skip
def test_score_bad_input_is_one_line_naming_the_place(tmp_path, which, edit, message):
    frames = dict(zip(("truth", "tracks"), _hand_made_scene(tmp_path), strict=True))
    edit(frames[which]).to_csv(tmp_path / f"{which}.csv", index=False)
    proc = run("score", str(tmp_path / "tracks.csv"), "--truth", str(tmp_path / "truth.csv"),
               "--site", "lx_default")  # fmt: skip
    assert proc.returncode == 1
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_score_times_the_stopped_between_the_barriers_event_of_a_stall(tmp_path):
    """A car stalled on the crossing for 60 s of a 200 s scene (the Python API writes the
    files as `adaptrack simulate --scene --truth` does): `track` raises the event, and
    `score --events` finds the true stop from the truth file alone (as the truth in memory
    does), detected within 1 s, no false event."""
    from adaptrack.crossing.simulation.scene import Stall, scene_spec, simulate_scene
    from adaptrack.crossing.site.model import load_site
    from adaptrack.crossing.studies.scene_metrics import HAZARD_COLUMNS, TRUTH_COLUMNS, hazard_stops

    site = load_site("lx_default")
    spec = scene_spec(site, duration_s=200.0,
                      stalls=(Stall(sorted(site.roads)[-1], 60.0, 0.0, 60.0),))  # fmt: skip
    rec = simulate_scene(site, spec, 1222)
    rec.detections.to_csv(tmp_path / "det.csv", index=False)
    rec.truth.table[TRUTH_COLUMNS + HAZARD_COLUMNS].to_csv(tmp_path / "truth.csv", index=False)
    proc = run("track", str(tmp_path / "det.csv"), "--site", "lx_default", "--out",
               str(tmp_path / "tracks.csv"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    proc = run("score", str(tmp_path / "tracks.csv"), "--truth", str(tmp_path / "truth.csv"),
               "--site", "lx_default", "--events", str(tmp_path / "tracks.events.csv"),
               "--json", str(tmp_path / "score.json"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    stops = json.loads((tmp_path / "score.json").read_text())["stopped_between_barriers"]
    assert stops["true_stops"] == len(hazard_stops(rec.truth, site.barrier_m)) >= 1
    assert stops["detected"] == stops["true_stops"] and stops["false_events"] == 0
    assert max(stops["delays_s"]) < 1.0
    assert "truly stood there" in proc.stdout


def test_score_events_need_the_truth_s_distance_to_the_crossing(tmp_path):
    _hand_made_scene(tmp_path)  # its truth has no to_crossing_m
    (tmp_path / "events.csv").write_text("time_s,event,track_id,east_m,north_m,lead_s\n")
    proc = run("score", str(tmp_path / "tracks.csv"), "--truth", str(tmp_path / "truth.csv"),
               "--site", "lx_default", "--events", str(tmp_path / "events.csv"))  # fmt: skip
    assert proc.returncode == 1
    assert "missing column(s) ['to_crossing_m']" in proc.stderr, proc.stderr


def test_simulate_recorded_motion_then_track(tmp_path):
    """An INTERACTION-layout file replayed through each radar kind, then tracked end to end."""
    t_ms = 100 * np.arange(1, 121)
    motion = tmp_path / "tracks.csv"
    pd.DataFrame({
        "track_id": 5, "frame_id": np.arange(1, 121), "timestamp_ms": t_ms, "agent_type": "car",
        "x": 501.75, "y": 630.0 - 11.0 * t_ms / 1000.0, "vx": 0.0, "vy": -11.0,
        "psi_rad": -np.pi / 2, "length": 4.5, "width": 1.8,
    }).to_csv(motion, index=False)  # fmt: skip
    for kind in ("object", "cluster", "cloud"):
        det, truth = tmp_path / f"{kind}.csv", tmp_path / f"{kind}.truth.csv"
        proc = run("simulate", "lx_default", "--motion", str(motion), "--origin", "500,500",
                   "--radar-kind", kind, "--out", str(det), "--truth", str(truth))  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        frame = pd.read_csv(det)
        assert ("object_id" in frame.columns) == (kind == "object")
        tr = pd.read_csv(truth)
        assert tr["north_m"].max() < 130.0 and tr["east_m"].to_numpy() == pytest.approx(1.75)
        proc = run("track", str(det), "--site", "lx_default", "--out", str(tmp_path / "t.csv"))
        assert proc.returncode == 0, proc.stderr
    proc = run("simulate", "lx_default", "--motion", str(motion), "--radar-kind", "lidar",
               "--out", str(det))  # fmt: skip
    assert proc.returncode != 0 and "--radar-kind must be one of" in proc.stderr
    proc = run("simulate", "lx_default", "--motion", str(motion), "--origin", "5",
               "--out", str(det))  # fmt: skip
    assert proc.returncode != 0 and "--origin takes two numbers" in proc.stderr
