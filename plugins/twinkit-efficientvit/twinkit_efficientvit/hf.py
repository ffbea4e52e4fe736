"""Image model ``hf_segformer``: Hugging Face transformers SegFormer / Mask2Former / MaskFormer.

The model is named by a Hub model id (``nvidia/segformer-b0-finetuned-cityscapes-1024-1024``,
``facebook/mask2former-swin-small-cityscapes-semantic``) or a local folder written by
``save_pretrained``. Its labels are mapped to CityScapes trainIds by *name* (``config.id2label``,
see :data:`twinkit_efficientvit.common.LABEL_SYNONYMS`); labels without a CityScapes counterpart
become 255 in :meth:`predict` and are dropped from :meth:`predict_proba`.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit.errors import InputError
from twinkit.ranges import param

from twinkit_efficientvit.common import (
    CITYSCAPES_CLASSES,
    N_CLASSES,
    as_batch,
    chunks,
    label_lookup,
    network_size,
    probs_to_cityscapes,
    resolve_device,
    torch_threads,
)

UNIVERSAL_TYPES = ("mask2former", "maskformer")


@dataclass
class HFParams:
    """Parameters of image model ``hf_segformer``."""

    model: str = param("nvidia/segformer-b0-finetuned-cityscapes-1024-1024", path=True,
                       help="Hugging Face Hub model id, or a local folder (save_pretrained output).")
    revision: str = param("main", help="Hub revision (branch, tag or commit); ignored for a local folder.")
    local_files_only: bool = param(False,
                                   help="Never touch the network (also implied by a local folder or "
                                        "HF_HUB_OFFLINE=1).")
    threads: int = param(0, ge=0, help="torch CPU threads during inference; 0 = torch's default.")
    batch_size: int = param(0, ge=0, le=1024, help="Images per forward pass; 0 = automatic (1 on CPU, 8 on CUDA).")
    device: str = param("auto", help="Where the model runs: auto (CUDA when available), cpu, cuda or cuda:N.")
    input_long_side_px: int = param(0, ge=0, le=8192,
                                    help="0 = let the model's image processor resize (to its own training size); > "
                                         "0 = resize to this long side (px) keeping the aspect ratio, sides rounded "
                                         "to size_multiple_px, and tell the processor not to resize.")
    size_multiple_px: int = param(32, ge=1, le=1024,
                                  help="With input_long_side_px > 0: each side is rounded to a multiple of this "
                                       "(px).")
    label_map: dict[str, int] = param(default_factory=dict, free=True,
                                      help="Overrides of the model's label name -> CityScapes trainId (-1 = ignore "
                                           "the label), applied before the built-in name table.")


class HFSegmentationModel:
    """A transformers segmentation model behind the image-model contract."""

    classes = list(CITYSCAPES_CLASSES)

    def __init__(self, params: HFParams):
        import torch  # noqa: F401  (fail early with a clear message below if missing)

        try:
            import transformers
            from transformers import AutoConfig, AutoImageProcessor
        except ImportError as exc:
            raise InputError(
                "image model hf_segformer needs the 'transformers' package: pip install 'twinkit-efficientvit[hf]'"
            ) from exc
        self.params = params
        src = params.model
        is_dir = Path(src).expanduser().is_dir()
        kwargs: dict = {"local_files_only": bool(params.local_files_only or is_dir or os.environ.get("HF_HUB_OFFLINE") == "1")}
        if is_dir:
            src = str(Path(src).expanduser())
        else:
            kwargs["revision"] = params.revision
        try:
            config = AutoConfig.from_pretrained(src, **kwargs)
            self.model_type = config.model_type
            if self.model_type in UNIVERSAL_TYPES:
                from transformers import AutoModelForUniversalSegmentation as Auto
            else:
                from transformers import AutoModelForSemanticSegmentation as Auto
            self.processor = AutoImageProcessor.from_pretrained(src, **kwargs)
            net = Auto.from_pretrained(src, **kwargs)
        except (OSError, ValueError) as exc:
            raise InputError(
                f"could not load Hugging Face model '{params.model}' ({exc.__class__.__name__}: {str(exc)[:300]}); "
                "fix: give a local folder written by save_pretrained, or an existing model id on a machine with "
                "internet (set local_files_only=false, unset HF_HUB_OFFLINE)"
            ) from exc
        self.transformers_version = transformers.__version__
        self.device = resolve_device(params.device)
        self.net = net.eval().to(self.device)
        self.batch_size = params.batch_size if params.batch_size > 0 else (8 if self.device.type == "cuda" else 1)
        id2label = {int(k): v for k, v in (self.net.config.id2label or {}).items()}
        self.lookup = label_lookup(id2label, dict(params.label_map) or None)
        if not (self.lookup < N_CLASSES).any():
            raise InputError(
                f"Hugging Face model '{params.model}': none of its labels ({list(id2label.values())[:8]}...) maps to a "
                "CityScapes class; set label_map (label name -> trainId)"
            )
        self.id2label = id2label

    def __repr__(self) -> str:
        return f"HFSegmentationModel(model={self.params.model!r}, type={self.model_type}, device={self.device})"

    # -- helpers -------------------------------------------------------------------------------
    def _inputs(self, batch: np.ndarray):
        """Run the image processor on a chunk; returns the model's keyword inputs (on device)."""
        import torch
        import torch.nn.functional as F

        _, h, w, _ = batch.shape
        kw: dict = {"return_tensors": "pt"}
        images = list(batch)
        if self.params.input_long_side_px > 0:
            nh, nw = network_size(h, w, self.params.input_long_side_px, self.params.size_multiple_px)
            if (nh, nw) != (h, w):
                x = torch.from_numpy(np.array(batch)).permute(0, 3, 1, 2).float()
                x = F.interpolate(x, size=(nh, nw), mode="bilinear", align_corners=False, antialias=nh < h)
                images = list(x.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy())
            kw["do_resize"] = False
        enc = self.processor(images=images, **kw)
        return {k: v.to(self.device) for k, v in enc.items() if k in ("pixel_values", "pixel_mask")}

    def _class_probs(self, outputs, h: int, w: int):
        """Model-label probabilities ``(b, L, h, w)`` float32 (torch) at input resolution."""
        import torch
        import torch.nn.functional as F

        if self.model_type in UNIVERSAL_TYPES:
            cls = outputs.class_queries_logits.float().softmax(-1)[..., :-1]  # drop "no object"
            masks = F.interpolate(outputs.masks_queries_logits.float(), size=(h, w), mode="bilinear",
                                  align_corners=False).sigmoid()
            seg = torch.einsum("bqc,bqhw->bchw", cls, masks)
            return seg / seg.sum(1, keepdim=True).clamp_min(1e-12)
        logits = F.interpolate(outputs.logits.float(), size=(h, w), mode="bilinear", align_corners=False)
        return logits.softmax(1)

    # -- contract --------------------------------------------------------------------------------
    def predict(self, images) -> np.ndarray:
        """``images (b, h, w, 3) uint8 RGB -> (b, h, w) uint8`` CityScapes trainIds (255 = unmapped label)."""
        import torch
        import torch.nn.functional as F

        batch = as_batch(images)
        b, h, w, _ = batch.shape
        out = np.empty((b, h, w), dtype=np.uint8)
        lut = torch.as_tensor(self.lookup)
        with torch_threads(self.params.threads), torch.inference_mode():
            for sl in chunks(b, self.batch_size):
                outputs = self.net(**self._inputs(batch[sl]))
                if self.model_type in UNIVERSAL_TYPES:
                    n = sl.stop - sl.start
                    maps = self.processor.post_process_semantic_segmentation(outputs, target_sizes=[(h, w)] * n)
                    labels = torch.stack([m.to("cpu", torch.long) for m in maps])
                else:
                    logits = F.interpolate(outputs.logits.float(), size=(h, w), mode="bilinear", align_corners=False)
                    labels = logits.argmax(1).cpu()
                out[sl] = lut[labels].numpy()
        return out

    def predict_proba(self, images) -> np.ndarray:
        """``images (b, h, w, 3) uint8 RGB -> (b, 19, h, w) float16``: probabilities of the model's labels
        summed per CityScapes class (mass of unmapped labels dropped, so a pixel may sum to < 1)."""
        import torch

        batch = as_batch(images)
        b, h, w, _ = batch.shape
        out = np.empty((b, N_CLASSES, h, w), dtype=np.float16)
        with torch_threads(self.params.threads), torch.inference_mode():
            for sl in chunks(b, self.batch_size):
                outputs = self.net(**self._inputs(batch[sl]))
                probs = probs_to_cityscapes(self._class_probs(outputs, h, w), self.lookup)
                out[sl] = probs.to(torch.float16).cpu().numpy()
        return out


def build_hf(params: HFParams | None = None) -> HFSegmentationModel:
    """Hugging Face SegFormer / Mask2Former by model id or local folder, labels mapped to CityScapes."""
    return HFSegmentationModel(params or HFParams())
