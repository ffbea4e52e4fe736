"""Cleaner views (issue 22 item 3): the 2D model's input scale, flip and multi-scale test-time
augmentation, and the hole fill, measured through the whole vote (predict -> backproject -> score).

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_views.py --run outputs/demo [--every 2]
        [--variants base,flip,s1536,ms] [--renders <other renders dir>] [--label fill]

Reads a finished run (NN_render_views/renders, NN_oversegment, NN_gt_labels, NN_texture), predicts
every ``--every``-th kept view once per variant with EfficientViT-B0 (CPU), fuses the votes with the
backproject step's defaults and prints mIoU / per-class IoU and the model time per view.
Variants: base (long side 1024, the default), flip (+ mirror image), s1536 / s2048 (long side),
ms (logits averaged over long sides 768, 1024 and 1536).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def _step(run: Path, name: str) -> Path:
    hits = sorted(run.glob(f"[0-9][0-9]_{name}"))
    if not hits:
        sys.exit(f"{run}: no finished {name} step; run `twinkit recipe=pointcloud_site site=demo` first")
    return hits[-1]


VARIANTS = {"base": ([1024], False), "flip": ([1024], True), "s1536": ([1536], False), "s2048": ([2048], False),
            "ms": ([768, 1024, 1536], False), "msflip": ([768, 1024, 1536], True)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, default=Path("outputs/demo"))
    ap.add_argument("--renders", type=Path, default=None, help="renders/ folder (default: the run's)")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--variants", default="base,flip,ms")
    ap.add_argument("--label", default="", help="name of the renders in the table")
    ap.add_argument("--out", type=Path, default=None, help="append the markdown table to this file")
    a = ap.parse_args(argv)

    from PIL import Image

    from twinkit.cityscapes import IGNORE, N_CLASSES
    from twinkit.mesh import edges as mesh_edges, read_mesh
    from twinkit.plugins import build_component
    from twinkit_segmentation.context import ContextOptions, fuse_with_context
    from twinkit_segmentation.metrics import blend_distribution, decide_distribution, propagate, scores
    from twinkit_segmentation.segmesh import unit_normals
    from twinkit_segmentation.steps import BackprojectParams

    renders = a.renders or _step(a.run, "render_views") / "renders"
    index = json.loads((renders / "index.json").read_text())
    kept = index["kept"][:: max(1, a.every)]
    n = int(index["n_vertices"])
    mesh = read_mesh(_step(a.run, "texture") / "textured_mesh.ply")
    seg = np.load(_step(a.run, "oversegment") / "segments.npy")
    gt = np.load(_step(a.run, "gt_labels") / "gt_labels.npy")
    nrm = unit_normals(mesh)
    e = mesh_edges(mesh.faces, len(mesh.vertices))
    bp = BackprojectParams()
    opt = ContextOptions(ground_window_m=bp.ground_window_m, max_curb_m=bp.max_curb_m, min_object_m=bp.min_object_m,
                         max_vehicle_m=bp.max_vehicle_m, min_curb_m=bp.min_curb_m, band_width_m=bp.band_width_m,
                         ground_factor=bp.context_factor, raised_factor=bp.context_factor,
                         high_factor=bp.context_factor, curb_factor=bp.curb_factor, curb_face=bp.curb_face,
                         band_default=bp.band_default)
    os.environ.setdefault("TWINKIT_PLUGINS", "builtins,efficientvit,segmentation")
    models: dict = {}  # (long side, flip) -> the image_model component, built by name through the registry
    rows = []
    for name in a.variants.split(","):
        sides, flip = VARIANTS[name]
        votes = np.zeros((n, N_CLASSES))
        t_model = 0.0
        for v in kept:
            img = np.asarray(Image.open(renders / f"{v['id']}.png").convert("RGB"))
            vm = np.load(renders / f"{v['id']}_vertex.npz")["vertex"].reshape(-1)
            for side in sides:  # built once, outside the timing
                if (side, flip) not in models:
                    models[(side, flip)] = build_component("image_model", None, {"image_model": {
                        "plugin": "efficientvit_b0", "input_long_side_px": side, "flip_tta": flip}})
            t1 = time.perf_counter()
            acc = 0.0
            for side in sides:
                acc = acc + models[(side, flip)].predict_proba(img[None])[0].astype(np.float32)
            lab = acc.argmax(0).reshape(-1)
            t_model += time.perf_counter() - t1
            hit = vm >= 0
            vv = np.bincount(vm[hit].astype(np.int64) * N_CLASSES + lab[hit], minlength=n * N_CLASSES)
            vv = vv.reshape(n, N_CLASSES).astype(np.float64)
            tot = vv.sum(axis=1, keepdims=True)
            votes += np.divide(vv, tot, out=np.zeros_like(vv), where=tot > 0)
        p, s_total = blend_distribution(seg, votes, bp.segment_weight, bp.ignore_classes, None)
        labels, _ = decide_distribution(p, s_total < bp.min_votes)
        keep = labels == IGNORE
        labels, _, _ = fuse_with_context(p, mesh.vertices, nrm, e, opt, bp.context_cues, min_retained=bp.min_retained,
                                         smooth_beta=bp.smooth_beta, smooth_iters=bp.smooth_iters)
        labels[keep] = IGNORE
        labels = propagate(labels, e)
        res = scores(labels, gt)
        rows.append((name, t_model / len(kept), res))
        print(f"{name}: mIoU {res['miou']:.1f}  {t_model / len(kept):.2f} s/view", flush=True)
    classes = list(rows[0][2]["per_class"])
    head = "| renders | variant | s / view | mIoU | " + " | ".join(classes) + " |"
    lines = [head, "|" + "---|" * 3 + "---:|" * (1 + len(classes))]
    for name, spv, res in rows:
        lines.append(f"| {a.label or renders.parent.name} | {name} | {spv:.2f} | {res['miou']:.1f} | "
                     + " | ".join(f"{res['per_class'][c]['iou']:.1f}" for c in classes) + " |")
    table = "\n".join(lines)
    print(f"\n{len(kept)} views (every {a.every}), {renders}\n\n{table}")
    if a.out:
        with open(a.out, "a") as fh:
            fh.write(f"\n{len(kept)} views (every {a.every}) of {renders}\n\n{table}\n")


if __name__ == "__main__":
    main()
