"""Fan-out (``foreach``): a step runs once per item of a JSON list, each item keyed by its own content and
the step's other inputs, so adding an item computes only that item. Items go to an executor
(``map(fn, tasks)``) as picklable tasks for :func:`_run_item_task`."""
from __future__ import annotations

import json
import logging
import os
import shutil
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from twinkit.engine.base import EngineBase
from twinkit.engine.memory import release_memory
from twinkit.engine.records import RECORD, StepOutcome, read_record
from twinkit.engine.store import compute_into_store, with_site
from twinkit.engine.workspace import DamagedStore
from twinkit.errors import InputError, StepError
from twinkit.hashing import artefact_hash

log = logging.getLogger("twinkit")


def _item_cost(item: Any) -> float:
    c = item.get("cost") if isinstance(item, dict) else None
    return float(c) if isinstance(c, (int, float)) and not isinstance(c, bool) else 0.0


def _run_item_task(task: dict) -> dict:
    """Executor entry point for one fan-out item (picklable, top level). In the run's own process (an
    executor with one worker) the item runs in a child process, like a step (twinkit.engine.isolate)."""
    task = dict(task)
    run_pid, threads = task.pop("run_pid", None), task.pop("threads", None)
    if run_pid == os.getpid():
        from twinkit.engine.isolate import run_in_child

        def cleanup(pid: int) -> None:
            for d in (Path(task["store"]) / ".tmp").glob(f"*-{pid}-*"):
                shutil.rmtree(d, ignore_errors=True)

        return run_in_child(compute_into_store, task, threads=threads, cleanup=cleanup)
    try:
        return compute_into_store(**task)
    finally:
        release_memory()


class FanoutMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: run a ``foreach`` step through the executor
    (``self.executor_factory``, or the configured ``executor``, or a local pool)."""

    def _executor(self):
        if self.executor_factory is not None:
            return self.executor_factory()
        from twinkit.plugins import build_component

        if self.cfg.get("executor"):
            return build_component("executor", None, self.cfg)
        from twinkit.executors import LocalExecutor

        return LocalExecutor(workers=min(2, self.threads))

    def _run_fanout(self, ps, folder, key, desc, rec, in_paths, forced, desc0=None, index=None,
                    fields=()) -> StepOutcome:
        items_path = in_paths.pop("__foreach__")
        items = _read_items(items_path, ps.id)
        # each item is keyed by its own content and the step's other inputs, not by the whole list,
        # so adding a tile computes only the new tile
        desc0 = desc if desc0 is None else desc0
        site = self.cfg.get("site")
        base = dict(desc0, inputs={k: v for k, v in desc0["inputs"].items() if k != "__foreach__"})
        item_descs = [{"step": base, "item": it} for it in items]
        keys = [with_site(d, site, fields)[0] for d in item_descs]
        if rec is not None and rec.get("key") == key and "site_fields" in rec and not forced:
            kept = self._fanout_kept(ps, folder, key, rec, len(items))
            if kept is not None:
                return kept
        why = "forced by rerun" if forced else self._why(rec, desc)
        n_computed, duration = self._compute_items(ps, in_paths, items, keys, item_descs, forced, index, fields)
        read = sorted(set(fields).union(*[(read_record(self.store / k) or {}).get("site_fields") or [] for k in keys]))
        if read != sorted(fields):
            key, desc = with_site(desc0, site, read)
        files, artefacts, metrics = self._fanout_results(ps, keys, len(items), n_computed)
        status = "ran" if n_computed else "cached"
        record = self._workspace_record(ps, key, desc, {"files": files, "artefacts": artefacts, "metrics": metrics,
                                                        "duration_s": round(duration, 3), "site_fields": read},
                                        status, why, in_paths)
        record["item_keys"] = keys
        self._keep_edits(folder, rec, "forced re-run" if forced else f"its step re-runs ({why})", forced)
        edit = self._edit_to_restore(ps, folder, key, record["files"], forced)
        try:
            self._materialize(folder, [(f"{i:03d}", self.store / k) for i, k in enumerate(keys)], record)
        except DamagedStore as exc:
            if getattr(self, "_fanout_retry", False):
                raise StepError(f"step '{ps.id}': the stored file {exc} differs from its record right after it "
                                f"was written; is something else writing to {self.store}?") from None
            log.warning("  stored result %s differs from its record; computing it again", exc)
            shutil.rmtree(exc.entry, ignore_errors=True)
            self._fanout_retry = True
            try:
                return self._run_fanout(ps, folder, key, desc, rec, {**in_paths, "__foreach__": items_path}, forced,
                                        desc0=desc0, index=index, fields=fields)
            finally:
                self._fanout_retry = False
        if edit is not None:  # the result an edit was made on is back: so is the edit
            files = self._reapply_edit(folder, *edit)
            kept = self._fanout_kept(ps, folder, key, record, len(items))
            if kept is not None:
                kept.why = f"re-applied hand-edited {', '.join(files)} from {edit[0]}; later steps re-run"
                return kept
        outputs = {p.filename: [folder / f"{i:03d}" / p.filename for i in range(len(items))] for p in ps.outputs}
        return StepOutcome(ps.id, ps.folder, ps.label, status, why + f" ({n_computed}/{len(items)} items computed)",
                           key, duration, outputs, artefacts, metrics)

    def _fanout_kept(self, ps, folder, key, rec, n_items: int) -> StepOutcome | None:
        """The outcome of a fan-out step whose workspace folder still holds its recorded items (reused) or
        hand-edited ones (kept); None when it must run."""
        state, files = self._check_workspace(folder, rec)
        if state not in ("unchanged", "edited"):
            return None
        outputs = {p.filename: [folder / f"{i:03d}" / p.filename for i in range(n_items)] for p in ps.outputs}
        if state == "unchanged":
            hashes = rec["artefacts"]
        else:
            hashes = {f: [artefact_hash(x, self.hashes) for x in paths] for f, paths in outputs.items()}
        status = "reused" if state == "unchanged" else "edited"
        return StepOutcome(ps.id, ps.folder, ps.label, status,
                           "unchanged" if state == "unchanged" else f"kept hand-edited {', '.join(files)}",
                           key, 0.0, outputs, hashes, rec.get("metrics", {}))

    def _compute_items(self, ps, in_paths, items: list, keys: list[str], item_descs: list[dict], forced, index,
                       fields) -> tuple[int, float]:
        """Compute the items not in the store (all when ``forced``) through the executor, costliest first;
        ``keys`` is updated in place for items that read a new site field. Returns how many were computed and
        the seconds that took."""
        todo = [i for i, k in enumerate(keys) if forced or self._store_valid(k) is None]
        # items that say what they cost ("cost": any number) start costliest first, so that a big
        # item does not start last and leave the other workers idle (results are keyed, not ordered)
        todo.sort(key=lambda i: -_item_cost(items[i]))
        if todo:
            self._share_threads()
        tasks = [dict(run=ps.plugin.run, params=ps.params, inputs=in_paths, outputs=ps.outputs, key=keys[i],
                      store=self.store, ctx_kwargs={**self._ctx_kwargs(ps), "log": None, "config": self.cfg},
                      item=items[i], wants_item=True, force=forced, hash_db=self.hashes.db_path,
                      key_descriptor=item_descs[i], fields=list(fields), index=index,
                      run_pid=os.getpid(), threads=self.threads) for i in todo]
        for t in tasks:
            t["ctx_kwargs"].pop("log")
        t0 = time.perf_counter()
        if not tasks:
            return 0, time.perf_counter() - t0
        log.debug("  %s: running %s on %d of %d items ...", ps.folder, ps.label, len(tasks), len(items))
        ex = self._executor()
        results = ex.map(_run_item_task, tasks)
        from twinkit.progress import is_interactive

        lines = not is_interactive() and len(tasks) > 1  # no bar to draw: say how far the items are in the log
        costs = [_item_cost(items[i]) for i in todo]
        by_cost = all(c > 0 for c in costs)  # the time left by the items' declared cost (costliest run first)
        total_cost, done_cost = sum(costs), 0.0
        try:
            for n, (i, res) in enumerate(zip(todo, _track(results, len(tasks), ps.id)), 1):
                if isinstance(res, dict) and res.get("key"):
                    keys[i] = res["key"]  # an item that read a new site field is stored under the key with it
                if lines:
                    el = time.perf_counter() - t0
                    done_cost += costs[n - 1]
                    done = done_cost / total_cost if by_cost else n / len(tasks)
                    log.info("  %s: %d of %d items done (%.0f s, about %.0f s left)", ps.folder, n, len(tasks), el,
                             el * (1 - done) / done)
        except BrokenProcessPool as exc:
            from twinkit.engine.isolate import NativeCrash

            raise NativeCrash("a worker process died while running its items (a crash in native code, or "
                              "killed: out of memory?); the Python stack of a crash, where known, is in the "
                              "run log") from exc
        return len(tasks), time.perf_counter() - t0

    def _fanout_results(self, ps, keys: list[str], n_items: int, n_computed: int):
        """The stored items' files (under their ``NNN/`` folders), artefact hashes per output and metrics."""
        stored: list[Any] = [read_record(self.store / k) for k in keys]  # each item's record, just written
        files: dict[str, Any] = {}
        for i, r in enumerate(stored):
            for rel, info in r["files"].items():
                if rel != RECORD:
                    files[f"{i:03d}/{rel}"] = info
        artefacts = {p.filename: [r["artefacts"][p.filename] for r in stored] for p in ps.outputs}
        metrics = {"items": n_items, "computed": n_computed,
                   "per_item": [r.get("metrics", {}) | {"peak_rss_mb": r.get("peak_rss_mb"), "start_rss_mb": r.get("start_rss_mb"),
                                                        "duration_s": r.get("duration_s")} for r in stored]}
        return files, artefacts, metrics


def _read_items(items_path, step_id: str) -> list:
    """The ``foreach`` list of a step: a JSON list, or the ``items`` of a JSON object; InputError otherwise."""
    try:
        items = json.loads(Path(items_path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{items_path}: the 'foreach' list of step '{step_id}' is not readable JSON ({exc})") from None
    if isinstance(items, dict) and "items" in items:
        items = items["items"]
    if not isinstance(items, list):
        raise InputError(f"{items_path}: 'foreach' of step '{step_id}' needs a JSON list (or {{\"items\": [...]}})")
    return items


def _track(iterable, total, desc):
    from twinkit.progress import track

    return track(iterable, total=total, desc=desc)
