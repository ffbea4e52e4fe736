"""Benchmark of view-based segmentation on the demo site: stage times and quality per sampler and model.

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_segmentation.py \
        --site-dir outputs/demo [--work /tmp/seg_bench] [--models oracle,efficientvit_b0]

``--site-dir`` is a finished ``recipe=pointcloud_site`` (or segment_demo) run's site folder: it reads
``06_texture/textured_mesh.ply`` (+ png), ``01_site/gt_mesh.ply``, ``roads.osm`` and ``site.json``.
Every view of the three samplers (auto_street, uniform, random) is rendered and segmented once;
each sampler's score uses its own views' votes, ``combined`` the sum of all. Prints Markdown tables:
times per stage (wall and CPU seconds; the machine may be shared, CPU is the fairer number) and
mIoU / mF1 / upper bound per sampler and model, then per-class IoU.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


class Timer:
    def __init__(self):
        self.rows = []

    def __call__(self, name, **extra):
        timer = self

        class _T:
            def __enter__(self):
                self.w, self.c = time.perf_counter(), time.process_time()
                return self

            def __exit__(self, *exc):
                timer.rows.append((name, time.perf_counter() - self.w, time.process_time() - self.c, extra))

        return _T()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--site-dir", default="outputs/demo", help="a finished pointcloud_site / segment_demo site folder")
    ap.add_argument("--work", default="/tmp/seg_bench")
    ap.add_argument("--models", default="oracle,efficientvit_b0")
    ap.add_argument("--uniform-spacing-m", type=float, default=8.0)
    ap.add_argument("--random-views", type=int, default=250)
    ap.add_argument("--k-threshold", type=float, default=None, help="default: the segmenter's default")
    ap.add_argument("--max-views", type=int, default=0, help="subsample the union of views (0 = all)")
    ap.add_argument("--reuse-renders", action="store_true",
                    help="take the renders and vertex maps an earlier run left in --work (same site and sampler options)")
    ap.add_argument("--segment-weight", type=float, default=None,
                    help="back-projection blend of segment and vertex votes (default: backproject's default)")
    a = ap.parse_args(argv)

    os.environ.setdefault("TWINKIT_PLUGINS", "builtins,efficientvit,segmentation")
    from PIL import Image

    from twinkit.plugins import build_component
    from twinkit_segmentation import views as V
    from twinkit.cityscapes import N_CLASSES
    from twinkit.mesh import edges as mesh_edges, read_mesh
    from twinkit.street.truth import transfer_labels
    from twinkit_segmentation.segmesh import face_labels, unit_normals, vertex_labels
    from twinkit_segmentation.metrics import blend_decide, decide, majority_labels, propagate, scores
    from twinkit_segmentation.oversegment import felzenszwalb_mesh
    from twinkit_segmentation.render import Renderer, load_texture
    from twinkit_segmentation.steps import BackprojectParams, FelzenszwalbParams

    alpha = BackprojectParams().segment_weight if a.segment_weight is None else a.segment_weight

    site = Path(a.site_dir)
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    T = Timer()
    mesh_path = site / "06_texture" / "textured_mesh.ply"
    with T("read mesh"):
        mesh = read_mesh(mesh_path)
        normals = unit_normals(mesh)
    gt_mesh = read_mesh(site / "01_site" / "gt_mesh.ply")
    gt, _ = transfer_labels(gt_mesh.vertices, gt_mesh.faces, mesh.vertices, face_labels=face_labels(gt_mesh),
                            vertex_labels=vertex_labels(gt_mesh))
    site_json = json.loads((site / "01_site" / "site.json").read_text())
    fp = FelzenszwalbParams()
    if a.k_threshold is not None:
        fp.k_threshold = a.k_threshold
    with T("over-segmentation", vertices=len(mesh.vertices)):
        seg = felzenszwalb_mesh(mesh.vertices, mesh.faces, normals, mesh.colors, fp.k_threshold, fp.min_vertices,
                                fp.max_vertices, fp.normal_weight, fp.colour_weight)
    edges = mesh_edges(mesh.faces, len(mesh.vertices))

    scene = V.Scene(mesh.vertices, mesh.faces, normals, site=site_json, roads_osm=site / "01_site" / "roads.osm")
    with T("view sampling"):
        sets = {
            "auto_street": V.AutoStreetSampler(V.AutoStreetParams()).sample(scene),
            "uniform": V.UniformSampler(V.UniformParams(spacing_m=a.uniform_spacing_m)).sample(scene),
            "random": V.RandomSampler(V.RandomParams(n_views=a.random_views)).sample(scene),
        }
    views = [v for s in sets.values() for v in s]
    if a.max_views and len(views) > a.max_views:
        keep = set(np.linspace(0, len(views) - 1, a.max_views).round().astype(int).tolist())
        views = [v for i, v in enumerate(views) if i in keep]
    print(f"views: {len(views)} ({', '.join(f'{k} {len(v)}' for k, v in sets.items())})", file=sys.stderr)

    tex = load_texture(mesh.texture)
    with T("renderer set-up (texture, mipmaps, upload)"):
        r = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, 1024, 512)
    from twinkit_segmentation.views import view_matrices

    kept, vmaps_dir = [], work / "vmaps"
    vmaps_dir.mkdir(exist_ok=True)
    with T("rendering", views=len(views)):
        for i, v in enumerate(views):
            if a.reuse_renders and (work / f"{v['id']}.png").is_file() and (vmaps_dir / f"{v['id']}.npy").is_file():
                kept.append(v)
                continue
            if a.reuse_renders and (vmaps_dir / ".complete").is_file():
                continue  # dropped (too empty) in the earlier run
            rgb, vid = r.render(*view_matrices(v))
            if (vid < 0).mean() > 0.6:
                continue
            Image.fromarray(rgb).save(work / f"{v['id']}.png", compress_level=1)
            np.save(vmaps_dir / f"{v['id']}.npy", vid)
            kept.append(v)
    r.release()
    (vmaps_dir / ".complete").write_text(str(len(kept)))
    print(f"kept {len(kept)} of {len(views)} views", file=sys.stderr)

    n = len(mesh.vertices)
    results = {}
    for model_name in [m for m in a.models.split(",") if m]:
        model = build_component("image_model", model_name, {})
        if getattr(model, "needs_ground_truth", False):
            model.set_ground_truth(gt)
        votes = {k: np.zeros((n, N_CLASSES)) for k in sets}  # one vote per view and vertex (predict_views default)
        votes_px = {k: np.zeros((n, N_CLASSES)) for k in sets}  # one vote per pixel
        with T(f"inference ({model_name})", views=len(kept)):
            for j in range(0, len(kept), 4):
                batch = kept[j:j + 4]
                ims = np.stack([np.asarray(Image.open(work / f"{v['id']}.png").convert("RGB")) for v in batch])
                vms = np.stack([np.load(vmaps_dir / f"{v['id']}.npy") for v in batch])
                kw = {"vertex_maps": vms} if getattr(model, "needs_vertex_map", False) else {}
                labs = model.predict(ims, **kw)
                for v, lab, vm in zip(batch, labs, vms):
                    hit = vm.reshape(-1) >= 0
                    l = lab.reshape(-1)[hit].astype(np.int64)
                    ok = l < N_CLASSES
                    vv = np.bincount(vm.reshape(-1)[hit][ok].astype(np.int64) * N_CLASSES + l[ok],
                                     minlength=n * N_CLASSES).reshape(n, N_CLASSES).astype(np.float64)
                    votes_px[v["sampler"]] += vv
                    tot = vv.sum(axis=1, keepdims=True)
                    votes[v["sampler"]] += np.divide(vv, tot, out=np.zeros_like(vv), where=tot > 0)
        votes["combined"] = sum(votes[k] for k in sets)
        votes_px["combined"] = sum(votes_px[k] for k in sets)
        for sname, vv in votes.items():
            if sname == "combined":
                ctx_t = T(f"back-projection ({model_name}, combined)")
            else:
                ctx_t = None
            if ctx_t:
                ctx_t.__enter__()
            lab, _ = blend_decide(seg, vv, alpha, ignore_classes=[10])
            lab = propagate(lab, edges)
            if ctx_t:
                ctx_t.__exit__(None, None, None)
            np.save(work / f"votes_{model_name}_{sname}.npy", vv.astype(np.float32))
            res = scores(lab, gt)
            slab, _ = blend_decide(seg, vv, 1.0, ignore_classes=[10])
            res_seg = scores(propagate(slab, edges), gt, res["classes"])
            vlab, _ = decide(vv, ignore_classes=[10])
            res_nos = scores(propagate(vlab, edges), gt, res["classes"])
            plab, _ = blend_decide(seg, votes_px[sname], alpha, ignore_classes=[10])
            res_px = scores(propagate(plab, edges), gt, res["classes"])
            results[(model_name, sname)] = (res, res_nos, res_seg, res_px)
    ub = scores(majority_labels(seg, gt), gt)

    print("## Stage times\n")
    print(f"Mesh: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces; {len(views)} views rendered "
          f"({len(kept)} kept), 1024x512.\n")
    print("| stage | wall s | CPU s | note |\n|---|---:|---:|---|")
    total_w = total_c = 0.0
    for name, w, c, extra in T.rows:
        note = ", ".join(f"{k} {v}" for k, v in extra.items())
        if "views" in extra:
            note += f"; {w / max(extra['views'], 1):.3f} s wall / view"
        print(f"| {name} | {w:.1f} | {c:.1f} | {note} |")
        total_w += w
        total_c += c
    print(f"| **total** | **{total_w:.1f}** | **{total_c:.1f}** | |\n")
    print(f"## Quality (demo site, over-segmentation k={fp.k_threshold}, min {fp.min_vertices}, max {fp.max_vertices}, "
          f"{int(seg.max()) + 1} segments; upper bound mIoU {ub['miou']:.1f}; segment_weight {alpha})\n")
    print("| model | sampler | views kept | mIoU | mF1 | mIoU segments only | mF1 segments only "
          "| mIoU without over-seg. | mF1 without | mIoU per-pixel votes | mF1 per-pixel |"
          "\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    count = {k: sum(1 for v in kept if v["sampler"] == k) for k in sets}
    count["combined"] = len(kept)
    for (m, s), (res, nos, sego, px) in results.items():
        print(f"| {m} | {s} | {count[s]} | {res['miou']:.1f} | {res['mf1']:.1f} | {sego['miou']:.1f} | {sego['mf1']:.1f} "
              f"| {nos['miou']:.1f} | {nos['mf1']:.1f} | {px['miou']:.1f} | {px['mf1']:.1f} |")
    classes = [c for c in ub["per_class"]]
    print("\n## Per-class IoU\n")
    print("| model / sampler | " + " | ".join(classes) + " |\n|---|" + "---:|" * len(classes))
    for (m, s), (res, *_) in results.items():
        print(f"| {m} / {s} | " + " | ".join(f"{res['per_class'][c]['iou']:.1f}" for c in classes) + " |")
    print("| upper bound | " + " | ".join(f"{ub['per_class'][c]['iou']:.1f}" for c in classes) + " |")
    (work / "bench.json").write_text(json.dumps({f"{m}/{s}": {"scores": r[0]["per_class"], "miou": r[0]["miou"],
                                                                "mf1": r[0]["mf1"]} for (m, s), r in results.items()},
                                                indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
