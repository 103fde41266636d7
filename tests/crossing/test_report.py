"""The HTML compliance report: plain data, self-containment, rendering in headless Chromium."""

import os
import re
import shutil
import subprocess

import pytest

from adaptrack.crossing.compliance import evaluate_site
from adaptrack.crossing.report import build_report, render_html, sample_tracks
from adaptrack.crossing.site import load_site
from adaptrack.crossing.traffic import DEFAULT_CASES, VEHICLES


@pytest.fixture(scope="module")
def report_html():
    site = load_site("lx_default")
    res = evaluate_site(site, 2, 0, cases=DEFAULT_CASES[2:4], classes={"car": VEHICLES["car"]})
    data = build_report(res, site, samples=sample_tracks(site, 0))
    assert len(data.rows) == 2 * 5 and len(data.samples) == 2  # plain data first
    return render_html(data)


def test_report_is_self_contained(report_html):
    assert "<script" not in report_html
    assert not re.search(r"(src|href)\s*=\s*['\"]?(https?:)?//", report_html)
    urls = set(re.findall(r"https?://[^\s\"'<>]+", report_html))
    assert urls <= {"http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink"}
    for element in ("id='worst'", "id='passfail-table'", "id='map'", "id='errors'", "id='rms'"):
        assert element in report_html


def test_user_strings_are_escaped():
    import dataclasses

    site = load_site("lx_default")
    res = evaluate_site(site, 1, 0, cases=DEFAULT_CASES[3:4], classes={"car": VEHICLES["car"]})
    data = build_report(res, site, samples=[])
    evil = "<script>alert(1)</script>"
    rows = [{**r, "filter": evil} for r in data.rows]
    html = render_html(dataclasses.replace(data, site=evil, title=evil, rows=rows))
    assert evil not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_report_renders_in_headless_chromium(report_html, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium must be installed in CI (.ci/run installs Debian chromium)")
        pytest.skip("chromium is not installed on this machine; CI installs it")
    page = tmp_path / "report.html"
    page.write_text(report_html)
    shot = tmp_path / "shot.png"
    flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--enable-logging=stderr",
        "--v=0",
    ]
    proc = subprocess.run(
        [chromium, *flags, f"--screenshot={shot}", "--window-size=1100,2600", page.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert shot.exists() and shot.stat().st_size > 20_000, proc.stderr[-2000:]
    assert "CONSOLE" not in proc.stderr and "Uncaught" not in proc.stderr
    dom = subprocess.run(
        [chromium, *flags, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120
    ).stdout
    assert "Pass/fail per estimator, class and case" in dom and "<svg" in dom


def test_profile_figure_shows_the_cv_member():
    site = load_site("lx_default")
    res = evaluate_site(site, 1, 0, cases=DEFAULT_CASES[3:4], classes={"car": VEHICLES["car"]})
    profile = {
        "lambda_per_s2": [0.0, 0.01, 0.1],
        "criterion": [0.2, 0.21, 0.25],
        "accel_psd": [0.4, 0.5, 1.0],
    }
    html = render_html(build_report(res, site, samples=[], profile=profile))
    assert "id='profile'" in html and "lambda = 0 (constant velocity)" in html
