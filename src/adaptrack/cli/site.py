"""The ``adaptrack site`` commands: list the built-in sites, write a template, check a file."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from ..crossing.site.authoring import coverage_svg, coverage_table, site_map_svg, site_template
from ..crossing.site.model import blind_zones, builtin_sites, load_site
from ..crossing.site.network import overlaps
from ..io.tables import write_text_atomic
from .errors import fail

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
