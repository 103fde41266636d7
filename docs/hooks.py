"""MkDocs hook: the command-line reference is generated from the commands at build time."""

from __future__ import annotations

from typing import Any

PLACEHOLDER = "<!-- generated: adaptrack CLI -->"


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    """Replace the placeholder of ``reference/cli.md`` with every command's help."""
    if PLACEHOLDER not in markdown:
        return markdown
    import click
    import typer
    import typer.cli

    from adaptrack.cli import app

    command = typer.main.get_command(app)
    text = typer.cli.get_docs_for_click(
        obj=command, ctx=click.Context(command, info_name="adaptrack"), name="adaptrack"
    )
    body = text.split("\n", 1)[1]  # its own title is the page's
    return markdown.replace(PLACEHOLDER, body.replace("\n## ", "\n## ").strip() + "\n")
