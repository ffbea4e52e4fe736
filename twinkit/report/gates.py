"""The report's "Quality gates" and "Warnings" sections (core): every gate a step declared with its figure,
passed or failed, and every warning of the run (kept with each step's result, and the run log's own)."""
from __future__ import annotations

import re
from pathlib import Path

from twinkit.quality import gates_of, warnings_of
from twinkit.report.page import table
from twinkit.report.run import RunView

#: a WARNING line of run.log (``%(asctime)s %(levelname)s %(name)s: %(message)s``)
_LOG_WARNING = re.compile(r"^\S+ \S+ WARNING (\S+): (.*)$")


def gates_section(run: RunView) -> str:
    """Table: step, gate, figure, threshold, pass or fail, why; empty when no step declared a gate."""
    rows = []
    for s in run.manifest.get("steps") or []:
        for g in gates_of(s.get("metrics"), s.get("id")):
            unit = f" {g['unit']}" if g.get("unit") else ""
            where = str(s.get("folder") or s.get("id")) + (f" (item {g['item']})" if "item" in g else "")
            figure = "n/a" if g.get("value") is None else f"{g['value']:.4g}{unit}"
            verdict = ("html", "<span class=\"badge st-ok\">pass</span>" if g.get("ok")
                       else "<span class=\"badge st-degraded\">FAIL</span>")
            rows.append([where, g["name"], figure, f"{g['op']} {g['threshold']:.4g}{unit}", verdict, g.get("why", "")])
    if not rows:
        return ""
    return table(["step", "gate", "figure", "threshold", "", "why"], rows)


def log_warnings(run_log: Path) -> list[tuple[str, str]]:
    """(logger, message) of each WARNING line of ``run_log`` not logged by a step (a step's own are kept in its
    result's metrics)."""
    out: list[tuple[str, str]] = []
    try:
        lines = run_log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return out
    for line in lines:
        m = _LOG_WARNING.match(line)
        if m and not m.group(1).startswith("twinkit.step."):
            out.append((m.group(1), m.group(2)))
    return out


def warnings_section(run: RunView) -> str:
    """Every warning of the run: each step's (from its stored result: a cached step's too) and the run log's."""
    rows: list[list] = []
    for s in run.manifest.get("steps") or []:
        for w in warnings_of(s.get("metrics"), s.get("id")):
            where = str(s.get("folder") or s.get("id")) + (f" (item {w['item']})" if "item" in w else "")
            rows.append([where, w["text"]])
    rows += [[name, text] for name, text in log_warnings(run.run_dir / "run.log")]
    if not rows:
        return ""
    return (f"<p>{len(rows)} warning(s); a cached step's come from the run that computed it.</p>"
            + table(["where", "warning"], rows))
