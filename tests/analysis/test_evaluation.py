"""Scenario evaluation and the `adaptrack evaluate` command."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from adaptrack.analysis.evaluation import evaluate_scenario, interval_masks
from adaptrack.simulation.scenario import load_scenario


def test_interval_masks_close_the_last_interval():
    sc = load_scenario("zimchuk_table1")
    t = 0.1 * np.arange(701)
    m = interval_masks(sc, t)
    assert list(m) == ["0-20", "20-30", "30-50", "50-70"]
    assert m["50-70"][-1] and not m["20-30"][300] and m["30-50"][300]
    assert sum(int(v.sum()) for v in m.values()) == 701


@pytest.mark.slow
def test_evaluation_on_table1_scenario():
    ev = evaluate_scenario(load_scenario("zimchuk_table1"), 10, 3, train_runs=4, profile_points=4)
    rows = {r.filter: r for r in ev.rows}
    cv = next(r for name, r in rows.items() if name.startswith("CV-KF (DWNA"))
    imm = rows["IMM (CV + CA + M2)"]
    # the IMM follows the manoeuvres the CV-KF (DWNA 22) cannot
    assert imm.rmse_m["20-30"] < 0.5 * cv.rmse_m["20-30"]
    assert imm.rmse_m["50-70"] < 0.5 * cv.rmse_m["50-70"]
    out = ev.to_json()
    assert set(out) >= {"scenario", "runs", "seed", "rows"}
    assert all(set(r["rmse_m"]) == {"0-20", "20-30", "30-50", "50-70"} for r in out["rows"])
    json.dumps(out)


@pytest.mark.slow
def test_evaluate_cli_writes_json(tmp_path):
    path = tmp_path / "ev.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "adaptrack",
            "evaluate",
            "atc_turns",
            "--runs",
            "5",
            "--train-runs",
            "3",
            "--profile-points",
            "3",
            "--json",
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "COLUMNS": "250"},
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(path.read_text())
    assert out["scenario"] == "atc_turns" and out["runs"] == 5
    assert {"0-125", "125-215"} <= set(out["rows"][0]["rmse_m"])
    bad = subprocess.run(
        [sys.executable, "-m", "adaptrack", "evaluate", "nope"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 1
    assert bad.stderr.strip().startswith("error: unknown scenario 'nope'")
    assert "Traceback" not in bad.stderr
