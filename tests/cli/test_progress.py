"""Progress of long commands off a terminal: lines with counts and an ETA on stderr."""

import io
import re

from rich.console import Console

from adaptrack._progress import LINE_PREFIX, progress


def test_lines_report_counts_elapsed_and_eta(monkeypatch, capsys):
    monkeypatch.setenv("ADAPTRACK_PROGRESS_EVERY_S", "0")
    clock = iter([0.0, 10.0, 30.0, 40.0])  # start, then each change
    monkeypatch.setattr("adaptrack._progress.time.monotonic", lambda: next(clock))
    console = Console(file=io.StringIO(), force_terminal=False)
    with progress(console, "tuning", total=4) as bar:
        bar.advance("cv tuned")  # 1 of 4 after 10 s: 30 s to go
        bar.advance("ca tuned")  # 2 of 4 after 30 s: 30 s to go
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        f"{LINE_PREFIX}tuning 1/4 (25 %), 10s elapsed, ETA 30s: cv tuned",
        f"{LINE_PREFIX}tuning 2/4 (50 %), 30s elapsed, ETA 30s: ca tuned",
        f"{LINE_PREFIX}tuning 2/4 (50 %), 40s elapsed, ETA 40s: ca tuned",
    ]


def test_lines_without_a_total_report_the_count_so_far(monkeypatch, capsys):
    monkeypatch.setenv("ADAPTRACK_PROGRESS_EVERY_S", "0")
    clock = iter([0.0, 5.0, 12.0, 15.0])  # start, each change, the closing line
    monkeypatch.setattr("adaptrack._progress.time.monotonic", lambda: next(clock))
    console = Console(file=io.StringIO(), force_terminal=False)
    with progress(console, "CV fit (likelihood evaluations)") as bar:
        bar.advance()
        bar.advance()
    assert capsys.readouterr().err.splitlines() == [
        f"{LINE_PREFIX}CV fit (likelihood evaluations) 1 done, 5s elapsed",
        f"{LINE_PREFIX}CV fit (likelihood evaluations) 2 done, 12s elapsed",
        f"{LINE_PREFIX}CV fit (likelihood evaluations) 2 done, 15s elapsed",
    ]


def test_quick_runs_print_nothing(capsys):
    console = Console(file=io.StringIO(), force_terminal=False)
    with progress(console, "tuning", total=4) as bar:  # default: a line every 10 s at most
        bar.advance("cv tuned")
    assert capsys.readouterr().err == ""


def test_track_in_a_pipe_shows_progress_lines(cli, tmp_path, monkeypatch):
    det = tmp_path / "det.csv"
    assert cli("simulate", "--scene", "--duration", "20", "--seed", "2", "--out", det)[0] == 0
    monkeypatch.setenv("ADAPTRACK_PROGRESS_EVERY_S", "0")
    code, out, err = cli("track", det, "--site", "lx_default", "--out", tmp_path / "t.csv")
    assert code == 0, err
    lines = err.splitlines()
    assert lines and all(ln.startswith(f"{LINE_PREFIX}tracking (scans) ") for ln in lines)
    last = re.match(r".* (\d+)/(\d+) \(100 %\)", lines[-1])
    assert last and last.group(1) == last.group(2)
    assert "wrote" in out


def test_a_first_run_says_that_it_compiles(monkeypatch, capsys, tmp_path):
    import adaptrack._progress as progress_module
    from adaptrack._backend import kernels_cached

    assert not kernels_cached("_no_such_module.kernel")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "_no_such_module.kernel-12.py311.nbi").write_text("")
    assert kernels_cached("_no_such_module.kernel")  # numba's cache folder counts too
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(empty))  # numba looks only there now
    assert not kernels_cached("_imm_kernel.imm_kernel", "filters")
    monkeypatch.setattr(progress_module, "kernels_cached", lambda kernel, package: False)
    progress_module.announce_compilation("5 min")
    assert "first run on this machine: numba compiles the kernels now" in capsys.readouterr().err
    monkeypatch.setattr(progress_module, "kernels_cached", lambda kernel, package: True)
    progress_module.announce_compilation("5 min")
    assert capsys.readouterr().err == ""
