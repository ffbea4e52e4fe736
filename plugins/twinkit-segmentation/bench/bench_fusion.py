"""Ablation of the 3D context in the vote (backproject): each geometric cue on / off, per class.

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_fusion.py \
        [--site-dirs outputs/demo,outputs/demo_s3/demo,outputs/demo_s7/demo]

Each site folder is a finished ``recipe=pointcloud_site`` run (textured mesh, segments, the 2D
model's per-vertex votes, ground truth); nothing is rendered or predicted again. For each site
the same fusion as the ``backproject`` step (its defaults) runs with no cue, each cue alone, all
but one, and all; then each shape cue on top of the ground cues, all shape cues but one, with and
without the floor for near-unanimous votes (``keep_share``); prints per-class IoU, car
precision, mIoU, the vertices each cue changed and the fusion's cost. ``--oracle`` fuses the
oracle's votes instead (ground truth through the stored renders' vertex maps). Site folders that
do not exist are skipped (said so).
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
           "terrain", "car", "motorcycle", "bicycle"]
SHORT = {"traffic light": "light", "traffic sign": "sign", "vegetation": "veget.", "motorcycle": "moto.",
         "bicycle": "bike"}


def oracle_votes(site: Path, gt: np.ndarray) -> np.ndarray:
    """The votes ``image_model=oracle`` gives through ``predict_views`` (one vote per view and vertex,
    for the vertex's true class), from the stored renders' vertex maps; nothing is rendered again."""
    import json

    from twinkit.cityscapes import N_CLASSES

    renders = site / "11_render_views/renders"
    kept = json.loads((renders / "index.json").read_text())["kept"]
    seen = np.zeros(len(gt))
    for v in kept:
        vm = np.load(renders / f"{v['id']}_vertex.npz")["vertex"].reshape(-1)
        seen[np.unique(vm[vm >= 0])] += 1
    votes = np.zeros((len(gt), N_CLASSES))
    ok = gt < N_CLASSES
    votes[np.nonzero(ok)[0], gt[ok].astype(np.int64)] = seen[ok]
    return votes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--site-dirs", default="outputs/demo,outputs/demo_s3/demo,outputs/demo_s7/demo")
    ap.add_argument("--oracle", action="store_true", help="fuse the oracle's votes (ground truth through the "
                    "stored renders) instead of the 2D model's")
    ap.add_argument("--rows", default="all", choices=["all", "shape", "floor", "short"],
                    help="all: every ablation; shape: the shape cues; floor: floor variants with every cue; "
                    "short: plain and default")
    a = ap.parse_args(argv)
    os.environ.setdefault("TWINKIT_PLUGINS", "builtins,segmentation")
    from twinkit.mesh import edges as mesh_edges, read_mesh
    from twinkit_segmentation.context import CUES, SHAPE_CUES, fuse_with_context, near_unanimous, potts_smooth
    from twinkit_segmentation.metrics import (_weighted_votes, blend_distribution, decide_distribution, propagate,
                                              scores)
    from twinkit_segmentation.segmesh import unit_normals
    from twinkit_segmentation.backproject_parts import BackprojectParams, context_options

    bp = BackprojectParams()
    opt = context_options(bp)
    b = bp.smooth_beta
    default = tuple(bp.context_cues)
    old = tuple(c for c in CUES if c not in SHAPE_CUES)
    # (name, cues, beta, variant, floor (share, votes) or None)
    k = (bp.keep_share, bp.keep_votes)
    fk = f"floor {k[0]:g} of >= {k[1]:g} votes"
    old_rows = [("plain blended vote", (), 0.0, None, None),
                (f"plain + Potts smoothing (beta {b:g})", (), b, None, None)] + \
        [(f"{c} only", (c,), 0.0, None, None) for c in old] + \
        [(f"all but {c}", tuple(x for x in old if x != c), 0.0, None, None) for c in old] + \
        [("ground, raised, high, curb", old, 0.0, None, None),
         ("ground, raised, high, curb + Potts, curb face off", old, b, "curb_face", None),
         ("ground, raised, high, curb + Potts, band default off", old, b, "band_default", None)]
    shape_rows = [("ground, raised, high, curb + Potts (no floor)", old, b, None, None),
                  (f"ground, raised, high, curb + Potts, {fk}", old, b, None, k)] + \
        [(f"+ {c}", old + (c,), b, None, k) for c in SHAPE_CUES] + \
        [(f"+ all shape cues but {c}", tuple(x for x in CUES if x != c), b, None, k) for c in SHAPE_CUES] + \
        [("+ all shape cues", CUES, b, None, k)]
    floor_rows = [("default cues + Potts, no floor", default, b, None, None)] + \
        [(f"default cues + Potts, floor {s_:g} of >= {n_:g} votes", default, b, None, (s_, n_))
         for s_, n_ in ((0.9, 0), (0.99, 0), (0.99, 8), (0.99, 16), (1.0, 32))]
    last = [(f"**default ({', '.join(default)} + Potts, {fk})**", default, b, None, k)]
    configs = {"all": old_rows + shape_rows + last, "shape": shape_rows + last, "floor": floor_rows,
               "short": [old_rows[0]] + last}[a.rows]
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
        if a.oracle:
            votes = oracle_votes(site, gt)
        normals = unit_normals(mesh)
        edges = mesh_edges(mesh.faces, len(mesh.vertices))
        t0 = time.perf_counter()
        p, _ = blend_distribution(seg, votes, bp.segment_weight, bp.ignore_classes, None)
        t_blend = time.perf_counter() - t0
        wv = _weighted_votes(votes, bp.ignore_classes, None)
        print(f"\n## {site} ({len(mesh.vertices):,} vertices{', oracle votes' if a.oracle else ''})\n")
        head = "| cues | " + " | ".join(SHORT.get(c, c) for c in CLASSES) + " | car prec. | **mIoU** | changed | s |"
        print(head)
        print("|---" * (len(CLASSES) + 5) + "|")
        for name, cues, beta, variant, floor in configs:
            t1 = time.perf_counter()
            o = replace(opt, **{variant: False}) if variant else opt
            if cues:
                sure = near_unanimous(wv, None, *floor) if floor else None
                lab, _, met = fuse_with_context(p, mesh.vertices, normals, edges, o, cues,
                                                min_retained=bp.min_retained, smooth_beta=beta,
                                                smooth_iters=bp.smooth_iters, keep=sure)
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
            print("\nvertices per cue (last row): " + ", ".join(
                f"{c}: {met[c + '_vertices']:,} flagged, {met[c + '_changed']:,} changed" for c in CUES)
                + f"; explained away {met['explained_away']:,}; curb step cells {met['step_cells']:,}; "
                f"objects {met['objects']:,}; near-unanimous vertices the floor shielded from a cue "
                f"{met['kept_unanimous']:,}")
    if not ran:
        print("no site folder with votes and ground truth; nothing measured")
    return 0


if __name__ == "__main__":
    sys.exit(main())
