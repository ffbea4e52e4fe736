"""The content store ``.cache/steps/<key>/``: results by cache key, shared by all runs and multirun jobs.

A step (or one fan-out item) writes into a temporary folder, which is moved into the store only when the
step returned and every declared output exists; an entry whose files no longer match their record is
dropped and computed again."""
from __future__ import annotations

import json
import logging
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any, Callable

from twinkit.context import StepContext
from twinkit.engine.memory import _PeakRSS
from twinkit.engine.records import RECORD, RECORD_SCHEMA, _now, read_record
from twinkit.errors import StepError
from twinkit.hashing import HashCache, artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic
from twinkit.signature import Port

log = logging.getLogger("twinkit")


def compute_into_store(run: Callable, params: Any, inputs: dict[str, Any], outputs: tuple[Port, ...], key: str,
                       store: Path, ctx_kwargs: dict, item: Any = None, wants_item: bool = False,
                       force: bool = False, hash_db: Path | None = None) -> dict:
    """Run one step (or one fan-out item) into ``store/<key>`` atomically; returns the stored record.

    Module-level so executors can ship it to other processes or machines.
    """
    from filelock import FileLock

    store.mkdir(parents=True, exist_ok=True)
    final = store / key
    with FileLock(str(store / f"{key}.lock")):
        if final.is_dir() and (final / RECORD).is_file() and not force:
            rec = json.loads((final / RECORD).read_text())
            rec["_computed_here"] = False
            return rec
        tmp = store / ".tmp" / f"{key}-{os.getpid()}-{threading.get_ident()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        out_paths = {p.param: tmp / p.filename for p in outputs}
        ctx = StepContext(workdir=tmp, **ctx_kwargs)
        kwargs = dict(inputs)
        kwargs.update(out_paths)
        if wants_item:
            kwargs["item"] = item
        t0 = time.perf_counter()
        try:
            with _PeakRSS() as mem:
                metrics = run(params, ctx, **kwargs)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        duration = time.perf_counter() - t0
        missing = [p.filename for p in outputs if not (tmp / p.filename).exists()]
        wrong = [p.filename for p in outputs if (tmp / p.filename).exists() and p.is_dir != (tmp / p.filename).is_dir()]
        if missing or wrong:
            shutil.rmtree(tmp, ignore_errors=True)
            what = f"did not write {missing}" if missing else f"wrote files where folders were declared (or the reverse): {wrong}"
            raise StepError(f"step '{ctx.step_id}' {what}; nothing from this attempt was kept")
        cache = HashCache(hash_db)
        files = {rel.as_posix(): {"sha256": cache.hash(tmp / rel), "size": (tmp / rel).stat().st_size}
                 for rel in list_files(tmp)}
        record = {
            "schema": RECORD_SCHEMA,
            "key": key,
            "duration_s": round(duration, 3),
            "peak_rss_mb": round(mem.peak / 2**20, 1) if mem.peak else None,
            # what the process held before the step began (a pooled worker keeps memory from earlier items)
            "start_rss_mb": round(mem.start / 2**20, 1) if mem.start else None,
            "metrics": metrics if isinstance(metrics, dict) else {},
            "files": files,
            "artefacts": {p.filename: artefact_hash(tmp / p.filename, cache) for p in outputs},
            "computed_at": _now(),
            "item": item,
        }
        cache.close()
        write_json_atomic(tmp / RECORD, record)
        if final.exists():
            shutil.rmtree(final)
        os.replace(tmp, final)
        record["_computed_here"] = True
        return record


class StoreMixin:
    """Part of :class:`~twinkit.engine.runner.Engine`: is a stored result still intact (``self.store``,
    ``self.hashes``)."""

    def _store_valid(self, key: str) -> dict | None:
        entry = self.store / key
        rec = read_record(entry)
        if rec is None:
            return None
        for rel, info in rec.get("files", {}).items():
            p = entry / rel
            if not p.is_file() or p.stat().st_size != info["size"] or self.hashes.hash(p) != info["sha256"]:
                log.warning("  cached result %s was modified (%s); computing it again", key, rel)
                shutil.rmtree(entry, ignore_errors=True)
                return None
        return rec
