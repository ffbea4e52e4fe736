"""Registration of the built-in plugins (exactly as a third-party package would do it)."""
from __future__ import annotations

from dataclasses import dataclass

from twinkit import hookimpl
from twinkit.ranges import param


@dataclass
class LocalExecutorParams:
    workers: int = param(2, ge=1, le=1024,
                         help="Worker processes for fanned-out items; 1 = run them in the main process.")
    threads_per_worker: int = param(0, ge=0,
                                    help="Cap on each worker's native thread pools (OpenMP, BLAS); 0 = cores / "
                                         "workers.")
    max_items_per_worker: int = param(0, ge=0,
                                      help="> 0: start a fresh worker process after this many items (bounds the "
                                           "memory a worker carries over); 0 = never.")


def local_executor(params: LocalExecutorParams):
    """Run fanned-out items in local worker processes."""
    from twinkit.executors import LocalExecutor

    return LocalExecutor(workers=params.workers, threads_per_worker=params.threads_per_worker,
                         max_items_per_worker=params.max_items_per_worker)


@hookimpl
def twinkit_register_executors(register):
    register("local", local_executor, params=LocalExecutorParams)
