"""The CLI run in a subprocess: exit codes and outputs."""

import json
import os
import subprocess
import sys


def run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "adaptrack", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
        env={**os.environ, "COLUMNS": "200"},
    )


def test_demo_writes_summary(tmp_path):
    proc = run("demo", "--runs", "5", "--seed", "3", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "Singer (matched)" in proc.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["n_runs"] == 5 and summary["seed"] == 3
    assert {r["filter"] for r in summary["rows"]} >= {"Singer (matched)", "constant velocity"}
    for row in summary["rows"]:
        assert row["position_rmse_m"] > 0 and row["smoothed_position_rmse_m"] > 0
    assert not list(tmp_path.glob("*.tmp"))


def test_demo_is_reproducible(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    run("demo", "--runs", "3", "--seed", "9", "--out", str(a))
    run("demo", "--runs", "3", "--seed", "9", "--out", str(b))
    assert (a / "summary.json").read_text() == (b / "summary.json").read_text()


def test_usage_error_exits_2():
    proc = run("demo", "--runs", "0")
    assert proc.returncode == 2
    proc = run("no-such-command")
    assert proc.returncode == 2
