"""Realism check: does a pretrained CityScapes model recognise the demo site's photos?

    .venv/bin/python plugins/twinkit-demo-site/bench/realism_iou.py [--site DIR] [--count 10] [--previews DIR]

Runs the ``efficientvit_b0`` image model (package ``twinkit-efficientvit``, real
weights from ../shared/models) on the demo photos and compares with the
ground-truth label renders (``photos/labels/*.png``; 255 = sky, scored as
CityScapes class 10). Prints per-class pixel IoU as a Markdown table.
Without ``--site`` the small preset is generated into a temporary folder.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

NAMES = ["road", "sidewalk", "building", "wall", "fence", "pole", "traffic light", "traffic sign", "vegetation",
         "terrain", "sky", "person", "rider", "car", "truck", "bus", "train", "motorcycle", "bicycle"]
from twinkit.cityscapes import PALETTE  # noqa: E402


def main() -> None:
    from PIL import Image

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", type=Path, default=None, help="folder written by the generator")
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--previews", type=Path, default=None, help="write photo | truth | prediction strips here")
    a = ap.parse_args()
    site = a.site
    if site is None:  # the small preset, seed 0, with its photo walk, in the demo site's frame (conf/site/demo.yaml)
        import yaml

        from twinkit.testing import run_plugin

        conf = yaml.safe_load((Path(__file__).resolve().parents[3] / "conf" / "site" / "demo.yaml").read_text())
        out = run_plugin("site_generator", "demo_intersection", Path(tempfile.mkdtemp(prefix="twinkit-realism-")),
                         site={k: conf[k] for k in ("name", "crs", "base_point")}, size="small", seed=0)
        site = out["site.json"].parent
    cams = json.loads((site / "cameras.json").read_text())["cameras"]
    if not cams:
        raise SystemExit(f"{site}: no photo walk (the point-cloud recipes generate the demo with photos=false); "
                         "give --site a folder generated with photos (recipe=image_site's 01_site), or no --site")
    idx = np.linspace(0, len(cams) - 1, min(a.count, len(cams))).round().astype(int)
    from twinkit.plugins import build_component  # the registry: image_model/efficientvit_b0, default params

    model = build_component("image_model", "efficientvit_b0", {})
    inter = np.zeros(19)
    union = np.zeros(19)
    gt_pix = np.zeros(19)
    correct = total = 0
    for k, i in enumerate(idx):
        cam = cams[i]
        rgb = np.array(Image.open(site / "photos" / cam["image"]).convert("RGB"))
        gt = np.array(Image.open(site / "photos" / cam["label_image"])).astype(np.int64)
        gt[gt == 255] = 10
        pred = model.predict(rgb[None])[0].astype(np.int64)
        for c in range(19):
            g, p = gt == c, pred == c
            inter[c] += np.count_nonzero(g & p)
            union[c] += np.count_nonzero(g | p)
            gt_pix[c] += np.count_nonzero(g)
        correct += np.count_nonzero(gt == pred)
        total += gt.size
        if a.previews:
            a.previews.mkdir(parents=True, exist_ok=True)
            strip = np.concatenate([rgb, PALETTE[gt], PALETTE[pred]], 1)
            Image.fromarray(strip).resize((strip.shape[1] // 2, strip.shape[0] // 2)).save(a.previews / f"realism_{k:02d}.png")
    present = [c for c in range(19) if gt_pix[c] > 0]
    iou = {c: inter[c] / union[c] for c in present}
    print(f"EfficientViT-Seg-B0 on {len(idx)} demo photos ({site}); pixel accuracy {correct / total:.3f}")
    print()
    print("| class | trainId | GT pixels % | IoU |")
    print("|---|---:|---:|---:|")
    for c in present:
        print(f"| {NAMES[c]} | {c} | {100 * gt_pix[c] / total:.2f} | {100 * iou[c]:.1f} |")
    print(f"| **mean (classes present)** | | | **{100 * np.mean(list(iou.values())):.1f}** |")


if __name__ == "__main__":
    main()
