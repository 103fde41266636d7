"""numba's on-disk cache of the package's kernels, stamped with every source they compile in.

numba keys a cached kernel on the content of its own file only. A kernel that calls a
compiled function of another module compiles that function into itself, yet stays cached
when that module changes: it keeps running the old code (``run_scans`` in
``crossing/scene/scan_loop.py`` after an edit of ``crossing/scene/gate.py``) until its own
file changes. An installed package is new as a whole, but in a source tree (an editable
install) a test or a benchmark after such an edit runs stale kernels and cannot tell.

:func:`register` puts cache locators for a package's files in front of numba's own. Each is
one of numba's, with the source stamp widened to the module's file and every module of the
package it imports, directly or through others (``from .x import y``, ``from ..x import y``,
``import pkg.x``; a name that is a submodule counts as imported, found by a scan of the
source lines, so an import inside a function counts too). A kernel's cache is then reused
only while none of those sources changed.

A kernel's index names the types of its signatures; after a type is renamed or removed
(a ``NamedTuple`` a kernel takes) numba cannot unpickle the index and fails. In the
package's cache directories such an index is a miss: the kernel compiles again and the
index is rewritten.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import re
from pathlib import Path
from typing import Any

from numba.core import caching

_CACHE_IMPL: Any = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")  # noqa: B009
_FILE_BACKED = caching._SourceFileBackedLocatorMixin
_OUR_CACHE_PATHS: set[str] = set()  # the cache directories of registered packages' kernels
_UNREADABLE = (AttributeError, ImportError, EOFError, pickle.UnpicklingError)


class _Package:
    """The modules of one package under ``root`` (named ``name``) and their imports."""

    def __init__(self, root: Path, name: str) -> None:
        self.root, self.name = root.resolve(), name
        self._imports: dict[Path, tuple[tuple[int, int], frozenset[Path]]] = {}
        self._digests: dict[Path, tuple[tuple[int, int], bytes]] = {}

    def holds(self, path: Path) -> bool:
        """Whether ``path`` is a module file of the package."""
        return path.suffix == ".py" and self.root in path.parents

    def module_name(self, path: Path) -> str:
        """Dotted name of a module file of the package (a package's ``__init__.py``: its own)."""
        parts = [self.name, *path.relative_to(self.root).with_suffix("").parts]
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    def module_file(self, name: str) -> Path | None:
        """Return the file of module ``name`` if it is one of the package's, else None."""
        parts = name.split(".")
        if parts[0] != self.name:
            return None
        base = self.root.joinpath(*parts[1:])
        for candidate in (base.with_suffix(".py"), base / "__init__.py"):
            if candidate.is_file():
                return candidate
        return None

    def imports(self, path: Path) -> frozenset[Path]:
        """Return the package's module files that module ``path`` imports directly."""
        stamp = _stat(path)
        known = self._imports.get(path)
        if known is not None and known[0] == stamp:
            return known[1]
        name = self.module_name(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        source = path.read_text(encoding="utf-8")
        targets: list[str] = []
        for dots, module, names in _FROM_IMPORT.findall(source):
            if dots:
                parts = package.split(".")
                parts = parts[: len(parts) - len(dots) + 1]
                module = ".".join([*parts, module] if module else parts)
            targets.append(module)
            targets.extend(f"{module}.{alias}" for alias in _aliases(names))
        for names in _IMPORT.findall(source):
            targets.extend(_aliases(names))
        found = {f for f in map(self.module_file, targets) if f is not None}
        result = frozenset(found)
        self._imports[path] = (stamp, result)
        return result

    def closure(self, path: Path) -> list[Path]:
        """Return module ``path`` and every package module it imports, directly or not."""
        seen, todo = {path}, [path]
        while todo:
            for nxt in self.imports(todo.pop()):
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return sorted(seen)

    def digest(self, path: Path) -> bytes:
        """SHA-256 over the relative paths and contents of :meth:`closure` of ``path``."""
        h = hashlib.sha256()
        for f in self.closure(path):
            h.update(str(f.relative_to(self.root)).encode())
            h.update(self._content_digest(f))
        return h.digest()

    def _content_digest(self, path: Path) -> bytes:
        stamp = _stat(path)
        known = self._digests.get(path)
        if known is None or known[0] != stamp:
            known = (stamp, hashlib.sha256(path.read_bytes()).digest())
            self._digests[path] = known
        return known[1]


_FROM_IMPORT = re.compile(
    r"^[ \t]*from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n;]*)", re.MULTILINE
)
_IMPORT = re.compile(r"^[ \t]*import[ \t]+([^\n;]*)", re.MULTILINE)


def _aliases(names: str) -> list[str]:
    """Return the imported names of an import list (``a as b, c``, in parentheses or not)."""
    names = re.sub(r"#[^\n]*", "", names).strip("() \t\n")
    return [part.split()[0] for part in names.split(",") if part.strip()]


def _stat(path: Path) -> tuple[int, int]:
    st = os.stat(path)
    return st.st_mtime_ns, st.st_size


def register(root: Path, name: str) -> None:
    """Stamp the cached kernels of package ``name`` (files under ``root``) with their imports.

    For each of numba's locators of files on disk (a ``NUMBA_CACHE_DIR``, the source tree's
    ``__pycache__``, the user-wide cache; not a zipped package's), a variant is put before
    it that takes the package's files only, with numba's source stamp and
    :meth:`_Package.digest`.
    Registering one package twice changes nothing.
    """
    package = _Package(root, name)
    classes = _CACHE_IMPL._locator_classes
    if any(getattr(c, "package", None) == (package.root, name) for c in classes):
        return

    def wrap(base: Any) -> type:
        def get_source_stamp(self: Any) -> Any:
            return base.get_source_stamp(self), package.digest(Path(self._py_file).resolve())

        def get_cache_path(self: Any) -> Any:
            path = base.get_cache_path(self)
            _OUR_CACHE_PATHS.add(os.path.abspath(path))
            return path

        def from_function(cls: type, py_func: Any, py_file: str) -> Any:
            if not package.holds(Path(py_file).resolve()):
                return None
            return base.from_function.__func__(cls, py_func, py_file)

        return type(
            f"{name}{base.__name__.lstrip('_')}",
            (base,),
            {"package": (package.root, name), "get_source_stamp": get_source_stamp,
             "get_cache_path": get_cache_path, "from_function": classmethod(from_function)},
        )  # fmt: skip

    ours = [wrap(c) for c in classes if issubclass(c, _FILE_BACKED) and "Zip" not in c.__name__]
    classes[:0] = ours
    index_file = caching.IndexDataCacheFile
    if not getattr(index_file._load_index, "reads_stale_types", False):
        index_file._load_index = _tolerant(index_file._load_index)  # type: ignore[method-assign]


def _tolerant(load_index: Any) -> Any:
    """Return numba's index loader with an unreadable index of a registered package a miss."""

    def _load_index(self: Any) -> Any:
        try:
            return load_index(self)
        except _UNREADABLE:
            if os.path.dirname(os.path.abspath(self._index_path)) not in _OUR_CACHE_PATHS:
                raise
            return {}

    _load_index.reads_stale_types = True  # type: ignore[attr-defined]
    return _load_index


register(Path(__file__).parent, __name__.partition(".")[0])
