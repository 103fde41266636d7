"""The report's mixed-traffic section: a short scored scene, its JSON round trip, its HTML."""

import copy
import json

import numpy as np
import pytest

from adaptrack.crossing.site.drawing import site_layers
from adaptrack.crossing.site.model import load_site, site_from_mapping
from adaptrack.crossing.studies.compliance import verdict_of
from adaptrack.crossing.studies.mixed_traffic import (
    MixedTraffic,
    mixed_traffic_html,
    mixed_traffic_study,
)
from tests.browser import render_in_chromium
from tests.crossing.test_report import SMALL

SITE = load_site("lx_default")


@pytest.fixture(scope="module")
def study():
    return mixed_traffic_study(SITE, seed=5, duration_s=60.0)


def test_the_study_scores_every_class_it_saw(study):
    assert study.road_users > 5 and study.detections > 10 * study.road_users
    seen = {c["class"] for c in study.classes}
    assert seen and seen <= set(SITE.classes) | {"pedestrian", "cyclist"}
    for c in study.classes:
        assert c["position_upper_m"] >= c["position_rms_m"] or np.isnan(c["position_upper_m"])
        assert c["verdict"] in ("pass", "fail", "undecided")
        assert 0 < c["coverage"] <= 1 and c["epochs"] >= c["vehicles"] >= 1
    series = study.gospa_series
    assert len(series["time_s"]) == len(series["gospa"]) > 100  # every 0.5 s of the minute
    assert study.gospa_mean == pytest.approx(np.mean(series["gospa"]))
    assert study.track_paths and study.truth_paths


def test_json_round_trip_keeps_nan_as_missing(study):
    text = json.dumps(study.to_json(), allow_nan=False)  # strict JSON: NaN written as null
    again = MixedTraffic.from_json(json.loads(text))
    assert again.to_json() == study.to_json()
    assert json.loads(text)["classes"] == again.to_json()["classes"]


def test_the_section_renders_in_chromium(study, tmp_path):
    roads, radars = site_layers(SITE)
    parts = mixed_traffic_html(study, roads, radars, SITE.zone_m)
    body = "".join(parts)
    for element in ("id='mixed'", "id='mixed-map'", "id='mixed-gospa'", "id='mixed-timeline'",
                    "id='mixed-events'", "id='mixed-classes'"):  # fmt: skip
        assert element in body
    assert body.count("<tr class=") == len(study.classes)
    page = tmp_path / "mixed.html"
    head = "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'></head>"
    page.write_text(f"{head}<body>{body}</body></html>")
    shown = render_in_chromium(page, tmp_path, height_px=1800)
    assert shown.screenshot_bytes > 20_000, shown.log[-2000:]
    assert "Uncaught" not in shown.log and shown.dom.count("<svg") == 3


def test_a_site_without_a_scene_says_why():
    site = site_from_mapping(copy.deepcopy(SMALL), "small.toml")
    with pytest.raises(ValueError, match="no traffic flow"):
        mixed_traffic_study(site, seed=1, duration_s=30.0)


@pytest.mark.parametrize(
    ("rms", "lower", "upper", "expected"),
    [
        ([0.5, 1.0], [0.4, 0.8], [0.6, 1.5], "pass"),
        ([0.8, 1.0], [0.71, 0.8], [0.9, 1.5], "fail"),  # position's lower bound beyond 0.7 m
        ([0.6, 1.9], [0.5, 1.7], [0.75, 2.2], "undecided"),
        ([0.5, np.nan], [0.4, np.nan], [0.6, np.nan], "pass"),  # speed not scored
        ([np.nan, 1.0], [np.nan, 0.8], [np.nan, 1.5], "undecided"),  # position must be scored
    ],
)
def test_verdict_of_bounds(rms, lower, upper, expected):
    limits = np.array([0.7, 2.0])
    assert verdict_of(np.array(rms), np.array(lower), np.array(upper), limits) == expected


def test_from_json_names_a_missing_or_unknown_field(study):
    data = study.to_json()
    with pytest.raises(ValueError, match="missing field 'seed'$"):
        MixedTraffic.from_json({k: v for k, v in data.items() if k != "seed"})
    with pytest.raises(ValueError, match=r"unknown field 'colour' \(and 1 more\)"):
        MixedTraffic.from_json({**data, "colour": 1, "size": 2})
