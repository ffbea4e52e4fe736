"""Ablation of the 3D context in the vote (backproject): each geometric cue on / off, per class.

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_fusion.py \
        [--site-dirs outputs/demo,outputs/demo_s3/demo,outputs/demo_s7/demo]

Each site folder is a finished ``recipe=pointcloud_site`` run (textured mesh, segments, the 2D
model's per-vertex votes, ground truth); nothing is rendered or predicted again. For each site
the same fusion as the ``backproject`` step (its defaults) runs with no cue, each cue alone, all
but one, and all; prints per-class IoU, car precision, mIoU, the vertices each cue changed and
the fusion's cost. Site folders that do not exist are skipped (said so).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

CLASSES = ["road", "sidewalk", "building", "wall", "fence", "pole", "traffic light", "traffic sign", "vegetation",
           "terrain", "car", "motorcycle"]
SHORT = {"traffic light": "light", "traffic sign": "sign", "vegetation": "veget.", "motorcycle": "moto."}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--site-dirs", default="outputs/demo,outputs/demo_s3/demo,outputs/demo_s7/demo")
    a = ap.parse_args(argv)
    os.environ.setdefault("TWINKIT_PLUGINS", "builtins,segmentation")
    from twinkit.mesh import edges as mesh_edges, read_mesh
    from twinkit_segmentation.context import CUES, ContextOptions, fuse_with_context, potts_smooth
    from twinkit_segmentation.metrics import blend_distribution, decide_distribution, propagate, scores
    from twinkit_segmentation.segmesh import unit_normals
    from twinkit_segmentation.steps import BackprojectParams

    bp = BackprojectParams()
    opt = ContextOptions(ground_window_m=bp.ground_window_m, max_curb_m=bp.max_curb_m, min_object_m=bp.min_object_m,
                         max_vehicle_m=bp.max_vehicle_m, min_curb_m=bp.min_curb_m, band_width_m=bp.band_width_m,
                         ground_factor=bp.context_factor, raised_factor=bp.context_factor,
                         high_factor=bp.context_factor, curb_factor=bp.curb_factor, curb_face=bp.curb_face,
                         band_default=bp.band_default)
    b = bp.smooth_beta
    configs = [("plain blended vote", (), 0.0), (f"plain + Potts smoothing (beta {b:g})", (), b)] + \
              [(f"{c} only", (c,), 0.0) for c in CUES] + \
              [(f"all but {c}", tuple(x for x in CUES if x != c), 0.0) for c in CUES] + [("all cues", CUES, 0.0)] + \
              [("all cues + Potts, curb face off", CUES, -b), ("all cues + Potts, band default off", CUES, -2 * b)] + \
              [("**all cues + Potts smoothing (default)**", CUES, b)]
    ran = 0
    for d in a.site_dirs.split(","):
        site = Path(d)
        need = [site / "06_texture/textured_mesh.ply", site / "09_oversegment/segments.npy",
                site / "12_predict_views/vertex_votes.npy", site / "08_gt_labels/gt_labels.npy"]
        if not all(p.exists() for p in need):
            print(f"\n{site}: skipped (run `twinkit recipe=pointcloud_site site=demo` there first)\n")
            continue
        ran += 1
        mesh = read_mesh(need[0])
        seg, votes, gt = np.load(need[1]), np.load(need[2]).astype(np.float64), np.load(need[3])
        normals = unit_normals(mesh)
        edges = mesh_edges(mesh.faces, len(mesh.vertices))
        t0 = time.perf_counter()
        p, _ = blend_distribution(seg, votes, bp.segment_weight, bp.ignore_classes, None)
        t_blend = time.perf_counter() - t0
        print(f"\n## {site} ({len(mesh.vertices):,} vertices)\n")
        head = "| cues | " + " | ".join(SHORT.get(c, c) for c in CLASSES) + " | car prec. | **mIoU** | changed | s |"
        print(head)
        print("|---" * (len(CLASSES) + 5) + "|")
        for name, cues, beta in configs:
            t1 = time.perf_counter()
            o = opt
            if beta < 0:  # the curb-face and band-default ablations
                o = replace(opt, curb_face=False) if beta == -b else replace(opt, band_default=False)
                beta = b
            if cues:
                lab, _, met = fuse_with_context(p, mesh.vertices, normals, edges, o, cues,
                                                min_retained=bp.min_retained, smooth_beta=beta,
                                                smooth_iters=bp.smooth_iters)
            else:
                lab, _ = decide_distribution(p)
                base = lab.copy()
                lab, _ = potts_smooth(lab, p, edges, beta, bp.smooth_iters)
                met = {"changed": int((lab != base).sum())}
            secs = time.perf_counter() - t1 + t_blend
            if (lab == 255).any():
                lab = propagate(lab, edges)
            r = scores(lab, gt)
            pc = r["per_class"]
            cells = " | ".join(f"{pc[c]['iou']:.1f}" if c in pc else "-" for c in CLASSES)
            print(f"| {name} | {cells} | {pc['car']['precision']:.1f} | **{r['miou']:.1f}** | {met['changed']:,} | "
                  f"{secs:.2f} |")
        if met.get("cues"):
            print("\nvertices per cue (all cues): " + ", ".join(
                f"{c}: {met[c + '_vertices']:,} flagged, {met[c + '_changed']:,} changed" for c in CUES)
                + f"; explained away {met['explained_away']:,}; curb step cells {met['step_cells']:,}")
    if not ran:
        print("no site folder with votes and ground truth; nothing measured")
    return 0


if __name__ == "__main__":
    sys.exit(main())
