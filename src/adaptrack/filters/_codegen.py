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
import math
import os
import sys
import tempfile
from collections.abc import Callable
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

from .._files import write_atomic

LANES = 4
Term = Callable[[int, int, int], str]  # (row, column, summation index) -> one product
Extra = Callable[[int, int], str]
GENERATED_MAX_STATES = 6  # larger states use the generic kernels (straight-line code for
# n = 9, m = 3 takes minutes to compile once)
_VERSION = 3
# Online steps within this many units in the last place of their time stamp share one
# discretisation: the steps are equal to the stamps' resolution (clock round-off, e.g.
# 0.15 - 0.1 != 0.05). A fixed tolerance (1 ns) was 0.07 % of a 1.4 us step (0.017 sigma).
STEP_MATCH_ULPS = 4.0
STEP_MATCH_REL = STEP_MATCH_ULPS * sys.float_info.epsilon  # times |t|: the tolerance [s]
# OnlineFilter work-buffer header: next bank row, series table h_max, the largest
# sum_a S_aa / R_aa the Joseph step takes (beyond it the filter continues in square-root form)
WS_NEXT_ROW, WS_H_MAX, WS_TRACE_LIMIT = 7, 8, 9
_FILL = ("from adaptrack.filters._kernels import series_bank_row as fill",)


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


def module_source(
    signature: str, doc: str, body: list[str], parallel: bool, imports: tuple[str, ...] = ()
) -> str:
    """Source of a module holding one ``numba.njit`` function with ``body``."""
    flags = "cache=True, parallel=True" if parallel else "cache=True"
    return "\n".join(
        [
            "import math",
            "",
            "import numba",
            "import numpy as np",
            "from numba import prange",
            *imports,
            "",
            "",
            f"@numba.njit({flags}, boundscheck=False, fastmath=False)",
            f"def {signature}:",
            f'    """{doc}"""',
            *("    " + line for line in body),
            "",
        ]
    )


def _lane_groups(n_tracks: str, group: Callable[[int], list[str]]) -> list[str]:
    """Loops over groups of ``LANES`` tracks (``prange``), then the remaining tracks one by one.

    ``group(lanes)`` returns the statements for tracks ``i0 .. i0 + lanes - 1``.
    """
    return [
        f"n_groups = {n_tracks} // {LANES}",
        "for grp in prange(n_groups):",
        f"    i0 = grp * {LANES}",
        *("    " + line for line in group(LANES)),
        f"for i0 in prange(n_groups * {LANES}, {n_tracks}):",
        *("    " + line for line in group(1)),
    ]


def _forward_source(n: int, m: int) -> str:
    def group(lanes: int) -> list[str]:
        body = [f"i{g} = i0 + {g}" for g in range(lanes)]
        body += [f"x{g}_{c} = x0[i{g}, {c}]" for g in range(lanes) for c in range(n)]
        body.append("for k in range(n_steps):")
        inner = [f"a{r}_{c} = a[k, {r}, {c}]" for r in range(n) for c in range(n)]
        inner += [f"b{r} = b[k, {r}]" for r in range(n)]
        inner += [f"k{r}_{c} = kg[k, {r}, {c}]" for r in range(n) for c in range(m)]
        inner += [f"o{c} = obs[k, {c}]" for c in range(m)]
        for g in range(lanes):
            inner += _step(str(g), n, m)
        return body + ["    " + s for s in inner]

    return module_source(
        "forward(a, b, kg, obs, z, x0, out)",
        f"Filtered means of every track; n = {n}, m = {m}, {LANES} lanes.",
        ["n_steps = z.shape[1]", *_lane_groups("z.shape[0]", group), "return out"],
        parallel=True,
    )


def _backward_source(n: int) -> str:
    def group(lanes: int) -> list[str]:
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
        return body + ["    " + s for s in inner]

    return module_source(
        "backward(d, cg, e, out)",
        f"RTS-smoothed means in place of the filtered ones; n = {n}, {LANES} lanes.",
        ["n_steps = out.shape[1]", *_lane_groups("out.shape[0]", group), "return out"],
        parallel=True,
    )


def _kernel_dir() -> Path:
    env = os.environ.get("ADAPTRACK_KERNEL_DIR")
    base = Path(env) if env else Path.home() / ".cache" / "adaptrack" / "kernels"
    try:
        base.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=base, prefix=".write-test-")  # own name: processes
        os.close(fd)  # (Dask workers, test workers) probe the folder at the same time
        os.unlink(probe)
    except OSError:
        base = Path(tempfile.gettempdir()) / f"adaptrack-kernels-{os.getuid()}"
        base.mkdir(parents=True, exist_ok=True)
    return base


def load(name: str, source: str) -> ModuleType:
    """Write ``source`` (once, atomically) and import it as a module."""
    digest = hashlib.sha1(source.encode()).hexdigest()[:12]
    path = _kernel_dir() / f"{name}_{digest}.py"
    if not path.exists():
        write_atomic(path, lambda tmp: Path(tmp).write_text(source))
    spec = importlib.util.spec_from_file_location(f"_adaptrack_kernel_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache re-imports the module by name
    spec.loader.exec_module(module)
    return module


@cache
def forward_kernel(n: int, m: int) -> Any:
    """``forward(a, b, kg, obs, z, x0, out)`` for state size ``n`` and measurement size ``m``."""
    return load(f"forward_v{_VERSION}_n{n}_m{m}", _forward_source(n, m)).forward


@cache
def backward_kernel(n: int) -> Any:
    """``backward(d, cg, e, out)`` (in place) for state size ``n``."""
    return load(f"backward_v{_VERSION}_n{n}", _backward_source(n)).backward


def _sym(i: int, j: int) -> tuple[int, int]:
    return (i, j) if i <= j else (j, i)


def kf_step_lines(n: int, m: int, trace_limit: str | None = None) -> list[str]:
    """Straight-line predict + Joseph update on scalar locals, every component present.

    Reads ``x{i}``, ``P{i}_{j}`` (i <= j), ``F{i}_{j}``, ``Q{i}_{j}``, ``u{i}``, ``H{a}_{j}``,
    ``R{a}_{b}``, ``o{a}`` (noise mean) and ``z{a}``; leaves the predicted moments in
    ``xp{i}``, ``pp{i}_{j}``, the filtered ones back in ``x{i}``, ``P{i}_{j}``, the innovation in
    ``nu{a}``, ``S{a}_{b}``, the transposed gain in ``kt{a}_{i}`` and ``nis``, ``logdet``.
    A non-positive pivot of ``S`` executes ``return 2``, a ``sum_a S_aa / R_aa`` (the
    numerator of :func:`~adaptrack.filters.kalman.joseph_ratio`) above the expression
    ``trace_limit`` (if given) ``return 6`` (in both cases the inputs are unchanged).
    """

    def p(i: int, j: int) -> str:
        a, b = _sym(i, j)
        return f"P{a}_{b}"

    def pp(i: int, j: int) -> str:
        a, b = _sym(i, j)
        return f"pp{a}_{b}"

    def s_(a: int, b: int) -> str:
        i, j = _sym(a, b)
        return f"S{i}_{j}"

    def dot(terms: list[str]) -> str:
        return " + ".join(terms) if terms else "0.0"

    def product(name: str, rows: int, cols: int, inner: int, term: Term) -> list[str]:
        """``name{i}_{j} = sum_k term(i, j, k)``."""
        return [
            f"{name}{i}_{j} = " + dot([term(i, j, k) for k in range(inner)])
            for i in range(rows)
            for j in range(cols)
        ]

    def symmetric(name: str, size: int, inner: int, term: Term, extra: Extra) -> list[str]:
        """Upper triangle of ``0.5 (M + M^T) + extra`` with ``M_ij = sum_k term(i, j, k)``."""
        return [
            f"{name}{i}_{j} = 0.5 * ("
            + dot([term(i, j, k) for k in range(inner)])
            + " + "
            + dot([term(j, i, k) for k in range(inner)])
            + f") + {extra(i, j)}"
            for i in range(size)
            for j in range(i, size)
        ]

    out = [f"xp{i} = " + dot([f"F{i}_{k} * x{k}" for k in range(n)] + [f"u{i}"]) for i in range(n)]
    out += product("tf", n, n, n, lambda i, j, k: f"F{i}_{k} * {p(k, j)}")
    out += symmetric("pp", n, n, lambda i, j, k: f"tf{i}_{k} * F{j}_{k}", lambda i, j: f"Q{i}_{j}")
    out += [
        f"nu{a} = z{a} - o{a} - (" + dot([f"H{a}_{k} * xp{k}" for k in range(n)]) + ")"
        for a in range(m)
    ]
    out += product("hp", m, n, n, lambda a, j, k: f"H{a}_{k} * {pp(k, j)}")
    out += symmetric("S", m, n, lambda a, b, k: f"hp{a}_{k} * H{b}_{k}", lambda a, b: f"R{a}_{b}")
    if trace_limit is not None:
        scaled = dot([f"{s_(a, a)} / R{a}_{a}" for a in range(m)])
        out += [f"if {scaled} > {trace_limit}:", "    return 6"]
    if m == 1:  # S is a scalar: one reciprocal instead of a square root and two divisions
        out += ["d0 = S0_0", "if not d0 > 0.0:", "    return 2", "iS = 1.0 / d0"]
        out += [f"kt0_{j} = hp0_{j} * iS" for j in range(n)]
        out += ["nis = nu0 * nu0 * iS"]
    else:  # Cholesky S = L L^T with reciprocal pivots
        for a in range(m):
            for b in range(a + 1):
                acc = s_(a, b) + "".join(f" - L{a}_{c} * L{b}_{c}" for c in range(b))
                if a == b:
                    out += [f"d{a} = {acc}", f"if not d{a} > 0.0:", "    return 2"]
                    out += [f"L{a}_{a} = math.sqrt(d{a})", f"iL{a} = 1.0 / L{a}_{a}"]
                else:
                    out.append(f"L{a}_{b} = ({acc}) * iL{b}")
        # K^T = S^-1 (H P): forward then backward substitution, column by column
        for j in range(n):
            for a in range(m):
                acc = f"hp{a}_{j}" + "".join(f" - L{a}_{c} * y{c}_{j}" for c in range(a))
                out.append(f"y{a}_{j} = ({acc}) * iL{a}")
            for a in range(m - 1, -1, -1):
                acc = f"y{a}_{j}" + "".join(f" - L{c}_{a} * kt{c}_{j}" for c in range(a + 1, m))
                out.append(f"kt{a}_{j} = ({acc}) * iL{a}")
        for a in range(m):
            acc = f"nu{a}" + "".join(f" - L{a}_{c} * w{c}" for c in range(a))
            out.append(f"w{a} = ({acc}) * iL{a}")
        out.append("nis = " + dot([f"w{a} * w{a}" for a in range(m)]))
    out.append("logdet = " + dot([f"math.log(d{a})" for a in range(m)]))
    out += [f"x{i} = xp{i} + " + dot([f"kt{a}_{i} * nu{a}" for a in range(m)]) for i in range(n)]
    out += [
        f"ikh{i}_{j} = {1.0 if i == j else 0.0} - ("
        + dot([f"kt{a}_{i} * H{a}_{j}" for a in range(m)])
        + ")"
        for i in range(n)
        for j in range(n)
    ]
    out += product("ta", n, n, n, lambda i, j, k: f"ikh{i}_{k} * {pp(k, j)}")
    out += product("kr", n, m, m, lambda i, b, a: f"kt{a}_{i} * R{_sym(a, b)[0]}_{_sym(a, b)[1]}")
    out += symmetric(
        "P",
        n,
        n,
        lambda i, j, k: f"ta{i}_{k} * ikh{j}_{k}",
        lambda i, j: dot([f"kr{i}_{b} * kt{b}_{j}" for b in range(m)]),
    )
    return out


def _bank_miss(
    n: int, series: tuple[int, int, int, int, int, int] | None, miss: list[str]
) -> list[str]:
    """Statements for a step length not in the bank.

    With ``series`` (offsets and term counts of the series table's three coefficient blocks in
    the work buffer) the next bank row is filled from it; without, ``miss`` (status 3).
    """
    if series is None:
        return ["if row < 0:", *("    " + line for line in miss)]
    po, p, qo, q, oo, r = series
    return [
        "if row < 0:",
        f"    row = int(ws[{WS_NEXT_ROW}])",
        f"    ws[{WS_NEXT_ROW}] = (row + 1) % bank.shape[0]",
        f"    fill(bank, row, dt, ws[{po}:{po + p * n * n}].reshape(({p}, {n}, {n})), "
        f"ws[{qo}:{qo + q * n * n}].reshape(({q}, {n}, {n})), "
        f"ws[{oo}:{oo + r * n}].reshape(({r}, {n})), ws[{WS_H_MAX}])",
    ]


Layout = tuple[int, int, int, int, int, int]


def _bank_view(n: int, bank: tuple[int, int]) -> str:
    """Statement making the transition bank (rows ``[dt, Phi, Qd, u]``) a work-buffer view."""
    offset, rows = bank
    width = 1 + 2 * n * n + n
    return f"bank = ws[{offset}:{offset + rows * width}].reshape(({rows}, {width}))"


def _load_state(n: int, m: int, layout: Layout) -> list[str]:
    """Locals ``x``, ``P`` (upper), ``H``, ``R`` (upper), ``o`` from the work buffer."""
    _, xo, po, ho, ro, oo = layout
    return [
        *(f"x{i} = ws[{xo + i}]" for i in range(n)),
        *(f"P{i}_{j} = ws[{po + i * n + j}]" for i in range(n) for j in range(i, n)),
        *(f"H{a}_{j} = ws[{ho + a * n + j}]" for a in range(m) for j in range(n)),
        *(f"R{a}_{b} = ws[{ro + a * m + b}]" for a in range(m) for b in range(a, m)),
        *(f"o{a} = ws[{oo + a}]" for a in range(m)),
    ]


def _store_state(n: int, layout: Layout) -> list[str]:
    """Write the locals ``x``, ``P`` back to the work buffer (``P`` in full)."""
    _, xo, po, _, _, _ = layout
    out = [f"ws[{xo + i}] = x{i}" for i in range(n)]
    for i in range(n):
        for j in range(i, n):
            out.append(f"ws[{po + i * n + j}] = P{i}_{j}")
            if j != i:
                out.append(f"ws[{po + j * n + i}] = P{i}_{j}")
    return out


def _online_source(
    n: int, m: int, layout: Layout, series: Layout | None, bank: tuple[int, int]
) -> str:
    """``online_step(ws, t, z) -> nis`` on the work buffer of ``OnlineFilter``.

    A failed step returns ``-status`` and changes nothing: 1 non-finite measurement, 2 ``S``
    not positive definite, 3 a step length not in the bank (no series table), 4 wrong shape,
    5 a time before the filter's, 6 ``sum_a S_aa / R_aa`` above the Joseph limit.
    """
    hdr_time = layout[0]
    body = [
        f"if z.shape[0] != {m}:",
        "    return -4.0",
        _bank_view(n, bank),
        f"dt = t - ws[{hdr_time}]",
        "if not (dt >= 0.0 and math.isfinite(t)):",
        "    return -5.0",
        "row = -1",
        f"tol = {STEP_MATCH_REL!r} * abs(t)",
        "for j in range(bank.shape[0]):",
        "    if abs(bank[j, 0] - dt) <= tol:",
        "        row = j",
        "        break",
        *_bank_miss(n, series, ["return -3.0"]),
    ]
    body += [f"z{a} = z[{a}]" for a in range(m)]
    body += [
        "if not (" + " and ".join(f"math.isfinite(z{a})" for a in range(m)) + "):",
        "    return -1.0",
    ]
    body += _load_state(n, m, layout)
    body += [f"F{i}_{j} = bank[row, {1 + i * n + j}]" for i in range(n) for j in range(n)]
    body += [f"Q{i}_{j} = bank[row, {1 + n * n + i * n + j}]" for i in range(n) for j in range(n)]
    body += [f"u{i} = bank[row, {1 + 2 * n * n + i}]" for i in range(n)]
    limit = f"ws[{WS_TRACE_LIMIT}]"
    body += [
        line.replace("return 2", "return -2.0").replace("return 6", "return -6.0")
        for line in kf_step_lines(n, m, limit)
    ]
    body += _store_state(n, layout)
    body += [
        f"ws[{hdr_time - 3}] = nis",
        f"ws[{hdr_time - 2}] = -0.5 * (logdet + nis + {m} * {math.log(2 * math.pi)!r})",
        f"ws[{hdr_time - 1}] = {float(m)}",
        f"ws[{hdr_time}] = t",
        "return nis",
    ]
    return module_source(
        "online_step(ws, t, z)",
        f"One online Joseph-form step, every component present; n = {n}, m = {m}.",
        body,
        parallel=False,
        imports=_FILL,
    )


def _online_run_source(
    n: int, m: int, layout: Layout, series: Layout | None, bank: tuple[int, int]
) -> str:
    """``online_run(ws, times, z, k, means, variances, nis) -> (status, k)``.

    The steps of ``online_step`` for rows ``k, k + 1, ...`` of validated ``times`` (T,) and
    ``z`` (T, m), the state in locals between steps; stops at the end (status 0), at a step
    length not in the bank (3), a non-positive-definite ``S`` (2) or a ``sum_a S_aa / R_aa``
    above the Joseph limit (6), with the state of the rows before ``k`` written back to ``ws``.
    """
    hdr_time = layout[0]
    body = [_bank_view(n, bank), *_load_state(n, m, layout)]
    body += [
        f"t_prev, last_nis, last_ll = ws[{hdr_time}], ws[{hdr_time - 3}], ws[{hdr_time - 2}]",
        f"last_nobs = ws[{hdr_time - 1}]",
        "status = 0",
    ]
    step = [
        "t = times[k]",
        "dt = t - t_prev",
        "row = -1",
        f"tol = {STEP_MATCH_REL!r} * abs(t)",
        "for j in range(bank.shape[0]):",
        "    if abs(bank[j, 0] - dt) <= tol:",
        "        row = j",
        "        break",
        *_bank_miss(n, series, ["status = 3", "break"]),
    ]
    step += [f"F{i}_{j} = bank[row, {1 + i * n + j}]" for i in range(n) for j in range(n)]
    step += [f"Q{i}_{j} = bank[row, {1 + n * n + i * n + j}]" for i in range(n) for j in range(n)]
    step += [f"u{i} = bank[row, {1 + 2 * n * n + i}]" for i in range(n)]
    step += [f"z{a} = z[k, {a}]" for a in range(m)]
    for line in kf_step_lines(n, m, f"ws[{WS_TRACE_LIMIT}]"):
        if line.strip() in ("return 2", "return 6"):
            step += [line.replace("return ", "status = "), "    break"]
        elif line.startswith("logdet = "):  # only the last step's is kept: after the loop
            step += [f"last_d{a} = d{a}" for a in range(m)]
        else:
            step.append(line)
    step += [f"means[k, {i}] = x{i}" for i in range(n)]
    step += [f"variances[k, {i}] = P{i}_{i}" for i in range(n)]
    step += ["nis_out[k] = nis", "last_nis = nis", "t_prev = t", "k += 1"]
    body += [f"last_d{a} = 1.0" for a in range(m)]
    body += ["k_start = k", "while k < times.shape[0]:"]
    body += ["    " + line for line in step]
    body += [
        "if k > k_start:",
        "    logdet = " + " + ".join(f"math.log(last_d{a})" for a in range(m)),
        f"    last_ll = -0.5 * (logdet + last_nis + {m} * {math.log(2 * math.pi)!r})",
        f"    last_nobs = {float(m)}",
    ]
    body += _store_state(n, layout)
    body += [
        f"ws[{hdr_time - 3}], ws[{hdr_time - 2}], ws[{hdr_time - 1}] = last_nis, last_ll, "
        "last_nobs",
        f"ws[{hdr_time}] = t_prev",
        "return status, k",
    ]
    return module_source(
        "online_run(ws, times, z, k, means, variances, nis_out)",
        f"Online Joseph-form steps over a sequence, every component present; n = {n}, m = {m}.",
        body,
        parallel=False,
        imports=_FILL,
    )


@cache
def online_run_kernel(
    n: int, m: int, layout: Layout, series: Layout | None, bank: tuple[int, int]
) -> Any:
    """``online_run(ws, times, z, k, means, variances, nis)`` for ``OnlineFilter``."""
    source = _online_run_source(n, m, layout, series, bank)
    return load(f"online_run_v{_VERSION}_n{n}_m{m}", source).online_run


@cache
def online_kernel(
    n: int, m: int, layout: Layout, series: Layout | None, bank: tuple[int, int]
) -> Any:
    """``online_step(ws, t, z)`` for ``OnlineFilter``.

    ``layout``: the header's time index and the offsets of x, P, H, R and the noise mean in the
    work buffer; ``series``: offsets and term counts of the series-table blocks (None: a new
    step length returns status 3 and is discretised in Python); ``bank``: offset and rows of
    the transition bank in the work buffer.
    """
    source = _online_source(n, m, layout, series, bank)
    return load(f"online_v{_VERSION}_n{n}_m{m}", source).online_step


def _sequence_source(n: int, m: int) -> str:
    """``sequence(x0, p0, phi, qd, u, z, h, r, off, pm, pc, fm, fc, nu, s, nis, ll, kg, status)``.

    ``status[i]`` becomes ``k + 1`` if track ``i`` stops at step ``k`` (S not positive definite).
    """
    body = [
        "n_tracks, n_steps = A_z.shape[0], A_z.shape[1]",
        "for i in prange(n_tracks):",
        "    ii = numba.int64(i)",  # prange's index may be unsigned: min() with it gives a float
        "    ix = min(ii, A_x0.shape[0] - 1)",
        "    ip = min(ii, A_phi.shape[0] - 1)",
        "    iu = min(ii, A_u.shape[0] - 1)",
    ]
    inner = [f"x{j} = A_x0[ix, {j}]" for j in range(n)]
    inner += [f"P{a}_{b} = A_p0[ix, {a}, {b}]" for a in range(n) for b in range(a, n)]
    inner += [f"H{a}_{j} = A_h[{a}, {j}]" for a in range(m) for j in range(n)]
    inner += [f"R{a}_{b} = A_r[{a}, {b}]" for a in range(m) for b in range(a, m)]
    inner += [f"o{a} = A_off[{a}]" for a in range(m)]
    inner.append("for k in range(n_steps):")
    step = [f"F{a}_{b} = A_phi[ip, k, {a}, {b}]" for a in range(n) for b in range(n)]
    step += [f"Q{a}_{b} = A_qd[ip, k, {a}, {b}]" for a in range(n) for b in range(n)]
    step += [f"u{a} = A_u[iu, k, {a}]" for a in range(n)]
    step += [f"z{a} = A_z[i, k, {a}]" for a in range(m)]
    for line in kf_step_lines(n, m):
        if line.strip() == "return 2":  # not positive definite: flag the track, stop it
            step += [line.replace("return 2", "A_status[i] = k + 1"), "    break"]
        else:
            step.append(line)
    for a in range(n):
        step += [f"A_pm[i, k, {a}] = xp{a}", f"A_fm[i, k, {a}] = x{a}"]
        for b in range(n):
            lo, hi = _sym(a, b)
            step += [f"A_pc[i, k, {a}, {b}] = pp{lo}_{hi}", f"A_fc[i, k, {a}, {b}] = P{lo}_{hi}"]
        step += [f"A_kg[i, k, {a}, {b}] = kt{b}_{a}" for b in range(m)]
    for a in range(m):
        step.append(f"A_nu[i, k, {a}] = nu{a}")
        for b in range(m):
            lo, hi = _sym(a, b)
            step.append(f"A_s[i, k, {a}, {b}] = S{lo}_{hi}")
    step += [
        "A_nis[i, k] = nis",
        f"A_ll[i, k] = -0.5 * (logdet + nis + {m} * {math.log(2 * math.pi)!r})",
    ]
    inner += ["    " + s for s in step]
    body += ["    " + s for s in inner]
    return module_source(
        "sequence(A_x0, A_p0, A_phi, A_qd, A_u, A_z, A_h, A_r, A_off, A_pm, A_pc, A_fm, A_fc, "
        "A_nu, A_s, A_nis, A_ll, A_kg, A_status)",
        f"Joseph-form filter of every track, all components present; n = {n}, m = {m}.",
        body,
        parallel=True,
    )


@cache
def sequence_kernel(n: int, m: int) -> Any:
    """Straight-line Kalman filter over (N, T) for state size ``n``, measurement size ``m``.

    Arguments as :func:`adaptrack.filters._kernels.kalman_kernel` (one ``R`` (m, m), every
    component present, Joseph form) followed by the output arrays it fills and a status (N,)
    of zeros.
    """
    return load(f"sequence_v{_VERSION}_n{n}_m{m}", _sequence_source(n, m)).sequence
