"""The live tracker without sockets: same numbers as offline, every detection accounted for."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.measurements_io import read_scene_detections, read_warnings
from adaptrack.crossing.scene.tracker import load_scene_config, track_scene
from adaptrack.service.engine import LiveTracker, load_state

from .records import live_records, tracks_of


def assert_accounted(live):
    s = live.stats()
    assert s["received"] == s["used"] + s["rejected"] + s["pending"]
    assert live.tracker.log.rejected_outside_view == live.rejected["outside_view"]


@pytest.fixture(scope="module")
def offline(scene_files):
    det = read_scene_detections(scene_files.detections, scene_files.site)
    warn = read_warnings(scene_files.warnings)
    return track_scene(scene_files.site, det, warnings=warn)


def test_live_tracks_and_events_equal_offline_exactly(scene_files, offline):
    live = LiveTracker(scene_files.site, window_s=0.2, warnings=read_warnings(scene_files.warnings))
    recs = live_records(live, scene_files.detections.read_text().splitlines())
    tracks, events, log = offline
    tracks = tracks.astype({"status": str})  # categorical offline, strings in JSON
    pd.testing.assert_frame_equal(tracks_of(recs), tracks, check_exact=True)
    got = pd.DataFrame([r for r in recs if r["type"] == "event"]).drop(columns="type")
    pd.testing.assert_frame_equal(got.fillna(np.nan), events, check_exact=True)  # null: NaN
    assert len(events) >= 1  # the scene's closure gives something to compare
    assert live.used == log.updated + log.opened + log.joined_new + log.off_road
    assert_accounted(live)
    assert live.stats()["pending"] == 0


def test_bad_lines_become_rejections_and_the_tracks_are_unchanged(scene_files, offline):
    lines = scene_files.lines
    junk = [
        ("garbage \x00", "malformed"),
        ("radar_Z,1.0,20,0.1,0", "unknown_radar"),
        ("radar_A,nan,20,0.1,0", "not_finite"),
        ('{"radar": "radar_A"}', "malformed"),
    ]
    mixed = list(lines)
    for k, (text, _) in enumerate(junk):
        mixed.insert(100 + 500 * k, text)
    stale = lines[50].split(",")
    mixed.insert(3000, ",".join([stale[0], str(float(stale[1]) - 5.0), *stale[2:]]))  # clock back
    live = LiveTracker(scene_files.site, warnings=read_warnings(scene_files.warnings))
    recs = live_records(live, mixed)
    expected = offline[0].astype({"status": str})  # categorical offline, strings in JSON
    pd.testing.assert_frame_equal(tracks_of(recs), expected, check_exact=True)
    rejections = [r for r in recs if r["type"] == "rejection"]
    reasons = [r["reason"] for r in rejections if r["reason"] != "outside_view"]
    assert reasons == [reason for _, reason in junk] + ["late"]
    late = next(r for r in rejections if r["reason"] == "late")
    assert "processed already" in late["detail"] and late["source"] == "test"
    assert live.received == len(lines) + len(junk) + 1
    assert live.rejected["late"] == 1
    assert_accounted(live)


def test_a_snapshot_resumes_to_the_same_numbers(scene_files, tmp_path):
    lines = scene_files.lines
    warn = read_warnings(scene_files.warnings)
    whole = LiveTracker(scene_files.site, warnings=warn)
    expected = live_records(whole, lines)
    first = LiveTracker(scene_files.site, warnings=warn)
    cut = len(lines) // 2
    part = []
    for line in lines[:cut]:
        part += [json.loads(x) for chunk in first.feed(line) for x in chunk.splitlines()]
    first.save(tmp_path / "state.pkl")
    resumed = load_state(tmp_path / "state.pkl", scene_files.site)
    assert resumed.received == cut and resumed.buffer.pending == first.buffer.pending > 0
    rest = live_records(resumed, lines[cut:])
    pd.testing.assert_frame_equal(tracks_of(part + rest), tracks_of(expected), check_exact=True)
    assert not (tmp_path / "state.pkl.tmp").exists()


def test_bad_state_files_are_one_line_errors(scene_files, tmp_path):
    junk = tmp_path / "junk.pkl"
    junk.write_bytes(b"not a pickle")
    with pytest.raises(ValueError, match="not a state snapshot"):
        load_state(junk, scene_files.site)
    other = LiveTracker(scene_files.site)
    other.site = dataclasses.replace(other.site, name="elsewhere")
    other.save(tmp_path / "other.pkl")
    with pytest.raises(ValueError, match="snapshot of site 'elsewhere', not 'lx_default'"):
        load_state(tmp_path / "other.pkl", scene_files.site)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[scene_tracker]\naccel_psd = 'fast'\n", "'accel_psd': expected a float"),
        ("[scene_tracker]\nacel_psd = 3.0\n", r"unknown SceneTrackerConfig setting\(s\) \['acel"),
        ("[scene_tracker.rules]\nmax_coast_s = -1.0\n", "max_coast_s must be > 0"),
        ("[scene_tracker]\nstationary_detections = 1\n", "expected a bool"),
        ("scene_tracker = 3\n", "must be tables"),
        ("[scene_tracker]\nsame_object_m = nan\n", "same_object_m must be >= 0; got nan"),
        ("[scene_tracker]\naccel_psd = inf\n", "accel_psd must be > 0 and finite"),
        ("[scene_tracker]\ngate_probability = 1.0\n", r"gate_probability must be in \(0, 1\)"),
        ("[scene_tracker]\nspread_limits_m = [2.0, 1.0]\n", "0 < low <= high"),
    ],
)
def test_scene_config_errors_name_the_file_and_the_key(tmp_path, text, message):
    path = tmp_path / "cfg.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        load_scene_config(path)
    assert str(path) in str(info.value)


def test_scene_config_is_read(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text(
        "[scene_tracker]\naccel_psd = 3\nspread_limits_m = [0.3, 2.5]\n"
        "[scene_tracker.rules]\nmax_coast_s = 2.0\n"
    )
    cfg = load_scene_config(path)
    assert cfg.accel_psd == 3.0 and cfg.spread_limits_m == (0.3, 2.5)
    assert cfg.rules.max_coast_s == 2.0 and cfg.rules.confirm_hits == 3
    assert np.isfinite(cfg.clutter_age_s)  # the rest default


def test_scene_config_allows_no_limit_where_it_means_one(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text("[scene_tracker]\nmerge_parts_speed_mps = inf\nsplit_kurtosis = 0.0\n")
    cfg = load_scene_config(path)
    assert cfg.merge_parts_speed_mps == np.inf and cfg.split_kurtosis == 0.0
