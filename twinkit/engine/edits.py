"""Hand edits: a numbered folder's files checked against its record (unchanged, edited or missing), edited
files set aside in ``.cache/edits/`` before their step runs again, and set back when the step's result they were
made on comes back (docs/engine.md, "When a step runs").

Each set-aside folder holds a note (:data:`NOTE`): the numbered folder it came from, the key of the result the
edit was made on, and per file the hash it had in that result (``base``, None for a file the step did not
write) and its edited hash. ``state`` is ``aside`` until the edit is re-applied (``reapplied``) or dropped by
``rerun=[<step>]`` (``dropped``)."""
from __future__ import annotations

import datetime as _dt
import json
import logging
import shutil
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.records import RECORD
from twinkit.errors import InputError
from twinkit.hashing import list_files
from twinkit.jsonio import write_json as write_json_atomic

log = logging.getLogger("twinkit")

NOTE = ".twinkit-edit.json"


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

    def _keep_edits(self, folder: Path, rec: dict | None, why: str, forced: bool = False) -> Path | None:
        """Before ``folder`` is replaced: set aside every file its record does not vouch for (edited, or
        unknown to the record, or all of them when the folder has no readable ``step.json``). ``forced``
        (``rerun=[<step>]``): the edit is set aside as dropped, never re-applied."""
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
        return self._set_aside(folder, sorted(files), why, rec, forced)

    def _differs(self, path: Path, info: dict) -> bool:
        return path.stat().st_size != info["size"] or self.hashes.hash(path) != info["sha256"]

    def _set_aside(self, folder: Path, files: list[str], why: str, rec: dict | None = None,
                   dropped: bool = False) -> Path:
        """Copy ``files`` of ``folder`` to a new ``.cache/edits/<folder>-<time>/`` with its note."""
        dest = self.edits_dir / f"{folder.name}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
        known = (rec or {}).get("files", {})
        note_files = {}
        for rel in files:
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(folder / rel, dest / rel)
            note_files[rel] = {"base": (known.get(rel) or {}).get("sha256"), "sha256": self.hashes.hash(dest / rel)}
        write_json_atomic(dest / NOTE, {**self._edit_place(folder), "key": (rec or {}).get("key"),
                                        "files": note_files, "why": why, "state": "dropped" if dropped else "aside"})
        log.warning("  %s: hand-edited %s set aside in %s (%s)", folder.name, ", ".join(files), dest, why)
        return dest

    def _edit_place(self, folder: Path) -> dict:
        """Which numbered folder an edit belongs to: the workspace (the site's, or a sweep job's), the folder
        and the recipe."""
        try:
            ws = folder.parent.resolve().relative_to(self.site_root.resolve()).as_posix()
        except ValueError:
            ws = str(folder.parent)
        return {"workspace": ws, "folder": folder.name, "recipe": (self.cfg.get("recipe") or {}).get("name")}

    def _pending_edits(self, folder: Path, key: str) -> list[tuple[Path, dict]]:
        """The edits set aside from ``folder`` on the result of ``key`` and not re-applied or dropped since,
        newest first."""
        place, found = self._edit_place(folder), []
        for note_path in sorted(self.edits_dir.glob(f"{folder.name}-*/{NOTE}"), reverse=True):
            try:
                note = json.loads(note_path.read_text())
            except (OSError, ValueError):
                continue
            if isinstance(note, dict) and note.get("state") == "aside" and note.get("key") == key \
                    and all(note.get(k) == v for k, v in place.items()):
                found.append((note_path.parent, note))
        return found

    def _edit_to_restore(self, ps, folder: Path, key: str, files: dict, forced: bool) -> tuple[Path, dict] | None:
        """The set-aside edit to lay over the result of ``key`` (its record's ``files``) about to fill
        ``folder``: the newest one made on that very result. ``forced``: pending ones are dropped instead.
        InputError when the newest was made on a result of this key whose files differ from this one (a
        stored result lost and computed again differently): the run stops before the folder is replaced."""
        pending = self._pending_edits(folder, key)
        if forced or not pending:
            for dest, note in pending:
                write_json_atomic(dest / NOTE, dict(note, state="dropped"))
            return None
        dest, note = pending[0]
        stale = [rel for rel, f in note.get("files", {}).items()
                 if (files.get(rel) or {}).get("sha256") != f.get("base")]
        if stale:
            raise InputError(
                f"{dest / stale[0]}: a hand edit of {folder} set aside when an upstream setting changed; the "
                f"setting is back, but step '{ps.id}' now gives a different result than the one the edit was made "
                f"on, so it is not laid over it; run with rerun=[{ps.id}] to go on without it (it stays in "
                f"{dest}), then copy the files you want to keep into {folder}")
        return dest, note

    def _reapply_edit(self, folder: Path, dest: Path, note: dict) -> list[str]:
        """Copy the set-aside files of ``dest`` back into ``folder`` (just filled with the result they were made
        on) and mark the note re-applied; the files' names."""
        files = sorted(note.get("files", {}))
        for rel in files:
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).unlink(missing_ok=True)
            shutil.copy2(dest / rel, folder / rel)
        write_json_atomic(dest / NOTE, dict(note, state="reapplied"))
        return files
