"""A clutter map learnt online: how many unexplained measurements a sensor gives per m^2 and scan.

The plane is cut into square cells of ``cell_m``; each cell counts the measurements that no
track explained, forgetting with the factor ``1 - 1 / memory_scans`` per scan of its sensor, so
that it follows a site whose clutter changes (rain, a parked lorry) over ``memory_scans``
scans. Its density estimate is the posterior mean of a Poisson rate with a gamma prior worth
``prior_scans`` scans at ``prior_density`` (per m^2 per scan): a cell never seen keeps the
prior, a cell that gives clutter every scan tends to one measurement per cell area and scan.
Decay is applied lazily (a cell remembers the scan of its last change).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._typing import FloatArray


@dataclass
class ClutterMap:
    """Per-cell clutter density of one sensor (module docstring); east/north in metres."""

    prior_density: float  # per m^2 per scan
    cell_m: float = 5.0
    memory_scans: float = 20000.0
    prior_scans: float = 200.0
    _count: dict[tuple[int, int], tuple[float, int]] = field(default_factory=dict, repr=False)
    scans: int = 0  # scans seen

    def __post_init__(self) -> None:
        for name in ("prior_density", "cell_m", "memory_scans", "prior_scans"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"ClutterMap.{name} must be finite and > 0; got {value}")

    @property
    def _keep(self) -> float:
        """The per-scan forgetting factor."""
        return 1.0 - 1.0 / self.memory_scans

    def _cells(self, xy: FloatArray) -> np.ndarray:
        """Return the cells (N, 2) of ground points (N, 2); a non-finite point is an error."""
        pts = np.asarray(xy, float).reshape(-1, 2)
        if not np.isfinite(pts).all():
            row = int(np.argwhere(~np.isfinite(pts))[0, 0])
            raise ValueError(f"ClutterMap: point {row} is not finite: {pts[row].tolist()}")
        return np.floor(pts / self.cell_m).astype(np.int64)

    def density(self, xy: FloatArray) -> FloatArray:
        """Clutter density at ground points (N, 2) [per m^2 per scan]."""
        cells = self._cells(xy)
        keep = self._keep
        # the scans' weight decays like the counts: sum of keep^k over the scans seen
        weight = (1.0 - keep**self.scans) / (1.0 - keep)
        area = self.cell_m**2
        out = np.empty(cells.shape[0])
        for k, (i, j) in enumerate(cells.tolist()):
            count, last = self._count.get((i, j), (0.0, self.scans))
            count *= keep ** (self.scans - last)
            out[k] = (count + self.prior_density * area * self.prior_scans) / (
                (weight + self.prior_scans) * area
            )
        return out

    def end_scan(self, unexplained_xy: FloatArray) -> None:
        """Count a scan's unexplained measurements (N, 2) and close the scan."""
        self.scans += 1
        keep = self._keep
        for i, j in self._cells(unexplained_xy).tolist():
            count, last = self._count.get((i, j), (0.0, self.scans))
            self._count[(i, j)] = (count * keep ** (self.scans - last) + 1.0, self.scans)


__all__ = ["ClutterMap"]
