"""Recorded-motion replay: the two file layouts, the transform onto the site, bad files."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.simulation.faces import FaceRadar
from adaptrack.crossing.simulation.motion import (
    MotionTransform,
    read_motion,
    replay_truth,
    simulate_replay,
)
from adaptrack.crossing.simulation.scene import STEP_S
from adaptrack.crossing.site.model import load_site
from adaptrack.io.tables import DataFormatError

SITE = load_site("lx_default")


def interaction_file(path, n=40):
    """Two cars in the INTERACTION layout: one driving east at 8 m/s, one standing."""
    t_ms = 100 * np.arange(1, n + 1)
    rows = [
        pd.DataFrame({
            "track_id": 1, "frame_id": np.arange(1, n + 1), "timestamp_ms": t_ms,
            "agent_type": "car", "x": 1000.0 + 8.0 * t_ms / 1000.0, "y": 980.0, "vx": 8.0,
            "vy": 0.0, "psi_rad": 0.0, "length": 4.2, "width": 1.8,
        }),
        pd.DataFrame({
            "track_id": 2, "frame_id": np.arange(1, n + 1), "timestamp_ms": t_ms,
            "agent_type": "truck", "x": 1010.0, "y": 990.0, "vx": 0.0, "vy": 0.0,
            "psi_rad": math.pi / 2, "length": 8.0, "width": 2.5,
        }),
    ]  # fmt: skip
    pd.concat(rows).to_csv(path, index=False)
    return path


def test_interaction_layout_onto_the_site_frame(tmp_path):
    path = interaction_file(tmp_path / "tracks.csv")
    m = read_motion(path, MotionTransform((1000.0, 980.0), 90.0))
    car = m.table[m.table["object_id"] == 1]
    # turned 90 deg counter-clockwise: the file's east is the site's north
    assert car["east_m"].to_numpy() == pytest.approx(0.0, abs=1e-9)
    assert car["north_speed_mps"].to_numpy() == pytest.approx(8.0)
    assert car["heading_rad"].to_numpy() == pytest.approx(0.0, abs=1e-9)  # north
    truck = m.table[m.table["object_id"] == 2]
    assert truck["heading_rad"].iloc[0] == pytest.approx(math.pi * 3 / 2)  # file north -> west
    assert set(m.users["vehicle_class"]) == {"car", "truck"}
    truth = replay_truth(m, SITE)
    steps = np.diff(np.unique(truth.table["time_s"]))
    assert steps == pytest.approx(STEP_S)
    c = truth.table[truth.table["object_id"] == 1]
    # linear between samples: the position at every step is on the recorded line
    assert c["north_m"].to_numpy() == pytest.approx(0.8 + 8.0 * c["time_s"].to_numpy(), abs=1e-9)


def test_generic_layout_derives_speed_from_positions_and_reads_geodetic(tmp_path):
    t = np.arange(0.0, 5.0, 0.2)
    frame = pd.DataFrame({"time_s": t, "object_id": 7, "class": "cyclist", "x_m": 3.0 * t,
                          "y_m": -2.0, "length_m": 1.8, "width_m": 0.6})  # fmt: skip
    frame.to_csv(tmp_path / "g.csv", index=False)
    m = read_motion(tmp_path / "g.csv")
    assert m.table["east_speed_mps"].to_numpy() == pytest.approx(3.0)
    assert m.table["heading_rad"].to_numpy() == pytest.approx(math.pi / 2)  # east
    # geodetic: 0.001 deg of latitude north of the origin is about 110.6 m
    geo = pd.DataFrame({"time_s": [0.0, 1.0], "object_id": 1, "class": "car",
                        "lat_deg": [50.001, 50.001], "lon_deg": [30.0, 30.0], "length_m": 4.0,
                        "width_m": 1.8})  # fmt: skip
    geo.to_csv(tmp_path / "geo.csv", index=False)
    m = read_motion(tmp_path / "geo.csv", MotionTransform(geodetic_origin=(50.0, 30.0)))
    assert m.table["north_m"].iloc[0] == pytest.approx(111.25, abs=0.05)
    assert m.table["east_m"].iloc[0] == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda f: f.drop(columns="vx"), "missing column"),
        (lambda f: f.assign(length=np.where(f.index == 3, -1.0, f["length"])), "row 4"),
        (lambda f: f.assign(agent_type="tram"), "unknown type 'tram'"),
        (lambda f: f.assign(timestamp_ms=100), "time repeats"),
        (lambda f: f.assign(x="abc"), "not a number"),
    ],
)
def test_bad_motion_files_name_the_row_and_column(tmp_path, change, message):
    path = interaction_file(tmp_path / "tracks.csv")
    change(pd.read_csv(path)).to_csv(path, index=False)
    with pytest.raises(DataFormatError, match=message):
        read_motion(path)


def test_geodetic_file_without_origin_is_refused(tmp_path):
    pd.DataFrame({"time_s": [0.0], "object_id": 1, "class": "car", "lat_deg": 50.0,
                  "lon_deg": 30.0, "length_m": 4.0, "width_m": 1.8}).to_csv(
        tmp_path / "geo.csv", index=False)  # fmt: skip
    with pytest.raises(DataFormatError, match="geodetic origin"):
        read_motion(tmp_path / "geo.csv")


@pytest.mark.parametrize("kind", ["object", "cluster", "cloud"])
def test_replay_gives_detections_of_every_kind(tmp_path, kind):
    """A car driving down the site's north lane, replayed through each radar kind."""
    t = np.arange(0.0, 12.0, 0.1)
    frame = pd.DataFrame({"time_s": t, "object_id": 3, "class": "car", "x_m": 1.75,
                          "y_m": 130 - 11 * t, "length_m": 4.5, "width_m": 1.8})  # fmt: skip
    frame.to_csv(tmp_path / "m.csv", index=False)
    rec = simulate_replay(SITE, read_motion(tmp_path / "m.csv"), 1, FaceRadar.of_kind(kind))
    own = rec.sources == 3
    scans = SITE.radars[0].period_s
    per_scan = own.sum() / (12.0 / scans)  # returns of the car per scan, over both radars
    low, high = {"object": (0.5, 2.1), "cluster": (1.0, 9.0), "cloud": (10.0, 400.0)}[kind]
    assert low < per_scan < high
    assert ("elevation_rad" in rec.detections.columns) == (kind == "cloud")
    assert rec.truth.table["time_s"].max() < 12.0
