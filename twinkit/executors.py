"""Executors run the items of a fanned-out step. The engine only calls ``map(fn, items)``.

``LocalExecutor`` uses worker processes on this machine (started with 'spawn', so
libraries that start threads, such as open3d, are safe). Other executors (Dask,
Ray) are plugins of kind ``executor`` that provide the same ``map``.
"""
from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable, Iterator

from twinkit.threads import BUDGET_ENV, THREAD_ENV, cores, limit_threads  # noqa: F401 (THREAD_ENV re-exported)

#: start methods of the standard library; a multirun job runs in a joblib (loky) worker whose default is
#: loky's own, which a spawned child cannot find ("cannot find context for 'loky'")
_STD_METHODS = ("spawn", "fork", "forkserver")


def use_standard_start_method() -> None:
    """Make 'spawn' this process's default start method when it is not one of the standard library's.

    A spawned child re-applies its parent's *default* start method (even when the pool asked for spawn
    explicitly), so a pool started inside a loky worker dies at once with BrokenProcessPool."""
    if mp.get_start_method(allow_none=True) not in (None, *_STD_METHODS):
        mp.set_start_method("spawn", force=True)


def _init_worker(n: int, parent_pid: int) -> None:
    """Worker initializer: die with the run, and cap the native thread pools before any library starts them."""
    from twinkit.signals import die_with_parent

    die_with_parent(parent_pid)
    limit_threads(n)


class LocalExecutor:
    """Run items in up to ``workers`` local processes (in this process when ``workers <= 1``, unless
    ``max_items_per_worker`` asks for fresh processes).

    Each worker's native thread pools are capped at ``threads_per_worker`` (0 = the cores divided
    among the workers), so that two workers on two cores do not each start an OpenMP pool of two
    threads and fight over the cores: measured on the tiled demo, 2 workers took 35 s uncapped and
    25 s capped for the same four tiles.
    """

    def __init__(self, workers: int = 2, threads_per_worker: int = 0, max_items_per_worker: int = 0):
        self.workers = max(1, int(workers))
        self.threads_per_worker = int(threads_per_worker)
        self.max_items_per_worker = max(0, int(max_items_per_worker))

    def _threads(self, n_workers: int) -> int:
        if self.threads_per_worker > 0:
            return self.threads_per_worker
        # the run's share of the cores (the engine sets it per step), divided among the workers
        try:
            budget = int(os.environ.get(BUDGET_ENV) or 0) or cores()
        except ValueError:
            budget = cores()
        return max(1, budget // n_workers)

    def map(self, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[Any]:
        # one worker runs in this process, unless every item must have a fresh process of its own
        # (max_items_per_worker): then one worker process, so that each item's peak memory is its own
        if not items:
            return
        if (self.workers <= 1 or len(items) <= 1) and not self.max_items_per_worker:
            for it in items:
                yield fn(it)
            return
        n = min(self.workers, len(items))
        extra = {"max_tasks_per_child": self.max_items_per_worker} if self.max_items_per_worker else {}
        use_standard_start_method()
        pool = ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("spawn"), initializer=_init_worker,
                                   initargs=(self._threads(n), os.getpid()), **extra)
        try:
            yield from pool.map(fn, items)
        except (KeyboardInterrupt, GeneratorExit):
            # Ctrl-C, SIGTERM, or the caller stopped early: a worker busy in a long C call would keep
            # shutdown() waiting, so the workers are killed (their temporary folders go at the next run)
            _kill_workers(pool)
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        except BaseException:  # a failed item: the items already running finish and are stored
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


def _kill_workers(pool: ProcessPoolExecutor) -> None:
    for p in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            p.kill()
            p.join(timeout=5)
        except (OSError, ValueError, AttributeError):
            pass
