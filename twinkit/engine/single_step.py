"""One step-like plugin run through the engine's atomic write path, outside any recipe
(``twinkit.testing.run_step``)."""
from __future__ import annotations

import hashlib
import logging
import os
import shutil
import time
from pathlib import Path
from typing import Any

from twinkit.engine.store import compute_into_store
from twinkit.errors import InputError
from twinkit.plugins import Plugin
from twinkit.signature import parse_signature


def execute_plugin(plugin: Plugin, workdir: Path, inputs: dict[str, Path], params: Any = None,
                   site: dict | None = None, config: dict | None = None) -> dict[str, Path]:
    """Run one step-like plugin through the engine's atomic write path, outside any recipe.

    ``inputs`` maps input parameter names (``in_mesh_ply``) to paths. Returns
    {output file name: path} inside ``workdir/result``.
    """
    sig = parse_signature(plugin.run)
    params = params if params is not None else plugin.default_params()
    kwargs = {p.param: (Path(inputs[p.param]) if p.param in inputs else None) for p in sig.inputs}
    missing = [p.param for p in sig.inputs if kwargs[p.param] is None and not p.optional]
    if missing:
        raise InputError(f"{plugin.qualname} needs inputs {missing}")
    store = Path(workdir) / ".store"
    key = hashlib.sha256(repr((plugin.qualname, time.time_ns())).encode()).hexdigest()[:16]
    compute_into_store(plugin.run, params, kwargs, sig.outputs, key, store,
                       {"step_id": plugin.name, "site": site or {"name": "test"}, "config": config or {},
                        "log": logging.getLogger(f"twinkit.step.{plugin.name}")})
    result = Path(workdir) / "result"
    if result.exists():
        shutil.rmtree(result)
    os.replace(store / key, result)
    for f in result.rglob("*"):  # the store keeps its files read-only; a test's result folder is its own
        if f.is_file():
            f.chmod(f.stat().st_mode | 0o200)
    return {p.filename: result / p.filename for p in sig.outputs}
