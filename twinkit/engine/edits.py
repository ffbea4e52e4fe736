"""Hand edits: a numbered folder's files checked against its record (unchanged, edited or missing), and
edited files set aside in ``.cache/edits/`` before their step runs again."""
from __future__ import annotations

import datetime as _dt
import logging
from pathlib import Path

from twinkit.engine.workspace import _link_or_copy

log = logging.getLogger("twinkit")


class EditsMixin:
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

    def _set_aside(self, folder: Path, files: list[str], why: str) -> Path:
        dest = self.edits_dir / f"{folder.name}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}"
        for rel in files:
            _link_or_copy(folder / rel, dest / rel)
        log.warning("  %s: hand-edited %s set aside in %s (%s)", folder.name, ", ".join(files), dest, why)
        return dest
