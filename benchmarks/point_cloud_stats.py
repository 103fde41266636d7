"""The face model's point cloud against a real 77 GHz point-cloud radar (TI AWR1843).

``python -m benchmarks.point_cloud_stats DATA_DIR [--fit man_walk] [--seed 1]`` reads the
recordings ``ti_awr1843_*.csv`` of ``DATA_DIR`` (columns ``frameNumber, x, y, z, v``; the
README of ``../shared/data/roadusers`` describes them; they are never copied here), and for
each one:

1. measures, over frames with at least one point: points per frame (10 %, 50 %, 90 %,
   mean, variance over mean), the spread of a frame's points along the path, in depth (along
   the boresight) and across both (interquartile range over 1.349, a standard deviation
   that a stray point does not move; median over frames), the Doppler
   quantum and the share of zero-Doppler points. The sensor's axes are found from the data:
   the boresight is ``y``; the path is the other axis along which the frames' centroids move
   most (the sensor lay on its side in these recordings: ``z`` runs along the path);
2. replays the same motion through the face model (``adaptrack simulate --motion`` with the
   cloud kind, via :func:`adaptrack.crossing.simulation.motion.simulate_replay`): one road
   user walking to and fro along a straight path at the recording's median lateral distance,
   over its span, at its median speed, in front of a radar at the mount height
   ``--mount-height`` (1.1 m; the recordings' documents also say 0.45 m), no false alarm or
   multipath (the body's points only), with range noise
   0.05 m and azimuth noise 1 deg (the sensor's resolution, 4.4 cm and about 15 deg, spread
   over a beam);
3. fits, on the ``--fit`` recording only, the cloud's density ``cloud_points_per_m2`` (the mean
   count), its count shape ``cloud_count_shape`` (the variance over mean) and
   ``elevation_std_deg`` (the vertical spread beyond the body's own; kept at its default when
   the body's reflections alone spread more than the recording's), then reports every
   recording with those values: the others are held out.

Prints one table: each statistic, real against simulated, per recording.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from adaptrack.crossing.simulation.faces import FaceRadar
from adaptrack.crossing.simulation.motion import read_motion, simulate_replay
from adaptrack.crossing.site.model import site_from_mapping

FRAME_S = 0.1  # the recordings' frame period [s]
IQR_PER_SIGMA = 1.349  # a normal law's interquartile range in sigmas (a robust spread)
CLASS_OF = {"escooter": "cyclist"}  # recording name part -> road-user class (else pedestrian)
STATS = ("points q10", "points median", "points q90", "points mean", "points var/mean",
         "spread along [m]", "spread depth [m]", "spread vertical [m]", "doppler step [m/s]",
         "zero doppler [%]")  # fmt: skip


def frame_stats(frame: pd.DataFrame, along: str, depth: str, vertical: str) -> dict[str, float]:
    """The statistics of a point cloud: one row per point, ``frame`` its frame number."""
    n = frame.groupby("frame").size()
    by_frame = frame.groupby("frame")[[along, depth, vertical]]
    spread = ((by_frame.quantile(0.75) - by_frame.quantile(0.25)) / IQR_PER_SIGMA).median()
    v = np.sort(np.unique(np.round(np.abs(frame["v"].to_numpy()), 4)))
    steps = np.diff(v)
    return {
        "points q10": float(np.percentile(n, 10)),
        "points median": float(np.median(n)),
        "points q90": float(np.percentile(n, 90)),
        "points mean": float(n.mean()),
        "points var/mean": float(n.var() / n.mean()),
        "spread along [m]": float(spread[along]),
        "spread depth [m]": float(spread[depth]),
        "spread vertical [m]": float(spread[vertical]),
        "doppler step [m/s]": float(steps[steps > 1e-3].min()) if (steps > 1e-3).any() else 0.0,
        "zero doppler [%]": 100.0 * float((np.abs(frame["v"]) < 1e-6).mean()),
    }


def real_cloud(path: Path) -> tuple[pd.DataFrame, dict[str, float]]:
    """Points of a recording with ``frame, along, depth, vertical, v``, and its motion."""
    raw = pd.read_csv(path)
    cen = raw.groupby("frameNumber")[["x", "y", "z"]].median()
    along = max(("x", "z"), key=lambda a: float(cen[a].var()))
    vertical = "z" if along == "x" else "x"
    pts = pd.DataFrame(
        {"frame": raw["frameNumber"], "along": raw[along], "depth": raw["y"],
         "vertical": raw[vertical], "v": raw["v"]}
    )  # fmt: skip
    c = cen[along].to_numpy()
    frames = cen.index.to_numpy()
    step = np.abs(np.diff(c)) / (np.diff(frames) * FRAME_S)
    motion = {
        "lateral_m": float(cen["y"].median()),
        "from_m": float(np.percentile(c, 5)),
        "to_m": float(np.percentile(c, 95)),
        "speed_mps": float(np.median(step[np.diff(frames) == 1])),
        "frames": float(len(frames)),
    }
    return pts, motion


def replay_site(lateral_m: float, span_m: float) -> dict:
    """A site of one straight path along north and a radar ``lateral_m`` east of it."""
    return {
        "name": "point_cloud_bench",
        "zone_m": max(span_m, 5.0),
        "run_in_m": 5.0,
        "lane_width_m": 3.5,
        "roads": [{"name": "path", "heading_deg": 0.0, "start_m": [1.75, -0.5 * span_m - 2.0],
                   "elements": [{"kind": "straight", "length_m": span_m + 20.0}]}],
        "scene": {"false_alarms_per_scan": 0.0, "multipath_probability": 0.0},
        "radars": [{"name": "ti", "position_m": [lateral_m, 0.0], "boresight_deg": 270.0,
                    "height_m": 1.0, "period_s": FRAME_S, "fov_half_deg": 60.0,
                    "max_range_m": 20.0, "min_range_m": 0.3, "range_std_m": 0.05,
                    "azimuth_std_deg": 1.0, "radial_speed_std_mps": 0.01,
                    "detection_probability": {"default": 1.0}}],
    }  # fmt: skip


def simulated_cloud(
    motion: dict[str, float], vehicle_class: str, cloud: FaceRadar, seed: int
) -> pd.DataFrame:
    """Points of the face model for a user walking to and fro along the recording's span."""
    span = motion["to_m"] - motion["from_m"]
    site = site_from_mapping(replay_site(motion["lateral_m"], span), "point_cloud_bench")
    duration = motion["frames"] * FRAME_S
    t = np.arange(0.0, duration, FRAME_S)
    leg = span / motion["speed_mps"]
    phase = np.mod(t, 2 * leg) / leg  # 0..2: out and back
    y = -0.5 * span + span * np.where(phase < 1, phase, 2 - phase)
    heading = np.where(phase < 1, 0.0, 180.0)
    size = (1.2, 0.6, 1.8) if vehicle_class == "cyclist" else (0.5, 0.5, 1.75)
    table = pd.DataFrame({
        "time_s": t, "object_id": 1, "class": vehicle_class, "x_m": 0.0, "y_m": y,
        "speed_mps": motion["speed_mps"], "heading_deg": heading,
        "length_m": size[0], "width_m": size[1], "height_m": size[2],
    })  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "walk.csv"
        table.to_csv(path, index=False)
        rec = simulate_replay(site, read_motion(path), seed, cloud)
    det = rec.detections
    radar = site.radars[0]
    horizontal = det["range_m"] * np.cos(det["elevation_rad"])
    east = radar.position_m[0] + horizontal * np.sin(det["azimuth_rad"])
    north = radar.position_m[1] + horizontal * np.cos(det["azimuth_rad"])
    return pd.DataFrame({
        "frame": np.rint(det["time_s"] / FRAME_S).astype(int), "along": north,
        "depth": radar.position_m[0] - east,
        "vertical": det["range_m"] * np.sin(det["elevation_rad"]),
        "v": det["radial_speed_mps"],
    })  # fmt: skip


def fit_cloud(
    pts: pd.DataFrame, motion: dict[str, float], vehicle_class: str, base: FaceRadar, seed: int
) -> FaceRadar:
    """Fit density, count shape and elevation noise of the cloud to one recording."""
    real = frame_stats(pts, "along", "depth", "vertical")
    cloud = base
    for _ in range(3):  # each statistic moves mostly with one parameter: alternate
        sim = frame_stats(simulated_cloud(motion, vehicle_class, cloud, seed), "along", "depth",
                          "vertical")  # fmt: skip
        density = cloud.cloud_points_per_m2 * real["points mean"] / sim["points mean"]
        # negative binomial: var/mean - 1 = mean / shape (at a fixed mean)
        excess_real = max(real["points var/mean"] - 1.0, 1e-3)
        excess_sim = max(sim["points var/mean"] - 1.0, 1e-3)
        shape = cloud.cloud_count_shape * excess_sim / excess_real
        lateral = motion["lateral_m"]
        body = math.degrees(math.atan2(sim["spread vertical [m]"], lateral))
        want = math.degrees(math.atan2(real["spread vertical [m]"], lateral))
        extra = want**2 - body**2 + cloud.elevation_std_deg**2
        # the body's own reflections may spread more than the recording: noise unidentified
        elevation = math.sqrt(extra) if extra > 0 else base.elevation_std_deg
        cloud = replace(cloud, cloud_points_per_m2=density, cloud_count_shape=shape,
                        elevation_std_deg=elevation)  # fmt: skip
    return cloud


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", type=Path, help="folder with ti_awr1843_*.csv")
    parser.add_argument("--fit", default="man_walk", help="recording to fit on (name part)")
    parser.add_argument("--mount-height", type=float, default=1.1)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    files = sorted(args.data.glob("ti_awr1843_*.csv"))
    if not files:
        raise SystemExit(f"{args.data}: no ti_awr1843_*.csv recording")
    recordings = {f.stem.removeprefix("ti_awr1843_"): real_cloud(f) for f in files}
    fit_name = next((n for n in recordings if args.fit in n), None)
    if fit_name is None:
        raise SystemExit(f"--fit {args.fit}: no such recording among {sorted(recordings)}")
    base = replace(FaceRadar.of_kind("cloud"), mount_height_m=args.mount_height)

    def cls(name: str) -> str:
        return next((c for k, c in CLASS_OF.items() if k in name), "pedestrian")

    fitted = fit_cloud(*recordings[fit_name], cls(fit_name), base, args.seed)
    print(
        f"fitted on {fit_name}: cloud_points_per_m2 {fitted.cloud_points_per_m2:.1f}, "
        f"cloud_count_shape {fitted.cloud_count_shape:.2f}, elevation_std_deg "
        f"{fitted.elevation_std_deg:.1f} (defaults {base.cloud_points_per_m2:g}, "
        f"{base.cloud_count_shape:g}, {base.elevation_std_deg:g}); mount {args.mount_height} m"
    )
    for name, (pts, motion) in recordings.items():
        real = frame_stats(pts, "along", "depth", "vertical")
        sim = frame_stats(simulated_cloud(motion, cls(name), fitted, args.seed), "along",
                          "depth", "vertical")  # fmt: skip
        role = "fit" if name == fit_name else "held out"
        print(
            f"{name} ({role}; {cls(name)}, {motion['speed_mps']:.2f} m/s at "
            f"{motion['lateral_m']:.1f} m, {motion['to_m'] - motion['from_m']:.1f} m span)"
        )
        for stat in STATS:
            print(f"  {stat:22s} real {real[stat]:8.2f}   model {sim[stat]:8.2f}")


if __name__ == "__main__":
    main()
