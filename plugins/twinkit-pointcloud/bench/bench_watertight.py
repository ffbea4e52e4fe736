"""Watertight ground on a finished run: open border on the ground classes inside the site, and the drop test.

For each run folder (a `twinkit recipe=pointcloud_site` output with ground truth, e.g. outputs/demo):

- the open border (edges with one face) of the textured mesh (``NN_texture``) and of the static mesh
  CARLA gets (``NN_lift_movables``), on road, sidewalk and terrain as judged by the ground-truth labels
  (``NN_gt_labels``, carried to the static mesh by nearest vertex), inside the scanned site
  (:class:`twinkit.surface.watertight.Footprint` of the cloud) and on its edge; per m² of that class;
  the inside border's chains by length;
- the drop test of the run (``NN_drop_test/drop_test.json``), when the recipe had it;
- the reconstruction's accuracy (``NN_evaluate``) and the segmentation's mIoU (``NN_evaluate_segmentation``).

    python plugins/twinkit-pointcloud/bench/bench_watertight.py outputs/demo outputs/demo_s3/demo ...

Prints a markdown table per run.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

CLASSES = {"road": (0,), "sidewalk": (1,), "road+sidewalk": (0, 1), "terrain": (9,)}


def _step(run: Path, name: str) -> Path | None:
    hits = sorted(run.glob(f"[0-9][0-9]_{name}"))
    return hits[-1] if hits else None


def _mesh(path: Path):
    from twinkit.mesh import read_obj, read_ply

    return read_obj(path) if path.suffix == ".obj" else read_ply(path)


def border_table(run: Path, mesh_path: Path, gt_vertices: np.ndarray, gt: np.ndarray, fp) -> dict:
    from scipy.spatial import cKDTree

    from twinkit.surface.watertight import ground_border

    m = _mesh(mesh_path)
    v, f = m.vertices, m.faces
    if len(v) != len(gt) or not np.allclose(v[: min(10, len(v))], gt_vertices[: min(10, len(v))]):
        _, near = cKDTree(gt_vertices).query(v)
        lab = gt[near]
    else:
        lab = gt
    out = {}
    for name, cls in CLASSES.items():
        r = ground_border(v, f, fp, np.isin(lab, cls))
        r.pop("_edges")
        out[name] = r
    return out


def main(argv: list[str]) -> int:
    from twinkit.mesh import read_ply
    from twinkit.surface.watertight import Footprint

    runs = [Path(a) for a in argv] or [Path("outputs/demo")]
    for run in runs:
        tex, gtd, lift = _step(run, "texture"), _step(run, "gt_labels"), _step(run, "lift_movables")
        pts = _step(run, "read_cloud")
        if not (tex and gtd and pts):
            print(f"{run}: needs the texture, gt_labels and read_cloud steps' outputs; skipped")
            continue
        tm = read_ply(tex / "textured_mesh.ply")
        gt = np.load(gtd / "gt_labels.npy")
        cloud = read_ply(pts / "points.ply")
        fp = Footprint.from_points(cloud.vertices, fill_limit_m=8.0)
        meshes = [("textured mesh", tex / "textured_mesh.ply")]
        if lift and (lift / "textured_mesh.obj").exists():
            meshes.append(("static mesh (after lift_movables)", lift / "textured_mesh.obj"))
        print(f"\n### {run}\n")
        print("| mesh | class | open border inside the site (m) | ground inside (m²) | m per m² | chains <0.5 / 0.5-2 / "
              "2-10 / >10 m | on the site's edge (m) |")
        print("|---|---|---:|---:|---:|---|---:|")
        for label, path in meshes:
            t = border_table(run, path, tm.vertices, gt, fp)
            for name, r in t.items():
                c = r["inside_chains_by_length"]
                print(f"| {label} | {name} | {r['inside_m']:.1f} | {r['ground_area_m2']:.0f} | "
                      f"{r['inside_m_per_m2']:.4f} | {c['under_0.5m']} / {c['0.5_2m']} / {c['2_10m']} / {c['over_10m']} | "
                      f"{r['site_edge_m']:.1f} |")
        dt = _step(run, "drop_test")
        if dt and (dt / "drop_test.json").exists():
            d = json.loads((dt / "drop_test.json").read_text())
            print("\n| drop test | rays | hit % (target) | fall through % | misses at another height | of them on a kerb "
                  "line | hit % off the kerb line | degrades the run |")
            print("|---|---:|---:|---:|---:|---:|---:|---|")
            for k, r in d["lanes"].items():
                print(f"| {k} | {r['rays']} | {r['hit_pct']} ({r['target_pct']}) | {r.get('fall_through_pct')} | "
                      f"{r['rays'] - r['hits'] - r.get('fall_through', 0)} | {r.get('kerb_line', '-')} | "
                      f"{r.get('hit_pct_off_kerb_line', '-')} | {'no' if r.get('ground_ok', r['ok']) else 'yes'} |")
        ev, es = _step(run, "evaluate"), _step(run, "evaluate_segmentation")
        extra = []
        if ev and (ev / "recon_metrics.json").exists():
            rm = json.loads((ev / "recon_metrics.json").read_text())
            g = rm.get("gt") or {}
            if g:
                extra.append(f"mesh -> truth mean {g['accuracy_mesh_to_gt_m']['mean']:.4f} m, median "
                             f"{g['accuracy_mesh_to_gt_m']['median']:.4f} m; truth covered within 5 cm "
                             f"{100 * g['gt_covered_within_5cm']:.1f} %")
        if es and (es / "seg_metrics.json").exists():
            sm = json.loads((es / "seg_metrics.json").read_text())
            miou = (sm.get("scores") or {}).get("miou")
            if miou is not None:
                extra.append(f"segmentation mIoU {miou:.1f}")
        if extra:
            print("\n" + "; ".join(extra))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
