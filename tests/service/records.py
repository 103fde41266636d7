"""The live tracker's output records, decoded, and the track rows among them."""

from __future__ import annotations

import json

import pandas as pd


def live_records(live, lines, source: str = "test") -> list[dict]:
    """The records ``live`` (a LiveTracker) writes for ``lines``, then released (a flush)."""
    out = []
    for line in lines:
        out += live.feed(line, source)
    out += live.flush()
    return [json.loads(x) for chunk in out for x in chunk.splitlines()]


def tracks_of(records: list[dict]) -> pd.DataFrame:
    """The track rows of decoded records (without their type)."""
    return pd.DataFrame([r for r in records if r["type"] == "track"]).drop(columns="type")
