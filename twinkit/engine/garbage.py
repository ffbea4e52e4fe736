"""``twinkit gc``: stored results that no numbered folder refers to, and remembered hashes of files that
are gone or changed."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from twinkit.engine.recipes import numbered_folders
from twinkit.engine.records import RECORD, read_record
from twinkit.hashing import HashCache


def recorded_folders(site_root: Path) -> list[Path]:
    """Every numbered step folder of the site, of its sweep jobs, of its parked recipes and its stale folders
    (any number of digits: ``07_texture``, ``112_export``)."""
    roots = [site_root, *site_root.glob("sweeps/*/*"), *site_root.glob("recipes/*"), *site_root.glob("stale/*")]
    return [d for r in roots for d in numbered_folders(r) if (d / RECORD).is_file()]


def collect_garbage(site_root: Path, dry_run: bool = False) -> tuple[list[Path], int]:
    """Stored results that no numbered folder (of the site or of any sweep job) refers to.

    Returns (removed or removable entries, bytes). Call it under :func:`twinkit.engine.locks.gc_locks`: a
    running job has results it has not yet recorded in its folders, so gc refuses while any job holds the
    store.
    """
    store = Path(site_root) / ".cache" / "steps"
    if not store.is_dir():
        return [], 0
    keep: set[str] = set()
    for folder in recorded_folders(Path(site_root)):
        rec = read_record(folder) or {}
        if rec.get("key"):
            keep.add(rec["key"])
        keep.update(rec.get("item_keys") or [])
    doomed = [d for d in store.iterdir() if d.is_dir() and d.name != ".tmp" and d.name not in keep]
    size = sum(f.stat().st_size for d in doomed for f in d.rglob("*") if f.is_file())
    if not dry_run:
        for d in doomed:
            shutil.rmtree(d, ignore_errors=True)
            (store / f"{d.name}.lock").unlink(missing_ok=True)
    return doomed, size


def prune_hash_cache(site_root: Path) -> int:
    """Forget remembered hashes of files that are gone or changed; returns how many were forgotten.

    Kept: every file under the site's folder (results, the store, runs) and every input file that a
    run manifest names and that still exists, so a large scan outside the workspace is not read again.
    """
    site_root = Path(site_root)
    db = site_root / ".cache" / "hashes.sqlite"
    if not db.is_file():
        return 0

    def sig(p: Path):
        try:
            st = os.stat(p)
        except OSError:
            return None
        return HashCache.signature(st)

    keep: set = set()
    for root, dirs, files in os.walk(site_root):
        for f in files:
            s = sig(Path(root) / f)
            if s is not None:
                keep.add(s)
    for m in site_root.glob("**/runs/*/manifest.json"):
        try:
            entries = json.loads(m.read_text()).get("inputs", [])
        except (OSError, ValueError):
            continue
        for e in entries:
            s = sig(Path(e.get("path", "")))
            if s is not None:
                keep.add(s)
    cache = HashCache(db)
    try:
        return cache.prune(keep)
    finally:
        cache.close()

