"""What a step leaves behind: the ``step.json`` record (in a store entry and in a numbered folder), and the
:class:`StepOutcome` the engine reports for each step."""
from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

RECORD = "step.json"
RECORD_SCHEMA = 1


@dataclass
class StepOutcome:
    step: str
    folder: str
    plugin: str
    status: str  # ran | reused | cached | edited | manual | failed | pending
    why: str
    key: str
    duration_s: float
    outputs: dict[str, Any]  # filename -> Path or list[Path]
    hashes: dict[str, Any]  # filename -> artefact hash (or list)
    metrics: dict = field(default_factory=dict)
    peak_rss_mb: float | None = None


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def read_record(folder: Path) -> dict | None:
    p = folder / RECORD
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text())
    except (OSError, json.JSONDecodeError):
        return None
