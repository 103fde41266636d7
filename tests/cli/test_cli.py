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
        timeout=600,
        env={**os.environ, "COLUMNS": "200"},
    )


def test_demo_writes_summary(tmp_path):
    proc = run(
        "demo", "--runs", "2", "--seed", "3", "--out", str(tmp_path), "--workers", "1",
        "--training-runs", "1", "--validation-runs", "2", "--families", "cv,ca,m1,m2",
        "--scene-seconds", "40",
    )  # fmt: skip
    summary = json.loads((tmp_path / "summary.json").read_text())
    verdict = summary["test"]["summary"][summary["deployed"]]["verdict"]
    assert proc.returncode == {"pass": 0, "fail": 4, "undecided": 5}[verdict], proc.stderr
    said = {"pass": "complies", "fail": "does NOT comply", "undecided": "undecided"}[verdict]
    assert f"VERDICT: lx_default {said} with {summary['deployed']}" in proc.stdout
    assert "road EKF (M2)" in proc.stdout and "(deployed)" in proc.stdout
    test = summary["test"]
    assert test["runs"] == 2 and summary["seed"] == 3 and summary["site"]["name"] == "lx_default"
    rows = test["rows"]
    assert {r["vehicle_class"] for r in rows} == {"motorcycle", "car", "truck", "bus"}
    for r in rows:
        assert {"filter", "case", "position_rms_m", "position_upper_m", "verdict"} <= set(r)
    assert summary["deployed"] in {r["filter"] for r in rows}
    assert not list(tmp_path.glob("*.tmp"))
    assert "lambda_per_s2" in (tmp_path / "tuned.toml").read_text()
    assert {"candidates", "deployed", "m1_profile"} <= set(summary["selection"])
    html = (tmp_path / "report.html").read_text()
    assert "Pass/fail per estimator, class and case" in html
    mixed = summary["mixed_traffic"]  # the scene tracker on 40 s of the site's traffic
    assert mixed["duration_s"] == 40.0 and mixed["classes"] and "mixed traffic, 40 s" in proc.stdout
    assert "id='mixed-classes'" in html
    # the report command re-renders from the summary
    proc = run("report", str(tmp_path / "summary.json"), "--out", str(tmp_path / "again.html"))
    assert proc.returncode == 0, proc.stderr
    again = (tmp_path / "again.html").read_text()
    assert "Verdict on the test runs" in again and "id='mixed-classes'" in again
    proc = run("report", str(tmp_path / "report.html"), "--out", str(tmp_path / "x.html"))
    assert proc.returncode == 1 and "not a demo summary" in proc.stderr
    broken = tmp_path / "broken.json"  # a mixed-traffic section with fields missing
    broken.write_text(json.dumps({**summary, "mixed_traffic": {"seed": 1}}))
    proc = run("report", str(broken), "--out", str(tmp_path / "y.html"))
    assert proc.returncode == 1 and "not a demo summary" in proc.stderr
    assert proc.stderr.count("\n") == 1 and not (tmp_path / "y.html").exists()


def test_usage_and_user_errors():
    assert run("demo", "--runs", "0").returncode == 2
    assert run("no-such-command").returncode == 2
    proc = run("demo", "--site", "nowhere")
    assert proc.returncode == 1 and proc.stderr.startswith("error: unknown site 'nowhere'")
