"""Two recipes on one site keep their numbered folders apart.

``outputs/<site>/NN_*`` shows the folders of the recipe that ran last there (``.twinkit.recipe`` names it).
When another recipe runs, those folders move, whole and as they are (hand edits included), to
``outputs/<site>/recipes/<recipe>/``, and the new recipe's own parked folders, if it ran there before, move
back. Moving is one ``rename`` per folder: nothing is copied, recomputed or lost."""
from __future__ import annotations

import datetime as _dt
import json
import logging
import os
import re
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.records import read_record
from twinkit.jsonio import write_text

log = logging.getLogger("twinkit")

MARKER = ".twinkit.recipe"
_NUMBERED = re.compile(r"^\d{2,}_\w+$")


def numbered_folders(root: Path) -> list[Path]:
    if not root.is_dir():
        return []
    return sorted(d for d in root.iterdir() if d.is_dir() and _NUMBERED.match(d.name))


def _safe(name: str) -> str:
    return re.sub(r"[^\w.-]", "_", name) or "_"


def recipe_here(workspace: Path) -> str | None:
    """The recipe whose numbered folders are at the top of ``workspace`` (None when there are none or it is
    unknown)."""
    m = workspace / MARKER
    if m.is_file():
        return m.read_text().strip() or None
    folders = numbered_folders(workspace)
    if not folders:
        return None
    for f in folders:
        rec = read_record(f) or {}
        if rec.get("recipe"):
            return rec["recipe"]
    for man in sorted(workspace.glob("runs/*/manifest.json"), reverse=True):  # folders of an older twinkit
        try:
            return json.loads(man.read_text())["config"]["recipe"]["name"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None


def parked_folder(workspace: Path, recipe: str) -> Path:
    """Where the numbered folders of ``recipe`` are while another recipe's are at the top."""
    here = recipe_here(workspace)
    if here is None or here == recipe:
        return workspace
    return workspace / "recipes" / _safe(recipe)


class RecipesMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine` (``self.workspace``, ``self.site_root``,
    ``self.edits_dir``, ``self.cfg``)."""

    def _switch_recipe(self) -> None:
        if self.workspace.resolve() != self.site_root.resolve():
            return  # a sweep job's folder holds one recipe
        name = str((self.cfg.get("recipe") or {}).get("name") or "")
        if not name:
            return
        here = recipe_here(self.workspace)
        if here is not None and here != name:
            folders = numbered_folders(self.workspace)
            if folders:
                dest = self.workspace / "recipes" / _safe(here)
                if numbered_folders(dest):  # an older park of the same recipe: kept, never overwritten
                    aside = self.edits_dir / f"parked-{_safe(here)}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
                    aside.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(dest, aside)
                    log.warning("  an older copy of recipe '%s' folders moved to %s", here, aside)
                dest.mkdir(parents=True, exist_ok=True)
                for f in folders:
                    os.replace(f, dest / f.name)
                log.info("recipe '%s' folders (%d) moved to %s; recipe '%s' runs here now", here, len(folders),
                         dest, name)
        back = self.workspace / "recipes" / _safe(name)
        if here != name and back.is_dir():
            restored = 0
            for f in numbered_folders(back):
                if not (self.workspace / f.name).exists():
                    os.replace(f, self.workspace / f.name)
                    restored += 1
            try:
                back.rmdir()
            except OSError:
                pass
            if restored:
                log.info("recipe '%s' folders (%d) moved back from %s", name, restored, back)
        write_text(self.workspace / MARKER, name + "\n")  # a link there is replaced, not followed
