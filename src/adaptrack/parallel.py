"""Independent tasks (Monte-Carlo partitions, tuning grid points) in-process or on Dask.

:func:`task_pool` yields a :class:`TaskPool` that runs tasks

* in this process, in order (``workers <= 1`` and no scheduler);
* on a ``dask.distributed`` LocalCluster of ``workers`` single-threaded processes;
* on an existing Dask cluster (``scheduler="tcp://host:8786"``).

A task is a pure function of its arguments (random tasks carry their own seed stream), so the
results are bit-identical whichever pool runs them; they come back in submission order.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

R = TypeVar("R")


class WorkerLost(RuntimeError):
    """A task's worker processes died every time the task ran (on them).

    Out of memory, a crash in compiled code, a kill: the run stops with this error instead of
    waiting for the task.
    """


class TaskPool:
    """Runs independent tasks; ``client`` is a ``distributed.Client`` or None (in-process)."""

    def __init__(self, client: Any | None = None) -> None:
        self.client = client

    @property
    def n_workers(self) -> int:
        """Worker processes (1 in-process)."""
        if self.client is None:
            return 1
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def share(self, obj: Any) -> Any:
        """Send ``obj`` to every worker once; pass the returned handle as a task argument."""
        if self.client is None:
            return obj
        return self.client.scatter(obj, broadcast=True, hash=False)

    def map(
        self,
        fn: Callable[..., R],
        tasks: Sequence[tuple[Any, ...]],
        progress: Callable[[int], None] | None = None,
    ) -> list[R]:
        """Return ``[fn(*args) for args in tasks]``; ``progress(i)`` as task ``i`` finishes.

        A failing task raises its own exception here (the remaining tasks are cancelled). A
        task whose worker process dies is run again on a live worker (the Nanny restarts the
        dead one); after Dask's ``allowed-failures`` deaths (3 by default) :class:`WorkerLost`
        names it.
        """
        if self.client is None:
            out = []
            for i, args in enumerate(tasks):
                out.append(fn(*args))
                if progress:
                    progress(i)
            return out
        from distributed import KilledWorker, as_completed

        futures = [self.client.submit(_one_kernel_thread, fn, *args, pure=False) for args in tasks]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(futures)
        try:
            for fut in as_completed(futures):
                i = index[fut.key]
                try:
                    results[i] = fut.result()
                except KilledWorker as exc:
                    raise WorkerLost(
                        f"task {i} of {len(futures)} ({getattr(fn, '__name__', fn)}): worker "
                        f"processes died every time it ran ({exc}); the run stops"
                    ) from exc
                if progress:
                    progress(i)
        finally:
            self.client.cancel([f for f in futures if not f.done()])
        return results


def _one_kernel_thread(fn: Callable[..., R], *args: Any) -> R:
    """Run ``fn`` on a cluster worker with one compiled-kernel thread.

    The workers (one task at a time each) are the parallelism; numba's default of a thread per
    core in every worker would oversubscribe the cores.
    """
    import numba

    numba.set_num_threads(1)
    return fn(*args)


@contextmanager
def task_pool(workers: int = 1, scheduler: str | None = None) -> Iterator[TaskPool]:
    """Open a task pool: in-process, a LocalCluster of ``workers`` processes, or ``scheduler``.

    Raises
    ------
    ValueError
        If both ``workers > 1`` and ``scheduler`` are given, or ``workers < 0``.
    """
    if workers < 0:
        raise ValueError(f"workers must be >= 0; got {workers}")
    if scheduler is not None and workers > 1:
        raise ValueError("give either workers (a local cluster) or scheduler (an existing one)")
    if scheduler is None and workers <= 1:
        yield TaskPool()
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - distributed is a runtime dependency
        raise RuntimeError("parallel runs need dask.distributed: pip install distributed") from exc
    if scheduler is not None:
        with Client(scheduler) as client:
            yield TaskPool(client)
        return
    with (
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # a free port (None is 8787: a second run failed)
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield TaskPool(client)


__all__ = ["TaskPool", "WorkerLost", "task_pool"]
