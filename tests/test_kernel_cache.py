"""The on-disk kernel cache is stamped with every package module a kernel's module imports."""

import importlib
import os
import pkgutil
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import adaptrack
from adaptrack import _kernel_cache
from adaptrack.crossing.scene import scan_loop

KERNEL = """\
import numba
from .helper import value

@numba.njit(cache=True)
def run():
    return value()
"""
HELPER = """\
import numba

@numba.njit(cache=True)
def value():
    return {}
"""
SCRIPT = """\
import sys
from pathlib import Path
if sys.argv[1] == "stamped":
    from adaptrack._kernel_cache import register
    register(Path(sys.argv[2]), "stampdemo")
from stampdemo.kernel import run
print(run())
"""


def test_a_kernel_recompiles_when_a_module_it_calls_changes(tmp_path):
    """A cached kernel calls a compiled function of another module; that module changes, the
    kernel's own file does not. numba alone reuses the stale kernel (the hazard); with the
    package registered, the kernel is compiled again and returns the new value."""
    package = tmp_path / "stampdemo"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "kernel.py").write_text(KERNEL)
    (package / "helper.py").write_text(HELPER.format(1))

    def run(mode):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"cache_{mode}"),
               "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}  # fmt: skip
        out = subprocess.run(
            [sys.executable, "-c", SCRIPT, mode, str(package)], env=env, cwd=tmp_path,
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        return out.stdout.strip()

    assert run("numba") == run("stamped") == "1"  # both compiled and cached
    (package / "helper.py").write_text(HELPER.format(2))
    # if numba ever tracks what a kernel compiles in, this fails and the stamp is not needed
    assert run("numba") == "1", "numba alone reran the cached kernel with the old helper"
    assert run("stamped") == "2"


def test_the_scene_loop_is_stamped_with_the_kernels_it_compiles_in():
    root = Path(adaptrack.__file__).parent.resolve()
    package = _kernel_cache._Package(root, "adaptrack")
    loop = Path(scan_loop.__file__).resolve()
    names = {str(f.relative_to(root)) for f in package.closure(loop)}
    stages = ("rows", "body", "predict", "gate", "update", "spawn", "prune", "modes", "scan_loop")
    expected = {
        *(f"crossing/scene/{stage}.py" for stage in stages), "crossing/estimators/kernels.py",
        "crossing/site/geometry.py", "filters/_kernels.py", "tracking/assignment.py",
        "tracking/lifecycle.py",
    }  # fmt: skip
    assert expected <= names
    assert not {"cli.py", "crossing/studies/report.py", "crossing/simulation/scene.py"} & names
    locator = scan_loop.run_scans._cache._impl.locator
    assert locator.get_source_stamp()[1] == package.digest(loop)


def _package_kernels():
    """Every compiled function defined in a module of adaptrack, with its module."""
    from numba.core.registry import CPUDispatcher

    for info in pkgutil.walk_packages(adaptrack.__path__, "adaptrack."):
        module = importlib.import_module(info.name)
        for obj in vars(module).values():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__:
                yield module, obj


def _callees(kernel):
    """The compiled functions ``kernel`` names: globals, and attributes of imported modules."""
    from numba.core.registry import CPUDispatcher

    names, scope = kernel.py_func.__code__.co_names, kernel.py_func.__globals__
    for name in names:
        obj = scope.get(name)
        if isinstance(obj, types.ModuleType):
            yield from (
                a for a in (getattr(obj, n, None) for n in names) if isinstance(a, CPUDispatcher)
            )
        elif isinstance(obj, CPUDispatcher):
            yield obj


def test_every_kernel_is_stamped_with_the_files_of_the_kernels_it_compiles_in():
    root = Path(adaptrack.__file__).parent.resolve()
    package = _kernel_cache._Package(root, "adaptrack")
    kernels = list(_package_kernels())
    assert len(kernels) > 100  # every wing's kernels were found
    unstamped = []
    for module, kernel in kernels:
        closure = set(package.closure(Path(module.__file__).resolve()))
        for callee in _callees(kernel):
            source = Path(callee.py_func.__code__.co_filename).resolve()
            if package.holds(source) and source not in closure:
                unstamped.append(f"{module.__name__}.{kernel.__name__} -> {source.name}")
    assert not unstamped


def test_relative_imports_resolve_to_the_package_files(tmp_path):
    root = tmp_path / "pkg"
    (root / "sub").mkdir(parents=True)
    for name in ("__init__.py", "sub/__init__.py", "a.py", "b.py", "sub/c.py", "sub/d.py"):
        (root / name).write_text("")
    (root / "sub/c.py").write_text(textwrap.dedent("""\
        from ..a import x
        from . import d
        import pkg.b
        import numpy
    """))  # fmt: skip
    root = root.resolve()
    package = _kernel_cache._Package(root, "pkg")
    names = {str(f.relative_to(root)) for f in package.closure(root / "sub/c.py")}
    assert names == {"sub/c.py", "a.py", "sub/__init__.py", "sub/d.py", "b.py"}


TYPED_KERNEL = """\
import numba
from .types import {name}

@numba.njit(cache=True)
def run(pair):
    return pair.a + pair.b

def call():
    return run({name}(1.0, 2.0))
"""
TYPES = """\
from typing import NamedTuple

class {name}(NamedTuple):
    a: float
    b: float
"""
TYPED_SCRIPT = """\
import sys
from pathlib import Path
if sys.argv[1] == "stamped":
    from adaptrack._kernel_cache import register
    register(Path(sys.argv[2]), "typedemo")
from typedemo.kernel import call
print(call())
"""


def test_a_kernel_index_naming_a_removed_type_is_a_miss(tmp_path):
    """A cached kernel's index names the types of its signatures. Renaming a NamedTuple that
    a kernel takes makes the index unreadable: numba alone fails (AttributeError while
    unpickling it); with the package registered it is a cache miss and the kernel compiles
    again (and the index is rewritten)."""
    package = tmp_path / "typedemo"
    package.mkdir()
    (package / "__init__.py").write_text("")

    def write(name):
        (package / "types.py").write_text(TYPES.format(name=name))
        (package / "kernel.py").write_text(TYPED_KERNEL.format(name=name))

    def run(mode):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"cache_{mode}"),
               "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}  # fmt: skip
        return subprocess.run(
            [sys.executable, "-c", TYPED_SCRIPT, mode, str(package)], env=env, cwd=tmp_path,
            capture_output=True, text=True,
        )  # fmt: skip

    write("Pair")
    assert run("numba").stdout.strip() == run("stamped").stdout.strip() == "3.0"
    write("Couple")
    plain = run("numba")
    # if numba ever treats an unreadable index as a miss, this fails and the guard can go
    assert plain.returncode != 0 and "Can't get attribute 'Pair'" in plain.stderr
    for _ in range(2):  # compiled again, then from the rewritten cache
        stamped = run("stamped")
        assert stamped.returncode == 0, stamped.stderr
        assert stamped.stdout.strip() == "3.0"
