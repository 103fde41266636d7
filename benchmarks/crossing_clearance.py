"""How fast the crossing is reported not clear, and how often falsely (extended tracker).

``python -m benchmarks.crossing_clearance [--site lx_default] [--trials 100] [--radar-kind
cluster] [--empty-s 600] [--traffic-site SITE.toml --traffic-hours 24]`` runs
:func:`adaptrack.crossing.studies.clearance.clearance_trials`
for a 0.5 x 0.5 x 1.0 m object placed between the barriers with no approach and for a car
stalling there, one seeded trial each (the background learnt from the empty site with another
seed), and counts the false ``crossing_not_clear`` events over ``--empty-s`` seconds of the
empty site. Prints, per kind: trials, raised within 1 s, the delays' median, 90 % and
maximum, and events raised before the object stood there. With ``--traffic-site``, each of
``--traffic-hours`` seeded hours of that site's scene with trains
(:func:`adaptrack.crossing.studies.clearance.traffic_run`) sorts the ``crossing_not_clear``
raises into: a road user in the area, one near it, and false (nobody there).
"""

from __future__ import annotations

import argparse

import numpy as np

from adaptrack.crossing.simulation.faces import RADAR_KINDS, FaceRadar
from adaptrack.crossing.site.model import load_site
from adaptrack.crossing.studies.clearance import clear_run, clearance_trials, traffic_run


def main(argv: list[str] | None = None) -> None:
    """Run the trials and print the table (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", default="lx_default")
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--radar-kind", default="cluster", choices=RADAR_KINDS)
    parser.add_argument("--empty-s", type=float, default=600.0)
    parser.add_argument("--traffic-site", default=None, help="a site with rails and trains")
    parser.add_argument("--traffic-hours", type=int, default=24)
    args = parser.parse_args(argv)
    site = load_site(args.site)
    radar = FaceRadar.of_kind(args.radar_kind)
    print(f"site {args.site}, {args.radar_kind} radar, {args.trials} trials per kind")
    print(f"{'kind':8s} {'trials':>6s} {'<= 1 s':>6s} {'median':>7s} {'90 %':>6s} {'max':>6s} "
          f"{'early':>5s}")  # fmt: skip
    for kind in ("placed", "stalled"):
        trials = clearance_trials(site, kind, range(args.trials), radar=radar)
        delay = np.array([t.delay_s for t in trials])
        found = delay[np.isfinite(delay)]
        within = int((found <= 1.0).sum())
        q = np.quantile(found, [0.5, 0.9]) if found.size else [np.nan, np.nan]
        top = found.max() if found.size else np.nan
        early = sum(t.false_events for t in trials)
        print(f"{kind:8s} {len(trials):6d} {within:6d} {q[0]:7.2f} {q[1]:6.2f} {top:6.2f} "
              f"{early:5d}")  # fmt: skip
    if args.empty_s > 0:
        false = clear_run(site, args.empty_s, seed=1, radar=radar)
        print(f"false 'not clear' over {args.empty_s:g} s of the empty site: {false}")
    if args.traffic_site is not None:
        traffic(load_site(args.traffic_site), args.traffic_hours, radar)


def traffic(site, hours: int, radar: FaceRadar) -> None:  # type: ignore[no-untyped-def]
    """Print the "not clear" raises of ``hours`` seeded hours of traffic with trains."""
    print(f"{'hour':>4s} {'trains':>6s} {'raised':>6s} {'in area':>7s} {'near':>4s} {'false':>5s}")
    total = np.zeros(5, int)
    for hour in range(hours):
        r = traffic_run(site, 3600.0, seed=100 + hour, radar=radar)
        row = np.array([r.trains, r.raised, r.in_area, r.near, r.false])
        total += row
        times = ", ".join(f"{t:.1f}" for t in r.false_times_s)
        print(f"{hour:4d} " + " ".join(f"{v:6d}" for v in row) + (f"  false at {times} s"
                                                                    if times else ""))  # fmt: skip
    print(f"{hours} h: " + ", ".join(f"{k} {v}" for k, v in zip(
        ("trains", "raised", "in area", "near", "false"), total, strict=True)))  # fmt: skip


if __name__ == "__main__":
    main()
