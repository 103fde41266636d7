"""Mixed-traffic scene: simulated traffic and detections, and the many-object tracker on them."""

import numpy as np
import pandas as pd
import pytest

from adaptrack.crossing.scene.tracker import SceneTracker, track_scene
from adaptrack.crossing.simulation.scene import (
    STEP_S,
    WALKERS_AND_RIDERS,
    Stall,
    scene_spec,
    simulate_scene,
)
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.site.traffic import VEHICLES
from adaptrack.crossing.studies.scene_metrics import event_outcomes, hazard_stops, score_scene

SITE = load_site("lx_default")


@pytest.fixture(scope="module")
def free_flow():
    spec = scene_spec(SITE, duration_s=120.0, closure_s=0.0, stalls=())
    return simulate_scene(SITE, spec, seed=3)


@pytest.fixture(scope="module")
def stalled():
    spec = scene_spec(SITE, duration_s=150.0, closure_s=0.0, stalls=(Stall("A", 20.0, 0.0, 60.0),))
    return simulate_scene(SITE, spec, seed=11)


def test_traffic_moves_at_its_reported_speed(free_flow):
    """Speed from the positions' own differences (independent of the corridor geometry)."""
    tab = free_flow.truth.table.sort_values(["object_id", "time_s"])
    for _, g in tab.groupby("object_id"):
        xy = g[["east_m", "north_m"]].to_numpy()
        t = g["time_s"].to_numpy()
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.diff(t)
        mid = 0.5 * (g["speed_mps"].to_numpy()[1:] + g["speed_mps"].to_numpy()[:-1])
        np.testing.assert_allclose(step, mid, atol=0.02 + 0.01 * mid.max())
        assert np.allclose(np.diff(t), STEP_S)


def _body_overlaps(tab, dims, speed_max):
    """Depth [m] of every overlap of two road users' bodies (rectangles: length along the
    heading, width across, centred on the reference point) both slower than ``speed_max``, by
    the separating-axis test on the truth table alone (not the simulator's lanes)."""
    depths = []
    half_s = tab["time_s"].to_numpy() / 0.5
    tab = tab[np.abs(half_s - np.round(half_s)) < 1e-6]  # every 0.5 s
    for _, g in tab.groupby("time_s"):
        g = g[g["speed_mps"].to_numpy() < speed_max]
        xy = g[["east_m", "north_m"]].to_numpy()
        head = g["heading_rad"].to_numpy()
        size = np.array([dims[c] for c in g["vehicle_class"]]).reshape(-1, 2)
        for a in range(len(g)):
            for b in range(a + 1, len(g)):
                if np.hypot(*(xy[b] - xy[a])) > 0.5 * (size[a].sum() + size[b].sum()):
                    continue  # further apart than their half diagonals
                axes = [(np.sin(h), np.cos(h)) for h in (head[a], head[b])]
                axes += [(-y, x) for x, y in axes]
                depth = np.inf
                for ax in axes:
                    reach = [
                        0.5 * size[k, 0] * abs(np.sin(head[k]) * ax[0] + np.cos(head[k]) * ax[1])
                        + 0.5 * size[k, 1] * abs(np.cos(head[k]) * ax[0] - np.sin(head[k]) * ax[1])
                        for k in (a, b)
                    ]
                    depth = min(depth, sum(reach) - abs(np.dot(xy[b] - xy[a], ax)))
                if depth > 0:
                    depths.append(depth)
    return np.array(depths)


def test_road_users_queued_at_a_closure_stand_clear_of_each_other():
    """A motorcycle or cyclist waits behind a bus or truck it has no room to pass (the lane
    leaves 0.95 m beside a 2.55 m bus); checked on the truth alone: the bodies of any two
    standing road users are disjoint rectangles."""
    spec = scene_spec(SITE, duration_s=700.0, first_closure_s=60.0, closure_s=240.0, stalls=())
    rec = simulate_scene(SITE, spec, seed=1)  # motorcycles stood inside trucks' bodies here
    tab = rec.truth.table
    tab = tab[tab["in_zone"].to_numpy()]
    classes = {**VEHICLES, **WALKERS_AND_RIDERS}
    dims = {name: (c.length_m, c.width_m) for name, c in classes.items()}
    standing = tab[tab["speed_mps"] < 0.1]
    counts = standing.groupby("vehicle_class")["object_id"].nunique()
    assert counts.get("motorcycle", 0) >= 3 and counts.get("bus", 0) + counts.get("truck", 0) >= 2
    depths = _body_overlaps(tab, dims, speed_max=0.1)
    assert depths.size == 0, (
        f"{depths.size} overlaps of standing bodies, deepest {depths.max():.2f} m"
    )


def test_detections_carry_no_identity_and_clutter_is_poisson(free_flow):
    det = free_flow.detections
    assert list(det.columns) == ["radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps"]
    src = free_flow.sources
    assert src.size == len(det)
    static = det[src == -2]
    assert static.size and np.abs(static["radial_speed_mps"]).max() < 1.0  # zero Doppler
    # false alarms: Poisson with the scene's rate per scan, thinned by the fields of view
    n_scans = sum(int(free_flow.spec.duration_s / r.period_s) for r in SITE.radars)
    rate = (src == -1).sum() / n_scans
    assert 0.3 < rate <= free_flow.spec.false_alarms_per_scan * 1.05
    users = set(free_flow.truth.users["object_id"])
    assert set(src[src >= 0]) <= users and len(set(src[src >= 0])) > 0.8 * len(users)


def test_moving_users_reflect_about_their_bodies_at_the_scans_own_time(free_flow):
    """Detections of moving users, put on the ground by plain trigonometry, centre on the body
    where the truth (interpolated) has it at the detection's time, for every radar.

    The radars scan at a random phase against the traffic's steps: a state taken from the
    nearest step sits up to STEP_S / 2 (0.38 m at 15 m/s) off along the road. Per radar the mean
    along-road offset over users (a user's reflections share its lateral spread: one sample per
    user) is within 4 standard errors of zero.
    """
    det = free_flow.detections
    src = free_flow.sources
    tab = free_flow.truth.table
    for radar in SITE.radars:
        mine = (det["radar"] == radar.name).to_numpy() & (src >= 0)
        d = det[mine]
        ground = np.sqrt(d["range_m"] ** 2 - radar.height_m**2).to_numpy()
        az = d["azimuth_rad"].to_numpy() - radar.azimuth_bias_rad
        east = radar.position_m[0] + ground * np.sin(az)
        north = radar.position_m[1] + ground * np.cos(az)
        t = d["time_s"].to_numpy() - radar.latency_s
        per_user = []
        for oid in np.unique(src[mine]):
            g = tab[tab["object_id"] == oid]
            at = src[mine] == oid
            te, tn, hd, v = (np.interp(t[at], g["time_s"], g[c]) for c in
                             ("east_m", "north_m", "heading_rad", "speed_mps"))  # fmt: skip
            moving = v > 5.0
            if moving.sum() >= 20:
                along = (east[at] - te) * np.sin(hd) + (north[at] - tn) * np.cos(hd)
                per_user.append(along[moving].mean())
        assert len(per_user) >= 10, radar.name
        mean, se = np.mean(per_user), np.std(per_user, ddof=1) / np.sqrt(len(per_user))
        assert abs(mean) < 4.0 * se, (radar.name, mean, se)


def test_tracker_meets_the_requirement_through_association(free_flow):
    tracks, _, log = track_scene(SITE, free_flow.detections)
    assert log.total == len(free_flow.detections)  # no detection lost without a record
    score = score_scene(free_flow.truth, tracks, SITE.zone_m)
    for row in score.classes.itertuples():
        assert row.position_rms_m <= 0.7, row
        assert row.speed_rms_kmh <= 2.0, row
        assert row.coverage >= 0.9, row
    assert score.gospa_false < 0.5 * 12.5  # under half a false track on average


def test_stall_between_the_barriers_raises_the_event_in_time(stalled):
    tracks, events, _ = track_scene(SITE, stalled.detections)
    hazards, false = event_outcomes(stalled.truth, events, SITE.barrier_m)
    stall = hazards[hazards["object_id"].isin(stalled.truth.stall_stops["object_id"])]
    assert len(stall) == 1
    assert -1.0 <= stall["delay_s"].iloc[0] <= 1.0, hazards
    assert hazards["delay_s"].notna().all() and len(false) == 0, (hazards, false)
    # the stalled track: stopped, and its covariance stays bounded through the stall
    ev = events.iloc[0]
    rows = tracks[(tracks["track_id"] == ev["track_id"]) & (tracks["status"] == "stopped")]
    assert rows["time_s"].max() - rows["time_s"].min() > 40.0
    assert rows["position_std_m"].max() < 0.5


def test_the_compiled_runs_equal_the_scan_by_scan_steps(stalled, monkeypatch):
    """track_scene (runs of 4096 scans in one compiled call, one row buffer) gives the same
    rows and events as SceneTracker.step scan by scan, and as runs of 7 scans whose row
    buffer starts empty and grows (a stall: alarms, a queue, tracks opened and deleted)."""
    import adaptrack.crossing.scene.tracker as scene_tracker
    from adaptrack.crossing.scene.tracker import iter_scans

    tracks, events, log = track_scene(SITE, stalled.detections)
    assert len(events) >= 1
    monkeypatch.setattr(scene_tracker, "ROWS_PER_SCAN", 0)
    monkeypatch.setattr(scene_tracker, "SCANS_PER_CALL", 7)
    small_runs = track_scene(SITE, stalled.detections)
    pd.testing.assert_frame_equal(small_runs[0], tracks, check_exact=True)
    pd.testing.assert_frame_equal(small_runs[1], events, check_exact=True)
    assert small_runs[2] == log
    tracker = SceneTracker(SITE)
    frames = []
    for radar, t, z, ids in iter_scans(stalled.detections):
        tracker.step(radar, t, z, ids)
        frames.append(tracker.rows(tracker.last_scan_s))
    stepped = pd.concat(frames, ignore_index=True)
    pd.testing.assert_frame_equal(stepped, tracks, check_exact=True)
    pd.testing.assert_frame_equal(pd.DataFrame(tracker.events), events, check_exact=True)
    assert tracker.log == log


def test_track_scene_names_the_scan_of_bad_input(free_flow):
    det = free_flow.detections.iloc[:500].copy()
    with pytest.raises(ValueError, match="unknown radar 'radar_Q'"):
        track_scene(
            SITE, det.assign(radar=det["radar"].where(det.index != det.index[9], "radar_Q"))
        )
    bad = det.copy()
    bad.loc[bad.index[40], "range_m"] = np.inf
    stamp = bad.loc[bad.index[40], "time_s"]
    with pytest.raises(ValueError, match=f"at {stamp} s: a detection is not finite"):
        track_scene(SITE, bad)
    with pytest.raises(ValueError, match="sensor ids must be integers >= -1"):
        track_scene(SITE, det.assign(object_id=-2))


def test_bad_scans_are_refused_with_a_reason():
    tracker = SceneTracker(SITE)
    with pytest.raises(ValueError, match="unknown radar 'nope'"):
        tracker.step("nope", 0.0, np.zeros((0, 3)))
    tracker.step("radar_A", 1.0, np.array([[50.0, 0.1, -10.0]]))
    with pytest.raises(ValueError, match="not after its previous scan"):
        tracker.step("radar_A", 0.5, np.array([[50.0, 0.1, -10.0]]))
    with pytest.raises(ValueError, match="not finite"):
        tracker.step("radar_A", 2.0, np.array([[np.nan, 0.1, -10.0]]))
    tracker.step("radar_A", 3.0, np.array([[50.0, 3.0, -10.0]]))  # far outside the view
    assert tracker.log.rejected_outside_view == 1


@pytest.mark.parametrize(("across_m", "opens"), [(5.0, True), (25.0, False)])
def test_a_detection_beside_every_road_opens_no_track_and_is_counted(across_m, opens):
    """A left-over detection in radar_A's view, ``across_m`` beside its lane's corridor: 5 m
    (a footway) opens a tentative track; 25 m (a field beside the site's roads, farther than
    ``max_open_offset_m`` = 15 m from every corridor) opens none and is counted as
    ``off_road``; every detection is accounted for either way."""
    from adaptrack.crossing.scene.spawn import nearest_sample

    tracker = SceneTracker(SITE)
    cor, radar, _ = _queue_lane(tracker)
    ground = cor.path.lane_geometry(np.array([cor.crossing_u - 40.0]), np.array([across_m]))[0]
    _, _, d = nearest_sample(tracker._tables.roads, tracker._tables.bounds, *ground[0])
    assert abs(abs(d) - across_m) < 0.5  # no other corridor nearer
    rng_m, az = radar.polar(ground)
    assert radar.in_view(rng_m, az).all()
    tracker.step(radar.name, 1.0, np.stack([rng_m, az, np.zeros(1)], -1))
    log = tracker.log
    assert (tracker.book.ids.size, log.opened, log.off_road) == ((1, 1, 0) if opens else (0, 0, 1))
    assert log.total == 1


def _write(tmp_path, text):
    path = tmp_path / "det.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("radar,time_s,range_m,azimuth_rad\nradar_A,0.1,50,0.1\n", "radial_speed_mps"),
        ("radar,time_s,range_m,azimuth_rad,radial_speed_mps\n", "no detections"),
        ("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_A,0.1,nan,0.1,-3\n", "row 1"),
        ("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_A,0.1,50,inf,-3\n", "infinite"),
        ("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_Q,0.1,50,0.1,-3\n", "radar_Q"),
        ("radar,time_s,range_m,azimuth_rad,radial_speed_mps\nradar_A,0.1,-5,0.1,-3\n", "> 0"),
    ],
)
def test_bad_detection_files_get_one_line_errors(tmp_path, text, message):
    from adaptrack.crossing.measurements_io import read_scene_detections

    with pytest.raises(ValueError, match=message):
        read_scene_detections(_write(tmp_path, text), SITE)


def test_bad_scene_settings_are_named():
    with pytest.raises(ValueError, match="unknown class 'tram'"):
        scene_spec(SITE, mix={"tram": 1.0})
    with pytest.raises(ValueError, match="unknown road 'Z'"):
        from adaptrack.crossing.simulation.scene import Flow

        scene_spec(SITE, flows=(Flow("A", "Z", 100.0),))
    with pytest.raises(ValueError, match="no traffic flow"):
        scene_spec(SITE, flows=(Flow("A", "B", 0.0),))
    with pytest.raises(ValueError, match="no traffic flow"):
        scene_spec(load_site("lx_curve_near"))  # one road: no corridor to drive through
    from adaptrack.crossing.site.model import site_from_mapping

    data = dict(SITE.source)
    data["scene"] = {"duraton_s": 10.0}
    with pytest.raises(ValueError, match="duraton_s"):
        site_from_mapping(data, "x.toml")


def test_corridor_follows_the_roads_as_built():
    """lx_default: arm A runs straight north for 60 m, arm B straight south (site file)."""
    from adaptrack.crossing.site.corridor import site_corridors

    (cor,) = site_corridors(SITE.roads, 200.0)
    pts = cor.path.lane_point(cor.crossing_u + np.array([-30.0, 0.0, 100.0]), 0.0)
    np.testing.assert_allclose(pts, [[0.0, 30.0], [0.0, 0.0], [0.0, -100.0]], atol=0.06)


def test_hazard_stops_are_standstills_between_the_barriers(stalled):
    """Truth hazards from the trajectories, checked against the stall the scene put there."""
    stops = hazard_stops(stalled.truth, SITE.barrier_m)
    stall = stalled.truth.stall_stops
    row = stops[stops["object_id"] == stall["object_id"].iloc[0]]
    assert len(row) == 1
    assert abs(row["stop_time_s"].iloc[0] - stall["stop_time_s"].iloc[0]) <= STEP_S + 1e-9
    tab = stalled.truth.table
    for st in stops.itertuples():
        g = tab[(tab["object_id"] == st.object_id) & (tab["time_s"] >= st.stop_time_s)]
        g = g[g["time_s"] < st.stop_time_s + 0.5]
        assert (g["speed_mps"] < 0.3).all() and (g["to_crossing_m"].abs() <= SITE.barrier_m).all()


@pytest.mark.statistical
@pytest.mark.parametrize("seed", [21, 22])
def test_events_over_closures_queues_and_a_stall(seed):
    """Five minutes with a 2-minute closure (queues at the stop line) and a stall.

    Every standstill between the barriers (the stall, and anyone queued behind it inside the
    barriers) raises its event within 1 s, and nothing else raises one. Before tracks had to
    be seen stopped, coasting tracks that lost their detections were taken for stopped: six
    false events in 10 minutes.
    """
    spec = scene_spec(
        SITE, duration_s=300.0, first_closure_s=60.0, closure_every_s=600.0, closure_s=120.0,
        stalls=(Stall("A", 100.0, 0.0, 60.0),),
    )  # fmt: skip
    rec = simulate_scene(SITE, spec, seed=seed)
    _, events, _ = track_scene(SITE, rec.detections)
    hazards, false = event_outcomes(rec.truth, events, SITE.barrier_m)
    assert len(hazards) >= 1
    assert (hazards["delay_s"].abs() <= 1.0).all(), hazards
    assert len(false) == 0, false


def test_learnt_clutter_reserves_its_own_detections():
    """A static object older than clutter_age_s keeps the detections in its tight gate; a
    young one (a vehicle waiting at a closure may look static) and moving tracks do not."""
    from adaptrack.crossing.scene.gate import reserve_clutter
    from adaptrack.crossing.scene.scan_loop import learnt_clutter
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig, _Tracks

    tracker = SceneTracker(SITE, SceneTrackerConfig(clutter_age_s=100.0))
    tracker.book.add(2, 0.0)  # an old static object and a road user
    tracker.book.add(1, 150.0)  # a young static object
    x, p = np.zeros((3, 4)), np.tile(np.eye(4), (3, 1, 1))
    tracker.tracks = _Tracks.opened(np.zeros(3, int), x, p, 200.0, 1.0, len(SITE.radars))
    tracker.tracks.stopped[[0, 2]] = True  # rows 0 and 2 never moved: static
    d2 = np.array([[1.0, 50.0, 2.0], [3.0, 4.0, 5.0], [60.0, 0.5, 70.0]])
    tr = tracker.tracks
    clutter = learnt_clutter(tr.stopped, tr.moved, tr.time_s, tracker.book.born_s, 100.0)
    reserve_clutter(d2, clutter, tracker._settings.clutter_gate)
    # the old object's detections 0 and 2 (gate 11.3 at 0.99) are its own against everyone
    # else; detection 1, within only the young one's gate, stays open to the road user
    np.testing.assert_array_equal(d2[0], [1.0, 50.0, 2.0])
    np.testing.assert_array_equal(d2[1], [np.inf, 4.0, np.inf])
    np.testing.assert_array_equal(d2[2], [np.inf, 0.5, np.inf])


def test_learnt_clutter_is_frozen_and_a_young_static_object_is_not():
    """A static object older than ``clutter_age_s`` (learnt clutter) is neither predicted nor
    updated by its detections: its state and covariance stay as they were, while a young
    static object's are updated (its place converges on its reflections)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig, _Tracks

    tracker = SceneTracker(SITE, SceneTrackerConfig(clutter_age_s=100.0))
    cor, radar, half_lane = _queue_lane(tracker)
    u = np.array([cor.crossing_u - 60.0, cor.crossing_u - 40.0])  # old, young
    x = np.column_stack([u + 0.4, np.zeros(2), np.zeros(2), np.full(2, -half_lane)])
    p = np.tile(np.diag([0.25, 1e-4, 1e-4, 0.04]), (2, 1, 1))
    tracker.book.add(1, 0.0)
    tracker.book.add(1, 150.0)
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(np.zeros(2, int), x, p, 200.0, 0.3, len(SITE.radars))
    tracker.tracks.stopped[:] = True  # never moved: static
    rng = np.random.default_rng(4)
    for k in range(1, 41):  # 2 s, each detected at its true place (0.4 m short of the state)
        z = np.vstack([_body_scan(rng, radar, cor, c, -half_lane, 0.2, 0.2, 1) for c in u])
        tracker.step(radar.name, 200.0 + k * radar.period_s, z)
    tr = tracker.tracks
    assert tracker.book.ids.tolist() == [1, 2] and tracker.log.updated == 80
    np.testing.assert_array_equal(tr.x[0], x[0])
    np.testing.assert_array_equal(tr.p[0], p[0])
    assert abs(tr.x[1, 0] - u[1]) < 0.1 and tr.p[1, 0, 0] < 0.01


def test_stored_clutter_views_equal_views_made_anew():
    """A frozen track's view of a radar is stored the first time it is gated and read back
    after; tracking 90 s of a scene (learnt clutter after 10 s; cars, trucks and clutter)
    with the stored views gives the same tracks, to the last bit, as making every view anew
    (the stored views cleared before each scan)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig, iter_scans

    spec = scene_spec(SITE, duration_s=90.0)
    rec = simulate_scene(SITE, spec, 5)
    config = SceneTrackerConfig(clutter_age_s=10.0)
    stored, anew = SceneTracker(SITE, config), SceneTracker(SITE, config)
    frozen_scans, rows = 0, {"stored": [], "anew": []}
    for name, time_s, z, ids in iter_scans(rec.detections):
        anew.tracks.clutter_views[:] = 0.0
        for key, tracker in (("stored", stored), ("anew", anew)):
            tracker.step(name, time_s, z, ids)
            rows[key].append(tracker.rows(time_s))
        frozen_scans += int((stored.tracks.clutter_views[:, :, 0] == 1.0).any())
    assert frozen_scans > 500  # the stored views were used
    pd.testing.assert_frame_equal(pd.concat(rows["stored"]), pd.concat(rows["anew"]))
    for name in ("x", "p", "spread"):
        np.testing.assert_array_equal(getattr(stored.tracks, name), getattr(anew.tracks, name))
    # the gate itself, on the last scan of each radar: the same to the last bit
    from adaptrack.crossing.scene.gate import associate_scan
    from adaptrack.crossing.scene.scan_loop import learnt_clutter
    from tests.crossing.scene_bundles import scan_radar_view

    t, st, site = stored._rows(), stored._settings, stored._tables
    clutter = learnt_clutter(t.stopped, t.moved, t.time_s, t.born_s, config.clutter_age_s)
    assert clutter.sum() >= 3
    last = {name: z for name, _, z, _ in iter_scans(rec.detections)}
    for r, radar in enumerate(SITE.radars):
        gates = []
        view = scan_radar_view(site, r)
        for views in (t.clutter_views[:, r].copy(), np.zeros_like(t.clutter_views[:, r])):
            all_views = t.clutter_views.copy()
            all_views[:, r] = views
            rows = t._replace(clutter_views=all_views)
            ids = np.full(len(last[radar.name]), -1)
            out = associate_scan(rows, clutter, r, site, view, st, last[radar.name], ids)
            assert (all_views[clutter, r, 0] == 1.0).all()  # stored now if not before
            gates.append(out[:4])  # seen, d2, logdet, gated
        for stored_part, anew_part in zip(*gates, strict=True):
            np.testing.assert_array_equal(stored_part, anew_part)


def test_will_not_stop_before_the_stop_line_rule():
    """Hand-made tracks on corridor 0 approaching the crossing (u increasing), lights flashing.

    At 20 m/s (sigma 1: at least 18.4 m/s at 95 %), 30 m before the stop line (front 2.6 m
    ahead of the centre) a driver needs 18.4^2 / (2 * 27.4) = 6.2 m/s^2 > 4: the event, lead
    27.4 / 20 s. At 10 m/s it needs 1.8 m/s^2: none. A car following the first one stops
    behind it: none. Not detected for longer than ``stop_seen_s``: none.
    """
    from adaptrack.crossing.scene.scan_loop import stop_line_rows, warning_on
    from adaptrack.crossing.scene.tracker import _Tracks

    tracker = SceneTracker(SITE, warnings=np.array([[0.0, 100.0]]))
    cor = tracker.corridors[0]
    line_u = cor.crossing_u - SITE.stop_line_m
    half_lane = 0.5 * SITE.roads[cor.first].lane_width_m
    u = np.array([line_u - 30.0, line_u - 80.0, line_u - 45.0])
    x = np.stack([u, [20.0, 10.0, 20.0], np.zeros(3), np.full(3, -half_lane)], -1)
    tracker.book.add(3, 10.0)  # detected at 10 s
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(
        np.zeros(3, int), x, np.tile(np.eye(4), (3, 1, 1)), 10.0, 1.5, len(SITE.radars)
    )
    tracker.tracks.moved[:] = True

    def raised(time_s):  # rows raised now, and their lead times [s]
        cant, lead = stop_line_rows(
            tracker._rows(), 3, time_s, np.ones(3, bool), tracker._settings, tracker._tables
        )  # all in the lane
        return np.flatnonzero(cant).tolist(), lead

    rows, lead = raised(10.0)
    assert rows == [0]  # track 1
    front = np.sqrt(3.0) * 1.5
    assert lead[0] == pytest.approx((30.0 - front) / 20.0)
    assert raised(10.05)[0] == []  # once per track
    tracker.tracks.line_event_raised[:] = False
    assert raised(10.5)[0] == []  # last detected 0.5 s ago
    assert warning_on(tracker._tables, 10.0)
    assert not warning_on(SceneTracker(SITE)._tables, 10.0)  # no warning: no prediction


def test_a_sites_own_classes_drive_in_its_scene():
    """A site's custom class (rural_crossing's tractor, its 16.5 m truck) joins its traffic."""
    from pathlib import Path

    from adaptrack.crossing.simulation.scene import detections_per_scan, road_users

    site = load_site(Path(__file__).parents[2] / "examples" / "sites" / "rural_crossing.toml")
    users = road_users(site)
    assert users["tractor"] is site.classes["tractor"] and {"pedestrian", "cyclist"} <= set(users)
    spec = scene_spec(site, duration_s=120.0, closure_s=0.0, stalls=(),
                      mix={"tractor": 0.5, "truck": 0.5})  # fmt: skip
    rec = simulate_scene(site, spec, seed=2)
    u = rec.truth.users
    assert set(u["vehicle_class"]) == {"tractor", "truck"}
    assert (u.loc[u["vehicle_class"] == "tractor", "length_m"] == 6.5).all()
    assert (u.loc[u["vehicle_class"] == "truck", "length_m"] == 16.5).all()
    tab = rec.truth.table
    # its top speed along the lane centre; a body up to 3 m off it on the R = 80 m curve's
    # outside moves up to 3/80 faster
    assert tab.loc[tab["vehicle_class"] == "tractor", "speed_mps"].max() <= 40 / 3.6 * (1 + 3 / 80)
    # detections per scan by body length: the built-in classes keep their counts
    np.testing.assert_array_equal(
        detections_per_scan(np.array([2.2, 5.0, 6.5, 7.1, 12.0, 16.5])),
        [[1, 1], [1, 2], [1, 2], [2, 4], [2, 4], [2, 4]],
    )


def _queue_scan(rng, radar, cor, centres, d, length=5.0, width=1.8, per_body=2):
    """One scan of two stopped cars: reflections uniform over each body, the radar's noise."""
    u = np.concatenate([c + rng.uniform(-length / 2, length / 2, per_body) for c in centres])
    across = d + rng.uniform(-width / 2, width / 2, u.size)
    ground = cor.path.lane_geometry(u, across)[0]
    rng_m, az = radar.polar(ground)
    sr, sa, sv = radar.noise_std(rng_m, az)
    return np.stack(
        [rng_m + sr * rng.normal(size=u.size), az + sa * rng.normal(size=u.size),
         sv * rng.normal(size=u.size)], -1,
    )  # fmt: skip


def _queue_lane(tracker):
    """The first corridor of ``tracker``, radar_A (looking along it) and half its lane [m]."""
    cor = tracker.corridors[0]
    radar = next(r for r in SITE.radars if r.name == "radar_A")
    return cor, radar, 0.5 * SITE.roads[cor.first].lane_width_m


def _one_stopped_track(tracker, u, d, spread):
    """Make ``tracker`` hold one confirmed road user (id 1) stopped at ``(u, d)`` on its
    first corridor, approaching the crossing, with body ``spread`` [m]."""
    from adaptrack.crossing.scene.tracker import _Tracks

    x = np.array([[u, 0.0, 0.0, d]])
    p = np.diag([0.01, 1e-4, 1e-4, 0.04])[None]
    tracker.book.add(1, 0.0)
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(np.zeros(1, int), x, p, 0.0, spread, len(SITE.radars))
    tracker.tracks.stopped[:] = tracker.tracks.moved[:] = True
    tracker.tracks.direction[:] = 1.0


@pytest.mark.parametrize("kurtosis", [1.8, 0.0])
def test_one_track_over_two_queued_cars_splits_into_two(kurtosis):
    """A stopped track that holds two cars of a queue (centres 7 m apart, itself between them
    with a spread stretched over both: its gate takes both cars' reflections) splits into two
    tracks on the cars; the part towards the crossing keeps the identity. With the split
    switched off (kurtosis 0) it stays one track between the cars (the test can fail)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    tracker = SceneTracker(SITE, SceneTrackerConfig(split_kurtosis=kurtosis))
    cor, radar, half_lane = _queue_lane(tracker)
    front, rear = cor.crossing_u - 30.0, cor.crossing_u - 37.0  # approaching with u rising
    _one_stopped_track(tracker, 0.5 * (front + rear), -half_lane, 3.0)
    rng = np.random.default_rng(5)
    for k in range(1, 400):  # 20 s
        tracker.step(
            radar.name, k * radar.period_s, _queue_scan(rng, radar, cor, (front, rear), -half_lane)
        )
    rows = tracker.rows(tracker.last_scan_s)
    assert set(rows["status"]) == {"stopped"}
    at = rows[["east_m", "north_m"]].to_numpy()
    cars = cor.path.lane_geometry(np.array([front, rear]), -half_lane)[0]
    if kurtosis == 0.0:
        assert rows["track_id"].tolist() == [1]
        assert np.hypot(*(at[0] - cars.mean(axis=0))) < 1.0
        return
    assert len(rows) == 2
    err = np.hypot(*(at[:, None, :] - cars[None]).transpose(2, 0, 1))  # track x car
    assert rows["track_id"].iloc[int(np.argmin(err[:, 0]))] == 1  # the front car keeps id 1
    assert err.min(axis=0).max() < 0.5


def test_a_stopped_users_body_spread_stays_what_it_learnt_while_moving():
    """A queued car's track keeps the body spread it learnt while moving (1.25 m) while
    reflections of its body (uniform over 5 m) and of the car stopped 5.5 m behind it come
    in: in a queue the bodies touch, and a spread stretched by a neighbour's reflections
    widens the gate that takes more of them (learning on, it reached 1.38 m here). The
    reflections' moments still learn (they decide a split, switched off here)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    tracker = SceneTracker(SITE, SceneTrackerConfig(split_kurtosis=0.0))
    cor, radar, half_lane = _queue_lane(tracker)
    front, rear = cor.crossing_u - 30.0, cor.crossing_u - 35.5
    _one_stopped_track(tracker, front, -half_lane, 1.25)
    rng = np.random.default_rng(8)
    for k in range(1, 200):  # 10 s
        tracker.step(
            radar.name, k * radar.period_s, _queue_scan(rng, radar, cor, (front, rear), -half_lane)
        )
    first = tracker.book.ids.tolist().index(1)
    assert tracker.tracks.stopped[first]
    assert tracker.tracks.spread[first] == 1.25
    # the moments learn on (towards a uniform 5 m body's 25 / 12 m^2 and the neighbour's)
    assert tracker.tracks.along_m2[first] > 1.1 * 1.25**2


def _stopped_tracks(tracker, bodies):
    """Make ``tracker`` hold confirmed road users (ids 1, 2, ...) stopped on its first corridor,
    approaching the crossing: ``bodies`` is a list of ``(u, d, spread)``."""
    from adaptrack.crossing.scene.tracker import _Tracks

    n = len(bodies)
    x = np.zeros((n, 4))
    x[:, 0], x[:, 3] = [b[0] for b in bodies], [b[1] for b in bodies]
    p = np.tile(np.diag([0.01, 1e-4, 1e-4, 0.04]), (n, 1, 1))
    tracker.book.add(n, 0.0)
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(np.zeros(n, int), x, p, 0.0, 1.0, len(SITE.radars))
    tracker.tracks.spread[:] = [b[2] for b in bodies]
    tracker.tracks.stopped[:] = tracker.tracks.moved[:] = True
    tracker.tracks.direction[:] = 1.0


def _body_scan(rng, radar, cor, centre, d, length, width, n):
    """``n`` reflections of a stopped body, along it N(0, length / 4) clipped to the body (the
    law of the scene simulator), across it uniform; the radar's noise."""
    u = centre + np.clip(rng.normal(0.0, length / 4, n), -length / 2, length / 2)
    across = d + rng.uniform(-width / 2, width / 2, n)
    rng_m, az = radar.polar(cor.path.lane_geometry(u, across)[0])
    sr, sa, sv = radar.noise_std(rng_m, az)
    noise = rng.normal(size=(3, n))
    return np.stack([rng_m + sr * noise[0], az + sa * noise[1], sv * noise[2]], -1)


def _queued_pair_errors(config, front, rear, seen_fraction, seconds, seed):
    """Two road users stopped 1 m apart in radar_A's lane, 30 m before the crossing, tracked
    from their true places (ids 1 and 2): ``front`` and ``rear`` are (length [m], width [m],
    reflections a scan, learnt spread [m]). The front one is detected every scan, the one
    behind it in ``seen_fraction`` of the scans. Returns each track's position error [m]
    after ``seconds``."""
    tracker = SceneTracker(SITE, config)
    cor, radar, half_lane = _queue_lane(tracker)
    u_front = cor.crossing_u - 30.0  # approaching with u rising: nearer the crossing
    u_rear = u_front - front[0] / 2 - 1.0 - rear[0] / 2
    _stopped_tracks(tracker, [(u_front, -half_lane, front[3]), (u_rear, -half_lane, rear[3])])
    rng = np.random.default_rng(seed)
    for k in range(1, round(seconds / radar.period_s)):
        z = _body_scan(rng, radar, cor, u_front, -half_lane, *front[:3])
        if rng.uniform() < seen_fraction:  # the one behind seen past the front one
            z = np.vstack([z, _body_scan(rng, radar, cor, u_rear, -half_lane, *rear[:3])])
        tracker.step(radar.name, k * radar.period_s, z)
    rows = tracker.rows(tracker.last_scan_s).set_index("track_id")
    where = cor.path.lane_geometry(np.array([u_front, u_rear]), -half_lane)[0]
    return np.hypot(*(rows.loc[[1, 2], ["east_m", "north_m"]].to_numpy() - where).T)


@pytest.mark.parametrize(("extent_gate", "occlusion_gate"), [(1, 1), (1, 0), (0, 0)])
def test_a_hidden_truck_in_a_queue_keeps_its_place_behind_the_car_ahead(
    extent_gate, occlusion_gate
):
    """A truck (7.1 m) queued 1 m behind a car (5 m), seen along the lane by radar_A at the
    crossing: the car hides it in 80 % of the scans, and the car's two reflections a scan fall
    within the truck's Gaussian gate, so global nearest neighbour gives the truck one of them.
    A detection on the car's body beyond the truck's end costs the truck track its excess
    over the sensor's along-lane sigma (extent gate): the truck track stays on the truck
    (within 0.5 m), with or without the occlusion gate. Without either it creeps 3 m towards
    the car in 45 s (a development-seed failure). (The occlusion gate alone does not hold it:
    it applies while the truck track stands, and a false start lets it learn a longer body.)"""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    config = SceneTrackerConfig(
        split_kurtosis=0.0, body_extent_gate=bool(extent_gate), occlusion_gate=bool(occlusion_gate)
    )
    car, truck = (5.0, 1.8, 2, 1.1), (7.1, 2.5, 2, 1.56)  # spreads as learnt
    err = _queued_pair_errors(config, car, truck, seen_fraction=0.2, seconds=45.0, seed=11)
    if extent_gate:
        assert err.max() < 0.5, err
    else:
        assert err[1] > 1.5, err


@pytest.mark.parametrize(
    ("bus_spread_m", "occlusion_gate", "extent_gate"),
    [(3.0, 1, 1), (2.0, 1, 1), (3.0, 0, 1), (2.0, 0, 1), (3.0, 1, 0), (3.0, 0, 0)],
)
def test_a_car_hidden_behind_a_queued_bus_does_not_creep_onto_the_bus(
    bus_spread_m, occlusion_gate, extent_gate
):
    """A car (5 m) queued 1 m behind a bus (12 m), seen along the lane by radar_A at the
    crossing: the bus hides it in 90 % of the scans and its reflections (4 a scan over 12 m)
    reach to within 1 m of the car. Two rules keep the car track in its place (within 0.5 m
    after a minute), with the bus's spread learnt (3 m) or under-learnt (2 m), each on its
    own: a track hidden behind a road user is seen, if at all, over its own body (occlusion
    gate: a detection in the bus's gate beyond the car's body is the bus's); a stopped road
    user's track pays for a detection beyond its body's end even when it lies on no other
    body (extent gate). Without both it creeps onto the bus (the cause of the bus's worst
    hours: development seed 42, where the car track then merged into the bus's). The bus
    track itself stays within 0.5 m; with 2 m its far end's reflections first open a static
    track, which is its own reflection and goes (``absorb_young_static``; kept, it held the
    bus's front reflections and the bus track drifted 1.7 m backwards in the minute)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    config = SceneTrackerConfig(
        split_kurtosis=0.0, occlusion_gate=bool(occlusion_gate), body_extent_gate=bool(extent_gate)
    )
    bus, car = (12.0, 2.5, 4, bus_spread_m), (5.0, 1.8, 2, 1.1)
    err = _queued_pair_errors(config, bus, car, seen_fraction=0.1, seconds=60.0, seed=12)
    if not (occlusion_gate or extent_gate):
        assert err[1] > 1.0, err
        return
    assert err.max() < 0.5, err


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_queued_bus_whose_reflections_are_missed_keeps_off_the_truck_ahead(seed):
    """A bus (12 m, spread 3 m) queued 1 m behind a truck (7.1 m), beside its radar shadow
    (the occlusion gate off: the line of sight passes the truck), seen by radar_A in 10 % of
    the scans. The truck's rear reflections fall between the two tracks' bodies, on neither:
    a moving road user takes such a detection as it is (its body may be longer than learnt),
    but a stopped one learns no spread, so it costs the bus track its excess over its body's
    end all the same. The bus track stays within 0.5 m after a minute; taking them whenever
    its own were missed, it stood 0.9-1.4 m towards the truck (validation seed 909, 0.93 m)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    config = SceneTrackerConfig(split_kurtosis=0.0, occlusion_gate=False)
    truck, bus = (7.1, 2.5, 3, 1.56), (12.0, 2.55, 3, 3.0)
    err = _queued_pair_errors(config, truck, bus, seen_fraction=0.1, seconds=60.0, seed=seed)
    assert err.max() < 0.5, err


@pytest.mark.parametrize("same_object_m", [2.5, 0.0])
def test_a_track_stopping_on_an_alarmed_object_raises_no_second_alarm(same_object_m):
    """A car stalled 2 m before the crossing has raised its alarm; a second track stops 1.5 m
    across and 1 m along from it (too far across to merge: a track from the other lane that
    took the car's reflections, validation seed 31 at 767 s) and one stops 7 m behind it (a
    second object). One object, one alarm: the first raises none, the second does; with
    ``same_object_m = 0`` both would (the test can fail)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    tracker = SceneTracker(SITE, SceneTrackerConfig(same_object_m=same_object_m))
    cor, radar, half_lane = _queue_lane(tracker)
    car = cor.crossing_u - 2.0
    _stopped_tracks(
        tracker,
        [(car, -half_lane, 1.1), (car - 1.0, -half_lane + 1.5, 1.1), (car - 7.0, -half_lane, 1.1)],
    )
    tracker.tracks.event_raised[0] = True
    rng = np.random.default_rng(3)
    for k in range(1, 20):  # 1 s
        z = np.vstack(
            [_body_scan(rng, radar, cor, u, -half_lane, 5.0, 1.8, 2) for u in (car, car - 7.0)]
        )
        tracker.step(radar.name, k * radar.period_s, z)
    alarms = [e["track_id"] for e in tracker.events if e["event"] == "stopped_between_barriers"]
    assert sorted(alarms) == ([3] if same_object_m else [2, 3])


def test_a_road_user_standing_beside_an_alarmed_one_raises_its_own_alarm():
    """A car stopped 8 m before the crossing has raised its alarm; a motorcycle that could not
    pass it stands 1 m behind its centre and 1.55 m beside it, towards the centre line
    (fresh seed 1196: alarmed 10.6 s late, as the car's duplicate). Its own reflections lie
    beside the car's body, so it is another road user and raises its alarm; the duplicate
    of the test above, 1.5 m across but on the car's reflections, raises none."""
    tracker = SceneTracker(SITE)
    cor, radar, half_lane = _queue_lane(tracker)
    car, moto = (cor.crossing_u - 8.0, -half_lane), (cor.crossing_u - 9.0, -half_lane + 1.55)
    _stopped_tracks(tracker, [(*car, 1.1), (*moto, 0.5)])
    tracker.tracks.event_raised[0] = True
    rng = np.random.default_rng(4)
    for k in range(1, 20):  # 1 s
        z = np.vstack(
            [
                _body_scan(rng, radar, cor, *car, 5.0, 1.8, 2),
                _body_scan(rng, radar, cor, *moto, 2.2, 0.8, 1),
            ]
        )
        tracker.step(radar.name, k * radar.period_s, z)
    alarms = [e["track_id"] for e in tracker.events if e["event"] == "stopped_between_barriers"]
    assert alarms == [2]


def _moving_track(tracker, u, d, speed, spread):
    """Add a confirmed road user moving at ``speed`` [m/s] along the first corridor (u
    rising) at ``(u, d)`` with body ``spread`` [m] to ``tracker`` (its next id)."""
    from adaptrack.crossing.scene.tracker import _Tracks

    x = np.array([[u, speed, 0.0, d]])
    p = np.diag([0.01, 0.01, 0.01, 0.04])[None]
    tracker.book.add(1, 0.0)
    tracker.book.confirmed[:] = True
    new = _Tracks.opened(np.zeros(1, int), x, p, 0.0, spread, len(SITE.radars))
    new.moved[:] = True
    new.direction[:] = 1.0
    tracker.tracks.append(new)


@pytest.mark.parametrize("passing_gate", [True, False])
def test_a_stopped_motorcycle_does_not_start_on_a_car_passing_beside_it(passing_gate):
    """A motorcycle stands in a queue 0.2 m from the centre line, 40 m before the crossing
    (radar_A looks along the lane); a car drives past it at 2.5 m/s in the lane, 1.55 m
    beside it, with two reflections a scan; the motorcycle is detected in one scan of two.
    A stopped track may start on a detection whose radial speed fits a start (up to
    ``start_speed_max_mps``), and the one-to-one assignment hands it the car's second
    reflection whenever its own is missed: it followed the car (validation seed 907: 4 m
    along and 1.3 m across from the motorcycle, which lost its track). A detection that a
    road user moving beside it (two across spreads or more) gates starts no stopped track
    (``passing_gate``): the motorcycle's track stays stopped on it (within 0.5 m after the
    car has passed); without the rule it follows the car (the test can fail)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    tracker = SceneTracker(SITE, SceneTrackerConfig(passing_gate=passing_gate))
    cor, radar, half_lane = _queue_lane(tracker)
    moto = (cor.crossing_u - 40.0, -half_lane + 1.55)
    car_u0, speed = moto[0] - 8.0, 2.5
    _one_stopped_track(tracker, *moto, 0.5)
    _moving_track(tracker, car_u0, -half_lane, speed, 1.1)
    rng = np.random.default_rng(9)
    for k in range(1, round(6.4 / radar.period_s)):  # the car ends 8 m past the motorcycle
        t = k * radar.period_s
        u_car = car_u0 + speed * t
        z = _body_scan(rng, radar, cor, u_car, -half_lane, 4.5, 1.8, 2)
        ground = cor.path.lane_geometry(
            u_car + np.zeros(2), np.full(2, -half_lane)
        )  # radial speed of a body moving along the lane (u rising), at its centre
        sight = ground[0] - np.asarray(radar.position_m)
        slant = np.sqrt((sight**2).sum(-1) + radar.height_m**2)
        z[:, 2] += speed * (sight * ground[1]).sum(-1) / slant
        if k % 2:
            z = np.vstack([z, _body_scan(rng, radar, cor, *moto, 2.2, 0.8, 1)])
        tracker.step(radar.name, t, z)
    first = tracker.book.ids.tolist().index(1) if 1 in tracker.book.ids else None
    where = cor.path.lane_geometry(np.array([moto[0]]), moto[1])[0][0]
    rows = tracker.rows(tracker.last_scan_s).set_index("track_id")
    if not passing_gate:
        assert first is None or np.hypot(*(rows.loc[1, ["east_m", "north_m"]] - where)) > 2.0
        return
    assert tracker.tracks.stopped[first]
    assert np.hypot(*(rows.loc[1, ["east_m", "north_m"]].to_numpy(float) - where)) < 0.5


def test_a_stop_ends_only_on_a_radial_speed_that_measures_the_speed_along_the_lane():
    """A car stopped 8 m past the crossing on the south arm; detections on its body whose
    radial speed says "moving forwards". From radar_X, across the line of sight (under
    ``GATE_MIN_COS`` along the lane), those of a road user passing beside it at 10 m/s do
    not end the stop (fresh seed 1154: the queued car's track followed the passer into the
    crossing and raised a false alarm on a rail); from radar_B, along the arm, the car's own
    start at 1 m/s does, within two scans."""
    tracker = SceneTracker(SITE)
    cor, _, half_lane = _queue_lane(tracker)
    u = cor.crossing_u + 8.0
    radars = {r.name: r for r in SITE.radars}
    _one_stopped_track(tracker, u, -half_lane, 1.1)
    rng = np.random.default_rng(7)
    stopped = {}
    for name, start_s, speed in (("radar_X", 0.0, 10.0), ("radar_B", 1.0, 1.0)):
        r = radars[name]
        stopped[name] = []
        for k in range(int(0.5 / r.period_s)):
            z = _body_scan(rng, r, cor, u, -half_lane, 4.0, 1.8, 2)
            rng_m, az = z[:, 0], z[:, 1]
            ground = np.asarray(r.position_m) + np.sqrt(rng_m**2 - r.height_m**2)[:, None] * (
                np.stack([np.sin(az), np.cos(az)], -1)
            )
            tangent = cor.path.lane_geometry(np.full(z.shape[0], u), -half_lane)[1]
            los = ((ground - np.asarray(r.position_m)) * tangent).sum(-1) / rng_m
            z[:, 2] = speed * los  # forwards (u rising), at each detection's point
            tracker.step(name, start_s + k * r.period_s, z)
            stopped[name].append(bool(tracker.tracks.stopped[0]))
        assert (np.abs(los) < 0.3).all() if name == "radar_X" else (np.abs(los) > 0.5).all()
    assert all(stopped["radar_X"])
    assert not stopped["radar_B"][1]


def test_a_standstill_seen_only_across_the_line_of_sight_raises_no_alarm_until_measured():
    """A car stalled 8 m past the crossing (between the barriers) on the south arm, where
    radar_X sees it across its line of sight: there its radial speed is near zero whatever
    the car does, so it shows no standstill (validation seed 910 raised a false alarm on
    such detections). No alarm in 1 s of radar_X's scans; radar_B, looking along the arm,
    shows the standstill and the alarm follows within its first scans."""
    tracker = SceneTracker(SITE)
    cor, _, half_lane = _queue_lane(tracker)
    u = cor.crossing_u + 8.0
    radars = {r.name: r for r in SITE.radars}
    body = cor.path.lane_geometry(np.linspace(u - 2.0, u + 2.0, 9), -half_lane)
    for name, across in (("radar_X", True), ("radar_B", False)):
        r = radars[name]
        sight = body[0] - np.asarray(r.position_m)
        slant = np.sqrt((sight**2).sum(-1) + r.height_m**2)
        cos = np.abs((sight * body[1]).sum(-1)) / slant  # radial speed per unit lane speed
        assert (cos < 0.3).all() if across else (cos > 0.5).all()
        assert r.in_view(*r.polar(body[0])).all()
    _one_stopped_track(tracker, u, -half_lane, 1.1)
    rng = np.random.default_rng(5)

    def scans(name, start_s, seconds):
        r = radars[name]
        for k in range(int(seconds / r.period_s)):
            z = _body_scan(rng, r, cor, u, -half_lane, 4.0, 1.8, 2)
            tracker.step(name, start_s + k * r.period_s, z)

    scans("radar_X", 0.0, 1.0)
    assert tracker.tracks.stopped[0] and not tracker.events
    scans("radar_B", 1.01, 0.2)
    alarms = [e for e in tracker.events if e["event"] == "stopped_between_barriers"]
    assert [e["track_id"] for e in alarms] == [1] and alarms[0]["time_s"] <= 1.01 + 0.1


def _moving_body_scan(rng, radar, cor, u, d, speed, length, width, n):
    """``n`` reflections of a body moving at ``speed`` [m/s] along the lane (u rising)."""
    z = _body_scan(rng, radar, cor, u, d, length, width, n)
    ground, tangent = cor.path.lane_geometry(np.full(n, u), np.full(n, d))[:2]
    sight = ground - np.asarray(radar.position_m)
    z[:, 2] += speed * (sight * tangent).sum(-1) / np.sqrt((sight**2).sum(-1) + radar.height_m**2)
    return z


def _confirmed_behind(config, length, spread, n, behind, seen_fraction, seed):
    """A road user (``length`` [m], ``n`` reflections a scan, learnt ``spread`` [m]) drives
    towards radar_A at 12 m/s for 8 s (track 1, given). In ``seen_fraction`` of the scans,
    one more detection lies behind it on the line of sight: ``behind`` = "ghost": a copy of
    a reflection 4-12 m further in range (multipath), or "car": a car 20 m behind in the
    lane. Returns the first time [s] another track is confirmed (inf: never)."""
    tracker = SceneTracker(SITE, config)
    cor, radar, half_lane = _queue_lane(tracker)
    u0, speed = cor.crossing_u - 130.0, 12.0
    _moving_track(tracker, u0, -half_lane, speed, spread)
    rng = np.random.default_rng(seed)
    for k in range(1, round(8.0 / radar.period_s)):
        t = k * radar.period_s
        u = u0 + speed * t
        z = _moving_body_scan(rng, radar, cor, u, -half_lane, speed, length, 2.5, n)
        if rng.uniform() < seen_fraction:
            if behind == "ghost":
                extra = z[:1].copy()
                extra[0, 0] += 8.0 * rng.uniform(0.5, 1.5)
            else:
                extra = _moving_body_scan(rng, radar, cor, u - 20.0, -half_lane, speed, 4.5, 1.8, 1)
            z = np.vstack([z, extra])
        tracker.step(radar.name, t, z)
        if (tracker.book.confirmed & (tracker.book.ids != 1)).any():
            return t
    return np.inf


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_ghost_behind_a_car_is_not_confirmed_but_a_car_in_a_trucks_shadow_is(seed):
    """Multipath ghosts behind a car (a copy of its reflection 4-12 m further out, in 5 % of
    the scans) are missed in the other scans, as a car hides nothing from a radar on a pole:
    with ``shadow_spread_m`` (1.4 m) those misses count against a tentative track's
    confirmation, and no ghost track is confirmed in 8 s. Taking every track as a shadow
    (``shadow_spread_m = 0``, the former rule), the misses tell nothing and a ghost track is
    confirmed within seconds (1.2-6.7 s over seeds 0-5). A real car 20 m behind a truck
    (spread 3 m), seen past it in 15 % of the scans (the scene simulator loses 85 % of the
    detections in a large body's shadow), is confirmed all the same, within 4 s (0.55-3.6 s
    over seeds 0-5): a truck's shadow still hides it."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    ghost = {}
    for s in (1.4, 0.0):
        config = SceneTrackerConfig(shadow_spread_m=s)
        ghost[s] = _confirmed_behind(config, 4.5, 1.1, 1, "ghost", 0.05, seed)
    assert ghost[1.4] == np.inf
    assert ghost[0.0] < 8.0
    car = _confirmed_behind(SceneTrackerConfig(), 12.0, 3.0, 3, "car", 0.15, seed)
    assert car < 4.0


def _track_left_behind(config, spread, scans):
    """A static object (stopped, never moved; learnt ``spread`` [m]) stands in radar_A's
    lane 50 m before the crossing, detected in every scan. One scan also holds a false
    alarm 20 m behind it on radar_A's line of sight through it, which opens a tentative
    track. Returns whether that track is still there after ``scans`` more scans
    (the object's reflection alone)."""
    from adaptrack.crossing.scene.tracker import _Tracks

    tracker = SceneTracker(SITE, config)
    cor, radar, half_lane = _queue_lane(tracker)
    u, d = cor.crossing_u - 50.0, -half_lane
    x, p = np.array([[u, 0.0, 0.0, d]]), np.diag([0.01, 1e-4, 1e-4, 0.04])[None]
    tracker.book.add(1, 0.0)
    tracker.book.confirmed[:] = True
    tracker.tracks = _Tracks.opened(np.zeros(1, int), x, p, 0.0, spread, len(SITE.radars))
    tracker.tracks.stopped[:] = True  # never moved: static
    rng = np.random.default_rng(3)
    body = cor.path.lane_geometry(np.array([u]), np.array([d]))[0][0]
    sight = body - np.asarray(radar.position_m)
    behind = body + 20.0 * sight / np.linalg.norm(sight)
    alarm = np.stack([*radar.polar(behind[None]), np.zeros(1)], -1)
    for k in range(1, scans + 2):
        z = _body_scan(rng, radar, cor, u, d, 0.2, 0.2, 1)
        tracker.step(radar.name, k * radar.period_s, np.vstack([z, alarm]) if k == 1 else z)
        if k == 1:
            assert tracker.book.ids.size == 2  # the track on the false alarm
    return tracker.book.ids.size == 2


def test_a_post_hides_no_track_but_a_body_as_long_as_a_trucks_does():
    """A false alarm behind a post (a static object of spread 0.3 m, as learnt clutter has)
    opens a tentative track whose misses count: it is dropped after its two misses in a row
    (``tentative_misses``). A static body of a truck's spread (3 m: a parked truck) hides it,
    and so does the post when every body is taken as a shadow (``shadow_spread_m = 0``, the
    former rule, under which such tracks stayed for seconds: 6 of the 19 live tracks per
    scan on the first 300 s of validation seed 901)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    default, every_body = SceneTrackerConfig(), SceneTrackerConfig(shadow_spread_m=0.0)
    assert not _track_left_behind(default, 0.3, 2)
    assert _track_left_behind(default, 3.0, 10)
    assert _track_left_behind(every_body, 0.3, 10)


@pytest.mark.parametrize("value", [np.nan, -0.5])
def test_a_bad_shadow_spread_is_named(value):
    """``shadow_spread_m`` must be >= 0 (inf: no body hides a new track; 0: every body does)."""
    from adaptrack.crossing.scene.tracker import SceneTrackerConfig

    with pytest.raises(ValueError, match=r"SceneTrackerConfig.shadow_spread_m must be >= 0"):
        SceneTrackerConfig(shadow_spread_m=value)
    assert SceneTrackerConfig(shadow_spread_m=np.inf).shadow_spread_m == np.inf
