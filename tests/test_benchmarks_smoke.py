"""The benchmark runner works on tiny sizes (no timing is asserted: speed lives in benchmarks/)."""

import json

import pytest
from benchmarks.runner import main


@pytest.mark.slow
def test_benchmarks_quick_run_writes_json(tmp_path, capsys):
    path = tmp_path / "bench.json"
    main(["--quick", "--json", str(path)])
    out = json.loads(path.read_text())
    assert out["machine"]["cores"] >= 1
    impls = {(r["workload"], r["impl"]) for r in out["results"]}
    for workload in ("single", "batch"):
        for impl in ("adaptrack", "filterpy", "pykalman", "simdkalman", "stonesoup"):
            assert (workload, impl) in impls
    for workload in (
        "rts",
        "rts_batch",
        "stream",
        "lx_mc",
        "memory",
        "scene",
        "scene_faces",
        "radar_ekf",
        "radar_imm",
    ):
        assert (workload, "adaptrack") in impls
    assert ("scene", "stonesoup (GNN 2-D, EKF CV, same gate)") in impls
    for peer in ("GNN", "JPDA"):
        assert ("scene", f"stonesoup {peer} (stopped kept, site noise, same coasting)") in impls
    assert ("radar_ekf", "filterpy") in impls and ("radar_imm", "filterpy") in impls
    timed = [r for r in out["results"] if r["workload"] not in ("lx_mc", "memory")]
    assert all(r["per_step_us"] > 0 and r["track_steps_per_s"] > 0 for r in timed)
    memory = [r for r in out["results"] if r["workload"] == "memory"]
    assert all(r["peak_memory_ratio"] >= 1.0 for r in memory)
    assert "adaptrack x faster" in capsys.readouterr().out


def test_live_service_benchmark_runs_on_a_short_scene(capsys):
    from benchmarks.live_service import main as live_main

    live_main(["--duration", "15", "--seed", "3"])
    out = capsys.readouterr().out
    assert "in = used + rejected: True" in out and "lost in the kernel 0" in out
    assert "equal offline 'adaptrack track': yes, exactly" in out


@pytest.mark.parametrize("kind", ["cv", "ca"])
def test_recorded_imm_filterpy_smoother_equals_ours_on_identical_inputs(kind):
    """The benchmark's FilterPy Kalman filter + RTS smoother (its offline peer) against
    adaptrack's on the same converted plots, per-step covariances, prior and model: the same
    smoothed positions to rounding (the layouts, the first step and the noise are wired
    alike)."""
    import numpy as np
    from benchmarks import recorded_imm as ri

    import adaptrack as at

    rng = np.random.default_rng(5)
    times = np.cumsum(rng.uniform(4.0, 5.5, 60))
    truth = np.stack([20e3 + 200.0 * (times - times[0]), 30e3 + 50.0 * np.sin(times / 40.0),
                      np.full(times.size, 3000.0)], -1)  # fmt: skip
    horiz = np.hypot(truth[:, 0], truth[:, 1])
    polar = np.stack([np.linalg.norm(truth, axis=1), np.arctan2(truth[:, 0], truth[:, 1]),
                      np.arctan2(truth[:, 2], horiz)], -1)  # fmt: skip
    plots = polar + rng.standard_normal(polar.shape) * np.sqrt(np.diag(ri.R_POLAR))
    track = ri.Track("synthetic", times, plots, truth)
    q = (0.5, 0.5, 0.01) if kind == "cv" else (0.1, 0.1, 0.001)
    theirs = ri.filterpy_smoothed(track, kind, q)
    z, r, priors = ri._filterpy_inputs(track, gnss=False)
    model = (at.models.ConstantVelocity if kind == "cv" else at.models.ConstantAcceleration)(
        q, n_axes=3
    )
    run = at.kalman_filter(times, z, model, ["x", "y", "z"], r,
                           priors[0 if kind == "cv" else 1])  # fmt: skip
    ours = at.rts_smooth(run).mean[:, :3]
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-6)
    assert np.sqrt(np.mean((ours - truth) ** 2)) < np.sqrt(np.mean((z - truth) ** 2))


def test_recorded_imm_online_run_is_the_fitted_run_before_its_first_refit():
    """The benchmark's causal refitting wiring: two radar stretches of 50 plots (fewer than
    the 120 a CV + CT IMM's six parameters need before a refit) give each stretch's own
    filtered run with the starting parameters, to the last bit."""
    import numpy as np
    from benchmarks import recorded_imm as ri

    rng = np.random.default_rng(6)
    tracks = []
    for start in (0.0, 120.0):
        times = start + 4.8 * np.arange(50)
        truth = np.stack([20e3 + 150.0 * times, 30e3 - 40.0 * times,
                          np.full(times.size, 3000.0)], -1)  # fmt: skip
        horiz = np.hypot(truth[:, 0], truth[:, 1])
        polar = np.stack([np.linalg.norm(truth, axis=1), np.arctan2(truth[:, 0], truth[:, 1]),
                          np.arctan2(truth[:, 2], horiz)], -1)  # fmt: skip
        plots = polar + rng.standard_normal(polar.shape) * np.sqrt(np.diag(ri.R_POLAR))
        tracks.append(ri.Track("synthetic", times, plots, truth))
    start = ri.START["cv+ct", False]
    online = ri.ours_online(tracks, "cv+ct", start)
    for est, track in zip(online, tracks, strict=True):
        fixed = ri.ours_run(track, "cv+ct", start).filtered.mean[:, :3]
        np.testing.assert_array_equal(est, fixed)


def test_recorded_imm_linear_filter_bound_of_a_parked_car_is_the_running_mean():
    """For a car standing still (truth constant) and white fix noise, the best linear filter
    of the last N fixes is their mean: RMSE sqrt(sum sigma^2 / N). The training weights are
    fitted on 20,000 fixes and scored on 20,000 others; the moving-average errors leave about
    20,000 / N independent squares, so the RMSE's relative spread is about sqrt(N / 20,000) / 2
    (1.1 %); the tolerance is 4 % (3.5 sigma)."""
    import numpy as np
    from benchmarks import recorded_imm as ri

    rng = np.random.default_rng(11)
    taps, n = 10, 20_000
    std = np.array(ri.GNSS_STD_M)
    tracks = []
    for start in (0.0, 2000.0):
        times = start + 0.1 * np.arange(n)
        truth = np.broadcast_to([120.0, -40.0, 15.0], (n, 3))
        tracks.append(ri.Track("parked", times, truth + rng.standard_normal((n, 3)) * std, truth))
    expected = np.sqrt(np.sum(std**2) / taps)
    assert ri.linear_filter_rmse(*tracks, taps) == pytest.approx(expected, rel=0.04)


def test_point_cloud_stats_of_a_known_cloud():
    """Frame statistics against a cloud built with known counts, spreads and Doppler steps."""
    import numpy as np
    import pandas as pd
    from benchmarks.point_cloud_stats import frame_stats

    rng = np.random.default_rng(3)
    counts = np.tile([40, 80], 200)  # mean 60, variance 400
    frame = np.repeat(np.arange(counts.size), counts)
    n = frame.size
    v = 0.44 * rng.integers(-3, 4, n)  # quantised, 1/7 of them zero
    pts = pd.DataFrame({"frame": frame, "a": rng.normal(0, 0.2, n), "d": rng.normal(0, 0.1, n),
                        "h": rng.normal(0, 0.5, n), "v": v})  # fmt: skip
    s = frame_stats(pts, "a", "d", "h")
    assert (s["points q10"], s["points median"], s["points q90"]) == (40, 60, 80)
    assert s["points mean"] == 60 and s["points var/mean"] == pytest.approx(400 / 60, rel=0.01)
    assert s["doppler step [m/s]"] == pytest.approx(0.44, abs=1e-4)
    assert s["zero doppler [%]"] == pytest.approx(100 / 7, abs=1.0)  # 24,000 points: sd 0.23 %
    # interquartile sigma per frame of 40-80 points: its median over frames ~3 % low
    assert s["spread along [m]"] == pytest.approx(0.2, rel=0.05)
    assert s["spread depth [m]"] == pytest.approx(0.1, rel=0.05)
    assert s["spread vertical [m]"] == pytest.approx(0.5, rel=0.05)


def test_point_cloud_stats_fits_and_reports_a_synthetic_recording(tmp_path, capsys, monkeypatch):
    """The script end to end on a recording in the TI layout written here (no shared data)."""
    import sys

    import numpy as np
    import pandas as pd
    from benchmarks import point_cloud_stats as pcs

    rng = np.random.default_rng(5)
    rows = []
    for k in range(120):  # a person 2.5 m from the sensor walking to and fro along z
        z = -3.0 + 6.0 * abs((k * 0.1 * 1.2 / 6.0) % 2 - 1)
        for _ in range(rng.poisson(15) + 1):
            rows.append((k, rng.normal(0, 0.4), 2.5 + rng.normal(0, 0.15),
                         z + rng.normal(0, 0.15), 0.44 * rng.integers(-2, 3)))  # fmt: skip
    table = pd.DataFrame(rows, columns=["frameNumber", "x", "y", "z", "v"])
    table.to_csv(tmp_path / "ti_awr1843_man_walk.csv", index=False)
    table.to_csv(tmp_path / "ti_awr1843_man_run.csv", index=False)
    monkeypatch.setattr(sys, "argv", ["point_cloud_stats", str(tmp_path)])
    pcs.main()
    out = capsys.readouterr().out
    assert "fitted on man_walk" in out and "man_run (held out" in out
    mean = next(line for line in out.splitlines() if "points mean" in line).split()
    assert float(mean[-1]) == pytest.approx(float(mean[-3]), rel=0.15)  # the fitted mean


def test_crossing_clearance_runs_its_trials(capsys):
    from benchmarks.crossing_clearance import main

    main(["--trials", "2", "--empty-s", "20"])
    out = capsys.readouterr().out
    assert "placed" in out and "stalled" in out and "false 'not clear'" in out
    rows = [line.split() for line in out.splitlines() if line.startswith(("placed", "stalled"))]
    assert all(row[1] == "2" and row[2] == "2" for row in rows)  # both raised within 1 s


def test_ti_radar_tracks_gives_one_track_per_pass_of_a_synthetic_walker(tmp_path, capsys):
    """The script end to end on a point cloud in the TI layout written here (no shared data)."""
    import numpy as np
    import pandas as pd
    from benchmarks.ti_radar_tracks import main

    rng = np.random.default_rng(8)
    rows = []
    speed, span, depth = 1.3, 8.0, 2.5
    for k in range(400):  # 40 s: five passes to and fro along z, 2.5 m in front of the sensor
        s = k * 0.1 * speed / span
        z = -0.5 * span + span * abs(s % 2 - 1)
        vz = speed * (1 if (s % 2) >= 1 else -1)
        radial = vz * z / np.hypot(z, depth)
        for _ in range(rng.poisson(15) + 1):
            rows.append((k, rng.normal(0, 0.3), depth + rng.normal(0, 0.15),
                         z + rng.normal(0, 0.15), 0.44 * np.round(radial / 0.44)))  # fmt: skip
    pd.DataFrame(rows, columns=["frameNumber", "x", "y", "z", "v"]).to_csv(
        tmp_path / "ti_awr1843_man_walk.csv", index=False
    )
    main([str(tmp_path), "--out", str(tmp_path / "tracks.png")])
    row = next(line for line in capsys.readouterr().out.splitlines() if "man_walk" in line)
    passes, tracks, per_pass, most, covered = row.split()[1:]
    assert int(passes) >= 4 and float(per_pass) == 1.0 and int(most) == 1
    assert int(tracks) <= 2 and float(covered.rstrip("%")) >= 90
    assert (tmp_path / "tracks.png").stat().st_size > 0
