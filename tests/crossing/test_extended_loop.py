"""The compiled scan loop of the extended tracker equals its NumPy reference, scan for scan.

:func:`track_scene_extended` runs :mod:`adaptrack.crossing.scene.extended_loop`;
``reference=True`` runs :class:`ExtendedTracker` one scan per call. The scenes take every
branch: births and duplicates (a 10 m lorry seen by a point cloud), a background of the
empty site with an object standing on the carriageway, trains due, lanes as priors, every
radar kind, mixed traffic with occlusions, and the tracks and output arrays outgrowing their
first room. The two share no arithmetic (the kernel writes every operation out), so equal
tables to rounding check each against the other.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.scene import extended_tracker
from adaptrack.crossing.scene.extended_tracker import track_scene_extended
from adaptrack.crossing.simulation.faces import FaceRadar, face_returns_of
from adaptrack.crossing.simulation.motion import read_motion, simulate_replay
from adaptrack.crossing.simulation.scene import scene_spec, simulate_scene
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.clearance import empty_background

from .test_extended_tracker import _motion_table, _path


def _assert_same(site, detections, **options):
    """Run both paths and compare tracks (1e-7 relative), events and the log."""
    tracks, events, log = track_scene_extended(site, detections, **options)
    ref_tracks, ref_events, ref_log = track_scene_extended(site, detections, reference=True,
                                                           **options)  # fmt: skip
    assert log == ref_log
    assert len(tracks) == len(ref_tracks) > 0
    assert list(tracks.columns) == list(ref_tracks.columns)
    for column in tracks.columns:
        got, want = tracks[column].to_numpy(), ref_tracks[column].to_numpy()
        if got.dtype.kind == "f":
            np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9, err_msg=column)
        else:
            assert (got == want).all(), column
    pd.testing.assert_frame_equal(events, ref_events, check_dtype=False, rtol=1e-9)
    return tracks, events, log


@pytest.mark.parametrize("kind", ["object", "cluster", "cloud"])
def test_free_motion_with_a_background_and_an_object_standing(tmp_path, kind):
    site = load_site("lx_default")
    radar = FaceRadar.of_kind(kind)
    background = empty_background(site, radar, 30.0, seed=99)
    t = np.arange(0.0, 16.0 + 1e-9, 0.1)
    box = _path(9, "unknown", 0.5, 0.5, t, np.tile([-1.2, 2.0], (t.size, 1)), np.zeros_like(t))
    pd.concat([_motion_table(), box]).to_csv(tmp_path / "motion.csv", index=False)
    rec = simulate_replay(site, read_motion(tmp_path / "motion.csv"), seed=7, radar=radar)
    trains = np.array([[5.0, 9.0]])
    _, events, log = _assert_same(site, rec.detections, background=background,
                                  train_intervals=trains)  # fmt: skip
    assert log.background > 0  # the reflectors of the empty site explained detections
    assert (events["event"] == "crossing_not_clear").any()


def test_a_train_passing_the_junction_site():
    """The rails' branch of the crossing's state: a train due on a site with rails."""
    site = load_site(Path(__file__).parents[2] / "examples" / "sites" / "junction_crossing.toml")
    spec = scene_spec(site, duration_s=24.0, first_closure_s=4.0, closure_s=16.0)
    rec = simulate_scene(site, spec, 5, face_returns_of(FaceRadar.of_kind("cluster")))
    assert (rec.truth.table["vehicle_class"] == "train").any()
    _, events, _ = _assert_same(site, rec.detections, train_intervals=spec.warnings())
    _, unannounced, _ = track_scene_extended(site, rec.detections)
    assert len(events) < len(unannounced)  # the train's tracks were its known occupant


def test_mixed_traffic_outgrowing_the_first_room(monkeypatch):
    site = load_site("lx_default")
    spec = scene_spec(site, duration_s=30.0, first_closure_s=10.0, closure_s=15.0)
    rec = simulate_scene(site, spec, 3, face_returns_of(FaceRadar.of_kind("cluster")))
    # small calls: the loop stops and resumes between them, and the track arrays grow
    monkeypatch.setattr(extended_tracker, "SCANS_PER_CALL", 97)
    _, _, log = _assert_same(site, rec.detections)
    assert log.opened > 64  # more tracks were opened than the first room holds
