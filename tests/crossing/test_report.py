"""The HTML compliance report: plain data, self-containment, rendering in headless Chromium."""

import copy
import json
import re

import pytest

from adaptrack.crossing.site.interactive import plotly_script
from adaptrack.crossing.site.model import site_from_mapping
from adaptrack.crossing.studies.compliance import evaluate_site
from adaptrack.crossing.studies.report import build_report, render_html, sample_tracks
from adaptrack.crossing.studies.selection import select_estimator
from tests.browser import chromium_executable

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
    library = plotly_script()
    assert html.count(library) == 1  # the plotting library, inlined once
    rest = html.replace(library, "")
    assert not re.search(r"<script[^>]*\bsrc\s*=", html) and "<link" not in html
    assert not re.search(r"(src|href)\s*=\s*['\"]?(https?:)?//", rest)
    urls = set(re.findall(r"https?://[^\s\"'<>]+", rest))
    assert urls <= {"http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink"}, urls
    for element in (
        "id='banner'",
        "id='matrix-table'",
        "id='verdict'",
        "id='worst'",
        "id='candidates'",
        "id='map'",
        'id="map-plot"',
        "id='blind'",
        'id="errors-plot"',
        "id='rms'",
        "id='profile'",
        "id='passfail-table'",
    ):
        assert element in html
    assert "(deployed)" in html and "RMS / PCRLB" in html
    assert html.index("id='banner'") < html.index("id='matrix-table'") < html.index("id='worst'")


def test_the_banner_and_the_matrix_say_the_verdict(small_report):
    import dataclasses

    data, html = small_report
    w = data.summary[data.deployed]
    said = {"pass": "COMPLIES", "fail": "DOES NOT COMPLY", "undecided": "UNDECIDED"}
    assert f"small: {said[w['verdict']]}</div>" in html
    mine = [r for r in data.rows if r["filter"] == data.deployed]
    assert html.count("<td class='m' ") == len(mine)  # one cell per class x case
    failing = dataclasses.replace(
        data,
        summary={**data.summary, data.deployed: {**w, "verdict": "fail", "fail": 1}},
        rows=[{**r, "verdict": "fail"} if r in mine[:1] else r for r in data.rows],
    )
    out = render_html(failing)
    assert "small: DOES NOT COMPLY</div>" in out and "background:#f2b8b8" in out


def test_user_strings_are_escaped(small_report):
    import dataclasses

    data, _ = small_report
    evil = "<script>alert(1)</script>"
    rows = [{**r, "filter": evil} for r in data.rows]
    html = render_html(
        dataclasses.replace(data, site=evil, title=evil, rows=rows, description=evil)
    )
    assert evil not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_report_renders_offline_in_headless_chromium(small_report, tmp_path):
    """The page in Chromium with every network request refused: banner, map, zoom."""
    from playwright.sync_api import sync_playwright

    page_file = tmp_path / "report.html"
    page_file.write_text(small_report[1])
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium_executable(), args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1200, "height": 900})
        errors, network = [], []
        page.on("pageerror", lambda e: errors.append(str(e)))

        def refuse(route):
            if not route.request.url.startswith(("file:", "data:", "blob:")):
                network.append(route.request.url)
                route.abort()
            else:
                route.continue_()

        page.route("**/*", refuse)
        page.goto(page_file.as_uri())
        banner = page.inner_text("#banner")
        assert banner.startswith("small: ") and "confidence" in banner
        page.wait_for_selector("#map-plot .main-svg", timeout=30_000)  # plotly drew the map
        assert page.locator("#map-plot .modebar-btn").count() > 3  # zoom/pan buttons
        assert page.locator("#errors-plot .main-svg").count() > 0
        before = page.evaluate("document.getElementById('map-plot')._fullLayout.xaxis.range")
        drag = page.locator("#map-plot .nsewdrag").first
        drag.scroll_into_view_if_needed()
        box = drag.bounding_box()
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.wheel(0, -400)  # scroll to zoom in
        page.wait_for_function(
            f"JSON.stringify(document.getElementById('map-plot')._fullLayout.xaxis.range)"
            f" != '{json.dumps(before, separators=(',', ':'))}'",
            timeout=10_000,
        )
        after = page.evaluate("document.getElementById('map-plot')._fullLayout.xaxis.range")
        assert after[1] - after[0] < before[1] - before[0]  # zoomed in
        shot = page.screenshot(full_page=False)
        browser.close()
    assert not errors and not network, (errors, network)
    assert len(shot) > 20_000


def test_profile_figure_shows_the_cv_member(small_report):
    import dataclasses

    data, _ = small_report
    profile = {"lambda_per_s2": [0.0, 0.01, 0.1], "criterion": [0.2, 0.21, 0.25]}
    html = render_html(dataclasses.replace(data, profile=profile))
    assert "id='profile'" in html and "lambda = 0 (constant velocity)" in html
