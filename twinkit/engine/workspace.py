"""The numbered step folders (``01_site/``, ``02_read_cloud/`` ...): stored results are swapped in
atomically as hard links (copies where links are impossible), with the folder's ``step.json`` record;
a folder's outputs and their hashes for the steps after it."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from twinkit.engine.plan import PlannedStep
from twinkit.engine.records import RECORD, RECORD_SCHEMA, _now
from twinkit.hashing import artefact_hash, list_files
from twinkit.jsonio import write_json as write_json_atomic


def _link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


class WorkspaceMixin:
    """Part of :class:`~twinkit.engine.runner.Engine`: write and read the numbered folders of
    ``self.workspace``."""

    def _materialize(self, folder: Path, entries: list[tuple[str, Path]], record: dict) -> None:
        """Atomically replace ``folder`` with hard links (or copies) of the stored files."""
        tmp = self.workspace / f".{folder.name}.tmp-{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        for prefix, src_dir in entries:
            for rel in list_files(src_dir):
                if rel.name == RECORD and rel.parent == Path("."):
                    continue
                _link_or_copy(src_dir / rel, tmp / prefix / rel)
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

    def _workspace_record(self, ps, key, desc, stored, status, why, in_paths) -> dict:
        return {
            "schema": RECORD_SCHEMA,
            "step": ps.id,
            "key": key,
            "descriptor": desc,
            "plugin": ps.label,
            "distribution": ps.plugin.distribution if ps.plugin else None,
            "params": ps.params_dict,
            "inputs": {k: (str(v) if not isinstance(v, list) else [str(x) for x in v]) for k, v in in_paths.items()},
            "files": stored.get("files", {}),
            "artefacts": stored.get("artefacts", {}),
            "metrics": stored.get("metrics", {}),
            "duration_s": stored.get("duration_s"),
            "peak_rss_mb": stored.get("peak_rss_mb"),
            "status": status,
            "why": why,
            "recorded_at": _now(),
        }
