"""Task pools: in-process order, Dask LocalCluster equivalence, errors."""

import operator

import pytest

from adaptrack.parallel import TaskPool, WorkerLost, task_pool


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise ArithmeticError(f"task {x} failed")
    return x * x


def test_in_process_pool_keeps_order_and_reports_progress():
    seen: list[int] = []
    pool = TaskPool()
    assert pool.n_workers == 1
    assert pool.share(obj := object()) is obj
    assert pool.map(operator.add, [(1, 2), (3, 4), (5, 6)], progress=seen.append) == [3, 7, 11]
    assert seen == [0, 1, 2]


def test_pool_arguments_are_checked():
    with pytest.raises(ValueError, match="workers must be >= 0"), task_pool(-1):
        pass
    with (
        pytest.raises(ValueError, match="either workers"),
        task_pool(2, scheduler="tcp://127.0.0.1:1"),
    ):
        pass


@pytest.mark.distributed
def test_local_cluster_map_is_ordered_and_complete(dask_pool):
    seen: list[int] = []
    assert dask_pool.n_workers == 2
    out = dask_pool.map(pow, [(i, 2) for i in range(20)], progress=seen.append)
    assert out == [i * i for i in range(20)]
    assert sorted(seen) == list(range(20))  # every task reported once, whatever the order
    big = dask_pool.share(list(range(1000)))
    assert dask_pool.map(len, [(big,)] * 3) == [1000] * 3


@pytest.mark.distributed
def test_a_failing_task_raises_its_own_error(dask_pool):
    with pytest.raises(ArithmeticError, match="task 3 failed"):
        dask_pool.map(_fail_on_three, [(i,) for i in range(6)])


@pytest.mark.distributed
def test_an_existing_scheduler_by_address(dask_pool):
    address = dask_pool.client.scheduler.address
    with task_pool(scheduler=address) as pool:
        assert pool.n_workers == 2
        assert pool.map(operator.mul, [(2, 3), (4, 5)]) == [6, 20]


def _die_once(marker: str, x: int) -> int:
    """Kill the worker process the first time (no marker file yet), then square ``x``."""
    import os
    from pathlib import Path

    if x == 2 and not Path(marker).exists():
        Path(marker).touch()
        os._exit(1)
    return x * x


def _always_die(x: int) -> int:
    import os

    if x == 1:
        os._exit(1)
    return x


@pytest.mark.distributed
def test_a_task_whose_worker_dies_runs_again_and_the_results_are_complete(tmp_path):
    marker = str(tmp_path / "died")
    with task_pool(workers=2) as pool:
        assert pool.map(_die_once, [(marker, i) for i in range(6)]) == [i * i for i in range(6)]
    assert (tmp_path / "died").exists()  # the worker did die once


@pytest.mark.distributed
def test_a_task_that_kills_every_worker_stops_the_run_with_a_clear_error():
    with (
        task_pool(workers=2) as pool,
        pytest.raises(WorkerLost, match=r"task \d of 4 \(_always_die\): worker processes died"),
    ):
        pool.map(_always_die, [(i,) for i in range(4)])


def test_the_command_line_reports_a_lost_worker_in_one_line(capsys):
    import typer

    from adaptrack.cli.options import worker_pool as _pool

    with pytest.raises(typer.Exit) as exit_info, _pool(1, None):
        raise WorkerLost("task 1 of 4 (fn): worker processes died every time it ran")
    assert exit_info.value.exit_code == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: task 1 of 4 (fn): worker processes died every time it ran"
    ]
