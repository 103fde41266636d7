"""The compiled scene stages equal a NumPy reference of one scan (``scene_reference``).

As every kernel of ``filters/`` equals its NumPy path: three road users moving on the
corridors of a built-in site (several straight ones; a curved one), each wholly in view of
one radar with one detection near it,
are predicted, gated and updated by the compiled stages (called as the scan loop calls
them, then through the whole loop) and by the reference; distances, states, covariances and
learnt spreads agree to rounding.
"""

import numpy as np
import pytest

from adaptrack.crossing.scene.gate import associate_scan
from adaptrack.crossing.scene.predict import predict_tracks
from adaptrack.crossing.scene.tracker import SceneTracker, SceneTrackerConfig, _Tracks
from adaptrack.crossing.scene.update import apply_scan
from adaptrack.crossing.site.model import load_site
from tests.crossing import scene_reference as ref
from tests.crossing.scene_bundles import scan_radar_view

SITES = ("lx_three_arm", "lx_curve_near")  # three straight corridors; one curved road
CONFIG = SceneTrackerConfig(occlusion_gate=False, passing_gate=False)  # the regime: none hides
T0, DT = 10.0, 0.05


def _wholly_in_view(radar, cor, u, d, spread):
    """Whether the body (2 spreads either side of ``u``) lies in the radar's field of view."""
    along = u + ref.BODY_HALF_SPREADS * spread * np.linspace(-1.0, 1.0, 33)
    pos = cor.path.lane_geometry(along, np.full(along.size, d))[0]
    return bool(radar.in_view(*radar.polar(pos)).all())


def _scene(name):
    """A tracker holding three moving confirmed road users, their truth and detections."""
    site = load_site(name)
    tracker = SceneTracker(site, CONFIG)
    radar, r = site.radars[0], 0
    rows, placed = [], []
    for offset in sorted(np.arange(-150.0, 150.0, 10.0), key=abs):  # each corridor in turn
        for c, cor in enumerate(tracker.corridors):
            u = cor.crossing_u + offset
            d, spread = -1.5, 1.1 + 0.2 * len(rows)
            pos = cor.path.lane_geometry(np.array([u]), np.array([d]))[0][0]
            far = all(np.hypot(*(pos - q)) > 30.0 for q in placed)
            if len(rows) < 3 and far and _wholly_in_view(radar, cor, u, d, spread):
                rows.append((c, u, d, spread))
                placed.append(pos)
    assert len(rows) == 3
    n = len(rows)
    corridor = np.array([c for c, *_ in rows])
    x = np.array([[u, 12.0 + 2.0 * k, 0.5, d] for k, (_, u, d, _) in enumerate(rows)])
    a = np.random.default_rng(3).normal(size=(n, 4, 4))
    p = 0.05 * a @ a.transpose(0, 2, 1) + np.diag([0.3, 0.5, 0.4, 0.05])
    tracker.book.add(n, 0.0)
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(corridor, x, p, T0, 1.0, len(site.radars))
    tracker.tracks.moved[:] = True
    tracker.tracks.direction[:] = 1.0
    tracker.tracks.spread[:] = [s for *_, s in rows]
    tracks = [
        {"corridor": int(corridor[i]), "x": x[i].copy(), "p": p[i].copy(), "spread": rows[i][3]}
        for i in range(n)
    ]
    # detections a little off each track's prediction (ahead, across, faster)
    roads, bounds = tracker._tables.roads, tracker._tables.bounds
    z = np.empty((n, 3))
    for i, tr in enumerate(tracks):
        xp, _ = ref.predict(tr["x"], tr["p"], DT, CONFIG.accel_psd, CONFIG.lateral_psd)
        true = xp + np.array([0.4, 0.6, 0.0, 0.15])
        lane = ref.lane_frame(roads, bounds, tr["corridor"], true[0])
        z[i] = ref.measurement(true, lane, radar, 0.0, 0.0)[0]
    return tracker, radar, r, tracks, z


def _close(a, b, scale):
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.parametrize("name", SITES)
def test_the_compiled_stages_of_one_scan_equal_the_numpy_reference(name):
    tracker, radar, r, tracks, z = _scene(name)
    roads, bounds = tracker._tables.roads, tracker._tables.bounds
    d2_ref, updated = ref.scan(tracks, z, radar, roads, bounds, DT, CONFIG)
    assert np.all(np.diag(d2_ref) < 16.0)  # each detection in its own track's gate ...
    assert np.all(d2_ref[~np.eye(3, dtype=bool)] > 100.0)  # ... and far beyond the others'
    kappa = [ref.lane_frame(roads, bounds, tr["corridor"], tr["x"][0])[2] for tr in tracks]
    corridors = {tr["corridor"] for tr in tracks}
    assert len(corridors) > 1 if name == "lx_three_arm" else max(np.abs(kappa)) > 1e-3
    # the stages as the scan loop calls them (no learnt clutter)
    t, site, cfg = tracker._rows(), tracker._tables, tracker._settings
    sensor = scan_radar_view(site, r)
    clutter = np.zeros(3, bool)
    time_s = T0 + DT
    predict_tracks(t, clutter, time_s, cfg)
    ids = np.full(3, -1)
    seen, d2, logdet, gated, simple, ti, di, sight = associate_scan(
        t, clutter, r, site, sensor, cfg, z, ids
    )
    assert seen.all() and simple and sorted(zip(ti, di)) == [(0, 0), (1, 1), (2, 2)]
    _close(np.diag(d2), np.diag(d2_ref), 1.0)
    used = apply_scan(
        time_s, seen, clutter, d2, logdet, gated, sight, ti, di, z, ids, r, t, site, sensor,
        cfg, 0.0, np.zeros(3),
    )  # fmt: skip
    assert used.all()
    for i, tr in enumerate(updated):
        assert t.spread[i] == pytest.approx(tr["spread"], rel=1e-12)
        _close(t.x[i], tr["x"], 100.0)
        _close(t.p[i], tr["p"], np.abs(tr["p"]).max())


@pytest.mark.parametrize("name", SITES)
def test_one_scan_through_the_whole_compiled_loop_equals_the_numpy_reference(name):
    tracker, radar, _, tracks, z = _scene(name)
    roads, bounds = tracker._tables.roads, tracker._tables.bounds
    _, updated = ref.scan(tracks, z, radar, roads, bounds, DT, CONFIG)
    tracker.step(radar.name, T0 + DT + radar.latency_s, z)
    assert tracker.book.ids.size == 3 and tracker.log.updated == 3
    for i, tr in enumerate(updated):
        assert tracker.tracks.spread[i] == pytest.approx(tr["spread"], rel=1e-12)
        _close(tracker.tracks.x[i], tr["x"], 100.0)
        _close(tracker.tracks.p[i], tr["p"], np.abs(tr["p"]).max())
