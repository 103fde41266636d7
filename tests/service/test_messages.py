"""Input lines of the live service: what is a detection, and why a line is rejected."""

import json
import math

import pytest

from adaptrack.service.messages import Detection, Rejected, is_header, parse_line, record_line

RADARS = frozenset({"radar_A", "radar_B"})


def test_json_and_csv_lines_give_the_same_detection():
    csv = parse_line("radar_A,12.5,41.25,0.21,-8.5\n", RADARS)
    js = parse_line(
        '{"radar": "radar_A", "time_s": 12.5, "range_m": 41.25, "azimuth_rad": 0.21, '
        '"radial_speed_mps": -8.5}',
        RADARS,
    )
    assert csv == js == Detection("radar_A", 12.5, 41.25, 0.21, -8.5)


def test_azimuth_in_degrees_is_converted_once():
    d = parse_line(
        json.dumps(
            {
                "radar": "radar_B",
                "time_s": 1,
                "range_m": 30,
                "azimuth_deg": 90,
                "radial_speed_mps": 0,
            }
        ),
        RADARS,
    )
    assert d.azimuth_rad == pytest.approx(math.pi / 2, rel=1e-15)


@pytest.mark.parametrize(
    ("line", "reason", "words"),
    [
        ("\x00\xff garbage", "malformed", "expected 5 CSV fields"),
        ("{not json", "malformed", "not JSON"),
        ("[1, 2]", "malformed", "must be an object"),
        ('{"radar": "radar_A", "time_s": 1}', "malformed", "missing field"),
        ("radar_C,1,30,0.1,2", "unknown_radar", "'radar_C'; the site has"),
        ("radar_A,1,30,abc,2", "malformed", "'azimuth_rad': 'abc' is not a number"),
        ("radar_A,nan,30,0.1,2", "not_finite", "'time_s' is nan"),
        ('{"radar": "radar_A", "time_s": 1, "range_m": Infinity, "azimuth_rad": 0,'
         ' "radial_speed_mps": 0}', "not_finite", "'range_m' is inf"),
        ("radar_A,1,-3,0.1,2", "bad_range", "must be > 0"),
    ],
)  # fmt: skip
def test_bad_lines_are_rejected_with_a_reason_naming_the_field(line, reason, words):
    with pytest.raises(Rejected) as info:
        parse_line(line, RADARS)
    assert info.value.reason == reason
    assert words in info.value.detail


def test_header_and_blank_lines_are_not_detections():
    assert is_header("radar,time_s,range_m,azimuth_rad,radial_speed_mps\n")
    assert is_header("  \n")
    assert not is_header("radar_A,1,30,0.1,2")


def test_records_are_one_json_line_with_nan_as_null():
    line = record_line({"type": "event", "lead_s": float("nan"), "track_id": 3})
    assert line.endswith("\n") and line.count("\n") == 1
    assert json.loads(line) == {"type": "event", "lead_s": None, "track_id": 3}
