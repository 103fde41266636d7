"""Input lines (one detection each) and output records (JSON objects, one per line).

Input: a JSON object ``{"radar": "radar_A", "time_s": 12.05, "range_m": 41.3,
"azimuth_rad": 0.21, "radial_speed_mps": -8.4}`` (``azimuth_deg`` instead of ``azimuth_rad``
accepted), or a CSV row in the column order of a scene detection file
(``radar,time_s,range_m,azimuth_rad,radial_speed_mps``; its header line is skipped). Azimuth
clockwise from north, radial speed positive away from the radar, time the radar's timestamp
[s].

Output records carry ``"type"``: ``"track"`` (the columns of offline ``adaptrack track``),
``"event"`` (a hazard event), ``"rejection"`` (an input that was not used, with its reason)
and ``"stats"`` (the counters).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import orjson

CSV_HEADER = "radar,time_s,range_m,azimuth_rad,radial_speed_mps"
FIELDS = ("time_s", "range_m", "azimuth_rad", "radial_speed_mps")


@dataclass(frozen=True)
class Detection:
    """One detection: radar, timestamp [s], slant range [m], azimuth [rad], radial speed [m/s]."""

    radar: str
    time_s: float
    range_m: float
    azimuth_rad: float
    radial_speed_mps: float


class Rejected(ValueError):
    """An input line that cannot be used: ``reason`` (a short key) and ``detail`` (a sentence)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def is_header(line: str) -> bool:
    """Whether ``line`` is the CSV header (or blank): not a detection."""
    text = line.strip()
    return not text or text.replace(" ", "") == CSV_HEADER


def parse_line(line: str, radars: frozenset[str] | set[str]) -> Detection:
    """Parse one input line (JSON object or CSV row) of a site with ``radars``.

    Raises :class:`Rejected` (reasons ``malformed``, ``unknown_radar``, ``not_finite``,
    ``bad_range``) naming the field and what was expected.
    """
    text = line.strip()
    raw: list[object]
    if text.startswith(("{", "[")):
        values = _json_fields(text)
        radar = str(values["radar"])
        raw = [values[name] for name in FIELDS]
    else:
        radar, *parts = text.split(",")  # float() ignores the spaces around a number
        radar, raw = radar.strip(), list(parts)
        if len(raw) != 4:
            raise Rejected("malformed", f"expected 5 CSV fields ({CSV_HEADER}); got {len(raw) + 1}")
    if radar not in radars:
        raise Rejected("unknown_radar", f"radar {radar!r}; the site has {sorted(radars)}")
    numbers = [_number(name, v) for name, v in zip(FIELDS, raw, strict=True)]
    for name, v in zip(FIELDS, numbers, strict=True):
        if not math.isfinite(v):
            raise Rejected("not_finite", f"field {name!r} is {v}")
    if numbers[1] <= 0:
        raise Rejected("bad_range", f"field 'range_m' must be > 0; got {numbers[1]}")
    return Detection(radar, *numbers)


def _number(name: str, value: object) -> float:
    """Return ``value`` as a float, or raise a rejection naming the field."""
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise Rejected("malformed", f"field {name!r}: {value!r} is not a number") from None


def _json_fields(text: str) -> dict[str, object]:
    """Fields of a JSON detection (``azimuth_deg`` converted to radians)."""
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise Rejected("malformed", f"not JSON ({exc.msg} at column {exc.colno})") from None
    if not isinstance(obj, dict):
        raise Rejected("malformed", "a JSON detection must be an object")
    if "azimuth_rad" not in obj and "azimuth_deg" in obj:
        try:
            obj["azimuth_rad"] = math.radians(float(obj["azimuth_deg"]))
        except (TypeError, ValueError):
            raise Rejected("malformed", f"field 'azimuth_deg': {obj['azimuth_deg']!r}") from None
    missing = [k for k in ("radar", *FIELDS) if k not in obj]
    if missing:
        raise Rejected("malformed", f"missing field(s) {missing}")
    return obj


def record_line(record: dict[str, object]) -> str:
    """Return one output record as a JSON line (``orjson``: NaN and inf written as null)."""
    return (orjson.dumps(record, option=orjson.OPT_SERIALIZE_NUMPY) + b"\n").decode()


__all__ = ["CSV_HEADER", "Detection", "Rejected", "is_header", "parse_line", "record_line"]
