"""Benchmark road_source=scan (roads derived from the scan, no OSM) on finished demo runs; prints a
Markdown table.

    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py [--run outputs/demo] [--run ...]

Needs a finished `twinkit recipe=pointcloud_site site=demo` run (any road_source: only the mesh, the
labels and the truth are read): NN_texture/textured_mesh.ply, NN_backproject/labels.npy (predicted),
NN_gt_labels/gt_labels.npy, 01_site/roads_truth.json. For each label source the scan road source runs
here (through the registry, the engine's code path, default parameters) and is scored as the OSM route
is in apply_alignment: RMSE of the driving-lane centre points (carla.Map, 1 m, outside junctions, 2 m
inside the truth's ends) to the nearest true centre line; lanes on road: share of the driving lanes'
area (outside junctions) on road-labelled surface of the ground-truth labels (and of the labels used).
When the run itself used road_source=scan, its apply_alignment numbers (after align_roads' curb fit)
are printed too.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twinkit.testing import run_plugin

ROOT = Path(__file__).resolve().parents[3]


def one(folder: Path, pattern: str) -> Path | None:
    hits = sorted(folder.glob(pattern))
    return hits[-1] if hits else None


def bench_run(run: Path, tmp: Path, sources: list[str]) -> list[dict]:
    from twinkit.artefacts import read_textured_mesh
    from twinkit_roads.scan import lanes_on_road

    site_json = json.loads((run / "01_site" / "site.json").read_text()) if (run / "01_site" / "site.json").is_file() else {}
    import yaml  # noqa: F401 -- (hydra's dependency) only to fail early when the environment is wrong

    mesh_p = one(run, "*_texture/textured_mesh.ply")
    pred = one(run, "*_backproject/labels.npy")
    gt_p = one(run, "*_gt_labels/gt_labels.npy")
    truth = one(run, "01_site/roads_truth.json")
    if not (mesh_p and gt_p and truth):
        sys.exit(f"{run}: not a finished demo run (textured_mesh.ply, gt_labels.npy, roads_truth.json needed)")
    site = _site(run)
    mesh = read_textured_mesh(mesh_p)
    gt = np.load(gt_p)
    rows = []
    for src in sources:
        inputs = {"in_textured_mesh_ply": mesh_p, "in_roads_truth_json": truth, "in_gt_labels_npy": gt_p}
        if pred is not None:
            inputs["in_labels_npy"] = pred
        t0 = time.perf_counter()
        labels, _, variant = src.partition(":")
        extra = {"use_curbs": False} if variant == "nocurbs" else {}
        out = run_plugin("road_source", "scan", tmp / src.replace(":", "_"), inputs, site=site, labels=labels, **extra)
        dt = time.perf_counter() - t0
        doc = json.loads(out["scan_roads.json"].read_text())
        text = out["opendrive.xodr"].read_text(encoding="utf-8")
        on_gt = lanes_on_road(text, mesh.vertices, mesh.faces, gt)
        rows.append({"labels": src, "roads": len(doc["roads"]),
                     "junctions": sum(n["kind"] == "junction" for n in doc["nodes"]),
                     "driving_lanes": sum(r["lanes"] * (2 if r["two_way"] else 1) for r in doc["roads"]),
                     "sidewalk_lanes": sum((r["sidewalk_left_m"] > 0) + (r["sidewalk_right_m"] > 0) for r in doc["roads"]),
                     "widths": ", ".join(f"{r['carriageway_m']:.2f}" for r in doc["roads"]),
                     "rmse": doc.get("centreline_rmse_m"), "points": doc.get("centreline_points"),
                     "on_gt": on_gt["on_road_share"], "centre_on_gt": on_gt["centre_on_road_share"],
                     "on_used": (doc.get("lanes_on_road") or {}).get("on_road_share"), "s": dt,
                     "png": out["scan_roads.png"]})
    del site_json
    return rows


def _site(run: Path) -> dict:
    """The demo site's georeference (the scan source writes the site frame's PROJ string)."""
    import yaml

    conf = yaml.safe_load((ROOT / "conf" / "site" / "demo.yaml").read_text())
    return {k: conf[k] for k in ("name", "crs", "base_point") if k in conf}


def pipeline_numbers(run: Path) -> dict | None:
    """apply_alignment's numbers when the run used road_source=scan (roads_check.json source scan)."""
    chk = one(run, "*_osm_to_opendrive/roads_check.json")
    rec = one(run, "*_apply_alignment/step.json")
    if not chk or not rec or json.loads(chk.read_text()).get("source") != "scan":
        return None
    m = json.loads(rec.read_text()).get("metrics") or {}
    return {k: m.get(k) for k in ("centreline_rmse_before_m", "centreline_rmse_after_m", "tx_m", "ty_m", "yaw_deg")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", action="append", type=Path, help="a finished demo run folder (default outputs/demo)")
    ap.add_argument("--labels", default="gt,predicted,none,gt:nocurbs,predicted:nocurbs",
                    help="label sources to compare (comma separated; ':nocurbs': the labels alone, use_curbs=false)")
    ap.add_argument("--keep", type=Path, help="keep the outputs (pictures) in this folder")
    a = ap.parse_args()
    runs = a.run or [ROOT / "outputs" / "demo"]
    sources = [s.strip() for s in a.labels.split(",") if s.strip()]
    with tempfile.TemporaryDirectory() as d:
        base = a.keep or Path(d)
        print("| run | labels | roads | junctions | driving lanes | sidewalk lanes | carriageway widths m | "
              "lane centre RMSE m | points | lanes on road (truth labels) | centres on road (truth) | "
              "lanes on road (labels used) | s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for run in runs:
            run = run.resolve()
            for r in bench_run(run, base / run.name, sources):
                name = run.relative_to(ROOT) if run.is_relative_to(ROOT) else run
                used = f"{100 * r['on_used']:.1f} %" if r["on_used"] is not None else "-"
                print(f"| {name} | {r['labels']} | {r['roads']} | {r['junctions']} | {r['driving_lanes']} | "
                      f"{r['sidewalk_lanes']} | {r['widths']} | {r['rmse']:.3f} | {r['points']} | "
                      f"{100 * r['on_gt']:.1f} % | {100 * r['centre_on_gt']:.1f} % | {used} | {r['s']:.1f} |")
            pn = pipeline_numbers(run)
            if pn:
                print(f"\n{run.name}: the run's own apply_alignment (road_source=scan, after align_roads): "
                      f"RMSE {pn['centreline_rmse_before_m']} m before, {pn['centreline_rmse_after_m']} m after the "
                      f"curb fit (t = {pn['tx_m']}, {pn['ty_m']} m, yaw {pn['yaw_deg']} deg)\n")


if __name__ == "__main__":
    main()
