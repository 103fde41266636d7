"""The ``adaptrack site`` commands: list, template, check, import a map, learn the background."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from ..crossing.measurements_io import read_scene_detections
from ..crossing.scene.background import learn_background
from ..crossing.site.authoring import coverage_svg, coverage_table, site_map_svg, site_template
from ..crossing.site.lanelet_map import project_latlon, read_lanelet_map
from ..crossing.site.map_import import site_from_map, site_toml
from ..crossing.site.model import blind_zones, builtin_sites, load_site, site_from_mapping
from ..crossing.site.network import overlaps
from ..io.tables import write_text_atomic
from .errors import fail
from .options import number_pair

site_app = typer.Typer(
    help="Site files: list the built-in sites, write a commented template, check a file.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@site_app.command("list")
def site_list() -> None:
    """List the built-in sites (usable by name wherever a site is asked for)."""
    table = Table(title="built-in sites")
    for col in ("name", "roads", "radars", "zone [m]", "description"):
        table.add_column(col)
    for name in builtin_sites():
        st = load_site(name)
        table.add_row(
            name, ", ".join(st.roads), ", ".join(r.name for r in st.radars), f"{st.zone_m:g}",
            _first_sentence(st.description),
        )  # fmt: skip
    Console().print(table)


def _first_sentence(text: str, limit: int = 80) -> str:
    """Return the first sentence of ``text``, cut to ``limit`` characters."""
    first = text.split(". ")[0].strip()
    return first if len(first) <= limit else first[: limit - 3] + "..."


@site_app.command("new")
def site_new(
    path: Path = typer.Argument(Path("site.toml"), help="Where to write the template."),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing file."),
) -> None:
    """Write a commented site template: every key, optional ones at their default."""
    if path.exists() and not force:
        fail(f"{path} exists; pass --force to overwrite it")
    if path.parent and not path.parent.is_dir():
        fail(f"{path}: folder {path.parent} does not exist")
    write_text_atomic(path, site_template())
    Console().print(f"wrote {path}; edit it, then run: adaptrack site check {path}")


@site_app.command("check")
def site_check(
    site: str = typer.Argument(..., help="A site .toml (or a built-in site name)."),
    out: Path = typer.Option(
        Path("site-check"), "--out", help="Folder for the map and coverage pictures (SVG)."
    ),
) -> None:
    """Validate a site file; print its coverage and write its map and coverage pictures.

    Every unknown or misspelt key, wrong type or out-of-range value is an error naming its
    place (with the nearest valid key for a misspelt one); exit status 1.
    """
    if out.exists() and not out.is_dir():
        fail(f"--out {out} is a file; give a folder")
    try:
        st = load_site(site)
    except ValueError as exc:
        fail(str(exc))
    out.mkdir(parents=True, exist_ok=True)
    cover = coverage_table(st)
    table = Table(title=f"{st.name}: share of each road's controlled zone ({st.zone_m:g} m) seen")
    for col in ("road", "radar", "tracks the road", "zone seen"):
        table.add_column(col)
    for row in cover.itertuples():
        table.add_row(
            row.road, row.radar, "yes" if row.tracks_road else "", f"{100 * row.zone_seen:.0f} %"
        )
    console = Console()
    console.print(table)
    blind = {k: v for k, v in blind_zones(st).items() if v}
    for name, parts in blind.items():
        spans = ", ".join(f"{a:.1f}-{b:.1f} m" for a, b in parts)
        console.print(f"blind zone on road {name}: {spans} (its radar does not see it)")
    for a, b, s0, s1 in overlaps(st.roads):
        console.print(
            f"warning: roads {a} and {b} lie on each other along {a} {s0:.0f}-{s1:.0f} m, away "
            "from where they meet (a road drawn twice, or roads that should meet at a junction)"
        )
    paths = ", ".join(f"{c.first}->{c.second}" for c in st.corridors if c.second in st.roads)
    if paths:
        console.print(f"driven paths: {paths}")
    write_text_atomic(out / "site_map.svg", site_map_svg(st))
    write_text_atomic(out / "coverage.svg", coverage_svg(st))
    console.print(
        f"{st.name}: valid ({len(st.roads)} roads, {len(st.radars)} radars, {len(st.cases)} "
        f"cases{', a scene' if 'scene' in st.source else ''}); "
        f"wrote {out / 'site_map.svg'} and {out / 'coverage.svg'}"
    )


@site_app.command("import")
def site_import(
    map_file: Path = typer.Argument(..., help="A Lanelet2 map (OSM XML)."),
    crossing: str = typer.Option(
        None, "--crossing", help="The crossing point X,Y in the map's metric frame [m]."
    ),
    crossing_latlon: str = typer.Option(
        None, "--crossing-latlon", help="The crossing point LAT,LON [deg] instead of X,Y."
    ),
    map_origin: str = typer.Option(
        "0,0", "--map-origin", help="LAT,LON of the map projection's origin (INTERACTION: 0,0)."
    ),
    out: Path = typer.Option(Path("site.toml"), "--out", help="The site file to write."),
    name: str = typer.Option(None, "--name", help="The site's name (default: the file's stem)."),
    junction_radius: float = typer.Option(
        15.0,
        "--junction-radius",
        help="Roads whose lanes pass this near the point start there [m].",
    ),
    rails_deg: float = typer.Option(
        None, "--rails-deg", help="Lay rails through the crossing point at this azimuth [deg]."
    ),
    zone: float = typer.Option(150.0, "--zone", help="The controlled zone [m]."),
    vehicles_per_h: float = typer.Option(
        30.0, "--vehicles-per-h", help="Traffic of each flow of the scene written [1/h]."
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing file."),
) -> None:
    """Import a Lanelet2 map into a site file: roads, lanes, stop lines, turns, flows, radars.

    The crossing point becomes the site's origin; replay motion recorded in the map's frame
    with ``adaptrack simulate SITE --motion FILE --origin X,Y`` (the point printed).
    """
    if out.exists() and not force:
        fail(f"{out} exists; pass --force to overwrite it")
    if (crossing is None) == (crossing_latlon is None):
        fail("give the crossing point: --crossing X,Y or --crossing-latlon LAT,LON")
    origin = number_pair(map_origin, "--map-origin")
    try:
        lmap = read_lanelet_map(map_file, origin)
        if crossing is not None:
            point = number_pair(crossing, "--crossing")
        else:
            xy = project_latlon(number_pair(crossing_latlon, "--crossing-latlon"), origin)
            point = (float(xy[0]), float(xy[1]))
        mapping = site_from_map(
            lmap, point, name or map_file.stem, junction_radius, zone,
            rails_deg=rails_deg, vehicles_per_h=vehicles_per_h,
        )  # fmt: skip
        site_from_mapping(mapping, str(out))
    except ValueError as exc:
        fail(str(exc))
    header = (
        f"Imported by `adaptrack site import {map_file.name}`: its lanes, stop lines, turns.\n"
        f"The crossing point ({point[0]:.2f}, {point[1]:.2f}) of the map's frame is the origin;\n"
        f"replay motion recorded in that frame with --origin {point[0]:.2f},{point[1]:.2f}.\n"
        "Radars, noise and flows are typical values: edit them to the site's."
    )
    write_text_atomic(out, site_toml(mapping, header))
    roads = ", ".join(
        f"{r['name']} ({r['lanes_in']} in, {r['lanes_out']} out)" for r in mapping["roads"]
    )
    Console().print(
        f"wrote {out}: roads {roads}; {len(mapping.get('connections', []))} turns from the map, "
        f"{len(mapping['radars'])} radars; next: adaptrack site check {out}\n"
        f"replay motion of the map's frame with: --origin {point[0]:.2f},{point[1]:.2f}"
    )


@site_app.command("background")
def site_background(
    detections: Path = typer.Argument(
        ..., help="Detections of the site while it is known to be clear (CSV or Parquet)."
    ),
    site: str = typer.Option(..., "--site", help="Built-in site name or a .toml."),
    out: Path = typer.Option(..., "--out", help="The background map to write (.npz)."),
    cell: float = typer.Option(0.5, "--cell", help="Ground cell size [m]."),
    min_rate: float = typer.Option(
        0.05, "--min-rate", help="A cell is a reflector at this many detections per scan."
    ),
    static_speed: float = typer.Option(
        0.5, "--static-speed", help="Detections this slow (|radial speed|) are stationary [m/s]."
    ),
) -> None:
    """Learn the empty site's background (standing reflectors) for `track --background`."""
    try:
        st = load_site(site)
        det = read_scene_detections(detections, st)
        background = learn_background(
            st, det, cell_m=cell, static_speed_mps=static_speed, min_rate=min_rate
        )
    except (ValueError, OSError) as exc:
        fail(str(exc))
    out.parent.mkdir(parents=True, exist_ok=True)
    background.save(out)
    busy = int((background.rates > 0).sum())
    Console().print(
        f"wrote {out}: {busy} cells of {cell:g} m with a standing reflector (>= {min_rate:g} "
        "detections "
        f"per scan) over {int(background.scans.sum())} scans of {len(background.radars)} radars"
    )
