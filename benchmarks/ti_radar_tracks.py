"""The extended tracker on a real point-cloud radar: tracks per pass of a person or an e-scooter.

``python -m benchmarks.ti_radar_tracks DATA_DIR [--out tracks.png]`` reads the TI AWR1843
recordings ``ti_awr1843_*.csv`` of ``DATA_DIR`` (the README of ``../shared/data/roadusers``
describes them; they are never copied here), puts the sensor on a one-path site as
:mod:`benchmarks.point_cloud_stats` does (the path along the recording's axis of motion, the
radar beside it at the recording's median depth, 1 m up), converts every point to a detection
(slant range, azimuth, radial speed) and runs :func:`~adaptrack.crossing.scene.
extended_tracker.track_scene_extended` on them with its defaults. The recordings have no
truth: a pass is a run of frames whose points' median moves one way along the path (split where
it turns or where no point is seen for a second), and each reported track is matched to the
pass whose median lies within 2 m of it at that frame. Prints, per recording: passes, reported
tracks, tracks per pass (mean, max) and the share of the passes' frames a track covers; with
``--out``, draws the points' and the tracks' positions along the path against time.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from adaptrack.crossing.scene.extended_tracker import track_scene_extended
from adaptrack.crossing.site.model import site_from_mapping
from benchmarks.point_cloud_stats import FRAME_S, real_cloud, replay_site

MATCH_M = 2.0  # a track this near a pass's median belongs to it
GAP_S = 1.0  # no point for this long ends a pass


def detections_of(points: pd.DataFrame, radar_x: float, height_m: float) -> pd.DataFrame:
    """Detections (range, azimuth, radial speed) of the points, the radar at (radar_x, 0)."""
    east = radar_x - points["depth"].to_numpy()
    north = points["along"].to_numpy()
    ground = np.hypot(east - radar_x, north)
    return pd.DataFrame({
        "radar": "ti", "time_s": points["frame"].to_numpy() * FRAME_S,
        "range_m": np.hypot(ground, height_m),
        "azimuth_rad": np.arctan2(east - radar_x, north),
        "radial_speed_mps": points["v"].to_numpy(),
    })  # fmt: skip


def passes_of(points: pd.DataFrame) -> pd.DataFrame:
    """Each frame's median point along the path and its pass number (-1: standing)."""
    med = points.groupby("frame")["along"].median()
    frames = med.index.to_numpy()
    along = med.to_numpy()
    step = np.diff(along, prepend=along[0])
    smooth = pd.Series(step).rolling(5, center=True, min_periods=1).mean().to_numpy()
    direction = np.sign(smooth)
    new = np.zeros(frames.size, bool)
    new[1:] = (np.diff(frames) * FRAME_S > GAP_S) | (direction[1:] != direction[:-1])
    label = np.cumsum(new)
    keep = pd.Series(label).map(pd.Series(label).value_counts()) >= 10  # at least a second
    return pd.DataFrame({"frame": frames, "along": along,
                         "pass": np.where(keep, label, -1)})  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    """Track every recording and print the table (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data_dir", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    files = sorted(args.data_dir.glob("ti_awr1843_*.csv"))
    if not files:
        parser.error(f"no ti_awr1843_*.csv in {args.data_dir}")
    panels = []
    print(f"{'recording':24s} {'passes':>6s} {'tracks':>6s} {'per pass':>8s} {'max':>4s} "
          f"{'covered':>7s}")  # fmt: skip
    for path in files:
        points, motion = real_cloud(path)
        span = motion["to_m"] - motion["from_m"] + 10.0
        mapping = replay_site(motion["lateral_m"], span)
        mapping["radars"][0]["max_range_m"] = 30.0
        site = site_from_mapping(mapping, path.stem)
        radar = site.radars[0]
        det = detections_of(points, radar.position_m[0], radar.height_m)
        tracks, _, _ = track_scene_extended(site, det)
        passes = passes_of(points)
        shown = tracks[tracks["status"] != "tentative"].assign(
            frame=lambda f: np.rint(f["time_s"] / FRAME_S).astype(int)
        )
        joined = shown.merge(passes, on="frame")
        joined = joined[(joined["pass"] >= 0)
                        & (np.abs(joined["north_m"] - joined["along"]) <= MATCH_M)]  # fmt: skip
        per_pass = joined.groupby("pass")["track_id"].nunique()
        real = passes[passes["pass"] >= 0]
        counts = per_pass.reindex(real["pass"].unique(), fill_value=0)
        covered = joined.drop_duplicates("frame")["frame"].size / max(len(real), 1)
        print(f"{path.stem:24s} {counts.size:6d} {shown['track_id'].nunique():6d} "
              f"{counts.mean():8.2f} {counts.max():4d} {covered:7.0%}")  # fmt: skip
        panels.append((path.stem, points, shown))
    if args.out is not None:
        _draw(panels, args.out)
        print(f"wrote {args.out}")


def _draw(panels: list[tuple[str, pd.DataFrame, pd.DataFrame]], out: Path) -> None:
    """Points (grey) and tracks (a colour each) along the path against time, a panel each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 3 * len(panels)), squeeze=False)
    for ax, (name, points, shown) in zip(axes[:, 0], panels, strict=True):
        ax.scatter(points["frame"] * FRAME_S, points["along"], s=1, c="0.75", lw=0)
        for _, g in shown.groupby("track_id"):
            ax.plot(g["time_s"], g["north_m"], lw=1.5)
        ax.set_title(f"{name}: points (grey), reported tracks (a colour each)")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("along the path [m]")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
