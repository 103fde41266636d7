"""--workers / --scheduler: the same result on a Dask cluster as in-process."""

import json

import pytest

from .test_cli import run

EVALUATE = ("evaluate", "zimchuk_table1", "--runs", "2", "--train-runs", "2")


@pytest.mark.slow
@pytest.mark.distributed
def test_evaluate_on_an_existing_scheduler_is_bit_identical(tmp_path, dask_pool):
    local = run(*EVALUATE, "--profile-points", "4", "--workers", "1", "--json", str(tmp_path / "a"))
    assert local.returncode == 0, local.stderr
    address = dask_pool.client.scheduler.address
    remote = run(
        *EVALUATE, "--profile-points", "4", "--scheduler", address, "--json", str(tmp_path / "b")
    )
    assert remote.returncode == 0, remote.stderr
    a, b = (json.loads((tmp_path / n).read_text()) for n in "ab")
    assert len(a["tuning"]["inverse_dynamics"]["profile"]["criterion"]) == 5
    assert a == b


def test_workers_and_scheduler_are_exclusive_and_checked():
    proc = run(*EVALUATE, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1")
    assert proc.returncode == 2 and "not both" in proc.stderr
    assert run(*EVALUATE, "--workers", "0").returncode == 2


def test_an_unreachable_scheduler_is_a_clear_error(monkeypatch):
    monkeypatch.setenv("DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT", "1s")
    proc = run("tune", "--out", "never.toml", "--scheduler", "tcp://127.0.0.1:9")
    assert proc.returncode == 1
    assert "cannot start the task pool" in proc.stderr
