"""Photo views against rendered views on the photo branch (docs/segmentation.md "The capture's photos as views").

Reads a finished ``recipe=image_site`` run (its photo_views, predict_views, backproject and, where the site
has them, gt_labels folders) and writes:

* ``--figure PATH``: one photo, the 2D model's prediction on it, the back-projected mesh labels seen from the
  same pose (each pixel shows the label of the vertex its vertex map names), and the ground truth the same
  way; a small JPEG for the docs.
* ``--gap``: the 2D domain gap itself, on sites whose photos come with per-pixel label images
  (the demo's ``photos/labels/``): the image model on each photo and on the textured mesh rendered from the
  same pose, both scored against the photo's labels on the pixels the mesh covers.

    python plugins/twinkit-segmentation/bench/bench_photo_views.py --site-dir outputs/demo \
        --figure docs/img/photo_views_demo.jpg --gap
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from PIL import Image

from twinkit.cityscapes import IGNORE, N_CLASSES, NAMES, lut


def step_dir(site: Path, name: str) -> Path | None:
    hits = sorted(p for p in site.iterdir() if p.is_dir() and p.name.split("_", 1)[-1] == name)
    return hits[-1] if hits else None


def _colour(labels: np.ndarray) -> np.ndarray:
    return lut()[labels]


def figure(site: Path, out: Path, view_id: str | None, panel_w: int = 360) -> str:
    ren = step_dir(site, "photo_views") / "renders"
    pred_dir = step_dir(site, "predict_views") / "predictions"
    labels = np.load(step_dir(site, "backproject") / "labels.npy")
    gt_dir = step_dir(site, "gt_labels")
    gt = np.load(gt_dir / "gt_labels.npy") if gt_dir and (gt_dir / "gt_labels.npy").exists() else None
    kept = [v for v in json.loads((ren / "index.json").read_text())["kept"] if v["sampler"] == "photo"]
    if view_id is None:  # the photo that sees the most mesh
        view_id = min(kept, key=lambda v: v["empty_fraction"])["id"]
    photo = np.asarray(Image.open(ren / f"{view_id}.png").convert("RGB"))
    pred = np.asarray(Image.open(pred_dir / f"{view_id}.png"))
    vm = np.load(ren / f"{view_id}_vertex.npz")["vertex"]
    hit = vm >= 0

    def on_mesh(lab):
        img = (photo * 0.35).astype(np.uint8)  # pixels the mesh does not cover: the photo, dimmed
        img[hit] = _colour(lab[vm[hit]])
        return img

    panels = [photo, _colour(pred), on_mesh(labels)] + ([on_mesh(gt)] if gt is not None else [])
    h = int(round(photo.shape[0] * panel_w / photo.shape[1]))
    small = [np.asarray(Image.fromarray(p).resize((panel_w, h), Image.NEAREST if i else Image.LANCZOS))
             for i, p in enumerate(panels)]
    gap = np.full((h, 4, 3), 255, np.uint8)
    row = np.concatenate(sum(([p, gap] for p in small), [])[:-1], axis=1)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(row).save(out, quality=82)
    return view_id


def _miou(pred: np.ndarray, gt: np.ndarray) -> tuple[float, dict]:
    ok = gt != IGNORE
    cm = np.bincount(gt[ok].astype(np.int64) * N_CLASSES + np.minimum(pred[ok], N_CLASSES - 1).astype(np.int64),
                     minlength=N_CLASSES * N_CLASSES).reshape(N_CLASSES, N_CLASSES)
    tp = np.diag(cm).astype(float)
    denom = cm.sum(0) + cm.sum(1) - tp
    present = cm.sum(1) > 0
    iou = {NAMES[c]: 100 * tp[c] / denom[c] for c in range(N_CLASSES) if present[c]}
    return float(np.mean(list(iou.values()))), iou


def gap(site: Path, model_name: str) -> dict:
    """2D pixel mIoU of the image model on the photos and on renders of the textured mesh from the same poses."""
    from twinkit.mesh import read_mesh
    from twinkit.plugins import build_component
    from twinkit_segmentation.photoviews import projection_from_K, view_matrix_opencv
    from twinkit_segmentation.render import Renderer, load_texture

    ren = step_dir(site, "photo_views") / "renders"
    photos = step_dir(site, "site") / "photos"
    kept = [v for v in json.loads((ren / "index.json").read_text())["kept"] if v["sampler"] == "photo"]
    mesh = read_mesh(step_dir(site, "photo_texture") / "textured_mesh.ply")
    tex = load_texture(mesh.texture)
    model = build_component("image_model", model_name, {})
    gts, p_photo, p_render = [], [], []
    renderers: dict = {}
    t_model = 0.0
    for v in kept:
        lab_path = photos / "labels" / (Path(v["image"]).stem + ".png")
        if not lab_path.exists():
            continue
        w, h = v["width"], v["height"]
        lab = np.asarray(Image.open(lab_path).resize((w, h), Image.NEAREST))
        if (w, h) not in renderers:
            renderers[(w, h)] = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, w, h)
        rgb, vm = renderers[(w, h)].render(view_matrix_opencv(np.asarray(v["R_world_from_camera"]), v["center"]),
                                           projection_from_K(np.asarray(v["K"]), w, h))
        photo = np.asarray(Image.open(ren / f"{v['id']}.png").convert("RGB"))
        t0 = time.perf_counter()
        a, b = model.predict(np.stack([photo, rgb]))
        t_model += time.perf_counter() - t0
        keep = vm >= 0  # where the mesh is, both images show the same surface
        g = np.where(keep, lab, IGNORE).astype(np.uint8)
        gts.append(g.ravel()), p_photo.append(a.ravel()), p_render.append(b.ravel())
    for r in renderers.values():
        r.release()
    if not gts:
        return {"views": 0}
    g = np.concatenate(gts)
    mp, ip = _miou(np.concatenate(p_photo), g)
    mr, ir = _miou(np.concatenate(p_render), g)
    return {"views": len(gts), "photo_miou": mp, "render_miou": mr, "photo_iou": ip, "render_iou": ir,
            "model_seconds": t_model}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--site-dir", type=Path, required=True)
    ap.add_argument("--figure", type=Path)
    ap.add_argument("--view", help="view id for the figure (default: the photo that sees the most mesh)")
    ap.add_argument("--gap", action="store_true")
    ap.add_argument("--model", default="efficientvit_b0")
    a = ap.parse_args(argv)
    if a.figure:
        print("figure:", a.figure, "view", figure(a.site_dir, a.figure, a.view))
    if a.gap:
        r = gap(a.site_dir, a.model)
        print(json.dumps({k: v for k, v in r.items() if not isinstance(v, dict)}, indent=1))
        if r.get("views"):
            names = [n for n in NAMES if n in r["photo_iou"]]
            print("| images | views | pixel mIoU | " + " | ".join(names) + " |")
            print("|---|---:|---:|" + "---:|" * len(names))
            for key, title in (("photo", "photos"), ("render", "textured mesh rendered from the photo's pose")):
                print(f"| {title} | {r['views']} | {r[key + '_miou']:.1f} | "
                      + " | ".join(f"{r[key + '_iou'][n]:.1f}" for n in names) + " |")


if __name__ == "__main__":
    main()
