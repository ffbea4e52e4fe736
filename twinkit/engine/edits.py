"""Hand edits: a numbered folder's files checked against its record (unchanged, edited or missing), and
edited files set aside in ``.cache/edits/`` before their step runs again."""
from __future__ import annotations

import datetime as _dt
import logging
import shutil
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.records import RECORD
from twinkit.hashing import list_files


log = logging.getLogger("twinkit")


class EditsMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: compare a folder with its record (``self.hashes``) and
    keep what a person changed (``self.edits_dir``)."""

    def _check_workspace(self, folder: Path, rec: dict) -> tuple[str, list[str]]:
        """'unchanged', 'edited' (+ files) or 'missing' (+ files) for a recorded step folder."""
        missing, edited = [], []
        for rel, info in rec.get("files", {}).items():
            p = folder / rel
            if not p.is_file():
                missing.append(rel)
            elif p.stat().st_size != info["size"] or self.hashes.hash(p) != info["sha256"]:
                edited.append(rel)
        if missing:
            return "missing", missing
        return ("edited", edited) if edited else ("unchanged", [])

    def _keep_edits(self, folder: Path, rec: dict | None, why: str) -> Path | None:
        """Before ``folder`` is replaced: set aside every file its record does not vouch for (edited, or
        unknown to the record, or all of them when the folder has no readable ``step.json``)."""
        if not folder.is_dir():
            return None
        present = [rel.as_posix() for rel in list_files(folder)]
        if rec is None:
            files = present  # nothing says what the step wrote: every file may be a person's work
            why = f"{folder / RECORD} is missing or unreadable; {why}"
        else:
            known = rec.get("files", {})
            files = [rel for rel in present if rel != RECORD and rel not in known]
            files += [rel for rel in present if rel in known and self._differs(folder / rel, known[rel])]
        if not files:
            return None
        return self._set_aside(folder, sorted(files), why)

    def _differs(self, path: Path, info: dict) -> bool:
        return path.stat().st_size != info["size"] or self.hashes.hash(path) != info["sha256"]

    def _set_aside(self, folder: Path, files: list[str], why: str) -> Path:
        dest = self.edits_dir / f"{folder.name}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
        for rel in files:
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(folder / rel, dest / rel)
        log.warning("  %s: hand-edited %s set aside in %s (%s)", folder.name, ", ".join(files), dest, why)
        return dest
