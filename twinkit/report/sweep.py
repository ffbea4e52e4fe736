"""The summary page of a multirun sweep (swept overrides against metrics, with small SVG plots), and the
Hydra callback that writes it when a multirun ends."""
from __future__ import annotations

import json
import logging
import math
import re
import shutil
from pathlib import Path
from typing import Any

from twinkit.report.html import esc, link
from twinkit.report.page import ASSETS, CSS_FILE, Page, fmt, render_page, table
from twinkit.report.run import REPORT_DIR, flatten, read_json, rel

log = logging.getLogger("twinkit.report")


def _parse_override(o: str) -> tuple[str, str] | None:
    if "=" not in o:
        return None
    k, v = o.split("=", 1)
    return k.lstrip("+~"), v


def _num(v: Any) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(str(v))
    except ValueError:
        return None


_SKIP_METRIC = re.compile(r"(peak|rss|delta_peak|seconds|timings|substeps|shift_m)", re.I)


def sweep_rows(sweep_dir: Path) -> tuple[list[str], list[str], list[dict]]:
    """(swept keys, metric names, one row per job: {'job', 'status', 'duration_s', 'params', 'metrics'})."""
    rows: list[dict[str, Any]] = []
    for mf in sorted(Path(sweep_dir).glob("job*/manifest.json"), key=lambda p: _job_num(p.parent.name)):
        m = read_json(mf, limit=50_000_000)
        if not isinstance(m, dict):
            continue
        params = dict(x for x in (_parse_override(o) for o in m.get("overrides") or []) if x)
        metrics: dict[str, Any] = {}
        for s in m.get("steps") or []:
            for k, v in flatten(s.get("metrics") or {}).items():
                if _SKIP_METRIC.search(k) or _num(v) is None:
                    continue
                metrics[f"{s.get('id')}.{k}"] = v
        rows.append({"job": mf.parent.name, "status": m.get("status"), "duration_s": m.get("duration_s"),
                     "params": params, "metrics": metrics, "dir": mf.parent})
    keys: list[str] = []
    for r in rows:
        for k in r["params"]:
            if k not in keys:
                keys.append(k)
    swept = [k for k in keys if len({r["params"].get(k) for r in rows}) > 1] or keys
    names: list[str] = []
    for r in rows:
        for k in r["metrics"]:
            if k not in names:
                names.append(k)
    varying = [k for k in names if len({json.dumps(r["metrics"].get(k)) for r in rows}) > 1]
    return swept, varying + [k for k in names if k not in varying], rows


def _job_num(name: str) -> int:
    m = re.search(r"\d+", name)
    return int(m.group()) if m else 0


def _nice_ticks(lo: float, hi: float, n: int = 4) -> list[float]:
    """Round tick values (1, 2, 5 x 10^k steps) covering [lo, hi]."""
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    start = math.floor(lo / step) * step
    ticks = []
    v = start
    while v < hi + step * 0.999:
        ticks.append(round(v, 12))
        v += step
    return ticks


def _svg_plot(xs: list[float], ys: list[float], xlabel: str, ylabel: str, w: int = 360, h: int = 240,
              labels: list[str] | None = None) -> str:
    """A small line plot with axes and ticks, as inline SVG."""
    ml, mr, mt, mb = 58, 12, 22, 40
    pw, ph = w - ml - mr, h - mt - mb
    x0, x1 = min(xs), max(xs)
    y0, y1 = min(ys), max(ys)
    if x1 == x0:
        x0, x1 = x0 - 1, x1 + 1
    if y1 == y0:
        y0, y1 = y0 - (abs(y0) * 0.1 or 1), y1 + (abs(y1) * 0.1 or 1)
    ticks = _nice_ticks(y0, y1)
    y0, y1 = min(y0, ticks[0]), max(y1, ticks[-1])

    def X(v):
        return ml + (v - x0) / (x1 - x0) * pw

    def Y(v):
        return mt + ph - (v - y0) / (y1 - y0) * ph

    out = [f"<svg class=\"plot\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" xmlns=\"http://www.w3.org/2000/svg\">",
           f"<text x=\"{ml}\" y=\"14\" class=\"t\">{esc(ylabel)}</text>",
           f"<rect x=\"{ml}\" y=\"{mt}\" width=\"{pw}\" height=\"{ph}\" class=\"frame\"/>"]
    for yv in ticks:
        out.append(f"<line x1=\"{ml}\" x2=\"{ml + pw}\" y1=\"{Y(yv):.1f}\" y2=\"{Y(yv):.1f}\" class=\"grid\"/>"
                   f"<text x=\"{ml - 4}\" y=\"{Y(yv) + 4:.1f}\" class=\"tick\" text-anchor=\"end\">{esc(fmt(yv))}</text>")
    for xv in sorted(set(xs)):
        out.append(f"<text x=\"{X(xv):.1f}\" y=\"{mt + ph + 14}\" class=\"tick\" text-anchor=\"middle\">{esc(fmt(xv))}</text>")
    out.append(f"<text x=\"{ml + pw / 2}\" y=\"{h - 6}\" class=\"t\" text-anchor=\"middle\">{esc(xlabel)}</text>")
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    out.append("<polyline class=\"line\" points=\"" + " ".join(f"{X(xs[i]):.1f},{Y(ys[i]):.1f}" for i in order) + "\"/>")
    for i in order:
        tip = f"{labels[i]}: " if labels else ""
        out.append(f"<circle cx=\"{X(xs[i]):.1f}\" cy=\"{Y(ys[i]):.1f}\" r=\"3.5\" class=\"pt\">"
                   f"<title>{esc(tip)}{esc(xlabel)}={esc(fmt(xs[i]))}, {esc(ylabel)}={esc(fmt(ys[i]))}</title></circle>")
    out.append("</svg>")
    return "".join(out)


#: metrics plotted first when a sweep varies them (substrings, in order of interest).
PRIMARY_METRICS = ("miou", "mean_iou", "iou", "f1", "residual", "chamfer", "cloud_to_mesh_mean", "mean")
MAX_PLOTS = 8


def write_sweep_summary(sweep_dir: Path) -> Path:
    """``<sweep_dir>/report/sweep.html``: the sweep table (swept overrides vs. metrics) and plots."""
    sweep_dir = Path(sweep_dir)
    swept, names, rows = sweep_rows(sweep_dir)
    out = sweep_dir / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ASSETS / CSS_FILE, out / CSS_FILE)
    page = Page(out)
    varying = [k for k in names if len({json.dumps(r["metrics"].get(k)) for r in rows}) > 1]
    shown = varying[:30] if varying else names[:12]
    head = ["job", "status"] + swept + ["time (s)"] + shown
    trs = []
    for r in rows:
        rep = r["dir"] / REPORT_DIR / "report.html"
        job = ("html", link(rel(rep, out), r["job"])) if rep.is_file() else r["job"]
        trs.append([job, r["status"] or "?"] + [_num(r["params"].get(k)) if _num(r["params"].get(k)) is not None
                                                 else r["params"].get(k, "") for k in swept]
                   + [r["duration_s"] or 0] + [r["metrics"].get(k, "") for k in shown])
    page.add("table", "Sweep", "<div class=\"scroll\">" + table(head, trs, "sweep") + "</div>" + (
        f"<p class=\"dim\">{len(names) - len(shown)} metric(s) that did not change are left out; "
        "each job's manifest has them all.</p>" if len(names) > len(shown) else ""))
    plots = []
    numeric = [k for k in swept if all(_num(r["params"].get(k)) is not None for r in rows)]

    def interest(name: str) -> tuple:
        low = name.lower()
        return (next((i for i, p in enumerate(PRIMARY_METRICS) if p in low), len(PRIMARY_METRICS)), name)

    for k in numeric:
        same = [m for m in varying if all(_num(r["metrics"].get(m)) == _num(r["params"][k]) for r in rows)]
        for metric in sorted((m for m in varying if m not in same), key=interest)[:MAX_PLOTS]:
            pts = [(_num(r["params"][k]), _num(r["metrics"].get(metric)), r["job"]) for r in rows]
            xy = [(x, y, job) for x, y, job in pts if x is not None and y is not None]  # x: numeric, always set
            if len(xy) >= 2:
                plots.append(_svg_plot([p[0] for p in xy], [p[1] for p in xy], k, metric,
                                       labels=[p[2] for p in xy]))
    if plots:
        page.add("plots", "Metrics against the swept parameter", "<div class=\"plots\">" + "".join(plots) + "</div>")
    elif rows and not numeric:
        page.notes.append("No swept parameter is numeric, so there is no plot; the table has every job.")
    title = f"twinkit sweep: {sweep_dir.name}"
    (out / "sweep.html").write_text(render_page(title, page, f"{len(rows)} job(s) in {esc(sweep_dir)}"),
                                    encoding="utf-8")
    return out / "sweep.html"


try:  # a Hydra callback: conf/config.yaml -> hydra.callbacks.report._target_: twinkit.report.SweepSummaryCallback
    from hydra.experimental.callback import Callback as _HydraCallback
except Exception:  # pragma: no cover - Hydra is a dependency; this keeps the module importable without it
    _HydraCallback = object  # type: ignore[misc, assignment]


class SweepSummaryCallback(_HydraCallback):
    """Writes the sweep summary when a multirun ends (never fails the sweep)."""

    _done: set = set()
    last_sweep: Path | None = None
    started: Path | None = None  # the sweep running now: its summary is written when a job failed too

    def on_multirun_start(self, config, **kwargs) -> None:
        SweepSummaryCallback.started = Path(str(config.hydra.sweep.dir)).resolve()

    def on_multirun_end(self, config, **kwargs) -> None:
        self.write(Path(str(config.hydra.sweep.dir)).resolve())

    @staticmethod
    def write(sweep: Path) -> None:
        """The summary of ``sweep``, written and said once."""
        SweepSummaryCallback.last_sweep = sweep  # the CLI reads its jobs' statuses for the exit status
        if sweep in SweepSummaryCallback._done:  # Hydra may call a callback twice; write and say it once
            return
        SweepSummaryCallback._done.add(sweep)
        try:
            path = write_sweep_summary(sweep)
            print(f"twinkit: sweep summary file://{path.resolve()}")
        except Exception as exc:
            log.warning("twinkit: no sweep summary (%s: %s)", type(exc).__name__, exc)
