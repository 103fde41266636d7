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
        "radar_ekf",
        "radar_imm",
    ):
        assert (workload, "adaptrack") in impls
    assert ("scene", "stonesoup (GNN 2-D, EKF CV, same gate)") in impls
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
