"""Where a run spends its time and memory: each step's wall seconds and peak resident memory, split by the
substeps it declared with ``ctx.substep`` (stored in its metrics under ``substeps``), read from the step folders'
``step.json``. ``twinkit profile <run folder>`` prints it; ``bench/bench_profile.py`` keeps it per demo size and
prints the change against the previous one; the report's timeline draws the same split.

A step's seconds are what computing it cost (a cached or reused step shows the time it took when it ran).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable

OTHER = "(other)"  # the step's time outside every substep it declared
MIN_OTHER_S = 0.05


def merged_substeps(metrics: Any) -> dict[str, dict]:
    """The substeps of a step's metrics; a fan-out step's items are added up (seconds summed, peaks the highest)."""
    from twinkit.context import add_substep

    if not isinstance(metrics, dict):
        return {}
    out: dict[str, dict] = {}
    sources = [metrics] + [m for m in (metrics.get("per_item") or []) if isinstance(m, dict)]
    for m in sources:
        subs = m.get("substeps")
        for name, rec in (subs.items() if isinstance(subs, dict) else []):
            if isinstance(rec, dict):
                out[name] = add_substep(out.get(name), rec)
    return out


def substep_parts(seconds: float, substeps: dict[str, dict]) -> list[tuple[str, dict]]:
    """The top-level substeps in the order they first ran (``start_s``), then the step's time outside them as ``(other)``
    (when a substep was declared and more than ``MIN_OTHER_S`` is left); nested ones (``a/b``) follow their parent."""
    if not substeps:
        return []
    order = sorted(substeps, key=lambda k: float(substeps[k].get("start_s", 0.0)))  # stored with sorted keys
    top = [(k, substeps[k]) for k in order if "/" not in k]
    parts: list[tuple[str, dict]] = []
    for k, v in top:
        parts.append((k, v))
        parts += [(n, substeps[n]) for n in order if n.startswith(k + "/")]
    other = float(seconds) - sum(float(v.get("seconds") or 0.0) for _, v in top)
    if other > MIN_OTHER_S:
        parts.append((OTHER, {"seconds": round(other, 3)}))
    return parts


def step_folders(path: Path) -> list[Path]:
    """The step folders of a run: those its ``manifest.json`` names (a folder under ``runs/``, or the manifest
    itself), else the numbered folders ``NN_<step>`` of a site or job folder."""
    path = Path(path)
    manifest = path if path.is_file() else path / "manifest.json"
    if manifest.is_file():
        m = json.loads(manifest.read_text())
        ws = Path(m.get("workspace") or manifest.parent)
        return [ws / str(s["folder"]) for s in m.get("steps") or [] if isinstance(s, dict) and s.get("folder")]
    return sorted(p for p in path.glob("[0-9][0-9]*_*") if (p / "step.json").is_file())


def read_profile(path: Path) -> dict:
    """The profile of the run at ``path`` (see :func:`step_folders`): ``{"source", "total_s", "steps": [{"step",
    "folder", "status", "seconds", "peak_rss_mb", "substeps"}]}``; a folder without a readable step.json is left out."""
    steps = []
    for folder in step_folders(path):
        try:
            rec = json.loads((folder / "step.json").read_text())
        except (OSError, ValueError):
            continue
        steps.append({"step": rec.get("step") or folder.name.split("_", 1)[-1], "folder": folder.name,
                      "status": rec.get("status"), "seconds": float(rec.get("duration_s") or 0.0),
                      "peak_rss_mb": rec.get("peak_rss_mb"), "substeps": merged_substeps(rec.get("metrics"))})
    return {"source": str(path), "total_s": round(sum(s["seconds"] for s in steps), 3), "steps": steps}


def profile_rows(profile: dict) -> list[dict]:
    """One row per step and per substep: ``{"step", "substep" ("" for the step), "seconds", "peak_rss_mb",
    "share"}``, share being of the run's total seconds."""
    total = float(profile.get("total_s") or 0.0) or 1.0
    rows = []
    for s in profile.get("steps") or []:
        rows.append({"step": s["step"], "substep": "", "seconds": s["seconds"], "peak_rss_mb": s.get("peak_rss_mb"),
                     "share": s["seconds"] / total})
        for name, rec in substep_parts(s["seconds"], s.get("substeps") or {}):
            sec = float(rec.get("seconds") or 0.0)
            rows.append({"step": s["step"], "substep": name, "seconds": sec, "peak_rss_mb": rec.get("peak_rss_mb"),
                         "share": sec / total, "calls": rec.get("calls")})
    return rows


def _mb(v: Any) -> str:
    return f"{float(v):.0f}" if isinstance(v, (int, float)) else ""


def profile_table(profile: dict) -> str:
    """The profile as a text table: step / substep / seconds / peak MB / share of the run."""
    lines = [f"{'step':<24} {'substep':<22} {'seconds':>9} {'peak MB':>8} {'share':>7}"]
    for r in profile_rows(profile):
        name = r["substep"] + (f" x{r['calls']}" if r.get("calls") else "")
        step = r["step"] if not r["substep"] else ""
        lines.append(f"{step:<24} {name:<22} {r['seconds']:9.1f} {_mb(r['peak_rss_mb']):>8} {100 * r['share']:6.1f}%")
    peak = max((float(s["peak_rss_mb"]) for s in profile.get("steps") or [] if s.get("peak_rss_mb")), default=0.0)
    lines.append(f"{'total':<24} {'':<22} {float(profile.get('total_s') or 0):9.1f} {_mb(peak):>8} {100.0:6.1f}%")
    return "\n".join(lines)


def _keyed(profile: dict) -> dict[tuple[str, str], dict]:
    return {(r["step"], r["substep"]): r for r in profile_rows(profile)}


def profile_delta(old: dict, new: dict, min_s: float = 0.0) -> str:
    """The change from ``old`` to ``new`` per step and substep (seconds, peak MB), rows that changed by less than
    ``min_s`` seconds left out, and the totals; a row only one side has shows ``-`` on the other."""
    a, b = _keyed(old), _keyed(new)
    keys = list(b) + [k for k in a if k not in b]
    lines = [f"{'step':<24} {'substep':<22} {'before s':>9} {'after s':>9} {'change':>16} {'peak MB':>13}"]
    for k in keys:
        ra, rb = a.get(k), b.get(k)
        sa, sb = (float(r["seconds"]) if r else None for r in (ra, rb))
        if sa is not None and sb is not None and abs(sb - sa) < min_s:
            continue
        change = f"{sb - sa:+8.1f} {_pct(sa, sb):>7}" if sa is not None and sb is not None else "-"
        pa, pb = (_mb(r and r.get("peak_rss_mb")) or "-" for r in (ra, rb))
        peak = "" if pa == pb == "-" else f"{pa} -> {pb}"
        lines.append(f"{k[0] if not k[1] else '':<24} {k[1]:<22} {_num(sa):>9} {_num(sb):>9} {change:>16} {peak:>13}")
    ta, tb = float(old.get("total_s") or 0), float(new.get("total_s") or 0)
    lines.append(f"{'total':<24} {'':<22} {ta:9.1f} {tb:9.1f} {f'{tb - ta:+8.1f} {_pct(ta, tb):>7}':>16}")
    return "\n".join(lines)


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _pct(a: float, b: float) -> str:
    return f"{100 * (b - a) / a:+.0f}%" if a > 0 else ""


def print_profile(paths: Iterable[str]) -> int:
    """``twinkit profile <run folder> [<earlier run folder or profile .json>]``: the profile, and the change
    from the earlier one when given."""
    from twinkit.errors import say_error

    args = list(paths)
    if len(args) not in (1, 2):
        return say_error("usage: twinkit profile <run folder | manifest.json> [<earlier run folder | profile .json>]")
    new = read_profile(Path(args[0]))
    if not new["steps"]:
        return say_error(f"{args[0]}: no step.json found; give a site folder (outputs/<site>), a run folder "
                         f"(outputs/<site>/runs/<time>) or its manifest.json")
    print(profile_table(new))
    if len(args) == 2:
        p = Path(args[1])
        old = json.loads(p.read_text()) if p.is_file() and p.suffix == ".json" and p.name != "manifest.json" \
            else read_profile(p)
        print(f"\nchange from {args[1]}:")
        print(profile_delta(old, new))
    return 0
