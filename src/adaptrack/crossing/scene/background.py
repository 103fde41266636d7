"""The background of an empty site: where each radar sees standing reflectors when nothing is there.

Learnt at commissioning from a recording made while the crossing is known to be clear (no road
user in the zone): the stationary detections (radial speed within ``static_speed_mps``) of
each radar are counted per ground cell of ``cell_m`` and divided by that radar's scans, so
each cell holds the mean number of detections a scan gives there (a barrier post, a sign, the
rails); a cell seen in fewer than ``min_rate`` of the scans, with no such cell beside it,
holds no reflector (a false alarm falls in a given cell in about one scan in 10^5). Each
connected group of kept cells is one reflector, with the mean, covariance and rate of its
detections.

The extended tracker takes a stationary detection on a reflector's cells for the
reflector's where the reflector's density there (:meth:`BackgroundMap.density`) exceeds every
track's, so no track grows on a post, while the detections of a stalled car or a fallen load
beside it make a track of their own; an object standing on the reflector itself is found by
a CUSUM of its detections against the reflector's scatter and rate (the tracker's
``background_alarm_nats``). Saved as a NumPy ``.npz`` beside the site file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import label, maximum_filter

from ..._typing import FloatArray
from ..site.model import Site
from .detection_table import check_detection_table


@dataclass(frozen=True, eq=False)
class BackgroundMap:
    """Mean stationary detections per scan and ground cell, per radar (module docstring)."""

    radars: tuple[str, ...]
    origin_m: tuple[float, float]  # east, north of cell (0, 0)'s corner [m]
    cell_m: float
    rates: FloatArray  # (radars, east cells, north cells) [detections per scan]
    scans: np.ndarray  # (radars,) scans learnt from
    static_speed_mps: float = 0.5  # a detection this slow (|radial speed|) can be background
    regions: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0), np.int64))
    reflector_mean: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))  # (K, 2) [m]
    reflector_cov: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 2)))  # [m^2]
    reflector_rate: FloatArray = field(default_factory=lambda: np.zeros(0))  # per scan

    def reflectors_seen_by(self, radar: str) -> np.ndarray:
        """Return the indices (into ``reflector_*``) of the reflectors learnt for a radar."""
        if radar not in self.radars:
            return np.zeros(0, np.int64)
        found = np.unique(self.regions[self.radars.index(radar)])
        return found[found > 0] - 1

    def reflector_of(self, radar: str, xy: FloatArray) -> np.ndarray:
        """Return the reflector (index into ``reflector_*``) holding each point; -1: none."""
        pts = np.asarray(xy, float).reshape(-1, 2)
        out = np.full(pts.shape[0], -1)
        if radar not in self.radars:
            return out
        ij = np.floor((pts - self.origin_m) / self.cell_m).astype(int)
        ok = (ij >= 0).all(axis=1) & (ij < self.regions.shape[1:]).all(axis=1)
        out[ok] = self.regions[self.radars.index(radar), ij[ok, 0], ij[ok, 1]] - 1
        return out

    def density(self, reflector: np.ndarray, xy: FloatArray) -> FloatArray:
        """Return the reflectors' detections per m^2 and scan at points (N, 2) (0 at ``-1``).

        Each reflector's detections scatter as a Gaussian about their mean.
        """
        pts = np.asarray(xy, float).reshape(-1, 2)
        out = np.zeros(pts.shape[0])
        k = np.asarray(reflector)
        on = k >= 0
        if on.any():
            e = pts[on] - self.reflector_mean[k[on]]
            cov = self.reflector_cov[k[on]]
            inv = np.linalg.inv(cov)
            d2 = np.einsum("ni,nij,nj->n", e, inv, e)
            out[on] = self.reflector_rate[k[on]] * np.exp(-0.5 * d2) / (
                2 * np.pi * np.sqrt(np.linalg.det(cov)))  # fmt: skip
        return out

    def save(self, path: str | Path) -> None:
        """Write the map as ``.npz``."""
        np.savez_compressed(
            Path(path), radars=np.array(self.radars), origin_m=np.array(self.origin_m),
            cell_m=np.array(self.cell_m), rates=self.rates, scans=self.scans,
            static_speed_mps=np.array(self.static_speed_mps), regions=self.regions,
            reflector_mean=self.reflector_mean, reflector_cov=self.reflector_cov,
            reflector_rate=self.reflector_rate,
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
                    np.asarray(data["regions"], np.int64),
                    np.asarray(data["reflector_mean"], float),
                    np.asarray(data["reflector_cov"], float),
                    np.asarray(data["reflector_rate"], float),
                )  # fmt: skip
        except (KeyError, ValueError, OSError) as exc:
            raise ValueError(f"{path}: not a background map ({exc})") from None


REFLECTOR_FLOOR_M = 0.05  # a reflector's scatter is known no better than this [m]


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
    check_detection_table(detections)
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
    regions = np.zeros((len(radars), n, n), np.int64)
    scans = np.zeros(len(radars), np.int64)
    means: list[FloatArray] = []
    covs: list[FloatArray] = []
    per_scan: list[float] = []
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
        labels, count = label(rates[k] > 0)
        mine_cells = labels[i[ok], j[ok]]
        pts = np.stack([east[ok], north[ok]], -1)
        for r in range(1, count + 1):
            sel = pts[mine_cells == r]
            regions[k][labels == r] = len(means) + 1
            means.append(sel.mean(axis=0))
            # the scatter, with a floor: the learnt spread of a few dozen detections
            covs.append(np.cov(sel.T) + REFLECTOR_FLOOR_M**2 * np.eye(2) if len(sel) > 2
                        else REFLECTOR_FLOOR_M**2 * np.eye(2) * 4)  # fmt: skip
            per_scan.append(len(sel) / max(scans[k], 1))
    return BackgroundMap(
        tuple(radars),
        (float(origin[0]), float(origin[1])),
        float(cell_m),
        rates,
        scans,
        float(static_speed_mps),
        regions,
        np.array(means).reshape(-1, 2),
        np.array(covs).reshape(-1, 2, 2),
        np.array(per_scan),
    )


__all__ = ["BackgroundMap", "learn_background"]
