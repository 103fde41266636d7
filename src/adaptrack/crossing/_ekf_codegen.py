"""Generated straight-line version of :func:`._ekf_kernels.ekf_kernel` per state size.

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

from ..filters._codegen import GENERATED_MAX_STATES, kf_step_lines, load, module_source

_VERSION = 1
_M = 3  # range, azimuth, radial speed


def _ekf_source(n: int) -> str:
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
        f"zp, h, rm = np.empty(3), np.zeros((3, {n})), np.empty((3, 3))",
        "jp, jv = np.empty((3, 2)), np.empty((3, 2))",
        *(f"x{j} = m0[i, {j}]" for j in range(n)),
        *(f"P{a}_{b} = p0[i, {a}, {b}]" for a in range(n) for b in range(a, n)),
        *(f"u{j} = 0.0" for j in range(n)),
        "speed[i, f] = planar(kind, m0[i], p0[i], k, road, half_width, pos[i, f], vel[i, f], "
        "pcov[i, f])",
        "for t in range(f + 1, n_steps):",
    ]
    step = [
        "transition(times[i, t] - times[i, t - 1], phi_coef, qd_coef, off_coef, h_max, phi, qd, "
        "uo, tmp)",
        *(f"F{a}_{b} = phi[{a}, {b}]" for a in range(n) for b in range(n)),
        *(f"Q{a}_{b} = qd[{a}, {b}]" for a in range(n) for b in range(a, n)),
        *predict,
        "if kind == ROAD and xp1 > 0.0:  # an approaching vehicle does not reverse",
        *(f"    if {a} < k:\n        xp{a} = 0.0" for a in range(1, n - 1)),
        "if detected[i, t]:",
        *(f"    xa[{j}] = xp{j}" for j in range(n)),
        "    measure(kind, xa, k, radar, road, half_width, scatter_std, zp, h, rm, jp, jv)",
        *(f"    H{a}_{j} = h[{a}, {j}]" for a in range(_M) for j in range(n)),
        *(f"    R{a}_{b} = rm[{a}, {b}]" for a in range(_M) for b in range(a, _M)),
        "    nu0 = z[i, t, 0] - zp[0]",
        "    nu1 = (z[i, t, 1] - zp[1] + np.pi) % (2 * np.pi) - np.pi",
        "    nu2 = z[i, t, 2] - zp[2]",
    ]
    for line in update:
        if line.strip() == "return 2":  # S not positive definite: flag the run, stop it
            step += ["    " + line.replace("return 2", "status[i] = t + 1"), "        break"]
        else:
            step.append("    " + line)
    step += [
        "else:",
        *(f"    x{j} = xp{j}" for j in range(n)),
        *(f"    P{a}_{b} = pp{a}_{b}" for a in range(n) for b in range(a, n)),
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
        "radar, road, "
        "half_width, scatter_std, pos, vel, speed, pcov, status)",
        f"Road or free EKF with {n} states (see adaptrack.crossing._ekf_kernels.ekf_kernel).",
        body,
        parallel=True,
        imports=(
            "from adaptrack.crossing._ekf_kernels import ROAD, measure",
            "from adaptrack.crossing._ekf_kernels import _planar_into as planar",
            "from adaptrack.filters._kernels import series_transition_into as transition",
        ),
    )


def _digest() -> str:
    """Digest of the modules whose jitted functions the generated kernel inlines."""
    from ..filters import _kernels
    from . import _ekf_kernels

    text = "".join(Path(m.__file__ or "").read_text() for m in (_kernels, _ekf_kernels))
    return hashlib.sha1(text.encode()).hexdigest()[:12]


@cache
def ekf_kernel(n: int) -> Any:
    """Return the EKF kernel for state size ``n`` (generated up to ``GENERATED_MAX_STATES``)."""
    if n > GENERATED_MAX_STATES:
        from ._ekf_kernels import ekf_kernel as generic

        return generic
    return load(f"ekf_v{_VERSION}_n{n}", _ekf_source(n)).ekf
