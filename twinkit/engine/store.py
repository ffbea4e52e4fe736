"""The content store ``.cache/steps/<key>/``: results by cache key, shared by all runs and multirun jobs.

A step (or one fan-out item) writes into a temporary folder, which is moved into the store only when the
step returned and every declared output exists; an entry whose files no longer match their record is
dropped and computed again. Stored files are made read-only, and nothing outside the store shares their
inode (the numbered folders get copies), so an edit elsewhere cannot reach them.

The site fields a step reads are part of its key. A step sees ``ctx.site`` (and ``ctx.config["site"]``)
through :class:`SiteReads`, which notes every field read; the fields are remembered per step descriptor in
``.cache/steps/<descriptor key>.site.json``, and the next key covers their values. A step that reads a field
it has not read before is stored under the key that includes it."""
from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import stat
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable, Iterator

from twinkit.context import StepContext, with_substeps
from twinkit.engine.base import EngineBase
from twinkit.engine.memory import _PeakRSS
from twinkit.engine.records import RECORD, RECORD_SCHEMA, _now, read_record
from twinkit.errors import StepError
from twinkit.hashing import HashCache, artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic
from twinkit.manifest import redact
from twinkit.quality import with_degraded, with_gates
from twinkit.signature import Port

log = logging.getLogger("twinkit")


class SiteReads(Mapping):
    """The site's configuration, read-only, noting every top-level field a step reads."""

    def __init__(self, site: Mapping | None):
        self._data = dict(site or {})
        self.seen: set[str] = set()

    def __getitem__(self, k: str) -> Any:
        self.seen.add(k)
        return self._data[k]

    def __contains__(self, k: object) -> bool:
        if isinstance(k, str):
            self.seen.add(k)
        return k in self._data

    def get(self, k: str, default: Any = None) -> Any:
        self.seen.add(k)
        return self._data.get(k, default)

    def __iter__(self) -> Iterator[str]:  # dict(site), {**site}: every field is read
        self.seen.update(self._data)
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"SiteReads({self._data!r})"

    def __reduce__(self):  # a plain dict when pickled to another process
        return (dict, (self._data,))


def descriptor_key(descriptor: dict) -> str:
    return hashlib.sha256(json.dumps(descriptor, sort_keys=True, default=str).encode()).hexdigest()[:32]


def with_site(descriptor: dict, site: Mapping | None, fields) -> tuple[str, dict]:
    """(key, descriptor) of a step that reads ``fields`` of the site: their values join the descriptor.
    With no fields it is the descriptor's own key."""
    d = dict(descriptor)
    site = dict(site or {})
    if fields:
        d["site"] = {f: site.get(f) for f in sorted(fields)}
    return descriptor_key(d), d


def site_fields(store: Path, index: str) -> list[str]:
    """The site fields the step of descriptor key ``index`` has read so far (none when it never ran)."""
    try:
        return sorted(json.loads((store / f"{index}.site.json").read_text()))
    except (OSError, ValueError, TypeError):
        return []


def _note_site_fields(store: Path, index: str, fields: set[str]) -> None:
    known = set(site_fields(store, index))
    if fields <= known:
        return
    write_json_atomic(store / f"{index}.site.json", sorted(known | fields))


def _read_only(folder: Path) -> None:
    """Stored files cannot be written (directories stay writable so that gc can remove entries)."""
    for root, _dirs, files in os.walk(folder):
        for f in files:
            p = os.path.join(root, f)
            mode = os.stat(p).st_mode
            os.chmod(p, mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def compute_into_store(run: Callable, params: Any, inputs: dict[str, Any], outputs: tuple[Port, ...], key: str,
                       store: Path, ctx_kwargs: dict, item: Any = None, wants_item: bool = False,
                       force: bool = False, hash_db: Path | None = None, key_descriptor: dict | None = None,
                       fields: list[str] | None = None, index: str | None = None) -> dict:
    """Run one step (or one fan-out item) into ``store/<key>`` atomically; returns the stored record.

    ``key`` covers ``key_descriptor`` and the values of the site ``fields`` the step read before
    (:func:`with_site`). When the step reads a site field beyond those, the result is stored under the key that
    includes it, the field is remembered under ``index``, and the record's ``key`` says where it went.

    Module-level so executors can ship it to other processes or machines.
    """
    from filelock import FileLock

    store.mkdir(parents=True, exist_ok=True)
    final = store / key
    lock_key = key
    with FileLock(str(store / f"{key}.lock")):
        if not force:
            rec = _stored_record(final)
            if rec is not None:
                return rec
        site = SiteReads(ctx_kwargs.get("site"))
        ctx_kwargs = dict(ctx_kwargs, site=site)
        if isinstance(ctx_kwargs.get("config"), Mapping):
            ctx_kwargs["config"] = {**ctx_kwargs["config"], "site": site}
        tmp = store / ".tmp" / f"{key}-{os.getpid()}-{threading.get_ident()}"
        metrics, duration, mem = _run_into(tmp, run, params, ctx_kwargs, inputs, outputs, item, wants_item)
        used = sorted(set(fields or ()) | site.seen)
        if key_descriptor is not None and set(used) != set(fields or ()):
            key, _ = with_site(key_descriptor, site._data, used)
            final = store / key
        if index is not None and used:
            _note_site_fields(store, index, set(used))
        _read_only(tmp)
        record = _record_of(tmp, key, used, duration, mem, metrics, outputs, item, hash_db)
        write_json_atomic(tmp / RECORD, record)
        if final.name != lock_key:  # stored under the key that covers the site fields it read
            with FileLock(str(store / f"{final.name}.lock")):
                _swap_in(tmp, final)
        else:
            _swap_in(tmp, final)
        record["_computed_here"] = True
        return record


def _stored_record(final: Path) -> dict | None:
    """The record of the stored entry ``final`` (marked not computed here), or None when there is none or it comes
    from an older twinkit that did not track the site fields (then it is computed again)."""
    if final.is_dir() and (final / RECORD).is_file():
        rec = json.loads((final / RECORD).read_text())
        if "site_fields" in rec:
            rec["_computed_here"] = False
            return rec
    return None


def _run_into(tmp: Path, run: Callable, params: Any, ctx_kwargs: dict, inputs: dict[str, Any],
              outputs: tuple[Port, ...], item: Any, wants_item: bool):
    """Run the step with its outputs in the fresh folder ``tmp``: (metrics with degradations, seconds, _PeakRSS).
    StepError (and ``tmp`` removed) when a declared output is missing or of the wrong kind; ``tmp`` is removed
    when the step raises."""
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
    warned = _Warnings()
    ctx.log.addHandler(warned)
    try:
        with _PeakRSS() as mem:
            metrics = run(params, ctx, **kwargs)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        ctx.log.removeHandler(warned)
    duration = time.perf_counter() - t0
    metrics = with_degraded(with_substeps(metrics if isinstance(metrics, dict) else {}, ctx._substeps), ctx._degraded)
    metrics = with_gates(with_gates(with_gates(metrics, ctx._gates), warned.texts, "warnings"), ctx._notes, "notes")
    missing = [p.filename for p in outputs if not (tmp / p.filename).exists()]
    wrong = [p.filename for p in outputs if (tmp / p.filename).exists() and p.is_dir != (tmp / p.filename).is_dir()]
    if missing or wrong:
        shutil.rmtree(tmp, ignore_errors=True)
        what = f"did not write {missing}" if missing else f"wrote files where folders were declared (or the reverse): {wrong}"
        raise StepError(f"step '{ctx.step_id}' {what}; nothing from this attempt was kept")
    _check_catalogued(outputs, tmp, ctx.step_id)
    return metrics, duration, mem


class _Warnings(logging.Handler):
    """The WARNING lines a step logs while it runs, kept with its result (``metrics["warnings"]``) so the report
    lists them for a cached step too."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.texts: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.texts.append(record.getMessage())
        except Exception:  # noqa: BLE001 - a bad format string must not fail the step
            self.texts.append(str(record.msg))


def _record_of(tmp: Path, key: str, used: list[str], duration: float, mem, metrics, outputs: tuple[Port, ...],
               item: Any, hash_db: Path | None) -> dict:
    """The store record of the files in ``tmp``: their sha256 and sizes, the outputs' artefact hashes, the site
    fields read, time and memory."""
    cache = HashCache(hash_db)
    files = {rel.as_posix(): {"sha256": cache.hash(tmp / rel), "size": (tmp / rel).stat().st_size}
             for rel in list_files(tmp)}
    record = {
        "schema": RECORD_SCHEMA,
        "key": key,
        "site_fields": used,
        "duration_s": round(duration, 3),
        "peak_rss_mb": round(mem.peak / 2**20, 1) if mem.peak else None,
        # what the process held before the step began (a pooled worker keeps memory from earlier items)
        "start_rss_mb": round(mem.start / 2**20, 1) if mem.start else None,
        "metrics": redact(metrics) if isinstance(metrics, dict) else {},  # no ${oc.env:...} value on disk
        "files": files,
        "artefacts": {p.filename: artefact_hash(tmp / p.filename, cache) for p in outputs},
        "computed_at": _now(),
        "item": item,
    }
    cache.close()
    return record


def _check_catalogued(outputs: tuple[Port, ...], tmp: Path, step_id: str) -> None:
    """Each output that is a catalogued artefact (twinkit.artefacts) must follow its schema; a file that does
    not fails the step (the temporary folder is removed, nothing is stored)."""
    from twinkit.artefacts import ArtefactError, check_output

    for p in outputs:
        try:
            check_output(tmp / p.filename)
        except ArtefactError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            msg = str(exc).replace(str(tmp / p.filename), p.filename)
            raise StepError(f"step '{step_id}' wrote {p.filename} against its schema in the artefact catalogue "
                            f"(docs/engine.md, 'Artefacts between plugins'): {msg}; nothing from this attempt "
                            f"was kept") from None


def _swap_in(tmp: Path, final: Path) -> None:
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)


class StoreMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: is a stored result still intact (``self.store``,
    ``self.hashes``)."""

    def _store_valid(self, key: str) -> dict | None:
        entry = self.store / key
        rec = read_record(entry)
        if rec is None or "site_fields" not in rec:  # none, or stored before site fields were tracked
            return None
        for rel, info in rec.get("files", {}).items():
            p = entry / rel
            if not p.is_file() or p.stat().st_size != info["size"] or self.hashes.hash(p) != info["sha256"]:
                log.warning("  cached result %s was modified (%s); computing it again", key, rel)
                shutil.rmtree(entry, ignore_errors=True)
                return None
        return rec
