"""The background of an empty site: where each radar sees standing reflectors when nothing is there.

Learnt at commissioning from a recording made while the crossing is known to be clear (no road
user in the zone): the stationary detections (radial speed within ``static_speed_mps``) of
each radar are counted per ground cell of ``cell_m`` and divided by that radar's scans, so
each cell holds the mean number of detections a scan gives there (a barrier post, a sign, the
rails); a cell seen in fewer than ``min_rate`` of the scans, with no such cell beside it,
holds no reflector (a false alarm falls in a given cell in about one scan in 10^5). The extended tracker takes a stationary
detection for the background's where the background there is likelier than every track
(:meth:`BackgroundMap.density`), so no track grows on a post, while the detections of a
stalled car or a fallen load beside it, off the reflector's cells, make a track of their own.
An object standing exactly on a reflector's cell, seen as one point, is not told from it
(a test of the cell's detection count against its rate would). Saved as a NumPy ``.npz``
beside the site file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import maximum_filter

from ..._typing import FloatArray
from ..site.model import Site


@dataclass(frozen=True, eq=False)
class BackgroundMap:
    """Mean stationary detections per scan and ground cell, per radar (module docstring)."""

    radars: tuple[str, ...]
    origin_m: tuple[float, float]  # east, north of cell (0, 0)'s corner [m]
    cell_m: float
    rates: FloatArray  # (radars, east cells, north cells) [detections per scan]
    scans: np.ndarray  # (radars,) scans learnt from
    static_speed_mps: float = 0.5  # a detection this slow (|radial speed|) can be background

    def density(self, radar: str, xy: FloatArray) -> FloatArray:
        """The background's stationary detections per m^2 and scan at ground points (N, 2)."""
        pts = np.asarray(xy, float).reshape(-1, 2)
        if radar not in self.radars:
            return np.zeros(pts.shape[0])
        ij = np.floor((pts - self.origin_m) / self.cell_m).astype(int)
        ok = (ij >= 0).all(axis=1) & (ij < self.rates.shape[1:]).all(axis=1)
        out = np.zeros(pts.shape[0])
        out[ok] = self.rates[self.radars.index(radar), ij[ok, 0], ij[ok, 1]] / self.cell_m**2
        return out

    def save(self, path: str | Path) -> None:
        """Write the map as ``.npz``."""
        np.savez_compressed(
            Path(path), radars=np.array(self.radars), origin_m=np.array(self.origin_m),
            cell_m=np.array(self.cell_m), rates=self.rates, scans=self.scans,
            static_speed_mps=np.array(self.static_speed_mps),
        )  # fmt: skip

    @classmethod
    def load(cls, path: str | Path) -> BackgroundMap:
        """Read a map written by :meth:`save`; a file of another layout is an error naming it."""
        try:
            with np.load(Path(path), allow_pickle=False) as data:
                return cls(
                    tuple(str(r) for r in data["radars"]),
                    (float(data["origin_m"][0]), float(data["origin_m"][1])),
                    float(data["cell_m"]), np.asarray(data["rates"], float),
                    np.asarray(data["scans"], np.int64), float(data["static_speed_mps"]),
                )  # fmt: skip
        except (KeyError, ValueError, OSError) as exc:
            raise ValueError(f"{path}: not a background map ({exc})") from None


def learn_background(
    site: Site,
    detections: pd.DataFrame,
    *,
    cell_m: float = 0.5,
    static_speed_mps: float = 0.5,
    min_rate: float = 0.05,
) -> BackgroundMap:
    """Learn the background from detections of the empty site (columns as ``adaptrack track``).

    A cell is a reflector when it gives a stationary detection in at least ``min_rate`` of
    the scans (a false alarm falls in a given cell in about one scan in 10^5); the others are
    zero.
    """
    if not (np.isfinite(cell_m) and cell_m > 0):
        raise ValueError(f"cell_m must be finite and > 0; got {cell_m}")
    radars = {r.name: r for r in site.radars}
    unknown = sorted(set(detections["radar"].astype(str)) - set(radars))
    if unknown:
        raise ValueError(f"detections of radars the site does not have: {unknown}")
    reach = max(r.max_range_m for r in site.radars)
    centre = np.array([np.mean([r.position_m[0] for r in site.radars]),
                       np.mean([r.position_m[1] for r in site.radars])])  # fmt: skip
    origin = centre - reach
    n = int(np.ceil(2 * reach / cell_m))
    rates = np.zeros((len(radars), n, n))
    scans = np.zeros(len(radars), np.int64)
    for k, (name, radar) in enumerate(radars.items()):
        mine = detections[detections["radar"].astype(str) == name]
        t = mine["time_s"].to_numpy(float)
        # scans with no detection leave no row: count them from the scan period
        scans[k] = round((t.max() - t.min()) / radar.period_s) + 1 if t.size else 0
        still = mine[np.abs(mine["radial_speed_mps"].to_numpy(float)) <= static_speed_mps]
        rng = still["range_m"].to_numpy(float)
        az = still["azimuth_rad"].to_numpy(float)
        rho = np.sqrt(np.maximum(rng**2 - radar.height_m**2, 0.0))
        east = radar.position_m[0] + rho * np.sin(az)
        north = radar.position_m[1] + rho * np.cos(az)
        i = np.floor((east - origin[0]) / cell_m).astype(int)
        j = np.floor((north - origin[1]) / cell_m).astype(int)
        ok = (i >= 0) & (i < n) & (j >= 0) & (j < n)
        np.add.at(rates[k], (i[ok], j[ok]), 1.0)
        if scans[k]:
            rates[k] /= scans[k]
        # a reflector's cells and their neighbours (its scatter's tails) are kept
        rates[k][~maximum_filter(rates[k] >= min_rate, size=3)] = 0.0
    return BackgroundMap(tuple(radars), (float(origin[0]), float(origin[1])), float(cell_m),
                         rates, scans, float(static_speed_mps))  # fmt: skip


__all__ = ["BackgroundMap", "learn_background"]
