"""Long mixed-traffic evaluation of the scene tracker: accuracy, identities and hazard events.

``python -m benchmarks.scene_hours --seeds 31 32 33 --duration 1200`` simulates each seed's
scene on ``lx_default`` (2-minute closures every 10 minutes, a vehicle stalled on road B at 58 %
of the duration for 90 s), tracks it and prints per seed: time per simulated second, mean GOSPA,
id switches, per-class position / speed RMS through association, the delay of every true
hazard (a standstill between the barriers) and the false "stopped" events, and the lead of the
"will not stop before the stop line" event for every user that ran the line (with the
scene's warning intervals given to the tracker) and the false ones; then the false events
per simulated hour over all seeds. ``--fold-kmh`` makes every radar fold its radial
speeds at that value; ``--set NAME=VALUE`` changes a
:class:`~adaptrack.crossing.scene_tracker.SceneTrackerConfig` setting (numbers, true/false).
Not a timing benchmark (accuracy and events; the time is indicative).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from adaptrack.crossing.scene import Stall, scene_spec, simulate_scene
from adaptrack.crossing.scene_metrics import event_outcomes, score_scene, stop_line_outcomes
from adaptrack.crossing.scene_tracker import SceneTrackerConfig, track_scene
from adaptrack.crossing.site import load_site


def main() -> None:
    """Run the evaluation (command line above)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="lx_default")
    ap.add_argument("--seeds", type=int, nargs="+", default=[31, 32, 33])
    ap.add_argument("--duration", type=float, default=1200.0, help="per seed [s]")
    ap.add_argument("--fold-kmh", type=float, default=None)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
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
    road = sorted(site.roads)[-1]
    spec = scene_spec(
        site, duration_s=args.duration, stalls=(Stall(road, 0.58 * args.duration, 0.0, 90.0),)
    )
    n_false, n_line_false, hours = 0, 0, 0.0
    for seed in args.seeds:
        rec = simulate_scene(site, spec, seed)
        start = time.perf_counter()
        tracks, events, _ = track_scene(site, rec.detections, config, warnings=spec.warnings())
        elapsed = time.perf_counter() - start
        score = score_scene(rec.truth, tracks, site.zone_m)
        hazards, false = event_outcomes(rec.truth, events, site.barrier_m)
        runs, line_false = stop_line_outcomes(rec.truth, events)
        n_false += len(false)
        n_line_false += len(line_false)
        hours += args.duration / 3600.0
        print(
            f"seed {seed}: {args.duration / elapsed:.0f}x real time, GOSPA "
            f"{score.gospa_mean:.2f} (parts: localisation {score.gospa_localisation:.2f}, "
            f"missed {score.gospa_missed:.2f}, false {score.gospa_false:.2f}), id switches "
            f"{score.id_switches}, hazard delays "
            f"{hazards['delay_s'].round(2).tolist()} s, false events {len(false)}; stop-line "
            f"runners {len(runs)}, event leads {runs['lead_s'].round(2).tolist()} s (NaN: "
            f"missed), false 'will not stop' events {len(line_false)}"
        )
        print(score.classes.round(2).to_string(index=False))
    print(f"false 'stopped between the barriers' events: {n_false} in {hours:.2f} h")
    print(f"false 'will not stop before the stop line' events: {n_line_false} in {hours:.2f} h")


if __name__ == "__main__":
    main()
