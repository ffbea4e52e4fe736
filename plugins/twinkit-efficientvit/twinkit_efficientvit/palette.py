"""CityScapes colour palette and PNG previews of predictions.

Command line::

    python -m twinkit_efficientvit.palette PHOTO.jpg [...] --out-dir previews/ [--model efficientvit_b0]

writes ``<stem>_seg.png`` (labels in colour, with a legend of the classes present) and
``<stem>_overlay.png`` (photo blended with the labels) per photo.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from twinkit import cityscapes
from twinkit_efficientvit.common import CITYSCAPES_CLASSES, IGNORE_ID

#: trainId -> RGB, the official CityScapes colours (shared: twinkit.cityscapes; 255 -> black).
CITYSCAPES_PALETTE = cityscapes.PALETTE


def colorize(labels: np.ndarray) -> np.ndarray:
    """``labels (h, w) uint8 trainIds -> (h, w, 3) uint8 RGB``; 255 and unknown ids are black."""
    return cityscapes.colorize(labels)


def overlay(image: np.ndarray, labels: np.ndarray, alpha: float = 0.5) -> np.ndarray:
    """Blend ``image (h, w, 3) uint8`` with the coloured labels; ``alpha`` = weight of the labels."""
    mixed = (1 - alpha) * image.astype(np.float32) + alpha * colorize(labels).astype(np.float32)
    return mixed.round().clip(0, 255).astype(np.uint8)


def _with_legend(rgb: np.ndarray, labels: np.ndarray):
    from PIL import Image, ImageDraw

    present = [int(c) for c in np.unique(labels) if c != IGNORE_ID and c < len(CITYSCAPES_CLASSES)]
    row_h = 16
    legend_w = 130
    h, w, _ = rgb.shape
    canvas = Image.new("RGB", (w + legend_w, max(h, row_h * len(present) + 8)), (255, 255, 255))
    canvas.paste(Image.fromarray(rgb), (0, 0))
    draw = ImageDraw.Draw(canvas)
    for i, c in enumerate(present):
        y = 4 + i * row_h
        draw.rectangle([w + 4, y, w + 16, y + 12], fill=tuple(int(v) for v in CITYSCAPES_PALETTE[c]))
        share = 100.0 * float((labels == c).mean())
        draw.text((w + 20, y), f"{CITYSCAPES_CLASSES[c]} {share:.0f}%", fill=(0, 0, 0))
    return canvas


def save_prediction_png(path: str | Path, labels: np.ndarray, image: np.ndarray | None = None,
                        legend: bool = True, alpha: float = 0.5) -> Path:
    """Write ``labels (h, w)`` as a colour PNG (over ``image`` when given, else plain colours)."""
    from PIL import Image

    rgb = colorize(labels) if image is None else overlay(image, labels, alpha)
    out = _with_legend(rgb, labels) if legend else Image.fromarray(rgb)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    out.save(path)
    return path


def main(argv: list[str] | None = None) -> int:
    from PIL import Image

    ap = argparse.ArgumentParser(description="Segment photos and write CityScapes-coloured PNG previews.")
    ap.add_argument("photos", nargs="+", type=Path)
    ap.add_argument("--out-dir", type=Path, default=Path("previews"))
    ap.add_argument("--model", default="efficientvit_b0", choices=["efficientvit_b0", "hf_segformer", "deeplab_edgetpu_tflite"])
    ap.add_argument("--weights", default="", help="weights file (efficientvit/tflite) or HF model id/folder")
    ap.add_argument("--threads", type=int, default=0)
    args = ap.parse_args(argv)
    if args.model == "efficientvit_b0":
        from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit
        model = build_efficientvit(EfficientViTParams(weights_path=args.weights, threads=args.threads))
    elif args.model == "hf_segformer":
        from twinkit_efficientvit.hf import HFParams, build_hf
        model = build_hf(HFParams(model=args.weights or HFParams.model, threads=args.threads))
    else:
        from twinkit_efficientvit.tflite import DeepLabTFLiteParams, build_deeplab_tflite
        model = build_deeplab_tflite(DeepLabTFLiteParams(weights_path=args.weights, threads=args.threads))
    for photo in args.photos:
        image = np.asarray(Image.open(photo).convert("RGB"))
        labels = model.predict(image[None])[0]
        seg = save_prediction_png(args.out_dir / f"{photo.stem}_seg.png", labels)
        ov = save_prediction_png(args.out_dir / f"{photo.stem}_overlay.png", labels, image=image, legend=False)
        print(f"{photo}: {seg} {ov}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
