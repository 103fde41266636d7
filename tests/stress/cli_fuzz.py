"""Fuzzing of the command line: malformed tables, site TOML, paths and options for every command.

Every case runs ``adaptrack.cli.main`` in-process on one spoiled input (a mutated detection or
measurement table, a mutated site TOML or summary, a missing/directory/unwritable path, a bad
option value) in a fresh directory, stopped by a simulated Ctrl-C (``KeyboardInterrupt`` from
an alarm) after ``--budget`` seconds. Outcomes:

- ``done``: exit 0, every output file complete (it parses);
- ``rejected``: exit 1 or 2, stderr exactly one ``error: ...`` line, no output file;
- ``interrupted``: exit 130 after the Ctrl-C, stderr ending in one ``error: interrupted`` line,
  no half-written or temporary file (only complete ones);
- defects: ``internal error`` (exit 3), ``traceback`` (an exception escaped ``main``),
  ``bad message`` (stderr not one ``error:`` line), ``partial output``, ``silent failure``
  (exit 0 without its output).

::

    python -m tests.stress.cli_fuzz --cases 500
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import signal
import sys
import tempfile
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import tomllib

from adaptrack._progress import LINE_PREFIX
from adaptrack.cli import main
from adaptrack.cli.crossing import VERDICT_EXIT

DEFECTS = ("internal error", "traceback", "bad message", "partial output", "silent failure")
SITES = Path(__file__).parents[2] / "src" / "adaptrack" / "crossing" / "site" / "sites"


FIT_TOML = """[fit]
measurement = "radar3d"
model = "cv"
axes = 3
source = "plots.csv"
log_likelihood = 0.0
converged = true
""" + "".join(
    f"\n[fit.parameters.{name}]\nvalue = {value!r}\nstd_error = 0.0\nlow_95 = 0.0\nhigh_95 = 0.0\n"
    for name, value in (
        ("q_horizontal", 1.0),
        ("q_vertical", 0.1),
        ("r_range", 900.0),
        ("r_azimuth", 2e-6),
        ("r_elevation", 3e-6),
        ("r_range_rate", 0.25),
    )
)  # a radar3d fit, as `adaptrack fit` writes it


class _Stop(KeyboardInterrupt):
    """The simulated Ctrl-C."""


@dataclass(frozen=True)
class Invocation:
    """A command line whose output files are ``outputs`` (relative to the case directory)."""

    argv: list[str]
    outputs: tuple[str, ...]
    spoiled: str


def _press_again(previous: Callable[[Any], None]) -> Callable[[Any], None]:
    """An unraisable hook for the simulated Ctrl-C.

    A ``KeyboardInterrupt`` that lands in a finaliser or a weak-reference callback (numba's
    type cache has some) is printed and ignored by Python, as a real Ctrl-C there would be; the
    user presses again: the alarm is re-armed for 50 ms. Any other unraisable exception goes to
    ``previous``.
    """

    def hook(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, _Stop):
            signal.setitimer(signal.ITIMER_REAL, 0.05)
        else:
            previous(unraisable)

    return hook


def run_case(inv: Invocation, workdir: Path, budget_s: float) -> tuple[str, str]:
    """Run ``inv`` in ``workdir``; its category and a one-line detail."""
    out, err = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(_Stop()))
    old_hook = sys.unraisablehook
    sys.unraisablehook = _press_again(old_hook)
    signal.setitimer(signal.ITIMER_REAL, budget_s)
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main(inv.argv)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    except BaseException as exc:  # anything escaping main is the defect counted
        return "traceback", f"{inv.spoiled}: {type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        sys.unraisablehook = old_hook
        os.chdir(cwd)
    lines = [  # (progress lines of a long run are not part of its message)
        ln for ln in err.getvalue().splitlines() if ln.strip() and not ln.startswith(LINE_PREFIX)
    ]
    leftovers = [p.name for p in workdir.iterdir() if p.name.endswith(".tmp")]
    if code == 3:
        return "internal error", f"{inv.spoiled}: {lines[-1] if lines else ''}"
    if leftovers:
        return "partial output", f"{inv.spoiled}: temporary files {leftovers}"
    broken = [
        name for name in inv.outputs if (workdir / name).exists() and not _complete(workdir / name)
    ]
    if broken:
        return "partial output", f"{inv.spoiled}: {broken} exist but do not parse"
    if code == 0 or (inv.argv[0] == "demo" and code in VERDICT_EXIT.values()):
        missing = [name for name in inv.outputs if not (workdir / name).exists()]
        if missing:
            return "silent failure", f"{inv.spoiled}: exit 0 without {missing}"
        return "done", ""
    if len(lines) != 1 or not lines[0].startswith("error: "):
        if not (code == 130 and lines and lines[-1] == "error: interrupted"):
            return "bad message", f"{inv.spoiled} (exit {code}): {lines[-3:]}"
    if code == 130:
        return "interrupted", ""
    made = [name for name in inv.outputs if (workdir / name).exists()]
    if made:
        return "partial output", f"{inv.spoiled}: rejected but wrote {made}"
    return "rejected", ""


def _complete(path: Path) -> bool:
    """Whether an output file parses completely (table, JSON, TOML, HTML)."""
    try:
        if path.is_dir():
            return True
        if path.suffix in (".csv", ".parquet"):
            (pd.read_parquet if path.suffix == ".parquet" else pd.read_csv)(path)
        elif path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".toml":
            tomllib.loads(path.read_text())
        elif path.suffix == ".html":
            return path.read_text().rstrip().endswith("</html>")
        return True
    except Exception:
        return False


# ------------------------------------------------------------------------- mutations


def mutate_table(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A CSV spoiled in one way, and the way."""
    lines = text.splitlines()
    header, rows = lines[0].split(","), lines[1:]
    how = rng.choice(
        ["drop column", "rename column", "bad cell", "duplicate row", "swap rows", "truncate",
         "ragged row", "empty", "header only", "binary", "semicolons"]
    )  # fmt: skip
    col = int(rng.integers(len(header)))
    if how in ("drop column", "rename column"):
        cells = [r.split(",") for r in lines]
        if how == "drop column":
            cells = [c[:col] + c[col + 1 :] for c in cells]
        else:
            cells[0][col] = cells[0][col] + "_x"
        return "\n".join(",".join(c) for c in cells) + "\n", how
    if how == "bad cell" and rows:
        i = int(rng.integers(len(rows)))
        cells = rows[i].split(",")
        value = str(rng.choice(["abc", "nan", "inf", "-inf", "1e400", "", "-1", "1e300"]))
        cells[col % len(cells)] = value
        rows[i] = ",".join(cells)
        return "\n".join([lines[0], *rows]) + "\n", f"cell {header[col]} = {value!r}"
    if how == "duplicate row" and rows:
        i = int(rng.integers(len(rows)))
        rows.insert(i, rows[i])
    elif how == "swap rows" and len(rows) > 1:
        i, j = rng.choice(len(rows), 2, replace=False)
        rows[i], rows[j] = rows[j], rows[i]
    elif how == "truncate":
        return text[: int(rng.integers(1, max(len(text), 2)))], how
    elif how == "ragged row" and rows:
        rows[int(rng.integers(len(rows)))] += ",1,2"
    elif how == "empty":
        return "", how
    elif how == "header only":
        return lines[0] + "\n", how
    elif how == "binary":
        return "\x00\xff\xfe garbage \x81\n", how
    elif how == "semicolons":
        return text.replace(",", ";"), how
    return "\n".join([lines[0], *rows]) + "\n", str(how)


def mutate_toml(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A TOML document spoiled in one way, and the way."""
    lines = text.splitlines()
    values = [i for i, ln in enumerate(lines) if "=" in ln and not ln.lstrip().startswith("#")]
    how = str(rng.choice(["delete line", "bad value", "truncate", "duplicate key", "garbage"]))
    i = int(rng.choice(values)) if values else 0
    if how == "delete line" and values:
        return "\n".join(lines[:i] + lines[i + 1 :]), f"deleted {lines[i].strip()[:40]!r}"
    if how == "bad value" and values:
        key = lines[i].split("=")[0]
        value = str(rng.choice(['"abc"', "-1", "0", "1e400", "nan", "inf", "[]", "{}", "true"]))
        lines[i] = f"{key}= {value}"
        return "\n".join(lines), f"{key.strip()} = {value}"
    if how == "truncate":
        return text[: int(rng.integers(1, max(len(text), 2)))], how
    if how == "duplicate key" and values:
        return "\n".join(lines[: i + 1] + [lines[i]] + lines[i + 1 :]), how
    return text + "\n[[[ not toml\n", how


# ----------------------------------------------------------------------- the commands


@dataclass(frozen=True)
class Fixtures:
    """Valid inputs every case starts from (made once by the command line itself)."""

    detections: str  # an object-list table (simulate)
    scene: str  # raw detections of a short scene (simulate --scene)
    navigation: str  # radar + velocity nodes (smooth)
    record: str  # one radar's samples with range-rate (smooth: triple nodes, EKF)
    plots: str  # a 3-D radar plot list (fit --measurement radar3d)
    site: str  # lx_default.toml
    summary: str  # a demo summary.json (report)


def make_fixtures(d: Path) -> Fixtures:
    """Simulate the valid inputs into ``d``."""
    with contextlib.redirect_stdout(io.StringIO()):
        for argv in (
            ["simulate", "lx_default", "--out", str(d / "det.csv"), "--runs", "1", "--seed", "1"],
            ["simulate", "lx_default", "--scene", "--duration", "20", "--seed", "2",
             "--out", str(d / "scene.csv")],
        ):  # fmt: skip
            with contextlib.suppress(SystemExit):
                main(argv)
    det = pd.read_csv(d / "det.csv")
    det = det[det.object_id.isin(det.object_id.unique()[:3])]
    nav = _navigation(np.random.default_rng(0))
    record = nav.assign(range_rate_mps=150.0 + np.random.default_rng(1).normal(0, 0.5, len(nav)))
    return Fixtures(
        det.to_csv(index=False),
        (d / "scene.csv").read_text(),
        nav.to_csv(index=False),
        record.to_csv(index=False),
        record.iloc[:30].to_csv(index=False),
        (SITES / "lx_default.toml").read_text(),
        json.dumps({"site": "lx_default", "rows": []}),
    )


def _navigation(rng: np.random.Generator) -> pd.DataFrame:
    """Radar nodes of an aircraft 20 km out (the ``smooth`` command's input)."""
    t = np.arange(0.0, 60.0, 1.0)
    return pd.DataFrame(
        {
            "time_s": t,
            "range_m": 2e4 + 150.0 * t + rng.normal(0, 30, t.size),
            "azimuth_deg": 30.0 + 0.01 * t + rng.normal(0, 0.08, t.size),
            "elevation_deg": 5.0 + rng.normal(0, 0.1, t.size),
        }
    )


def invocation(fx: Fixtures, d: Path, rng: np.random.Generator) -> Invocation:
    """One spoiled command line, its inputs written into ``d``."""
    command = str(rng.choice(["track", "track scene", "smooth", "smooth record", "fit radar",
                              "filter radar", "simulate", "report", "tune", "evaluate", "demo",
                              "options"]))  # fmt: skip
    site = d / "site.toml"
    site.write_text(fx.site)
    spoil_site = rng.uniform() < 0.3
    if spoil_site:
        text, how = mutate_toml(fx.site, rng)
        site.write_text(text)
    where = f"{command}: " + (f"site {how}" if spoil_site else "")
    if command in ("track", "track scene", "smooth", "smooth record", "fit radar", "filter radar"):
        source = {
            "track": fx.detections,
            "track scene": fx.scene,
            "smooth": fx.navigation,
            "smooth record": fx.record,
            "fit radar": fx.plots,
            "filter radar": fx.plots,
        }
        text, how = mutate_table(source[command], rng)
        (d / "in.csv").write_text(text)
        where += f" table {how}"
        if command.startswith("smooth"):
            method = str(rng.choice(["lsq", "rts"]))
            return Invocation(["smooth", "in.csv", "--site", "50.4,30.5,180", "--method", method,
                               "--out", "est.csv"], ("est.csv",), where)  # fmt: skip
        if command == "fit radar":
            model = str(rng.choice(["cv", "ca", "ct"]))
            argv = [
                "fit",
                "in.csv",
                "--measurement",
                "radar3d",
                "--model",
                model,
                "--out",
                "fit.toml",
            ]
            return Invocation(argv, ("fit.toml",), where + f" --model {model}")
        if command == "filter radar":
            (d / "fit.toml").write_text(FIT_TOML)
            return Invocation(["filter", "in.csv", "--config", "fit.toml", "--out", "est.csv"],
                              ("est.csv",), where)  # fmt: skip
        return Invocation(["track", "in.csv", "--site", "site.toml", "--out", "est.csv"],
                          ("est.csv", "est.events.csv"), where)  # fmt: skip
    if command == "simulate":
        return Invocation(["simulate", "site.toml", "--out", "det.csv", "--runs", "1"],
                          ("det.csv",), where)  # fmt: skip
    if command == "report":
        text, how = mutate_table(fx.summary.replace(",", ",\n"), rng)
        (d / "summary.json").write_text(text)
        return Invocation(["report", "summary.json", "--out", "r.html"], ("r.html",), where + how)
    if command in ("tune", "demo"):
        out = "tuned.toml" if command == "tune" else "out"
        argv = (
            [command, "site.toml", "--out", out, "--workers", "1"]
            if command == "tune"
            else ["demo", "--site", "site.toml", "--out", out, "--runs", "2", "--workers", "1"]
        )
        return Invocation(argv, (out,), where)
    if command == "evaluate":
        scen = str(rng.choice(["no_such_scenario", "site.toml", "1e3"]))
        return Invocation(["evaluate", scen, "--runs", "2", "--workers", "1"], (), where + scen)
    # an option spoiled on a command that would otherwise succeed
    option, value = (
        str(rng.choice(["--runs", "--seed", "--duration", "--degree", "--window", "--method",
                        "--site", "--ids", "--criterion", "--families"])),
        str(rng.choice(["-1", "0", "nan", "inf", "abc", "1e12", "", "lx_nowhere", "1,2"])),
    )  # fmt: skip
    (d / "in.csv").write_text(fx.navigation if option in ("--degree", "--window", "--method")
                              else fx.detections)  # fmt: skip
    smooth = ["smooth", "in.csv", "--site", "50,30,0", "--out", "det.csv"]
    argv = {
        "--runs": ["simulate", "lx_default", "--out", "det.csv", "--runs", value],
        "--seed": ["simulate", "lx_default", "--out", "det.csv", "--seed", value],
        "--duration": ["simulate", "--scene", "--out", "det.csv", "--duration", value],
        "--degree": [*smooth, "--degree", value],
        "--window": [*smooth, "--window", value],
        "--method": [*smooth, "--method", value],
        "--site": ["smooth", "in.csv", "--out", "det.csv", "--site", value],
        "--ids": ["track", "in.csv", "--out", "det.csv", "--ids", value],
        "--criterion": ["tune", "--out", "det.csv", "--workers", "1", "--criterion", value],
        "--families": ["tune", "--out", "det.csv", "--workers", "1", "--families", value],
    }[option]  # fmt: skip
    return Invocation(argv, ("det.csv",), f"{option} {value!r}")


def campaign(
    n_cases: int, seed: int, budget_s: float, progress: bool = False
) -> tuple[Counter, dict]:
    """Run ``n_cases`` cases; counts by (command, category) and one example per defect."""
    counts: Counter = Counter()
    examples: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as base:
        fx = make_fixtures(Path(base))
        for i in range(n_cases):
            rng = np.random.default_rng((seed, i))
            d = Path(base) / f"case{i}"
            d.mkdir()
            inv = invocation(fx, d, rng)
            category, detail = run_case(inv, d, budget_s)
            counts[(inv.argv[0], category)] += 1
            if category in DEFECTS and category not in examples:
                examples[category] = f"seed {(seed, i)}: {detail}"
            shutil.rmtree(d, ignore_errors=True)
            if progress and (i + 1) % 50 == 0:
                defects = sum(v for (_, c), v in counts.items() if c in DEFECTS)
                print(f"{i + 1} cases, {defects} defects", flush=True)
    return counts, examples


def main_cli() -> None:
    """Command line: run the campaign, print counts by category; exit 1 on any defect."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--budget", type=float, default=8.0, help="seconds before Ctrl-C")
    args = parser.parse_args()
    counts, examples = campaign(args.cases, args.seed, args.budget, progress=True)
    print(f"{sum(counts.values())} cases")
    for category in ("done", "rejected", "interrupted", *DEFECTS):
        by = ", ".join(f"{c} {v}" for (c, k), v in sorted(counts.items()) if k == category)
        print(
            f"{category}: {sum(v for (_, k), v in counts.items() if k == category)}"
            + (f" ({by})" if by else "")
        )
    for key, text in examples.items():
        print(f"example {key}: {text}")
    raise SystemExit(1 if any(k in DEFECTS for (_, k) in counts) else 0)


if __name__ == "__main__":
    main_cli()
