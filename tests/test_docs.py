"""The documentation's Python: every tutorial (and the getting-started page) runs as written.

Each page's ```python blocks run in order in one namespace, in a scratch folder that has the
repository's ``docs`` and ``examples`` as the tutorials expect when run from its root.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
PAGES = [ROOT / "docs" / "getting-started.md", *sorted((ROOT / "docs" / "tutorials").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def test_every_tutorial_is_tested():
    assert len(PAGES) == 6 and all(BLOCK.search(p.read_text()) for p in PAGES)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_page_runs(page, tmp_path, monkeypatch, capsys):
    for name in ("docs", "examples"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    for k, code in enumerate(BLOCK.findall(page.read_text())):
        exec(compile(code, f"{page.name} (block {k + 1})", "exec"), namespace)
    assert capsys.readouterr().out.strip()  # every page prints what it shows
