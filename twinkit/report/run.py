"""The run folder, as the report reads it (:class:`RunView`), and small file helpers."""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any, Iterable

REPORT_DIR = "report"
CACHE_KEEP_DAYS = 30


def read_json(p: Path, limit: int = 4_000_000) -> Any:
    """The JSON document in ``p``, or None when it is missing, unreadable or bigger than ``limit`` bytes."""
    try:
        if p.stat().st_size > limit:
            return None
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def frame_unit(steps: list[dict]) -> str:
    """The unit of the site frame's lengths, for the report's labels: "model units" where the latest step that
    says whether the frame is scaled (its metric ``scaled``: a photo run's georeference and roi) says it is
    not, else "m". ``steps`` are the report's steps (manifest entries with ``metrics``), in run order."""
    for s in reversed(steps):
        scaled = (s.get("metrics") or {}).get("scaled")
        if isinstance(scaled, bool):
            return "m" if scaled else "model units"
    return "m"


def flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts -> {"a.b.c": scalar}; lists of scalars stay as values."""
    out: dict[str, Any] = {}
    if isinstance(d, dict):
        for k, v in d.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, dict):
                out.update(flatten(v, key))
            else:
                out[key] = v
    return out


def link_or_copy(src: Path, dst: Path) -> None:
    """A hard link to a file of the report's own cache (rendered pictures, script bundles)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    if dst.exists() or dst.is_symlink():
        dst.unlink()
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def cached_copy(src: Path, cache: Path) -> Path:
    """A copy of ``src`` in the report cache, named by its content (made once; reports hard-link it), so a
    picture of a step folder is on disk once however many reports show it, and never shares an inode with
    the step folder."""
    import hashlib

    h = hashlib.sha256()
    with open(src, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    dst = Path(cache) / f"pic-{h.hexdigest()[:24]}{Path(src).suffix.lower()}"
    if dst.is_file():
        touch(dst)
        return dst
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
    shutil.copyfile(src, tmp)
    tmp.replace(dst)
    return dst


def write_text(path: Path, text: str) -> None:
    """Atomic (parallel multirun jobs share the cache)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def touch(p: Path) -> None:
    try:
        os.utime(p)
    except OSError:
        pass


def prune_cache(cache: Path, keep_days: float = CACHE_KEEP_DAYS) -> int:
    """Delete cached pictures and models not used for ``keep_days`` (reports keep their hard links)."""
    if not cache.is_dir():
        return 0
    limit = time.time() - keep_days * 86400
    n = 0
    for p in cache.iterdir():
        try:
            if p.is_file() and p.stat().st_mtime < limit:
                p.unlink()
                n += 1
        except OSError:
            pass
    return n


def rel(target: Path, start: Path) -> str:
    """A relative URL from folder ``start`` to ``target`` (quoted for HTML attributes)."""
    try:
        r = os.path.relpath(target, start)
    except ValueError:
        return Path(target).resolve().as_uri()
    from urllib.parse import quote

    return quote(r.replace(os.sep, "/"))


def file_key(p: Path, known: dict[str, str] | None = None) -> str:
    """The content hash recorded by the step (step.json), else a (size, mtime, inode) stamp."""
    if known and p.name in known:
        return known[p.name]
    st = p.stat()
    return f"{st.st_size}-{st.st_mtime_ns}-{st.st_ino}"


class RunView:
    """What a run produced: its steps (manifest + step.json) and the files in their numbered folders."""

    def __init__(self, run_dir: Path, manifest: dict, engine=None):
        self.run_dir = Path(run_dir)
        self.manifest = manifest or {}
        ws = getattr(engine, "workspace", None) or self.manifest.get("workspace") or self.run_dir
        self.workspace = Path(ws)
        site_root = getattr(engine, "site_root", None)
        self.site_root = Path(site_root) if site_root else self.workspace
        self.report_dir = self.run_dir / REPORT_DIR
        self.steps: list[dict] = []
        for i, s in enumerate(self.manifest.get("steps") or []):
            if not isinstance(s, dict):
                continue
            folder = self.workspace / str(s.get("folder") or f"{i + 1:02d}_{s.get('id', 'step')}")
            rec = read_json(folder / "step.json") or {}
            files = []
            if folder.is_dir():
                files = sorted((p for p in folder.rglob("*") if p.is_file() and not p.name.startswith(".")),
                               key=lambda p: str(p.relative_to(folder)))
            hashes = {k: v.get("sha256") for k, v in (rec.get("files") or {}).items() if isinstance(v, dict)}
            self.steps.append({**s, "dir": folder, "record": rec, "files": files, "hashes": hashes})
        failed = self.manifest.get("failed_step")
        if isinstance(failed, dict) and failed.get("id"):  # the step a failed run stopped in (docs/report.md)
            folder = self.workspace / str(failed.get("folder") or failed["id"])
            self.steps.append({"id": failed["id"], "folder": failed.get("folder") or failed["id"],
                               "plugin": failed.get("plugin", ""), "status": "failed",
                               "why": failed.get("error", ""), "dir": folder, "record": {}, "files": [],
                               "hashes": {}})

    # ------------------------------------------------------------------ finding files
    def all_files(self) -> Iterable[tuple[dict, Path]]:
        for s in self.steps:
            for f in s["files"]:
                yield s, f

    def find(self, pattern: str, latest: bool = True) -> list[tuple[dict, Path]]:
        """Files whose name matches a glob (latest step first)."""
        import fnmatch

        hits = [(s, f) for s, f in self.all_files() if fnmatch.fnmatch(f.name.lower(), pattern.lower())]
        return list(reversed(hits)) if latest else hits

    def first(self, pattern: str) -> tuple[dict, Path] | None:
        hits = self.find(pattern)
        return hits[0] if hits else None

    def key_of(self, step: dict, p: Path) -> str:
        return file_key(p, step.get("hashes"))

    @property
    def cache_dir(self) -> Path:
        return self.site_root / ".cache" / "report"
