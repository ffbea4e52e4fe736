"""JSON files the way every step writes them: sorted keys, indented, numpy values as plain numbers.

``write_json(path, data)`` is part of the plugin API: the write is atomic (a temporary file, then a
rename), so a step that fails half-way never leaves a truncated JSON file for a user to open.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def json_default(o: Any):
    """``json.dumps(default=...)`` for paths and numpy scalars/arrays (anything else: its str)."""
    if isinstance(o, Path):
        return str(o)
    if hasattr(o, "item") and getattr(o, "ndim", 0) == 0:
        return o.item()
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


def write_json(path: str | os.PathLike, data: Any, indent: int = 2) -> None:
    """Write ``data`` to ``path`` atomically (sorted keys, ``indent`` spaces, trailing newline)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=indent, sort_keys=True, default=json_default) + "\n")
    os.replace(tmp, path)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically: a temporary file, then a rename over ``path``. A symbolic link at
    ``path`` is replaced by the file, never followed, so its target is left as it was."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.unlink(missing_ok=True)
    tmp.write_text(text)
    os.replace(tmp, path)
