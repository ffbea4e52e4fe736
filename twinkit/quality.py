"""Quality gates and degraded results: a step that produced far less than it should says so, and the run ends
"degraded".

A step declares each figure that decides whether its result holds with ``ctx.gate(name, value, threshold, op,
unit, why, hint)``: every gate's figure is stored in the step's metrics under ``gates`` whether it passes or not
(printed on the step's log line, listed in the report's "Quality gates" table), and a gate that fails makes the
step degraded. A step may also call ``ctx.degraded(reason, hint)`` (or returns ``{"degraded": [{"reason": ..., "hint": ...}]}`` in its
metrics). The reasons travel with the step's stored record, so a cached or reused step is as degraded as the
run that computed it. The run's manifest says ``"status": "degraded"`` and lists them under ``degraded``, the
report shows them in red, ``twinkit status`` names the steps, and the command exits with
``engine.degraded_exit_code`` (4 by default; 0 keeps the old behaviour for scripts that only want a warning).
"""
from __future__ import annotations

import operator
from typing import Any, Iterable

#: exit code of a run that finished with a degraded result (1 failed, 2 config error, 3 waiting on a manual step)
DEGRADED_EXIT = 4

#: how a gate's figure is compared with its threshold (the figure passes when ``op(value, threshold)``)
GATE_OPS = {">=": operator.ge, ">": operator.gt, "<=": operator.le, "<": operator.lt}


def gate_entry(name: str, value: float | None, threshold: float, op: str = ">=", unit: str = "",
               why: str = "") -> dict:
    """One gate's record: ``{"name", "value", "threshold", "op", "unit", "why", "ok"}``; a figure of None (nothing
    to measure) passes. ValueError for an ``op`` outside :data:`GATE_OPS`."""
    if op not in GATE_OPS:
        raise ValueError(f"gate '{name}': op must be one of {', '.join(GATE_OPS)}, not {op!r}")
    value = None if value is None else float(value)
    ok = value is None or value != value or bool(GATE_OPS[op](value, float(threshold)))
    if value is not None and value != value:
        value = None
    entry: dict[str, Any] = {"name": str(name), "value": None if value is None else round(value, 6),
                             "threshold": float(threshold), "op": op, "unit": str(unit), "ok": ok}
    if why:
        entry["why"] = str(why)
    return entry


def gate_text(g: dict) -> str:
    """One gate as text: ``continuity driving 99.95 % (>= 99.9 %) ok``."""
    unit = f" {g['unit']}" if g.get("unit") else ""
    value = "n/a" if g.get("value") is None else f"{g['value']:.4g}"
    return f"{g['name']} {value}{unit} ({g['op']} {g['threshold']:.4g}{unit}) {'ok' if g.get('ok') else 'FAILED'}"


def with_gates(metrics: dict, gates: Iterable[Any], key: str = "gates") -> dict:
    """``metrics`` with the records under ``key`` (``gates``, ``warnings`` or ``notes``) added after its own."""
    extra = list(gates)
    if not extra:
        return metrics
    return {**metrics, key: list(metrics.get(key) or []) + extra}


def _listed(metrics: dict | None, key: str, step: str | None) -> list:
    """The entries under ``key`` of a step's metrics and of its fan-out items (dicts get ``step``/``item``)."""
    if not isinstance(metrics, dict):
        return []
    out: list = []
    for i, m in [(None, metrics)] + list(enumerate(metrics.get("per_item") or [])):
        for e in (m.get(key) or []) if isinstance(m, dict) and isinstance(m.get(key), list) else []:
            e = dict(e) if isinstance(e, dict) else {"text": str(e)}
            if step:
                e.setdefault("step", step)
            if i is not None:
                e.setdefault("item", i)
            out.append(e)
    return out


def gates_of(metrics: dict | None, step: str | None = None) -> list[dict]:
    """Every gate a step declared (its items' too), passed or failed."""
    return [g for g in _listed(metrics, "gates", step) if "name" in g]


def warnings_of(metrics: dict | None, step: str | None = None) -> list[dict]:
    """Every warning a step logged (``{"text", "step", "item"}``), kept with its result like its gates."""
    return _listed(metrics, "warnings", step)


def notes_of(steps: Iterable[dict]) -> list[str]:
    """The run's notes on the twin (``ctx.note``: "no road network"), once each, in step order."""
    out: list[str] = []
    for s in steps:
        for e in _listed(s.get("metrics"), "notes", None):
            if e["text"] not in out:
                out.append(e["text"])
    return out


def run_gates(steps: Iterable[dict]) -> list[dict]:
    """Every gate of a manifest's steps, in step order."""
    out: list[dict] = []
    for s in steps:
        out += gates_of(s.get("metrics"), s.get("id"))
    return out


def run_status_text(manifest: dict) -> str:
    """The run's status as the report's top line says it: ``ok``, ``degraded``, ..., with the run's notes on the
    twin (``ok · no road network``)."""
    return " · ".join([str(manifest.get("status", "?"))] + list(manifest.get("notes") or []))


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
