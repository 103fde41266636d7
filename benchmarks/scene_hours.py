"""Long mixed-traffic evaluation of the scene tracker: accuracy, identities and hazard events.

``python -m benchmarks.scene_hours --seeds 31 32 33 --duration 1200`` simulates each seed's
scene on ``lx_default`` (2-minute closures every 10 minutes, a vehicle stalled on road B at
58 % of the duration for 90 s:
:func:`adaptrack.crossing.studies.mixed_traffic.mixed_traffic_study`), tracks it and prints
per seed: time per simulated second, mean GOSPA,
id switches, per-class position / speed RMS through association, the delay of every true
hazard (a standstill between the barriers) and the false "stopped" events, and the lead of the
"will not stop before the stop line" event for every user that ran the line (with the
scene's warning intervals given to the tracker) and the false ones; then the false events
per simulated hour over all seeds, and the per-class RMS pooled over every epoch of every
seed. ``--workers N`` runs the seeds on N local processes (Dask). ``--fold-kmh`` makes every
radar fold its radial speeds at that value; ``--object-list`` makes the radars label their
detections with object ids (reissued, sometimes swapped) that the tracker takes as hints;
``--set NAME=VALUE`` changes a :class:`~adaptrack.crossing.scene.tracker.SceneTrackerConfig`
setting (numbers, true/false).
Not a timing benchmark (accuracy and events; the time is indicative).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import pandas as pd

from adaptrack.crossing.scene.tracker import SceneTrackerConfig
from adaptrack.crossing.site.model import Site, load_site
from adaptrack.crossing.studies.mixed_traffic import MixedTraffic, mixed_traffic_study
from adaptrack.parallel import task_pool


def _study(
    site: Site, seed: int, duration_s: float, config: SceneTrackerConfig, object_list: bool
) -> MixedTraffic:
    return mixed_traffic_study(site, seed, duration_s, config=config, object_list=object_list)


def pooled_classes(studies: list[MixedTraffic]) -> pd.DataFrame:
    """Per-class position [m] and speed [km/h] RMS over every scored epoch of ``studies``."""
    rows = [
        (c["class"], c["position_rms_m"] ** 2 * c["epochs"], c["speed_rms_kmh"] ** 2 * c["epochs"],
         c["epochs"], c["vehicles"])
        for m in studies
        for c in m.classes
    ]  # fmt: skip
    sums = pd.DataFrame(rows, columns=["class", "p2", "s2", "epochs", "vehicles"])
    sums = sums.groupby("class").sum()
    return pd.DataFrame(
        {
            "position_rms_m": np.sqrt(sums["p2"] / sums["epochs"]),
            "speed_rms_kmh": np.sqrt(sums["s2"] / sums["epochs"]),
            "epochs": sums["epochs"],
            "vehicles": sums["vehicles"],
        }
    )


def main() -> None:
    """Run the evaluation (command line above)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="lx_default")
    ap.add_argument("--seeds", type=int, nargs="+", default=[31, 32, 33])
    ap.add_argument("--duration", type=float, default=1200.0, help="per seed [s]")
    ap.add_argument("--fold-kmh", type=float, default=None)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument(
        "--object-list", action="store_true", help="radars label detections with object ids"
    )
    ap.add_argument("--workers", type=int, default=1, help="local processes (Dask)")
    args = ap.parse_args()
    changes: dict[str, float | bool] = {}
    for item in args.set:
        name, _, value = item.partition("=")
        changes[name] = value == "true" if value in ("true", "false") else float(value)
    config = SceneTrackerConfig(**changes)  # type: ignore[arg-type]
    site = load_site(args.site)
    if args.fold_kmh:
        radars = tuple(
            dataclasses.replace(r, max_unambiguous_speed_mps=args.fold_kmh / 3.6)
            for r in site.radars
        )
        site = dataclasses.replace(site, radars=radars)
    with task_pool(args.workers) as pool:
        studies = pool.map(
            _study, [(site, s, args.duration, config, args.object_list) for s in args.seeds]
        )
    n_false, n_line_false, hours = 0, 0, 0.0
    for seed, m in zip(args.seeds, studies, strict=True):
        n_false += len(m.false_stop_times_s)
        n_line_false += len(m.false_line_times_s)
        hours += args.duration / 3600.0
        delays = [round(h["delay_s"], 2) for h in m.hazards]
        leads = [round(r["lead_s"], 2) for r in m.stop_line_runs]
        print(
            f"seed {seed}: {args.duration / m.tracker_s:.0f}x real time, GOSPA "
            f"{m.gospa_mean:.2f} (parts: localisation {m.gospa_localisation:.2f}, "
            f"missed {m.gospa_missed:.2f}, false {m.gospa_false:.2f}), id switches "
            f"{m.id_switches}, false tracks {m.false_tracks}, hazard delays {delays} s, false "
            f"events {len(m.false_stop_times_s)}; stop-line runners {len(m.stop_line_runs)}, event "
            f"leads {leads} s (NaN: missed), false 'will not stop' events "
            f"{len(m.false_line_times_s)}"
        )
        print(pd.DataFrame(m.classes).round(2).to_string(index=False))
    print(
        f"mean GOSPA over the seeds: {np.mean([m.gospa_mean for m in studies]):.3f} m, id "
        f"switches {sum(m.id_switches for m in studies)}, false tracks "
        f"{sum(m.false_tracks for m in studies) / hours:.1f} per hour; per class over every "
        "epoch:"
    )
    print(pooled_classes(studies).round(3).to_string())
    print(f"false 'stopped between the barriers' events: {n_false} in {hours:.2f} h")
    print(f"false 'will not stop before the stop line' events: {n_line_false} in {hours:.2f} h")


if __name__ == "__main__":
    main()
