"""Manual steps: the files a person provides, with instructions written into the step's folder; an
interactive run waits for them, any other stops with exit code 3 until they exist."""
from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.records import RECORD, RECORD_SCHEMA, StepOutcome, _now
from twinkit.errors import ManualActionPending
from twinkit.hashing import artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic

log = logging.getLogger("twinkit")


class ManualMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: record a manual step's files once they exist
    (``self.interactive``, ``self.manual_timeout_s``)."""

    def _run_manual(self, ps, folder, key, desc, rec) -> StepOutcome:
        folder.mkdir(parents=True, exist_ok=True)
        wanted = [folder / p.filename for p in ps.outputs]
        missing = [p for p in wanted if not p.exists()]
        if missing:
            text = str(ps.spec.manual["instructions"]).format(
                folder=folder, path=missing[0], files=", ".join(str(m) for m in missing),
                workspace=self.workspace)
            (folder / "INSTRUCTIONS.txt").write_text(text.strip() + "\n\nWaiting for: " +
                                                     ", ".join(str(m) for m in missing) + "\n")
            log.warning("  %s: manual action needed:\n    %s\n    waiting for %s", ps.folder,
                        text.strip().replace("\n", "\n    "), ", ".join(str(m) for m in missing))
            if not self.interactive:
                raise ManualActionPending(
                    f"step '{ps.id}' waits for {', '.join(str(m) for m in missing)} "
                    f"(instructions in {folder / 'INSTRUCTIONS.txt'}); create it and run the same command again"
                )
            _wait_for_files(missing, self.manual_timeout_s)
        hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
        files = {rel.as_posix(): {"sha256": self.hashes.hash(folder / rel), "size": (folder / rel).stat().st_size}
                 for rel in list_files(folder) if rel.name not in (RECORD, "INSTRUCTIONS.txt")}
        stale = rec is not None and rec.get("key") not in (None, key)
        why = "provided by hand" + ("; NOTE: its inputs changed since — check it is still right" if stale else "")
        status = "manual"
        record = {"schema": RECORD_SCHEMA, "step": ps.id, "key": key, "descriptor": desc, "plugin": "manual",
                  "files": files, "artefacts": hashes, "status": status, "why": why, "recorded_at": _now()}
        write_json_atomic(folder / RECORD, record)
        outputs = {p.filename: folder / p.filename for p in ps.outputs}
        return StepOutcome(ps.id, ps.folder, "manual", status, why, key, 0.0, outputs, hashes)


def _wait_for_files(paths: list[Path], timeout_s: float | None) -> None:
    """Block until every path exists and its size stopped changing (watching the folder)."""
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    event = threading.Event()
    observer = None
    try:
        from watchdog.events import FileSystemEventHandler
        from watchdog.observers import Observer

        class _Handler(FileSystemEventHandler):
            def on_any_event(self, ev):  # noqa: D401
                event.set()

        observer = Observer()
        for d in {p.parent for p in paths}:
            observer.schedule(_Handler(), str(d), recursive=False)
        observer.start()
    except ImportError:  # polling is a fine fallback
        observer = None
    try:
        sizes: dict[Path, int] = {}
        while True:
            if all(p.exists() for p in paths):
                now = {p: (p.stat().st_size if p.is_file() else -1) for p in paths}
                if now == sizes:
                    return
                sizes = now
            if deadline is not None and time.monotonic() > deadline:
                raise ManualActionPending(f"gave up waiting for {', '.join(str(p) for p in paths)}")
            event.wait(0.5)
            event.clear()
    finally:
        if observer is not None:
            observer.stop()
            observer.join()
