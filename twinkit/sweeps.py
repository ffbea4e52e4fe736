"""A sweep's jobs (``twinkit -m``): they die with the sweep, a lost one fails alone, and a memory budget.

- The sweep's process puts its pid in ``$TWINKIT_SWEEP_PID`` (:func:`mark_sweep`) before Hydra's joblib
  launcher starts its (loky) workers; at the start of each job the worker asks the kernel to kill it when
  the sweep's process dies (:func:`twinkit.signals.die_with_parent`), so ``kill -9`` of the sweep leaves
  no worker computing.
- Each job runs in a child of the pool's worker (:func:`run_job`, through
  :func:`twinkit.engine.isolate.run_in_child`); the worker only waits. When the job's process is killed
  (the kernel's out-of-memory kill, ``kill -9``), the worker marks the job's manifest ``failed`` with the
  reason and reports the job failed; the pool stays whole and the other jobs finish.
- ``engine.sweep_memory_gb`` caps what the sweep's jobs may use together (:func:`memory_plan`).
"""
from __future__ import annotations

import datetime as _dt
import json
import logging
import os
from pathlib import Path
from typing import Any, Callable

log = logging.getLogger("twinkit")

SWEEP_PID_ENV = "TWINKIT_SWEEP_PID"


def mark_sweep() -> None:
    """In the sweep's own process, before the launcher starts its workers: they inherit its pid."""
    os.environ[SWEEP_PID_ENV] = str(os.getpid())


def sweep_pid() -> int | None:
    """The pid of the sweep this process runs a job of; None outside a sweep's worker (or in the sweep's
    own process, where a launcher may run jobs itself)."""
    try:
        pid = int(os.environ.get(SWEEP_PID_ENV, ""))
    except ValueError:
        return None
    return pid if pid != os.getpid() else None


def run_job(job: Callable[[Any], int], cfg, output_dir: Path, label: str) -> int:
    """``job(cfg)`` for one job of a sweep, in a worker of the sweep's pool: die with the sweep, and run
    the job in a child so that the job's death is its own failure (see the module's doc). ``label`` names
    the job in the error line. Returns the job's exit status; raises its error (a Hydra job error)."""
    from twinkit.engine.isolate import NativeCrash, isolation_enabled, run_in_child
    from twinkit.hydra_glue import job_error
    from twinkit.signals import die_with_parent

    parent = sweep_pid()
    if parent is None:
        return job(cfg)
    die_with_parent(parent)
    if not isolation_enabled():
        return job(cfg)
    try:
        return run_in_child(job, {"cfg": cfg}, pass_signals=True)
    except NativeCrash as exc:
        reason = lost_reason(exc.signal)
        mark_lost(output_dir / "manifest.json", reason)
        raise job_error(f"twinkit: error: sweep {label} failed: {reason}; the other jobs go on "
                        f"(its manifest: {output_dir / 'manifest.json'})", 1) from None


def lost_reason(sig: int) -> str:
    """Why a job's process died, in words."""
    import signal

    try:
        name = signal.Signals(sig).name
    except ValueError:
        name = f"signal {sig}"
    if not sig:
        return "the worker running this job ended without a result"
    if sig == signal.SIGKILL:
        return "the worker running this job was killed (SIGKILL, out of memory?)"
    return f"the worker running this job died from {name}"


def mark_lost(manifest: Path, reason: str) -> None:
    """A lost job's manifest (written ``running`` when the job started) says ``failed`` with ``reason``."""
    from twinkit.manifest import write_manifest

    try:
        data = json.loads(manifest.read_text())
    except (OSError, ValueError):
        data = {"steps": []}  # the job died before its manifest was written
    if not isinstance(data, dict) or data.get("status") not in (None, "running"):
        return
    data.update(status="failed", error=reason,
                finished=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    try:
        write_manifest(manifest, data)
    except OSError as exc:
        log.error("twinkit: could not write %s: %s", manifest, exc)


def summary_after_failure() -> None:
    """The summary of a sweep that ended with a failed job (Hydra calls no end-of-sweep callback then)."""
    try:
        from twinkit.report.sweep import SweepSummaryCallback
    except ImportError:
        return
    sweep, SweepSummaryCallback.started = SweepSummaryCallback.started, None
    if sweep is not None and sweep.is_dir():
        SweepSummaryCallback.write(sweep)
