"""The benchmark runner works on tiny sizes (no timing is asserted: speed lives in benchmarks/)."""

import json

from benchmarks.runner import main


def test_benchmarks_quick_run_writes_json(tmp_path, capsys):
    path = tmp_path / "bench.json"
    main(["--quick", "--json", str(path)])
    out = json.loads(path.read_text())
    assert out["machine"]["cores"] >= 1
    impls = {(r["workload"], r["impl"]) for r in out["results"]}
    for workload in ("single", "batch"):
        for impl in ("adaptrack", "filterpy", "pykalman", "simdkalman"):
            assert (workload, impl) in impls
    assert all(r["per_step_us"] > 0 and r["track_steps_per_s"] > 0 for r in out["results"])
    assert "adaptrack is x faster" in capsys.readouterr().out
