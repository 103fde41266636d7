"""Adapter: a radar whose output differs from adaptrack's detection lines, fed to the service.

This (made-up but typical) radar writes ``sensor;t_ms;dist_m;angle_left_deg;v_kmh``: time in
milliseconds, azimuth in degrees *positive to the left of its boresight*, radial speed in km/h
*positive approaching*. adaptrack's lines want seconds, azimuth in radians clockwise from
north, and radial speed in m/s positive away from the radar (docs/guide.md, "Live service").
The adapter converts each row with the radar's boresight from the site file and writes JSON
lines: pipe them into ``adaptrack serve --site SITE --listen stdin``, or give ``--to udp://HOST:PORT``.
Here the rows also go through the service's own tracker in-process, to show they are taken.

Run: python examples/radar_adapter.py [--to udp://127.0.0.1:5600]
"""

import argparse
import json
import math
import socket
from urllib.parse import urlsplit

from adaptrack.crossing.site.model import load_site
from adaptrack.service.engine import LiveTracker

VENDOR_ROWS = """\
sensor;t_ms;dist_m;angle_left_deg;v_kmh
radar_A;1000;62.40;-1.10;54.0
radar_A;1050;61.65;-1.12;54.0
radar_A;1100;60.90;-1.13;54.1
radar_A;1150;60.15;-1.15;54.0
radar_A;1200;59.40;-1.16;53.9
"""


def to_line(row: str, boresight_rad: dict[str, float]) -> str:
    """One vendor row as an adaptrack JSON detection line."""
    sensor, t_ms, dist_m, left_deg, v_kmh = row.split(";")
    azimuth = boresight_rad[sensor] - math.radians(float(left_deg))  # left = anticlockwise
    return json.dumps(
        {
            "radar": sensor,
            "time_s": float(t_ms) / 1000.0,
            "range_m": float(dist_m),
            "azimuth_rad": math.remainder(azimuth, 2.0 * math.pi),
            "radial_speed_mps": -float(v_kmh) / 3.6,  # approaching: towards the radar
        }
    )


def main() -> None:
    """Convert the rows; print them (or send them) and show how the tracker took them."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--to", help="udp://HOST:PORT of a running 'adaptrack serve'")
    args = ap.parse_known_args()[0]
    site = load_site("lx_default")
    boresight = {r.name: r.boresight_rad for r in site.radars}
    lines = [to_line(row, boresight) for row in VENDOR_ROWS.splitlines()[1:]]
    if args.to:
        target = urlsplit(args.to)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for line in lines:
                s.sendto((line + "\n").encode(), (target.hostname, target.port))
    live = LiveTracker(site)
    for line in lines:
        print(line)
        live.feed(line, "adapter")
    live.flush()
    stats = live.stats()
    print(f"received {stats['received']}, used {stats['used']}, rejected {stats['rejected']}")


if __name__ == "__main__":
    main()
