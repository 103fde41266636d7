"""Generated, fully unrolled numba kernels of the shared-gain recursion, per (n, m).

When every track shares its gain, a track's filtered mean follows the affine recursion
``x_k = A_k x_{k-1} + b_k + K_k z_k`` and its RTS-smoothed mean
``s_k = D_k x_k + C_k s_{k+1} + e_k``. Generic loops over run-time sizes are several times
slower than straight-line code for the small sizes used here, so the kernel source is written
for each (n, m) with scalar locals, ``LANES`` tracks advanced in lock-step (independent
dependency chains the CPU overlaps) and ``prange`` over groups of tracks. The source goes to a
cache directory (``$ADAPTRACK_KERNEL_DIR``, else ``~/.cache/adaptrack/kernels``) so that
numba's on-disk cache works across processes.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

LANES = 4
_VERSION = 1


def _step(lane: str, n: int, m: int) -> list[str]:
    """Statements advancing lane ``lane`` (track index ``i{lane}``) by one step."""
    lines = [f"z{lane}_{c} = z[i{lane}, k, {c}] if o{c} else 0.0" for c in range(m)]
    for r in range(n):
        terms = [f"b{r}"]
        terms += [f"a{r}_{c} * x{lane}_{c}" for c in range(n)]
        terms += [f"k{r}_{c} * z{lane}_{c}" for c in range(m)]
        lines.append(f"t{r} = " + " + ".join(terms))
    lines += [f"x{lane}_{r} = t{r}" for r in range(n)]
    lines += [f"out[i{lane}, k, {r}] = x{lane}_{r}" for r in range(n)]
    return lines


def _forward_source(n: int, m: int) -> str:
    def group(lanes: int, indent: str) -> list[str]:
        body = [f"i{g} = i0 + {g}" for g in range(lanes)]
        body += [f"x{g}_{c} = x0[i{g}, {c}]" for g in range(lanes) for c in range(n)]
        body.append("for k in range(n_steps):")
        inner = [f"a{r}_{c} = a[k, {r}, {c}]" for r in range(n) for c in range(n)]
        inner += [f"b{r} = b[k, {r}]" for r in range(n)]
        inner += [f"k{r}_{c} = kg[k, {r}, {c}]" for r in range(n) for c in range(m)]
        inner += [f"o{c} = obs[k, {c}]" for c in range(m)]
        for g in range(lanes):
            inner += _step(str(g), n, m)
        body += ["    " + s for s in inner]
        return [indent + s for s in body]

    src = [
        "import numba",
        "from numba import prange",
        "",
        "",
        "@numba.njit(cache=True, parallel=True, boundscheck=False, fastmath=False)",
        "def forward(a, b, kg, obs, z, x0, out):",
        f'    """Filtered means of every track; n = {n}, m = {m}, {LANES} lanes."""',
        "    n_tracks, n_steps = z.shape[0], z.shape[1]",
        f"    n_groups = n_tracks // {LANES}",
        "    for grp in prange(n_groups):",
        f"        i0 = grp * {LANES}",
        *group(LANES, "        "),
        f"    for i0 in prange(n_groups * {LANES}, n_tracks):",
        *group(1, "        "),
        "    return out",
        "",
    ]
    return "\n".join(src)


def _backward_source(n: int) -> str:
    def group(lanes: int, indent: str) -> list[str]:
        body = [f"i{g} = i0 + {g}" for g in range(lanes)]
        body += [f"s{g}_{c} = out[i{g}, n_steps - 1, {c}]" for g in range(lanes) for c in range(n)]
        body.append("for k in range(n_steps - 2, -1, -1):")
        inner = [f"d{r}_{c} = d[k, {r}, {c}]" for r in range(n) for c in range(n)]
        inner += [f"c{r}_{c} = cg[k, {r}, {c}]" for r in range(n) for c in range(n)]
        inner += [f"e{r} = e[k, {r}]" for r in range(n)]
        for g in range(lanes):
            inner += [f"f{g}_{c} = out[i{g}, k, {c}]" for c in range(n)]
            for r in range(n):
                terms = [f"e{r}"]
                terms += [f"d{r}_{c} * f{g}_{c}" for c in range(n)]
                terms += [f"c{r}_{c} * s{g}_{c}" for c in range(n)]
                inner.append(f"t{r} = " + " + ".join(terms))
            inner += [f"s{g}_{r} = t{r}" for r in range(n)]
            inner += [f"out[i{g}, k, {r}] = s{g}_{r}" for r in range(n)]
        body += ["    " + s for s in inner]
        return [indent + s for s in body]

    src = [
        "import numba",
        "from numba import prange",
        "",
        "",
        "@numba.njit(cache=True, parallel=True, boundscheck=False, fastmath=False)",
        "def backward(d, cg, e, out):",
        f'    """RTS-smoothed means in place of the filtered ones; n = {n}, {LANES} lanes."""',
        "    n_tracks, n_steps = out.shape[0], out.shape[1]",
        f"    n_groups = n_tracks // {LANES}",
        "    for grp in prange(n_groups):",
        f"        i0 = grp * {LANES}",
        *group(LANES, "        "),
        f"    for i0 in prange(n_groups * {LANES}, n_tracks):",
        *group(1, "        "),
        "    return out",
        "",
    ]
    return "\n".join(src)


def _kernel_dir() -> Path:
    env = os.environ.get("ADAPTRACK_KERNEL_DIR")
    base = Path(env) if env else Path.home() / ".cache" / "adaptrack" / "kernels"
    try:
        base.mkdir(parents=True, exist_ok=True)
        probe = base / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError:
        base = Path(tempfile.gettempdir()) / f"adaptrack-kernels-{os.getuid()}"
        base.mkdir(parents=True, exist_ok=True)
    return base


def _load(name: str, source: str) -> ModuleType:
    """Write ``source`` (once, atomically) and import it as a module."""
    digest = hashlib.sha1(source.encode()).hexdigest()[:12]
    path = _kernel_dir() / f"{name}_{digest}.py"
    if not path.exists():
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            f.write(source)
        os.replace(tmp, path)
    spec = importlib.util.spec_from_file_location(f"_adaptrack_kernel_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache re-imports the module by name
    spec.loader.exec_module(module)
    return module


@cache
def forward_kernel(n: int, m: int) -> Any:
    """``forward(a, b, kg, obs, z, x0, out)`` for state size ``n`` and measurement size ``m``."""
    return _load(f"forward_v{_VERSION}_n{n}_m{m}", _forward_source(n, m)).forward


@cache
def backward_kernel(n: int) -> Any:
    """``backward(d, cg, e, out)`` (in place) for state size ``n``."""
    return _load(f"backward_v{_VERSION}_n{n}", _backward_source(n)).backward
