"""The numbered step folders (``01_site/``, ``02_read_cloud/`` ...): stored results are swapped in
atomically as copies (reflinks where the file system has them), with the folder's ``step.json`` record;
a folder's outputs and their hashes for the steps after it.

Copies, not hard links: a folder a person edits shares no inode with the store or with another folder
(a sweep job's), so an editor that rewrites a file in place changes that one file. Each file's bytes are
hashed while they are copied and checked against the stored record, so a damaged store entry is never
served."""
from __future__ import annotations

import fcntl
import hashlib
import logging
import os
import shutil
from pathlib import Path

from twinkit.engine.base import EngineBase
from twinkit.engine.plan import PlannedStep
from twinkit.engine.records import RECORD, RECORD_SCHEMA, _now, read_record
from twinkit.hashing import CHUNK, HashCache, artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic

log = logging.getLogger("twinkit")

_FICLONE = 0x40049409  # Linux ioctl: share the data blocks copy-on-write (btrfs, XFS, bcachefs)


class DamagedStore(Exception):
    """A stored file's bytes differ from its record."""

    def __init__(self, entry: Path, rel: str):
        super().__init__(f"{entry / rel}")
        self.entry, self.rel = entry, rel


def copy_checked(src: Path, dst: Path, expect: str | None, cache: HashCache) -> str:
    """Copy ``src`` to a new file ``dst`` (a reflink where possible), checking its sha256 against ``expect``;
    the copy's hash is remembered so that it is never read again. Raises DamagedStore on a mismatch."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    digest = None
    with open(src, "rb") as fi, open(dst, "wb") as fo:
        try:
            fcntl.ioctl(fo.fileno(), _FICLONE, fi.fileno())
            digest = cache.hash(src)  # shared blocks: the source's (ctime-checked) hash is the copy's
        except OSError:
            h = hashlib.sha256()
            while chunk := fi.read(CHUNK):
                h.update(chunk)
                fo.write(chunk)
            digest = h.hexdigest()
    if expect is not None and digest != expect:
        dst.unlink(missing_ok=True)
        raise DamagedStore(src.parent, src.name)
    cache.remember(dst, digest)
    return digest


class WorkspaceMixin(EngineBase):
    """Part of :class:`~twinkit.engine.runner.Engine`: write and read the numbered folders of
    ``self.workspace``."""

    def _materialize(self, folder: Path, entries: list[tuple[str, Path]], record: dict) -> None:
        """Atomically replace ``folder`` with checked copies of the stored files (DamagedStore, leaving the
        folder as it was, when a stored file differs from its record)."""
        tmp = self.workspace / f".{folder.name}.tmp-{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        try:
            for prefix, src_dir in entries:
                known = (read_record(src_dir) or {}).get("files", {})
                for rel in list_files(src_dir):
                    if rel.name == RECORD and rel.parent == Path("."):
                        continue
                    info = known.get(rel.as_posix())
                    if info is None:
                        raise DamagedStore(src_dir, rel.as_posix())
                    copy_checked(src_dir / rel, tmp / prefix / rel, info["sha256"], self.hashes)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        write_json_atomic(tmp / RECORD, record)
        old = None
        if folder.exists():
            old = self.workspace / f".{folder.name}.old-{os.getpid()}"
            os.replace(folder, old)
        os.replace(tmp, folder)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def _outputs_of(self, folder: Path, ps: PlannedStep, rec: dict, current: bool) -> tuple[dict, dict]:
        outputs = {p.filename: folder / p.filename for p in ps.outputs}
        if current:
            hashes = {p.filename: artefact_hash(folder / p.filename, self.hashes) for p in ps.outputs}
        else:
            hashes = dict(rec["artefacts"])
        return outputs, hashes

    def _redacted(self, obj):
        """``obj`` with the values read through ``${oc.env:...}`` replaced (twinkit.manifest.redact)."""
        from twinkit.manifest import redact

        return redact(obj, getattr(self, "secrets", None) or None)  # None: those the process knows

    def _workspace_record(self, ps, key, desc, stored, status, why, in_paths) -> dict:
        desc = self._redacted(desc)
        return {
            "schema": RECORD_SCHEMA,
            "step": ps.id,
            "recipe": (self.cfg.get("recipe") or {}).get("name"),
            "key": key,
            "descriptor": desc,
            "plugin": ps.label,
            "distribution": ps.plugin.distribution if ps.plugin else None,
            "params": self._redacted(ps.params_dict),
            "inputs": {k: (str(v) if not isinstance(v, list) else [str(x) for x in v]) for k, v in in_paths.items()},
            "files": stored.get("files", {}),
            "artefacts": stored.get("artefacts", {}),
            "metrics": self._redacted(stored.get("metrics", {})),
            "duration_s": stored.get("duration_s"),
            "peak_rss_mb": stored.get("peak_rss_mb"),
            "status": status,
            "why": why,
            "site_fields": stored.get("site_fields", []),
            "recorded_at": _now(),
        }
