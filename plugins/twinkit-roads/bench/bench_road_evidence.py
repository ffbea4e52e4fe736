"""Benchmark road_evidence against the demo site's ground truth; prints Markdown tables.

    .venv/bin/python plugins/twinkit-roads/bench/bench_road_evidence.py [--run outputs/demo] [--run ...]

Needs finished `recipe=pointcloud_site site=demo` runs (default: seeds 0, 3, 7 in outputs/demo,
outputs/demo_s3/demo, outputs/demo_s7/demo). For each run, road_evidence runs here on the
segmentation's labels (NN_backproject/labels.npy) and the aligned OpenDRIVE, in variants:
- off (the labels as they are), default, without the plateau growth, lanes of the OpenDRIVE
  shifted 10 m east and 10 m north (a wrong OSM);
and is scored against NN_gt_labels/gt_labels.npy with the segmentation plugin's IoU definition
(classes present in the ground truth; unlabelled predictions are misses).

"final": what the simulator gets: lift_movables (twinkit-export, through the registry) on the labels
with and without road_evidence, mapped back onto the textured mesh's vertices by position (lifted
vertices keep their label: they become actors of that class). Road_Sidewalk area: split_classes on
those final labels, face area of the sidewalk class mesh; the true area is split_classes on the
ground-truth labels of the same mesh.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

from twinkit.testing import plugin_from_module, run_plugin, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.align import transform_xodr
from twinkit_roads.evidence import iou

ROOT = Path(__file__).resolve().parents[3]
RUNS = [ROOT / "outputs" / "demo", ROOT / "outputs" / "demo_s3" / "demo", ROOT / "outputs" / "demo_s7" / "demo"]
CLASSES = ("road", "sidewalk", "terrain")


def one(folder: Path, pattern: str) -> Path | None:
    hits = sorted(folder.glob(pattern))
    return hits[-1] if hits else None


def evidence(run: Path, labels: Path, xodr: Path, tmp: Path, **params) -> tuple[np.ndarray, dict]:
    mesh = one(run, "*_texture/textured_mesh.ply")
    out = run_step(plugin_from_module(roads, "step", "road_evidence"), tmp,
                   {"in_aligned_xodr": xodr, "in_textured_mesh_ply": mesh, "in_labels_npy": labels},
                   roads.RoadEvidenceParams(**params))
    return np.load(out["labels.npy"]), json.loads(out["road_evidence.json"].read_text())


def final_labels(run: Path, labels: np.ndarray, tmp: Path) -> tuple[np.ndarray, Path, Path]:
    """lift_movables on ``labels``; its labels mapped back onto the textured mesh's vertices."""
    from scipy.spatial import cKDTree

    from twinkit.mesh import read_obj

    tmp.mkdir(parents=True, exist_ok=True)
    np.save(tmp / "labels.npy", labels)
    obj = one(run, "*_texture/textured_mesh.obj")
    out = run_plugin("step", "lift_movables", tmp / "lift",
                     {"in_labels_npy": tmp / "labels.npy", "in_textured_mesh_obj": obj})
    lifted = read_obj(out["textured_mesh.obj"]).vertices
    lab = np.load(out["labels.npy"])
    orig = read_obj(obj).vertices
    d, i = cKDTree(orig).query(lifted)
    ok = d < 1e-5
    final = labels.copy()
    final[i[ok]] = lab[ok]
    return final, out["labels.npy"], out["textured_mesh.obj"]


def sidewalk_area(labels_npy: Path, obj: Path, tmp: Path) -> float:
    from twinkit.mesh import read_ply
    from twinkit.mesh.core import face_areas

    out = run_plugin("step", "split_classes", tmp, {"in_labels_npy": labels_npy, "in_textured_mesh_obj": obj},
                     max_texture_px=256)
    folder = out["class_meshes"]
    man = json.loads(next(folder.glob("*.json")).read_text())
    for c in man["classes"]:
        if c["cityscapes"] == "sidewalk":
            m = read_ply(folder / c["file"])
            return float(face_areas(m.vertices, m.faces).sum()) if m.faces is not None and len(m.faces) else 0.0
    return 0.0


def bench_run(run: Path, tmp: Path) -> dict:
    site = json.loads((run / "01_site" / "site.json").read_text())
    seed = site.get("seed", "?")
    before_npy = one(run, "*_backproject/labels.npy")
    gt = np.load(one(run, "*_gt_labels/gt_labels.npy"))
    before = np.load(before_npy)
    xodr = one(run, "*_place_signals/aligned.xodr") or one(run, "*_apply_alignment/aligned.xodr")
    rows = {"off": (before, None)}
    rows["default"] = evidence(run, before_npy, xodr, tmp / "default")
    rows["plateau=false"] = evidence(run, before_npy, xodr, tmp / "noplateau", plateau=False)
    rows["sidewalk lanes vote nothing"] = evidence(run, before_npy, xodr, tmp / "nosw", sidewalk_types=[])
    # what-if: car votes on flat ground-level surface may change too (issue 22 item 1's cue, not a default here)
    rows["relabel_classes +car (what-if)"] = evidence(run, before_npy, xodr, tmp / "car", relabel_classes=[0, 1, 9, 13])
    text = xodr.read_text(encoding="utf-8")
    for name, (dx, dy) in (("OSM shifted 10 m east", (10.0, 0.0)), ("OSM shifted 10 m north", (0.0, 10.0))):
        p = tmp / f"shift_{dx:.0f}_{dy:.0f}.xodr"
        p.write_text(transform_xodr(text, 0.0, dx, dy))
        rows[name] = evidence(run, before_npy, p, tmp / p.stem)
    print(f"\n### {run.relative_to(ROOT) if run.is_relative_to(ROOT) else run} (seed {seed})\n")
    print("| variant | road | sidewalk | terrain | mIoU | changed m² | of it wrong vs truth m² | lanes' area m² | "
          "disagree (geometry) m² | disagree (non-ground label) m² | vetoed lanes | driving lanes disagree |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    res = {"seed": seed}
    for name, (lab, doc) in rows.items():
        s = iou(lab, gt)
        ch = lab != before
        wrong = ch & (lab != gt)
        area = _areas(run)
        if doc is None:
            extra = "| – | – | – | – | – | – | – |"
        else:
            lab_dis = doc["per_vote"]["road"]["disagree_label_m2"] + doc["per_vote"]["sidewalk"]["disagree_label_m2"]
            extra = (f"| {area[ch].sum():.1f} | {area[wrong].sum():.1f} | {doc['lane_area_m2']:.0f} | "
                     f"{doc['disagreement_geometry_m2']:.0f} ({100 * doc['disagreement_fraction']:.0f} %) | "
                     f"{lab_dis:.0f} | {len(doc['vetoed_lanes'])} | {100 * doc['network_disagreement']:.0f} %"
                     f"{' (network vetoed)' if doc['network_vetoed'] else ''} |")
        print(f"| {name} | " + " | ".join(f"{s.get(c, 0):.1f}" for c in CLASSES) + f" | {s['miou']:.1f} " + extra)
        res[name] = {**{c: s.get(c, 0) for c in CLASSES}, "miou": s["miou"], "changed_m2": float(area[ch].sum()),
                     "wrong_m2": float(area[wrong].sum())}
    # what the simulator gets: after lift_movables, and the split's sidewalk area
    print("\n| final labels (after lift_movables) | road | sidewalk | terrain | mIoU | Road_Sidewalk m² | "
          "true sidewalk m² | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    np.save(tmp / "gt.npy", gt.astype(np.uint8))
    true_area = sidewalk_area(tmp / "gt.npy", one(run, "*_texture/textured_mesh.obj"), tmp / "split_gt")
    for name in ("off", "default", "relabel_classes +car (what-if)"):
        fl, lnpy, lobj = final_labels(run, rows[name][0], tmp / f"final_{name}")
        s = iou(fl, gt)
        a = sidewalk_area(lnpy, lobj, tmp / f"split_{name}")
        print(f"| road_evidence {name} | " + " | ".join(f"{s.get(c, 0):.1f}" for c in CLASSES)
              + f" | {s['miou']:.1f} | {a:.0f} | {true_area:.0f} | {a / max(true_area, 1e-9):.2f} |")
        res[f"final {name}"] = {**{c: s.get(c, 0) for c in CLASSES}, "miou": s["miou"], "sidewalk_m2": a,
                                "true_sidewalk_m2": true_area}
    return res


_AREA: dict = {}


def _areas(run: Path) -> np.ndarray:
    if run not in _AREA:
        from twinkit.mesh import read_ply

        from twinkit_roads.evidence import vertex_areas

        m = read_ply(one(run, "*_texture/textured_mesh.ply"))
        _AREA[run] = vertex_areas(m.vertices, m.faces)
    return _AREA[run]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="append", type=Path, help="a finished pointcloud_site run folder")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    runs = [r for r in (args.run or RUNS) if (r / "01_site" / "site.json").is_file()]
    if not runs:
        print("no finished demo runs found; run `twinkit recipe=pointcloud_site site=demo` first", file=sys.stderr)
        return 1
    out = []
    with tempfile.TemporaryDirectory() as d:
        for r in runs:
            out.append(bench_run(r, Path(d) / r.parent.name / r.name))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
