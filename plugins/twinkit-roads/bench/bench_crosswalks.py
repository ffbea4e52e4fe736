"""Benchmark place_crosswalks against the demo site's painted zebras; prints a Markdown table.

    python plugins/twinkit-roads/bench/bench_crosswalks.py --run /work/runs/base45/demo [--run ...]

Needs finished `recipe=pointcloud_site site=demo` runs (any seed). For each run, the crosswalks
carla.Map (0.9.16, offline, ``get_crosswalks``) reports:
- "before": in place_signals' aligned.xodr (what the package got until now);
- "after": place_crosswalks run here with default settings on the run's artefacts (OSM crossings moved
  by the run's alignment.json, zebras in the textured mesh on the segmentation's road labels), and the
  same with OSM only and with the scan only.
Truth: the zebras of 01_site/roads_truth.json (``crossings``, the painted areas). The position error of
a zebra is the horizontal distance from its centre to the nearest reported crosswalk's centre; a zebra
counts as found when that is at most 1 m. The step's own runs (NN_place_crosswalks) are not read.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from twinkit.street.lanes import LaneMap
from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.crosswalks import nearest_errors


def _one(ws: Path, pattern: str) -> Path | None:
    hits = sorted(ws.glob(pattern))
    return hits[-1] if hits else None


def _run_step(ws: Path, params: dict) -> list[np.ndarray]:
    site = json.loads((ws / "01_site" / "site.json").read_text())
    inputs = {"in_aligned_xodr": _one(ws, "*_place_signals/aligned.xodr"),
              "in_textured_mesh_ply": _one(ws, "*_texture/textured_mesh.ply"),
              "in_labels_npy": _one(ws, "*_backproject/labels.npy"),
              "in_osm_osm": _one(ws, "*_fetch_roads/osm.osm"),
              "in_alignment_json": _one(ws, "*_align_roads/alignment.json")}
    with tempfile.TemporaryDirectory() as tmp:
        out = run_step(plugin_from_module(roads, "step", "place_crosswalks"), Path(tmp) / "run",
                       {k: v for k, v in inputs.items() if v is not None},
                       params=roads.CrosswalkParams(**params), site=site)
        return LaneMap(out["aligned.xodr"].read_text(), "after").crosswalks()


def bench_run(ws: Path) -> dict:
    truth = [np.asarray(c["polygon"], float)
             for c in json.loads((ws / "01_site" / "roads_truth.json").read_text())["crossings"]]
    before = LaneMap(_one(ws, "*_place_signals/aligned.xodr").read_text(), "before").crosswalks()
    row = {"run": str(ws), "zebras": len(truth), "before": len(before)}
    for name, params in (("after", {}), ("osm_only", {"from_scan": False}), ("scan_only", {"from_osm": False})):
        got = _run_step(ws, params)
        err = nearest_errors(got, truth)
        row[name] = len(got)
        row[f"{name}_found"] = sum(1 for e in err if e is not None and e <= 1.0)
        row[f"{name}_err_m"] = [None if e is None else round(e, 3) for e in err]
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="append", type=Path, required=True, help="a finished demo run's site folder")
    ap.add_argument("--json", type=Path, help="also write the rows here")
    a = ap.parse_args(argv)
    rows = [bench_run(ws) for ws in a.run]
    print("| run | zebras | CARLA crosswalks before | after (found <= 1 m) | position error per zebra, m | "
          "OSM only (found) | scan only (found) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        errs = ", ".join("-" if e is None else f"{e:.2f}" for e in r["after_err_m"])
        print(f"| {r['run']} | {r['zebras']} | {r['before']} | {r['after']} ({r['after_found']}) | {errs} | "
              f"{r['osm_only']} ({r['osm_only_found']}) | {r['scan_only']} ({r['scan_only_found']}) |")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
