"""Generated straight-line version of :func:`.kernels.ekf_kernel` per state size.

The generic kernel's run-time-sized loops cost about 0.7 us per step for four states; this one
keeps the state and covariance in scalar locals and runs the predict and Joseph update of
:func:`adaptrack.filters._codegen.kf_step_lines` (unrolled), calling the generic code only
for the per-step transition (series table), the measurement model and the planar output.
Same arguments, same numbers to rounding (tests).
"""

from __future__ import annotations

import hashlib
from functools import cache
from pathlib import Path
from typing import Any

from ..._typing import FloatArray
from ...filters._codegen import GENERATED_MAX_STATES, kf_step_lines, load, module_source

_VERSION = 6
_M = 3  # range, azimuth, radial speed


Pattern = tuple[tuple[tuple[bool, ...], ...], ...]  # [row][column][term]: non-zero


def _horner(name: str, terms: tuple[bool, ...], times_h: bool) -> str:
    """``sum_i name_i dt^i`` over the non-zero terms (times ``dt`` once more if ``times_h``)."""
    if not any(terms):
        return "0.0"
    top = max(i for i, nz in enumerate(terms) if nz)
    acc = f"{name}_{top}"
    for i in range(top - 1, -1, -1):
        acc = f"({acc}) * dt" + (f" + {name}_{i}" if terms[i] else "")
    return f"({acc}) * dt" if times_h else acc


def _transition_lines(n: int, pattern: tuple[Pattern, Pattern]) -> tuple[list[str], list[str]]:
    """Coefficient loads (per run) and straight-line ``F``, ``Q`` of a step (per step).

    ``pattern``: which coefficients of the series table (``phi_coef``, ``qd_coef``) are non-zero;
    only those are loaded and multiplied. Steps longer than ``h_max`` use the generic series
    evaluation (with doublings).
    """
    phi_nz, qd_nz = pattern
    loads = [
        f"a{a}_{b}_{i} = phi_coef[{i}, {a}, {b}]"
        for a in range(n)
        for b in range(n)
        for i, nz in enumerate(phi_nz[a][b])
        if nz
    ]
    loads += [
        f"c{a}_{b}_{i} = qd_coef[{i}, {a}, {b}]"
        for a in range(n)
        for b in range(a, n)
        for i, nz in enumerate(qd_nz[a][b])
        if nz
    ]
    step = [
        "dt = times[i, t] - times[i, t - 1]",
        "if dt <= h_max:",
        *(
            f"    F{a}_{b} = {_horner(f'a{a}_{b}', phi_nz[a][b], False)}"
            for a in range(n)
            for b in range(n)
        ),
        *(
            f"    Q{a}_{b} = {_horner(f'c{a}_{b}', qd_nz[a][b], True)}"
            for a in range(n)
            for b in range(a, n)
        ),
        "else:",
        "    transition(dt, phi_coef, qd_coef, off_coef, h_max, phi, qd, uo, tmp)",
        *(f"    F{a}_{b} = phi[{a}, {b}]" for a in range(n) for b in range(n)),
        *(f"    Q{a}_{b} = qd[{a}, {b}]" for a in range(n) for b in range(a, n)),
    ]
    return loads, step


def _ekf_source(n: int, pattern: tuple[Pattern, Pattern]) -> str:
    loads, transition = _transition_lines(n, pattern)
    step_lines = kf_step_lines(n, _M)
    split = next(i for i, line in enumerate(step_lines) if line.startswith("nu0 ="))
    predict = step_lines[:split]
    update = [line for line in step_lines[split:] if not line.startswith("nu")]
    run = [
        "f = first[i]",
        "if f < 0:",
        "    continue",
        f"phi, qd, tmp = np.empty(({n}, {n})), np.empty(({n}, {n})), np.empty(({n}, {n}))",
        f"xa, pa, uo = np.empty({n}), np.empty(({n}, {n})), np.empty({n})",
        f"zp, h, rm, nu = np.empty(3), np.zeros((3, {n})), np.empty((3, 3)), np.empty(3)",
        "jp, jv = np.empty((3, 2)), np.empty((3, 2))",
        f"gate_x, gate_p = np.empty({n}), np.empty(({n}, {n}))",
        f"gate_ikh, gate_hp, gate_kt = np.empty(({n}, {n})), np.empty((1, {n})), "
        f"np.empty((1, {n}))",
        "gate_s, gate_lo, gate_r = np.empty((1, 1)), np.empty((1, 1)), np.empty((1, 1))",
        "gate_w, gate_nu = np.empty(1), np.empty(1)",
        "miss_run = 1.0",
        *(f"x{j} = m0[i, {j}]" for j in range(n)),
        *(f"P{a}_{b} = p0[i, {a}, {b}]" for a in range(n) for b in range(a, n)),
        *(f"u{j} = 0.0" for j in range(n)),
        *loads,
        "speed[i, f] = planar(kind, m0[i], p0[i], k, road, half_width, pos[i, f], vel[i, f], "
        "pcov[i, f])",
        "for t in range(f + 1, n_steps):",
    ]
    step = [
        *transition,
        *predict,
        "if kind == ROAD and xp1 > 0.0:  # an approaching vehicle does not reverse",
        *(f"    if {a} < k:\n        xp{a} = 0.0" for a in range(1, n - 1)),
        "if detected[i, t]:",
        *(f"    xa[{j}] = xp{j}" for j in range(n)),
        "    measure(kind, xa, k, radar, noise_tab, noise_cnt, road, half_width, scatter_std, "
        "zp, h, rm, jp, jv)",
        *(f"    pa[{a}, {b}] = pa[{b}, {a}] = pp{a}_{b}" for a in range(n) for b in range(a, n)),
        "    doppler = doppler_usable(h, pa, rm, radar)",
        "    innovation_into(z[i, t], zp, radar, doppler, nu)",
        "    nu0, nu1, nu2 = nu[0], nu[1], nu[2]",
        *(f"    H{a}_{j} = h[{a}, {j}]" for a in range(_M) for j in range(n)),
        *(f"    R{a}_{b} = rm[{a}, {b}]" for a in range(_M) for b in range(a, _M)),
        "    miss_run = 1.0",
    ]
    for line in update:
        if line.strip() == "return 2":  # S not positive definite: flag the run, stop it
            step += ["    " + line.replace("return 2", "status[i] = t + 1"), "        break"]
        else:
            step.append("    " + line)
    step += [
        "else:  # a missed detection: the Doppler gate may explain it",
        *(f"    xa[{j}] = xp{j}" for j in range(n)),
        *(f"    pa[{a}, {b}] = pa[{b}, {a}] = pp{a}_{b}" for a in range(n) for b in range(a, n)),
        "    _, miss_run = gate_update(kind, xa, pa, k, radar, noise_tab, noise_cnt, fields, "
        "pd_tab, pd_cnt, road, half_width, scatter_std, miss_run, gate_x, gate_p, zp, h, rm, "
        "jp, jv, gate_hp, gate_s, gate_lo, gate_kt, gate_w, gate_ikh, tmp, gate_nu, gate_r)",
        *(f"    x{j} = gate_x[{j}]" for j in range(n)),
        *(f"    P{a}_{b} = gate_p[{a}, {b}]" for a in range(n) for b in range(a, n)),
        *(f"xa[{j}] = x{j}" for j in range(n)),
        *(f"pa[{a}, {b}] = pa[{b}, {a}] = P{a}_{b}" for a in range(n) for b in range(a, n)),
        "speed[i, t] = planar(kind, xa, pa, k, road, half_width, pos[i, t], vel[i, t], pcov[i, t])",
    ]
    body = [
        f"# imported kernels' source digest (numba's cache does not track imports): {_digest()}",
        "n_runs, n_steps = detected.shape",
        "for i in prange(n_runs):",
        *("    " + line for line in run),
        *("        " + line for line in "\n".join(step).split("\n")),
    ]
    return module_source(
        "ekf(kind, times, phi_coef, qd_coef, off_coef, h_max, z, detected, first, m0, p0, k, "
        "radar, noise_tab, noise_cnt, fields, pd_tab, pd_cnt, road, half_width, scatter_std, "
        "pos, vel, speed, pcov, status)",
        f"Road or free EKF with {n} states (see adaptrack.crossing.estimators.kernels.ekf_kernel).",
        body,
        parallel=True,
        imports=(
            "from adaptrack.crossing.estimators.kernels import ROAD, doppler_usable",
            "from adaptrack.crossing.estimators.kernels import innovation_into",
            "from adaptrack.crossing.estimators.kernels import measure",
            "from adaptrack.crossing.estimators.kernels import gate_update_into as gate_update",
            "from adaptrack.crossing.estimators.kernels import _planar_into as planar",
            "from adaptrack.filters._kernels import series_transition_into as transition",
        ),
    )


def _digest() -> str:
    """Digest of the modules whose jitted functions the generated kernel inlines."""
    from ...filters import _kernels
    from ..site import geometry
    from . import kernels

    modules = (_kernels, kernels, geometry)
    text = "".join(Path(m.__file__ or "").read_text() for m in modules)
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def ekf_kernel(n: int, phi_coef: FloatArray, qd_coef: FloatArray) -> Any:
    """Return the EKF kernel for state size ``n`` and the series table's non-zero pattern.

    Generated up to ``GENERATED_MAX_STATES`` states (one compilation per pattern: per model
    structure, not per parameter value); the generic kernel beyond.
    """
    if n > GENERATED_MAX_STATES:
        from .kernels import ekf_kernel as generic

        return generic

    def nonzero(coef: FloatArray) -> Pattern:
        rows = (coef != 0).transpose(1, 2, 0).tolist()  # [row][column][term]
        return tuple(tuple(tuple(terms) for terms in row) for row in rows)

    return _generated(n, (nonzero(phi_coef), nonzero(qd_coef)))


@cache
def _generated(n: int, pattern: tuple[Pattern, Pattern]) -> Any:
    return load(f"ekf_v{_VERSION}_n{n}", _ekf_source(n, pattern)).ekf
