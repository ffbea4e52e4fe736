"""The step runner: :class:`Engine` walks the plan and decides per step whether to reuse the numbered
folder, keep a hand edit, link a stored result or run the step (see docs/engine.md, "When a step runs").

The parts of its work live beside it, one concern per module, as mix-ins of :class:`Engine`:
``locks`` (the workspace), ``keys`` (cache keys), ``store`` (the content store), ``edits`` (hand edits),
``workspace`` (numbered folders), ``fanout``, ``manual`` and ``status`` (the dry run)."""
from __future__ import annotations

import logging
import os
import shutil
import time
import traceback
from pathlib import Path
from typing import Any, Callable

from twinkit.engine.edits import EditsMixin
from twinkit.engine.fanout import FanoutMixin
from twinkit.engine.keys import KeysMixin
from twinkit.engine.locks import LockMixin
from twinkit.engine.manual import ManualMixin
from twinkit.engine.plan import PlannedStep, build_plan
from twinkit.engine.preflight import run_preflight
from twinkit.engine.records import StepOutcome, read_record
from twinkit.engine.recipes import RecipesMixin
from twinkit.engine.status import StatusMixin
from twinkit.engine.store import StoreMixin, compute_into_store, with_site
from twinkit.engine.workspace import DamagedStore, WorkspaceMixin
from twinkit.errors import ConfigError, StepError, TwinkitError
from twinkit.hashing import HashCache
from twinkit.plugins import Registry

log = logging.getLogger("twinkit")


class Engine(LockMixin, KeysMixin, EditsMixin, StoreMixin, WorkspaceMixin, FanoutMixin, ManualMixin, StatusMixin,
             RecipesMixin):
    """Runs a plan in a workspace with a shared store.

    Args:
        cfg: the composed configuration (plain dict, resolved).
        registry: loaded plugins.
        workspace: where numbered step folders live (``outputs/<site>`` or a multirun job folder).
        site_root: ``outputs/<site>``; its ``.cache`` is shared by runs and jobs.
        rerun: step ids (or folder names) to force.
        interactive: manual steps wait for their files when true; exit with code 3 otherwise.
    """

    def __init__(self, cfg: dict, registry: Registry, workspace: Path, site_root: Path,
                 rerun: list[str] | None = None, interactive: bool = False, threads: int | None = None,
                 config_root: Path | None = None, executor_factory: Callable[[], Any] | None = None,
                 manual_timeout_s: float | None = None, max_threads: int | None = None):
        self.cfg = cfg
        self.registry = registry
        self.workspace = Path(workspace)
        self.site_root = Path(site_root)
        self.rerun = set(rerun or [])
        self.interactive = interactive
        self.threads = threads or os.cpu_count() or 1
        # engine.threads given: that many; else the run's share of the machine, read again before each
        # step (twinkit.threads), at most max_threads (a multirun job: cores / n_jobs)
        self._fixed_threads = threads
        self.max_threads = max_threads
        self.config_root = config_root
        self.store = self.site_root / ".cache" / "steps"
        self.edits_dir = self.site_root / ".cache" / "edits"
        self.hashes = HashCache(self.site_root / ".cache" / "hashes.sqlite")
        self.executor_factory = executor_factory
        self.manual_timeout_s = manual_timeout_s
        self.skipped: list[tuple[str, str]] = []
        self.fallbacks: list[tuple[str, str]] = []  # (step id, why its plugin was replaced by its fallback)
        self.plan = build_plan(cfg, registry, config_root, skipped=self.skipped, fallbacks=self.fallbacks)
        # each plugin's code hash read once, now, as its modules were loaded: a source file edited while
        # the run goes on must not be recorded as the code that produced this run's results
        self.code_hashes = {ps.plugin.qualname: ps.plugin.code_hash() for ps in self.plan if ps.plugin is not None}
        known = {s.id for s in self.plan} | {s.folder for s in self.plan}
        bad = self.rerun - known
        if bad:
            raise ConfigError(f"rerun names unknown step(s) {sorted(bad)}; steps are: {', '.join(s.id for s in self.plan)}")
        self.outcomes: list[StepOutcome] = []
        self.current_step: str | None = None
        self._lock = None

    def _ctx_kwargs(self, ps: PlannedStep) -> dict:
        return {
            "step_id": ps.id,
            "site": self.cfg.get("site") or {},
            "config": self.cfg,
            "threads": self.threads,
            "log": logging.getLogger(f"twinkit.step.{ps.id}"),
        }

    def _share_threads(self) -> None:
        from twinkit.threads import BUDGET_ENV, budget

        self.threads = self._fixed_threads or budget(self.max_threads)
        os.environ[BUDGET_ENV] = str(self.threads)

    def _remove_tmp_of(self, pid: int) -> None:
        """What a killed or crashed step process left in the store's temporary folder."""
        import shutil

        for d in (self.store / ".tmp").glob(f"*-{pid}-*"):
            shutil.rmtree(d, ignore_errors=True)

    def run(self, on_step: Callable[[StepOutcome, int, int], None] | None = None) -> list[StepOutcome]:
        from twinkit.threads import registered

        with registered():
            return self._run(on_step)

    def _run(self, on_step: Callable[[StepOutcome, int, int], None] | None = None) -> list[StepOutcome]:
        try:  # a Ctrl-C or SIGTERM while the workspace is being taken gives it back too
            self._prepare()
            self._switch_recipe()
        except BaseException:
            self._release()
            raise
        for sid, reason in self.skipped:
            log.info("[-] %-28s skipped  %s", sid, reason)
        for sid, reason in self.fallbacks:
            log.info("[~] %-28s fallback %s", sid, reason)
        try:
            run_preflight(self.plan, self.cfg)  # cheap checks of every step before the first runs (exit 2)
            n = len(self.plan)
            for ps in self.plan:
                self.current_step = ps.id
                t0 = time.perf_counter()
                try:
                    outcome = self._run_step(ps)
                except TwinkitError:
                    raise
                except Exception as exc:
                    tb = traceback.format_exc()
                    log.debug(tb)
                    raise StepError(
                        f"step '{ps.id}' ({ps.label} {ps.plugin.version if ps.plugin else ''}) failed: "
                        f"{type(exc).__name__}: {exc}. Earlier results are kept; the traceback is in the run log"
                    ) from exc
                if outcome.status not in ("ran",):
                    outcome.duration_s = time.perf_counter() - t0
                self.outcomes.append(outcome)
                if on_step:
                    on_step(outcome, ps.index, n)
            return self.outcomes
        finally:
            self._release()

    def _run_step(self, ps: PlannedStep) -> StepOutcome:
        folder = self.workspace / ps.folder
        in_paths, in_hashes = self._input_values(ps)
        desc0 = self._descriptor(ps, in_hashes)
        key, desc, index, fields = self._keyed(desc0)
        rec = read_record(folder)
        forced = ps.id in self.rerun or ps.folder in self.rerun
        if ps.plugin is None:
            return self._run_manual(ps, folder, key, desc, rec)
        if ps.foreach is not None:
            return self._run_fanout(ps, folder, key, desc, rec, in_paths, forced, desc0=desc0, index=index,
                                    fields=fields)

        if rec is not None and rec.get("key") == key and "site_fields" in rec and not forced:
            state, files = self._check_workspace(folder, rec)
            if state == "unchanged":
                outputs, hashes = self._outputs_of(folder, ps, rec, current=False)
                return StepOutcome(ps.id, ps.folder, ps.label, "reused", "unchanged", key, 0.0, outputs, hashes,
                                   rec.get("metrics", {}), rec.get("peak_rss_mb"))
            if state == "edited":
                outputs, hashes = self._outputs_of(folder, ps, rec, current=True)
                return StepOutcome(ps.id, ps.folder, ps.label, "edited",
                                   f"kept hand-edited {', '.join(files)}; later steps re-run", key, 0.0, outputs,
                                   hashes, rec.get("metrics", {}), rec.get("peak_rss_mb"))
            why = f"output missing: {', '.join(files)}"
        elif forced:
            why = "forced by rerun"
        else:
            why = self._why(rec, desc)
        self._keep_edits(folder, rec, "forced re-run" if forced else f"its step re-runs ({why})", forced)

        index_key = key
        for attempt in (1, 2):
            stored = None if forced else self._store_valid(key)
            status = "cached" if stored else "ran"
            if stored is None:
                log.debug("  %s: running %s ...", ps.folder, ps.label)
                from twinkit.engine.isolate import run_in_child
                from twinkit.progress import step_status

                self._share_threads()
                with step_status(f"{ps.folder} ({ps.label})"):
                    # in a child process: a native crash is this step's failure, Ctrl-C stops it within seconds
                    stored = run_in_child(compute_into_store, dict(
                        run=ps.plugin.run, params=ps.params, inputs=in_paths, outputs=ps.outputs, key=index_key,
                        store=self.store, ctx_kwargs=self._ctx_kwargs(ps), force=forced or attempt > 1,
                        hash_db=self.hashes.db_path, key_descriptor=desc0, fields=fields, index=index),
                        threads=self.threads, cleanup=self._remove_tmp_of)
                if not stored.pop("_computed_here", True):
                    status, why = "cached", why + " (computed by a concurrent job)"
                if stored.get("key", key) != key:  # it read a site field it had not read before
                    key, desc = stored["key"], with_site(desc0, self.cfg.get("site"), stored["site_fields"])[1]
            record = self._workspace_record(ps, key, desc, stored, status, why, in_paths)
            edit = self._edit_to_restore(ps, folder, key, record["files"], forced)  # stops on one made elsewhere
            try:
                self._materialize(folder, [("", self.store / key)], record)
                break
            except DamagedStore as exc:
                if attempt > 1:
                    raise StepError(f"step '{ps.id}': the stored file {exc} differs from its record right after "
                                    f"it was written; is something else writing to {self.store}?") from None
                log.warning("  stored result %s/%s differs from its record; computing it again", key, exc.rel)
                shutil.rmtree(self.store / key, ignore_errors=True)
        assert stored is not None  # the loop above ends with a stored result or raises
        if edit is not None:  # the result an edit was made on is back: so is the edit
            files = self._reapply_edit(folder, *edit)
            outputs, hashes = self._outputs_of(folder, ps, stored, current=True)
            return StepOutcome(ps.id, ps.folder, ps.label, "edited", f"re-applied hand-edited {', '.join(files)} "
                               f"from {edit[0]}; later steps re-run", key, 0.0, outputs, hashes,
                               stored.get("metrics", {}), stored.get("peak_rss_mb"))
        outputs, hashes = self._outputs_of(folder, ps, stored, current=False)
        return StepOutcome(ps.id, ps.folder, ps.label, status, why, key,
                           stored.get("duration_s", 0.0) if status == "ran" else 0.0, outputs, hashes,
                           stored.get("metrics", {}), stored.get("peak_rss_mb"))
