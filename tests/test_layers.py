"""The package's layers: which may import which, and no import circle anywhere in ``src/``.

Every ``import`` counts, at module level or inside a function, under ``TYPE_CHECKING`` too: a
circle drawn lazily is still a circle a reader has to follow. The rules are those of the
architecture page (``docs/architecture.md``).
"""

import ast
from pathlib import Path

import pytest

import adaptrack

ROOT = Path(adaptrack.__file__).parent
CROSSING = "adaptrack.crossing"
# the library beneath the applications
CORE = ("tracking", "filters", "models", "smoothers", "coords", "analysis", "io", "tuning")
CORE += ("simulation",)
# layer -> layers it must never import
FORBIDDEN = {
    f"{CROSSING}.site": [
        f"{CROSSING}.{w}" for w in ("simulation", "estimators", "scene", "studies")
    ],
    f"{CROSSING}.simulation": [f"{CROSSING}.{w}" for w in ("estimators", "scene", "studies")],
    f"{CROSSING}.estimators": [f"{CROSSING}.{w}" for w in ("simulation", "scene", "studies")],
    f"{CROSSING}.scene": [f"{CROSSING}.{w}" for w in ("simulation", "studies")],
    **{
        f"adaptrack.{core}": ["adaptrack.crossing", "adaptrack.service", "adaptrack.cli"]
        for core in CORE
    },
    "adaptrack.service": ["adaptrack.cli"],
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in ROOT.rglob("*.py")}


def _imports(name: str, path: Path) -> set[str]:
    """The package's modules that module ``name`` imports (a name that is a module counts)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + [node.module or ""])
                base = base.rstrip(".")
            else:
                base = node.module or ""
            for alias in node.names:
                target = f"{base}.{alias.name}"
                found.add(target if target in MODULES else base)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {m for m in found if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _within(module: str, layer: str) -> bool:
    return module == layer or module.startswith(layer + ".")


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_the_graph_sees_the_imports():
    assert len(MODULES) > 120
    assert f"{CROSSING}.site.geometry" in GRAPH[f"{CROSSING}.scene.gate"]
    assert "adaptrack.filters._kernels" in GRAPH[f"{CROSSING}.estimators.kernels"]


def test_no_import_circle_anywhere():
    assert _circles(GRAPH) == []


def test_the_circle_finder_finds_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _circles(graph) == [["a", "b", "c"]]


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_a_layer_imports_only_what_it_stands_on(layer):
    broken = [
        f"{m} -> {t}"
        for m, targets in GRAPH.items()
        if _within(m, layer)
        for t in targets
        if any(_within(t, bad) for bad in FORBIDDEN[layer])
    ]
    assert broken == []


def test_the_crossing_top_holds_only_a_handful_of_files():
    top = sorted(p.name for p in (ROOT / "crossing").iterdir() if p.suffix == ".py")
    assert len(top) <= 4, top
