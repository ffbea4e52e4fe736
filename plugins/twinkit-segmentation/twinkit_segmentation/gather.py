"""Gather a sweep's per-job segmentation metrics into one table (like the thesis's Tables 5.2-5.4).

    python -m twinkit_segmentation.gather outputs/<site>/sweeps/<time> [--out DIR]

Reads, per job folder (``job<N>/``), the overrides of its run (``manifest.json``) and the
``seg_metrics.json`` of its ``evaluate_segmentation`` step; writes ``sweep_table.md`` (summary with
the change against the first job, then per-class IoU) and ``sweep_table.csv`` into the sweep
folder (or ``--out``), and prints the Markdown.
"""
from __future__ import annotations

import argparse
import csv
import json
import re
from pathlib import Path


def _job_num(p: Path) -> int:
    m = re.search(r"(\d+)$", p.name)
    return int(m.group(1)) if m else 0


def _overrides(job: Path) -> list[str]:
    for cand in sorted(job.rglob("manifest.json")):
        try:
            return list(json.loads(cand.read_text()).get("overrides") or [])
        except (OSError, ValueError):
            continue
    hydra = job / ".hydra" / "overrides.yaml"
    if hydra.is_file():
        return [ln.lstrip("- ").strip() for ln in hydra.read_text().splitlines() if ln.strip()]
    return []


def _step_metrics(job: Path, suffix: str) -> dict:
    for rec in sorted(job.glob(f"[0-9][0-9]_*{suffix}/step.json")):
        try:
            return json.loads(rec.read_text()).get("metrics") or {}
        except (OSError, ValueError):
            pass
    return {}


def collect(sweep: Path) -> list[dict]:
    jobs = sorted([p for p in Path(sweep).iterdir() if p.is_dir() and p.name.startswith("job")], key=_job_num)
    if not jobs and list(Path(sweep).glob("[0-9][0-9]_*")):
        jobs = [Path(sweep)]  # a single run's folder
    rows = []
    for job in jobs:
        files = sorted(job.glob("[0-9][0-9]_*/seg_metrics.json"))
        if not files:
            rows.append({"job": job.name, "overrides": _overrides(job), "missing": True})
            continue
        m = json.loads(files[-1].read_text())
        sc, ub = m["scores"], m.get("upper_bound")
        seg = _step_metrics(job, "oversegment")
        ren = _step_metrics(job, "render_views")
        rows.append({
            "job": job.name, "overrides": _overrides(job), "miou": sc["miou"], "mf1": sc["mf1"],
            "accuracy": sc["accuracy"], "upper_bound_miou": ub["miou"] if ub else None,
            "segments": seg.get("segments"), "views_kept": ren.get("kept"), "views_dropped": ren.get("dropped_empty"),
            "per_class_iou": {k: v["iou"] for k, v in sc["per_class"].items()},
            "per_class_f1": {k: v["f1"] for k, v in sc["per_class"].items()},
        })
    return rows


def _varying(rows: list[dict]) -> list[str]:
    """Override keys that differ between jobs (the swept parameters)."""
    vals: dict[str, set] = {}
    for r in rows:
        for o in r["overrides"]:
            k, _, v = o.partition("=")
            vals.setdefault(k, set()).add(v)
    keys = [k for k, v in vals.items() if len(v) > 1]
    return keys or [k for k in vals if k not in ("recipe", "site")]


def tables(rows: list[dict]) -> tuple[str, list[list]]:
    keys = _varying(rows)
    ok = [r for r in rows if not r.get("missing")]
    base = ok[0] if ok else None

    def setting(r):
        d = dict(o.partition("=")[::2] for o in r["overrides"])
        return ", ".join(f"{k}={d.get(k, '(default)')}" for k in keys) or r["job"]

    f = lambda x: "" if x is None else f"{x:.1f}"  # noqa: E731
    md = ["| job | setting | mIoU | Δ mIoU | mF1 | Δ mF1 | upper bound mIoU | segments | views kept |",
          "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    csv_rows = [["job", "setting", "miou", "delta_miou", "mf1", "delta_mf1", "upper_bound_miou", "segments",
                 "views_kept", "views_dropped"]]
    classes: list[str] = []
    for r in ok:
        for c in r["per_class_iou"]:
            if c not in classes:
                classes.append(c)
    csv_rows[0] += [f"iou_{c}" for c in classes]
    for r in rows:
        if r.get("missing"):
            md.append(f"| {r['job']} | {setting(r)} | (no seg_metrics.json) | | | | | | |")
            continue
        dm, df = r["miou"] - base["miou"], r["mf1"] - base["mf1"]
        md.append(f"| {r['job']} | {setting(r)} | {f(r['miou'])} | {dm:+.1f} | {f(r['mf1'])} | {df:+.1f} | "
                  f"{f(r['upper_bound_miou'])} | {r['segments'] or ''} | {r['views_kept'] or ''} |")
        csv_rows.append([r["job"], setting(r), round(r["miou"], 2), round(dm, 2), round(r["mf1"], 2), round(df, 2),
                         None if r["upper_bound_miou"] is None else round(r["upper_bound_miou"], 2),
                         r["segments"], r["views_kept"], r["views_dropped"]]
                        + [round(r["per_class_iou"].get(c, float("nan")), 2) for c in classes])
    md.append("")
    md.append("Per-class IoU (%):")
    md.append("")
    md.append("| job | " + " | ".join(classes) + " |")
    md.append("|---|" + "---:|" * len(classes))
    for r in ok:
        md.append(f"| {r['job']} | " + " | ".join(f(r["per_class_iou"].get(c)) for c in classes) + " |")
    return "\n".join(md) + "\n", csv_rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sweep", help="a sweep folder (outputs/<site>/sweeps/<time>) or one run's site folder")
    ap.add_argument("--out", help="folder for sweep_table.md / .csv (default: the sweep folder)")
    a = ap.parse_args(argv)
    rows = collect(Path(a.sweep))
    if not rows:
        print(f"no job folders with results under {a.sweep}")
        return 1
    md, rows_csv = tables(rows)
    out = Path(a.out or a.sweep)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep_table.md").write_text(md)
    with open(out / "sweep_table.csv", "w", newline="") as fh:
        csv.writer(fh).writerows(rows_csv)
    print(md)
    print(f"wrote {out / 'sweep_table.md'} and {out / 'sweep_table.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
