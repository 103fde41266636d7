"""TOML reading (stdlib ``tomllib`` on Python >= 3.11, the ``tomli`` backport before)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib


def load_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; errors name the file."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: invalid TOML: {exc}") from None


def load_named_toml(
    name_or_path: str | Path, package: str, folder: str, kind: str
) -> tuple[dict[str, Any], str]:
    """Load a built-in TOML by name (``package/folder/<name>.toml``) or a file by path.

    Returns the parsed data and the name used in error messages.
    """
    from importlib import resources

    path = Path(name_or_path)
    if path.suffix:
        if not path.is_file():
            raise ValueError(f"{kind} file {path} does not exist")
        return load_toml(path), str(path)
    names = builtin_names(package, folder)
    if str(name_or_path) not in names:
        raise ValueError(
            f"unknown {kind} {str(name_or_path)!r}; built-in {kind}s: "
            f"{', '.join(names)}; or pass a .toml path"
        )
    ref = resources.files(package) / folder / f"{name_or_path}.toml"
    with resources.as_file(ref) as p:
        return load_toml(p), str(name_or_path)


def builtin_names(package: str, folder: str) -> list[str]:
    """Names of the TOML files shipped in ``package/folder``."""
    from importlib import resources

    files = (resources.files(package) / folder).iterdir()
    return sorted(p.name[:-5] for p in files if p.name.endswith(".toml"))


__all__ = ["builtin_names", "load_named_toml", "load_toml"]
