"""The reorder window: scans of several radars released in the order they were made."""

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.scene.tracker import iter_scans
from adaptrack.service.messages import Detection
from adaptrack.service.reorder import ReorderBuffer


def det(radar, t, r=10.0):
    return Detection(radar, t, r, 0.0, 0.0)


def test_scans_are_released_in_made_time_order_once_the_window_passed():
    buf = ReorderBuffer(0.2, {"A": 0.0, "B": 0.05})  # B stamps 50 ms late
    for d in (det("A", 1.00), det("B", 1.04), det("A", 1.00, 11.0), det("B", 1.10)):
        assert buf.push(d) is None
    assert buf.ready() == []  # newest made time 1.05: nothing 0.2 s older
    assert buf.pending == 4
    buf.push(det("A", 1.30))
    out = buf.ready()  # until 1.10: B@1.04 (made 0.99), A@1.00 (two detections), B@1.10 (made 1.05)
    assert [(s.radar, s.time_s, len(s.rows)) for s in out] == [
        ("B", 1.04, 1), ("A", 1.00, 2), ("B", 1.10, 1)
    ]  # fmt: skip
    np.testing.assert_array_equal(out[1].z[:, 0], [10.0, 11.0])  # arrival order kept
    assert buf.pending == 1
    assert [s.time_s for s in buf.flush()] == [1.30]
    assert buf.pending == 0


def test_a_detection_behind_the_released_scans_is_late_not_buffered():
    buf = ReorderBuffer(0.1, {"A": 0.0, "B": 0.0})
    buf.push(det("A", 1.0))
    buf.push(det("A", 2.0))
    assert [s.time_s for s in buf.ready()] == [1.0]
    reason = buf.push(det("B", 0.95))
    assert reason is not None and "processed already" in reason
    assert buf.push(det("A", 1.0)) is not None  # its scan was released: not a second scan
    assert buf.push(det("B", 1.5)) is None  # still within the window
    assert buf.pending == 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_release_order_is_the_offline_order(seed):
    """With a window wider than the jitter, the live order is iter_scans' order."""
    rng = np.random.default_rng(seed)
    n = 400
    radar = rng.choice(["A", "B", "C"], n)
    t = np.round(rng.uniform(0, 5, n), 2)
    table = pd.DataFrame({"radar": radar, "time_s": t, "range_m": rng.uniform(5, 50, n),
                          "azimuth_rad": 0.0, "radial_speed_mps": 0.0})  # fmt: skip
    latency = {"A": 0.0, "B": 0.03, "C": 0.08}
    table = table.iloc[np.argsort(t + rng.uniform(0, 0.1, n), kind="stable")]  # arrival
    buf = ReorderBuffer(0.25, latency)
    live = []
    for row in table.itertuples():
        assert buf.push(Detection(row.radar, row.time_s, row.range_m, 0.0, 0.0)) is None
        live += buf.ready()
    live += buf.flush()
    offline = list(iter_scans(table, latency))
    assert [(s.radar, s.time_s) for s in live] == [(r, t) for r, t, _, _ in offline]
    for s, (_, _, z, _) in zip(live, offline, strict=True):
        np.testing.assert_array_equal(s.z, z)


def test_negative_window_is_an_error():
    with pytest.raises(ValueError, match="reorder window must be >= 0"):
        ReorderBuffer(-1.0, {})
