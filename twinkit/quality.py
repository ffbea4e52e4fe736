"""Degraded results: a step that produced far less than it should says so, and the run ends "degraded".

A step calls ``ctx.degraded(reason, hint)`` (or returns ``{"degraded": [{"reason": ..., "hint": ...}]}`` in its
metrics). The reasons travel with the step's stored record, so a cached or reused step is as degraded as the
run that computed it. The run's manifest says ``"status": "degraded"`` and lists them under ``degraded``, the
report shows them in red, ``twinkit status`` names the steps, and the command exits with
``engine.degraded_exit_code`` (4 by default; 0 keeps the old behaviour for scripts that only want a warning).
"""
from __future__ import annotations

from typing import Any, Iterable

#: exit code of a run that finished with a degraded result (1 failed, 2 config error, 3 waiting on a manual step)
DEGRADED_EXIT = 4


def _entries(value: Any, step: str | None = None) -> list[dict]:
    out = []
    for e in value if isinstance(value, list) else [value] if value else []:
        if isinstance(e, str):
            e = {"reason": e}
        if isinstance(e, dict) and e.get("reason"):
            entry: dict[str, Any] = {"reason": str(e["reason"])}
            if e.get("hint"):
                entry["hint"] = str(e["hint"])
            if e.get("item") is not None:
                entry["item"] = e["item"]
            if step or e.get("step"):
                entry["step"] = e.get("step") or step
            out.append(entry)
    return out


def with_degraded(metrics: dict, reasons: Iterable[dict]) -> dict:
    """``metrics`` with the reasons a step gave (by ``ctx.degraded`` or in its own metrics) under ``degraded``."""
    merged = _entries(metrics.get("degraded")) + _entries(list(reasons))
    if not merged:
        return {k: v for k, v in metrics.items() if k != "degraded"} if "degraded" in metrics else metrics
    seen, unique = set(), []
    for e in merged:
        k = (e["reason"], e.get("hint"))
        if k not in seen:
            seen.add(k)
            unique.append(e)
    return {**metrics, "degraded": unique}


def degraded_of(metrics: dict | None, step: str | None = None) -> list[dict]:
    """The degraded reasons in a step's metrics; a fan-out step's items' reasons carry their item number."""
    if not isinstance(metrics, dict):
        return []
    out = _entries(metrics.get("degraded"), step)
    for i, item in enumerate(metrics.get("per_item") or []):
        if isinstance(item, dict):
            out += [dict(e, item=e.get("item", i)) for e in _entries(item.get("degraded"), step)]
    return out


def run_degraded(steps: Iterable[dict]) -> list[dict]:
    """Every degraded reason of a manifest's steps, in step order."""
    out = []
    for s in steps:
        out += degraded_of(s.get("metrics"), s.get("id"))
    return out


def describe(entry: dict) -> str:
    """One line: ``step (item 3): reason (hint)``."""
    where = entry.get("step", "?") + (f" (item {entry['item']})" if entry.get("item") is not None else "")
    return f"{where}: {entry['reason']}" + (f" ({entry['hint']})" if entry.get("hint") else "")
