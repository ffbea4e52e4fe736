"""A thread budget shared by every twinkit run on this machine.

Each run that computes (a single run, or one multirun job) registers itself as a file named after its
process id in a per-user runtime folder (``$TWINKIT_RUNTIME_DIR``, else ``$XDG_RUNTIME_DIR/twinkit``,
else ``<tmp>/twinkit-<uid>``). A run's share of the cores is ``max(1, cores // active runs)``, read again
before each step, so a second run started beside a long one halves the threads of the next steps of
both. Files of dead processes are ignored and removed. A multirun job is also capped at
``cores // n_jobs`` from its start, before the other jobs have registered.

:func:`limit_threads` applies a count to the native thread pools: the environment variables read when a
library starts (OpenMP, OpenBLAS, MKL, numba), the pools of libraries already loaded (through
threadpoolctl) and torch when imported.
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Iterator

from twinkit.signals import pid_alive

#: thread-pool sizes read by OpenMP (open3d, scipy), OpenBLAS/MKL (numpy), numba and torch at start-up
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")

#: the thread count the engine gives the running step; executors read it for their workers
BUDGET_ENV = "TWINKIT_THREADS"


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def runtime_dir() -> Path:
    env = os.environ.get("TWINKIT_RUNTIME_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    if xdg and os.path.isdir(xdg):
        return Path(xdg) / "twinkit"
    return Path(tempfile.gettempdir()) / f"twinkit-{os.getuid() if hasattr(os, 'getuid') else 'user'}"


def active_runs() -> int:
    """How many registered runs are alive (at least 1: the caller counts itself)."""
    folder = runtime_dir() / "runs"
    n = 0
    try:
        entries = list(folder.iterdir())
    except OSError:
        return 1
    for p in entries:
        try:
            pid = int(p.name)
        except ValueError:
            continue
        if pid_alive(pid):
            n += 1
        else:
            with contextlib.suppress(OSError):
                p.unlink()
    return max(1, n)


def share(n_cores: int, n_runs: int, cap: int | None = None) -> int:
    """Threads for one of ``n_runs`` runs on ``n_cores`` cores, at most ``cap``."""
    t = max(1, n_cores // max(1, n_runs))
    return max(1, min(t, cap)) if cap else t


def budget(cap: int | None = None) -> int:
    """This run's share of the machine's cores now."""
    return share(cores(), active_runs(), cap)


@contextlib.contextmanager
def registered() -> Iterator[None]:
    """Count this process as an active run while the block runs."""
    folder = runtime_dir() / "runs"
    path = folder / str(os.getpid())
    written = True
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{' '.join(sys.argv)[:500]}\n")
    except OSError:
        written = False
    try:
        yield
    finally:
        if written:
            with contextlib.suppress(OSError):
                path.unlink()


def limit_threads(n: int) -> None:
    """Cap this process's native thread pools at ``n`` threads (libraries loaded now and later).

    Libraries loaded later read the environment variables; the OpenMP, BLAS and MKL pools already loaded
    are set through threadpoolctl; torch, when imported, through its own call.
    """
    from threadpoolctl import threadpool_limits

    n = max(1, int(n))
    for var in THREAD_ENV:
        os.environ[var] = str(n)
    os.environ[BUDGET_ENV] = str(n)
    threadpool_limits(limits=n)  # applied now, kept (not used as a context manager)
    torch = sys.modules.get("torch")
    if torch is not None:
        with contextlib.suppress(Exception):
            torch.set_num_threads(n)
