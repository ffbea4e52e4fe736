"""Registration of the built-in plugins (exactly as a third-party package would do it)."""
from __future__ import annotations

from dataclasses import dataclass

from twinkit import hookimpl


@dataclass
class LocalExecutorParams:
    workers: int = 2  # worker processes for fanned-out items (1 = run in the main process)


def local_executor(params: LocalExecutorParams):
    """Run fanned-out items in local worker processes."""
    from twinkit.executors import LocalExecutor

    return LocalExecutor(workers=params.workers)


@hookimpl
def twinkit_register_executors(register):
    register("local", local_executor, params=LocalExecutorParams)
