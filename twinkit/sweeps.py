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
        raise job_error(f"twinkit: error: {output_dir / 'manifest.json'}: sweep {label} failed: {reason}; the "
                        f"other jobs ran on; run it again with fewer jobs at once (engine.sweep_memory_gb, "
                        f"hydra.launcher.n_jobs)", 1) from None


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
    if sweep is None or not sweep.is_dir():
        return
    for manifest in sorted(sweep.glob("job*/manifest.json")):  # jobs the broken pool took down with it
        mark_lost(manifest, BROKEN_POOL)
    SweepSummaryCallback.write(sweep)


BROKEN_POOL = ("the sweep's pool of workers broke (one of its processes was killed: out of memory?), and it "
               "stopped the jobs it was running")


def broken_pool(exc: BaseException) -> str:
    """The one-line error for a sweep whose pool broke (a pool worker itself killed), else ""."""
    from concurrent.futures import BrokenExecutor

    if not isinstance(exc, BrokenExecutor):
        return ""
    return (f"twinkit: error: hydra.launcher: {BROKEN_POOL}; their manifests say failed; run the sweep again "
            f"with fewer jobs at once (engine.sweep_memory_gb, hydra.launcher.n_jobs)")


# --------------------------------------------------------------------------- the sweep's memory budget


def _available_gb() -> float | None:
    """This machine's available memory (``MemAvailable``), GB; None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) / 2**20
    except (OSError, ValueError, IndexError):
        pass
    return None


def _step_records(workspace: Path, step_id: str) -> list[Path]:
    """The step records (``step.json``) earlier runs and sweep jobs of this site left for step ``step_id``."""
    found = list(workspace.glob(f"[0-9]*_{step_id}/step.json"))
    sweeps = sorted(workspace.glob("sweeps/*"))[-20:]  # the latest sweeps are enough
    for sweep in sweeps:
        found += list(sweep.glob(f"job*/[0-9]*_{step_id}/step.json"))
    return found


def _record_peak_mb(path: Path, workers: int) -> float:
    """What a step recorded in ``path`` held at its peak, MB: its process, or its ``workers`` largest
    fan-out items at once."""
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return 0.0
    if not isinstance(rec, dict):
        return 0.0
    peak = float(rec.get("peak_rss_mb") or 0)
    items = (rec.get("metrics") or {}).get("per_item") if isinstance(rec.get("metrics"), dict) else None
    if isinstance(items, list):
        peaks = sorted((float(i.get("peak_rss_mb") or 0) for i in items if isinstance(i, dict)), reverse=True)
        peak = max(peak, sum(peaks[:max(1, workers)]))
    return peak


def job_estimate_gb(config: dict) -> tuple[float, str]:
    """A job's memory, GB, as its recipe's steps peaked in earlier runs of its site (the largest; the steps
    of a job run one after another), and the step that peaked; (0, "") when none has run yet."""
    engine = config.get("engine") or {}
    workspace = Path(str(engine.get("outputs_dir", "outputs"))) / str((config.get("site") or {}).get("name", ""))
    workers = int((config.get("executor") or {}).get("workers") or 1)
    best, which = 0.0, ""
    for step in (config.get("recipe") or {}).get("steps") or []:
        sid = step.get("id") if isinstance(step, dict) else None
        if not sid:
            continue
        for rec in _step_records(workspace, str(sid)):
            peak = _record_peak_mb(rec, workers)
            if peak > best:
                best, which = peak, str(sid)
    return best / 1024, which


def memory_plan(configs: list[dict], asked: Callable[[], int]) -> tuple[int, str]:
    """How many of a sweep's jobs may run at once under ``engine.sweep_memory_gb`` (0: the memory this
    machine has available now), and a line that says why when fewer than ``asked()`` (the launcher's
    jobs at once, read only when needed). Raises ConfigError when one job alone needs more than a budget
    that was set; (0, "") when nothing is known of the jobs' memory."""
    from twinkit.errors import ConfigError

    if not configs:
        return 0, ""
    budget = float((configs[0].get("engine") or {}).get("sweep_memory_gb") or 0)
    chosen = budget > 0
    if not chosen:
        budget = _available_gb() or 0
    estimates = sorted((job_estimate_gb(c) for c in configs), reverse=True)
    if budget <= 0 or estimates[0][0] <= 0:
        return 0, ""  # nothing known: the jobs run as asked
    top, step = estimates[0]
    setting = f"engine.sweep_memory_gb={budget:g}" if chosen else f"the {budget:.1f} GB available"
    if chosen and top > budget:
        raise ConfigError(f"engine.sweep_memory_gb: a job of this sweep needs about {top:.2f} GB (step '{step}' "
                          f"peaked at that in an earlier run of the site) and the sweep's budget is {budget:g} GB; "
                          f"raise engine.sweep_memory_gb, or run the jobs one by one without -m")
    n_jobs = asked()
    at_once, total = 0, 0.0
    for gb, _ in estimates[:max(1, n_jobs)]:
        if at_once and total + gb > budget:
            break
        at_once, total = at_once + 1, total + gb
    if at_once >= n_jobs:
        return n_jobs, ""
    return at_once, (f"twinkit: sweep: {at_once} job(s) at a time, not {n_jobs}: a job needs about {top:.2f} GB "
                     f"(step '{step}' in an earlier run) and the sweep may use {setting}")
