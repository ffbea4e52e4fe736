"""The dry run (``twinkit status``): what a run would do for each step, computing keys but running and
writing nothing."""
from __future__ import annotations

from twinkit.engine.base import EngineBase
from twinkit.engine.recipes import JOURNAL, numbered_folders, parked_folder, stale_folder
from twinkit.engine.records import StepOutcome, read_record
from twinkit.errors import TwinkitError
from twinkit.hashing import HashCache, artefact_hash
from twinkit.quality import degraded_of, describe


class StatusMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`."""

    def status(self) -> list[tuple[str, str, str]]:
        """What a run would do, without running or writing anything: (folder, decision, why)."""
        rows = []
        dirty = False
        self.hashes.close()
        self.hashes = HashCache(self.hashes.db_path, read_only=True)  # a dry run writes nothing, not even hashes
        if (self.site_root / JOURNAL).is_file():  # folders may be half-way between two recipes
            rows.append((JOURNAL, "unfinished", "a recipe switch was stopped among its folder moves; the next run "
                                                "finishes them first"))
        if self.workspace.resolve() == self.site_root.resolve():  # another recipe's folders may be at the top
            self.workspace = parked_folder(self.workspace, str((self.cfg.get("recipe") or {}).get("name") or ""))
        for ps in self.plan:
            folder = self.workspace / ps.folder
            rec = read_record(folder)
            if dirty:
                rows.append((ps.folder, "would run", "an earlier step re-runs"))
                self.outcomes.append(None)  # type: ignore[arg-type]
                continue
            try:
                in_paths, in_hashes = self._input_values(ps)
            except TwinkitError as exc:
                rows.append((ps.folder, "blocked", str(exc)))
                dirty = True
                continue
            key, desc, _, _ = self._keyed(self._descriptor(ps, in_hashes))
            forced = ps.id in self.rerun
            if ps.plugin is None:
                done = all((folder / p.filename).exists() for p in ps.outputs)
                rows.append((ps.folder, "manual done" if done else "waits for you",
                             ", ".join(p.filename for p in ps.outputs)))
                if not done:
                    dirty = True
                    continue
                hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
            elif rec is not None and rec.get("key") == key and "site_fields" in rec and not forced:
                state, files = self._check_workspace(folder, rec)
                if state == "missing":
                    rows.append((ps.folder, "would run", f"output missing: {', '.join(files)}"))
                    dirty = True
                    continue
                bad = degraded_of(rec.get("metrics"))
                if bad:  # up to date, but its result is degenerate: say so, with the reason and the setting to try
                    rows.append((ps.folder, "DEGRADED", "; ".join(describe(dict(e, step=ps.id)) for e in bad)
                                 + ("" if state == "unchanged" else f" (edited: {', '.join(files)})")))
                else:
                    rows.append((ps.folder, "up to date" if state == "unchanged" else "edited",
                                 "" if state == "unchanged" else ", ".join(files)))
                if ps.foreach is not None:
                    artefacts = rec["artefacts"] if state == "unchanged" else None
                    if artefacts is None:
                        dirty = True
                        continue
                    hashes = artefacts
                else:
                    _, hashes = self._outputs_of(folder, ps, rec, current=state == "edited")
            else:
                stored = None if forced else read_record(self.store / key)
                if stored is not None and "site_fields" not in stored:
                    stored = None
                if stored is not None:
                    row, seen = self._status_cached(ps, folder, key, stored)
                    rows.append(row)
                    if seen is None:
                        dirty = True
                        continue
                    hashes = seen
                else:
                    rows.append((ps.folder, "would run", "forced by rerun" if forced else self._why(rec, desc)))
                    dirty = True
                    continue
            outputs = {p.filename: folder / p.filename for p in ps.outputs}
            self.outcomes.append(StepOutcome(ps.id, ps.folder, ps.label, "status", "", key, 0, outputs, hashes))
        self.hashes.close()
        return rows

    def stale_note(self) -> str | None:
        """One line on the folders of steps this plan does not have: how many a run would move out of the top of
        the site and how many are kept in :func:`~twinkit.engine.recipes.stale_folder` (None when there are none)."""
        name = str((self.cfg.get("recipe") or {}).get("name") or "")
        if not name or self.workspace.resolve() != self.site_root.resolve():
            return None
        plan = {ps.folder for ps in self.plan}
        park = stale_folder(self.site_root, name)
        top = [f.name for f in numbered_folders(self.site_root) if f.name not in plan]
        kept = [f.name for f in numbered_folders(park) if f.name not in plan]
        if not top and not kept:
            return None
        parts = [f"{len(kept)} folder(s) of steps not in this plan are kept in {park}"] if kept else []
        if top:
            parts.append(f"the next run moves {len(top)} there from the top ({', '.join(top)})")
        return "; ".join(parts) + " (they come back when the plan has them again)"

    def _status_cached(self, ps, folder, key: str, stored: dict) -> tuple[tuple[str, str, str], dict | None]:
        """The row of a step whose result is stored, and the hashes later steps would see (None when they cannot
        be told without running): an edit set aside on that result would be re-applied over it."""
        pending = self._pending_edits(folder, key)
        if not pending:
            return (ps.folder, "cached", "result stored for this key"), stored["artefacts"]
        dest, note = pending[0]
        files = sorted(note.get("files", {}))
        row = (ps.folder, "edited", f"would re-apply hand-edited {', '.join(files)} from {dest}")
        if ps.foreach is not None:
            return row, None
        return row, {f: artefact_hash(dest / f, self.hashes) if f in files else h
                     for f, h in stored["artefacts"].items()}

