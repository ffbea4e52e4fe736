"""Two recipes on one site keep their numbered folders apart.

``outputs/<site>/NN_*`` shows the folders of the recipe that ran last there (``.twinkit.recipe`` names it).
When another recipe runs, those folders move, whole and as they are (hand edits included), to
``outputs/<site>/recipes/<recipe>/``, and the new recipe's own parked folders, if it ran there before, move
back. Moving is one ``rename`` per folder: nothing is copied, recomputed or lost. The moves are written to a
journal (``.twinkit.switch.json``) before the first, and a run killed among them is finished by the next run
before it does anything else.

Folders of steps that this run's plan does not have (a step dropped, renamed or renumbered, a road source set to
``none``) move the same way, journalled by the same file, to ``outputs/<site>/stale/<recipe>/``; they come back
when the plan has them again."""
from __future__ import annotations

import datetime as _dt
import json
import logging
import os
import re
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.records import read_record
from twinkit.errors import InputError
from twinkit.jsonio import write_json as write_json_atomic
from twinkit.jsonio import write_text

log = logging.getLogger("twinkit")

MARKER = ".twinkit.recipe"
JOURNAL = ".twinkit.switch.json"  # a recipe switch's folder moves, written before the first, removed after the last
STALE = "stale"  # <site>/stale/<recipe>/NN_*: folders of steps the plan of the recipe's last run did not have
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


def _write_marker(workspace: Path, name: str) -> None:
    """``.twinkit.recipe`` written whole or not at all (a half-written marker would hide the recipe); a link there
    is replaced, never followed (twinkit.jsonio.write_text)."""
    write_text(workspace / MARKER, name + "\n")


def switch_moves(workspace: Path, here: str | None, name: str, edits_dir: Path) -> list[tuple[str, str]]:
    """The folder moves (``src``, ``dst``, relative to ``workspace``) that put recipe ``name``'s folders at the
    top: the folders of recipe ``here`` parked (an older park of it set aside first, never overwritten), then
    ``name``'s parked folders moved back where no folder stays."""
    moves: list[tuple[str, str]] = []
    staying = {f.name for f in numbered_folders(workspace)}
    if here is not None and here != name and staying:
        dest = workspace / "recipes" / _safe(here)
        if numbered_folders(dest):
            aside = edits_dir / f"parked-{_safe(here)}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
            moves.append((os.path.relpath(dest, workspace), os.path.relpath(aside, workspace)))
        moves += [(f.name, os.path.relpath(dest / f.name, workspace)) for f in numbered_folders(workspace)]
        staying = set()
    back = workspace / "recipes" / _safe(name)
    if here != name:
        moves += [(os.path.relpath(f, workspace), f.name) for f in numbered_folders(back) if f.name not in staying]
    return moves


def stale_folder(workspace: Path, recipe: str) -> Path:
    """Where the folders of ``recipe``'s steps that its current plan does not have are kept."""
    return workspace / STALE / _safe(recipe)


def stale_moves(workspace: Path, recipe: str, plan: set[str], edits_dir: Path) -> list[tuple[str, str]]:
    """The folder moves (``src``, ``dst``, relative to ``workspace``) that take the numbered folders not in
    ``plan`` (folder names) out of the top of ``workspace`` into :func:`stale_folder` (an older one of the same
    name set aside into ``edits_dir`` first, never overwritten), and bring back those of ``plan`` kept there."""
    park = stale_folder(workspace, recipe)
    moves: list[tuple[str, str]] = []
    for f in numbered_folders(workspace):
        if f.name in plan:
            continue
        if os.path.lexists(park / f.name):
            aside = edits_dir / f"stale-{_safe(recipe)}-{f.name}-{_dt.datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
            moves.append((os.path.relpath(park / f.name, workspace), os.path.relpath(aside, workspace)))
        moves.append((f.name, os.path.relpath(park / f.name, workspace)))
    moves += [(os.path.relpath(f, workspace), f.name) for f in numbered_folders(park)
              if f.name in plan and not os.path.lexists(workspace / f.name)]
    return moves


def _journalled(workspace: Path, here: str | None, name: str, moves: list[tuple[str, str]]) -> None:
    """Make ``moves`` as one journalled switch (:data:`JOURNAL`, :func:`finish_switch`)."""
    write_json_atomic(workspace / JOURNAL, {"recipe": name, "from": here, "moves": moves})
    finish_switch(workspace)


def finish_switch(workspace: Path) -> None:
    """Carry out the recipe switch journalled in ``workspace`` (:data:`JOURNAL`), from wherever a run killed
    during it stopped: a move whose source is gone or whose target exists is done. Then the marker names the
    new recipe and the journal goes."""
    journal = workspace / JOURNAL
    try:
        plan = json.loads(journal.read_text())
        moves, recipe = [(str(s), str(d)) for s, d in plan["moves"]], str(plan["recipe"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{journal}: unreadable ({type(exc).__name__}); it lists the folder moves of a recipe "
                         f"switch a killed run left half done: move the numbered folders where they belong "
                         f"(docs/engine.md, 'Where things go') and remove it") from None
    for src, dst in moves:
        s, d = workspace / src, workspace / dst
        if os.path.lexists(s) and not os.path.lexists(d):
            d.parent.mkdir(parents=True, exist_ok=True)
            os.replace(s, d)
        elif os.path.lexists(s):
            log.warning("  %s was not moved to %s, which exists already; both are kept", s, d)
    for d in {(workspace / s).parent for s, _ in moves}:  # a park the moves emptied
        if d.parent in (workspace / "recipes", workspace / STALE) and d.is_dir() and not any(d.iterdir()):
            d.rmdir()
    if (workspace / STALE).is_dir() and not any((workspace / STALE).iterdir()):
        (workspace / STALE).rmdir()
    _write_marker(workspace, recipe)
    journal.unlink()


class RecipesMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine` (``self.workspace``, ``self.site_root``,
    ``self.edits_dir``, ``self.cfg``)."""

    def _switch_recipe(self) -> None:
        """Put this run's recipe's folders at the top of the site's folder, parking those of the recipe that ran
        there last. The moves are journalled first (:data:`JOURNAL`), so a run killed half-way leaves no mix of
        two recipes taken as one: the next run finishes them before anything else."""
        if self.workspace.resolve() != self.site_root.resolve():
            return  # a sweep job's folder holds one recipe
        name = str((self.cfg.get("recipe") or {}).get("name") or "")
        if not name:
            return
        if (self.workspace / JOURNAL).is_file():
            log.warning("finishing the recipe switch a killed run left half done (%s)", self.workspace / JOURNAL)
            finish_switch(self.workspace)
        here = recipe_here(self.workspace)
        moves = switch_moves(self.workspace, here, name, self.edits_dir)
        if not moves:
            if here != name:
                _write_marker(self.workspace, name)
            self._move_stale(name)
            return
        _journalled(self.workspace, here, name, moves)
        parked = [d for s, d in moves if d.startswith(os.path.relpath(self.edits_dir, self.workspace))]
        if parked:
            log.warning("  an older copy of recipe '%s' folders moved to %s", here, self.workspace / parked[0])
        n_out = sum(1 for s, d in moves if "/" not in s)
        n_back = sum(1 for s, d in moves if "/" not in d)
        if n_out:
            log.info("recipe '%s' folders (%d) moved to %s; recipe '%s' runs here now", here, n_out,
                     self.workspace / "recipes" / _safe(str(here)), name)
        if n_back:
            log.info("recipe '%s' folders (%d) moved back from %s", name, n_back,
                     self.workspace / "recipes" / _safe(name))
        self._move_stale(name)

    def _move_stale(self, name: str) -> None:
        """Take the folders of steps this plan does not have out of the top (to :func:`stale_folder`) and bring
        back those it has again, journalled like a recipe switch."""
        moves = stale_moves(self.workspace, name, {ps.folder for ps in self.plan}, self.edits_dir)
        if not moves:
            return
        _journalled(self.workspace, name, name, moves)
        park = os.path.relpath(stale_folder(self.workspace, name), self.workspace)
        out = [s for s, d in moves if "/" not in s]
        back = [d for s, d in moves if "/" not in d]
        if out:
            log.info("folders of steps not in this plan (%s) moved to %s", ", ".join(out), self.workspace / park)
        if back:
            log.info("folders of steps back in this plan (%s) moved back from %s", ", ".join(back),
                     self.workspace / park)
