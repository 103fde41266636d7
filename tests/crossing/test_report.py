"""The HTML compliance report: plain data, self-containment, rendering in headless Chromium."""

import copy
import re

import pytest

from adaptrack.crossing.compliance import evaluate_site
from adaptrack.crossing.report import build_report, render_html, sample_tracks
from adaptrack.crossing.selection import select_estimator
from adaptrack.crossing.site import site_from_mapping
from tests.browser import render_in_chromium

# a small site written as a user would: one arm, a near and a far field, two cases
SMALL = {
    "name": "small",
    "description": "One curved arm; ARS408-like near/far fields.",
    "traffic": {"mix": {"car": 0.8, "bus": 0.2}},
    "roads": [
        {
            "name": "west",
            "heading_deg": 270.0,
            "elements": [
                {"kind": "straight", "length_m": 40.0},
                {"kind": "arc", "radius_m": 120.0, "angle_deg": 40.0, "turn": "left"},
                {"kind": "straight", "length_m": 120.0},
            ],
        }
    ],
    "radars": [
        {
            "name": "pole",
            "position_m": [-3.0, 6.0],
            "boresight_deg": 280.0,
            "period_s": 0.072,
            "fields": [
                {"max_range_m": 70.0, "fov_half_deg": 60.0},
                {"max_range_m": 250.0, "fov_half_deg": 20.0},
            ],
            "range_std_m": [[0.0, 0.2], [250.0, 0.5]],
            "azimuth_std_deg": [[0.0, 0.2], [60.0, 1.0]],
            "radial_speed_std_mps": 0.15,
        }
    ],
    "cases": [
        {"name": "pass_50", "road": "west", "kind": "pass", "speed_kmh": 50.0},
        {"name": "stop_go", "road": "west", "kind": "stop", "speed_kmh": 50.0, "dwell_s": 5.0},
    ],
}


@pytest.fixture(scope="module")
def small_report():
    site = site_from_mapping(copy.deepcopy(SMALL), "small.toml")
    tuning, validation = select_estimator(
        site, seed=1, training_runs=2, validation_runs=3, families=("cv", "ca", "m1")
    )
    winner = tuning.winner
    test = evaluate_site(site, 3, 5, trackers={winner.label: winner.tracker()})
    data = build_report(
        test,
        site,
        samples=sample_tracks(site, 0, winner.tracker()),
        deployed=winner.label,
        tuning=tuning,
        validation=validation,
    )
    return data, render_html(data)


def test_report_data_shows_every_candidate_and_the_bound(small_report):
    data, _ = small_report
    assert [c["family"] for c in data.candidates] == ["cv", "ca", "m1"]
    assert sum(c["deployed"] for c in data.candidates) == 1
    for c in data.candidates:  # validation results and the ratio to the PCRLB are there
        assert 0 < c["validation_criterion"] < 1 and 0 < c["pcrlb_position_ratio"] < 20
        assert c["worst_case"].startswith(("car / ", "bus / "))
    assert data.selection["reason"].startswith(data.deployed)
    assert len(data.rows) == 2 * 2 and len(data.samples) == 2  # plain data first
    assert data.profile["lambda_per_s2"][0] == 0.0


def test_report_is_self_contained(small_report):
    _, html = small_report
    assert "<script" not in html
    assert not re.search(r"(src|href)\s*=\s*['\"]?(https?:)?//", html)
    urls = set(re.findall(r"https?://[^\s\"'<>]+", html))
    assert urls <= {"http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink"}
    for element in (
        "id='verdict'",
        "id='worst'",
        "id='candidates'",
        "id='map'",
        "id='blind'",
        "id='errors'",
        "id='rms'",
        "id='profile'",
        "id='passfail-table'",
    ):
        assert element in html
    assert "(deployed)" in html and "RMS / PCRLB" in html


def test_user_strings_are_escaped(small_report):
    import dataclasses

    data, _ = small_report
    evil = "<script>alert(1)</script>"
    rows = [{**r, "filter": evil} for r in data.rows]
    html = render_html(
        dataclasses.replace(data, site=evil, title=evil, rows=rows, description=evil)
    )
    assert evil not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_report_renders_in_headless_chromium(small_report, tmp_path):
    page = tmp_path / "report.html"
    page.write_text(small_report[1])
    shown = render_in_chromium(page, tmp_path)
    assert shown.screenshot_bytes > 20_000, shown.log[-2000:]
    assert "CONSOLE" not in shown.log and "Uncaught" not in shown.log
    assert "Pass/fail per estimator, class and case" in shown.dom and "<svg" in shown.dom
    assert "Design-time selection" in shown.dom


def test_profile_figure_shows_the_cv_member(small_report):
    import dataclasses

    data, _ = small_report
    profile = {"lambda_per_s2": [0.0, 0.01, 0.1], "criterion": [0.2, 0.21, 0.25]}
    html = render_html(dataclasses.replace(data, profile=profile))
    assert "id='profile'" in html and "lambda = 0 (constant velocity)" in html
