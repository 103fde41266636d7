"""A table of raw radar detections as the extended tracker and the background map take it."""

from __future__ import annotations

import numpy as np
import pandas as pd

DETECTION_COLUMNS = ("radar", "time_s", "range_m", "azimuth_rad", "radial_speed_mps")


def check_detection_table(detections: pd.DataFrame) -> None:
    """Raise naming the missing columns, or the first row whose values are not finite numbers."""
    missing = [c for c in DETECTION_COLUMNS if c not in detections.columns]
    if missing:
        raise ValueError(
            f"detections: missing column(s) {missing}; found {list(detections.columns)}"
        )
    values = detections[list(DETECTION_COLUMNS[1:])].apply(pd.to_numeric, errors="coerce")
    bad = ~np.isfinite(values.to_numpy(float))
    if bad.any():
        row, col = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"detections: row {row + 1}, column {DETECTION_COLUMNS[1 + col]!r}: expected a "
            f"finite number; got {detections[DETECTION_COLUMNS[1 + col]].iloc[row]!r}"
        )


__all__ = ["DETECTION_COLUMNS", "check_detection_table"]
