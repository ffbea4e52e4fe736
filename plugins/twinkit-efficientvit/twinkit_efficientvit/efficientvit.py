"""Image model ``efficientvit_b0``: EfficientViT-Seg-B0 trained on CityScapes (MIT Han Lab weights)."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import numpy as np

from twinkit.errors import InputError
from twinkit.ranges import param

from twinkit_efficientvit.common import (
    CITYSCAPES_CLASSES,
    as_batch,
    chunks,
    network_size,
    resolve_device,
    torch_threads,
)

WEIGHTS_FILE = "efficientvit_seg_b0_cityscapes.pt"
WEIGHTS_SHA256 = "923d6fdd5e93640cc0c2f3f213764f34e80b477cd98a6b294d870ea6df5acc50"
HF_REPO = "han-cai/efficientvit-seg"
WEIGHTS_URL = f"https://huggingface.co/{HF_REPO}/resolve/main/{WEIGHTS_FILE}"
OFFICIAL = f"model id {HF_REPO}, file {WEIGHTS_FILE} ({WEIGHTS_URL})"

log = logging.getLogger(__name__)


@dataclass
class EfficientViTParams:
    """Parameters of image model ``efficientvit_b0``."""

    weights_path: str = param("", path=True,
                              help="Checkpoint file, or a folder holding it; empty = search $TWINKIT_MODELS_DIR, "
                                   "../shared/models (from the working directory, then the repository root) and the "
                                   "download cache.")
    weights_sha256: str = param("",
                                help="Expected sha256 of the checkpoint; empty = the official file's hash when "
                                     "weights_path is empty, no check for a given path.")
    download_if_missing: bool = param(False,
                                      help="Fetch the official checkpoint (needs internet) when no copy is found.")
    threads: int = param(0, ge=0, help="CPU threads during inference; 0 = the step's thread budget (the engine's "
                                       "share of the cores), else torch's default.")
    runtime: str = param("auto", choices=("auto", "openvino", "onnxruntime", "torch"),
                         help="What runs the network: auto (on CPU OpenVINO when openvino and onnx are installed, "
                              "else ONNX Runtime when onnxruntime and onnx are, else torch), openvino or onnxruntime "
                              "(both run the ONNX file exported from the torch model at first use into "
                              "~/.cache/twinkit/models) or torch. The labels agree to well under 0.1 % of pixels.")
    batch_size: int = param(0, ge=0, le=1024,
                            help="Images per forward pass; 0 = automatic (1 on CPU, 8 on CUDA). Larger batches need "
                                 "more memory.")
    device: str = param("auto", help="Where the model runs: auto (CUDA when available), cpu, cuda or cuda:N.")
    input_long_side_px: int = param(1024, ge=32, le=8192,
                                    help="The network sees the image with its long side scaled to this (px); the "
                                         "logits are upsampled back to the input size.")
    size_multiple_px: int = param(32, ge=1, le=1024,
                                  help="Each side the network sees is rounded to a multiple of this (px); the model "
                                       "needs 32.")
    optimize: bool = param(True,
                           help="Fold BatchNorm into the convolutions and run channels-last (about 2x faster on "
                                "CPU, the same labels up to float rounding); false = the checkpoint's modules as "
                                "loaded.")
    flip_tta: bool = param(False,
                           help="Test-time augmentation: average the logits of the image and of its mirror image "
                                "(twice the inference time).")


class EfficientViTModel:
    """EfficientViT-Seg-B0 with the image-model contract (see :mod:`twinkit_efficientvit.common`)."""

    classes = list(CITYSCAPES_CLASSES)

    def __init__(self, params: EfficientViTParams):
        import torch

        from twinkit_efficientvit.model import (
            IMAGENET_MEAN,
            IMAGENET_STD,
            efficientvit_seg_b0_cityscapes,
            fuse_for_inference,
        )
        from twinkit_efficientvit.weights import resolve_weights

        if params.size_multiple_px % 32:
            raise ValueError(f"size_multiple_px must be a multiple of 32 for EfficientViT, got {params.size_multiple_px}")
        self.params = params
        self.weights_path = resolve_weights(
            WEIGHTS_FILE, params.weights_path, params.weights_sha256, WEIGHTS_SHA256, OFFICIAL,
            WEIGHTS_URL, params.download_if_missing, hf_repo=HF_REPO,
        )
        try:
            ckpt = torch.load(self.weights_path, map_location="cpu", weights_only=True)
        except Exception as exc:
            raise InputError(
                f"weights file {self.weights_path} could not be read as a PyTorch checkpoint ({exc.__class__.__name__}: "
                f"{str(exc)[:200]}); replace it with the official file ({OFFICIAL}) or set weights_path"
            ) from exc
        state = ckpt.get("state_dict", ckpt) if isinstance(ckpt, dict) else None
        if not isinstance(state, dict):
            raise InputError(f"weights file {self.weights_path} holds no state dict; expected {OFFICIAL}")
        self.device = resolve_device(params.device)
        net = efficientvit_seg_b0_cityscapes()
        try:
            net.load_state_dict(state, strict=True)
        except RuntimeError as exc:
            raise InputError(
                f"weights file {self.weights_path} does not fit EfficientViT-Seg-B0 (CityScapes): {str(exc)[:400]}; "
                f"expected {OFFICIAL}"
            ) from exc
        net = net.eval()
        self._memory_format = torch.contiguous_format
        if params.optimize:
            net = fuse_for_inference(net).to(memory_format=torch.channels_last)
            self._memory_format = torch.channels_last
        self.net = net.to(self.device)
        self.batch_size = params.batch_size if params.batch_size > 0 else (8 if self.device.type == "cuda" else 1)
        self._mean = torch.tensor(IMAGENET_MEAN, device=self.device).view(1, 3, 1, 1) * 255.0
        self._std = torch.tensor(IMAGENET_STD, device=self.device).view(1, 3, 1, 1) * 255.0
        self.onnx = self._onnx_net(params)
        self.runtime = self.onnx.backend if self.onnx is not None else "torch"

    def _onnx_net(self, params: EfficientViTParams):
        """The exported network on OpenVINO or ONNX Runtime, or None where torch runs it (runtime=torch, a GPU,
        auto with neither installed)."""
        from twinkit_efficientvit import onnx_net

        if params.runtime == "torch" or (params.runtime == "auto" and self.device.type != "cpu"):
            return None
        if params.runtime == "auto":
            backend = next((b for b in ("openvino", "onnxruntime") if onnx_net.available(b)), None)
            if backend is None:
                return None
        else:
            backend = params.runtime
            if not onnx_net.available(backend):
                raise InputError(f"image_model.runtime={backend} needs the {backend} and onnx packages "
                                 f"(pip install {backend} onnx); or set image_model.runtime=torch")
        from twinkit_efficientvit.weights import sha256_of

        try:
            return onnx_net.OnnxNet(self.net, self.weights_path, sha256_of(self.weights_path), self.params.optimize,
                                    self.threads(), backend)
        except Exception as exc:  # export or check failed: torch gives the same labels, only slower
            if params.runtime != "auto":
                raise InputError(f"image_model.runtime={backend}: {str(exc)[:300]}; set image_model.runtime=torch"
                                 ) from exc
            log.warning("%s not used (%s); the network runs on torch", backend, str(exc)[:300])
            return None

    def _torch_threads(self) -> int:
        """torch's threads in predict: all of :meth:`threads` where torch runs the network; one where OpenVINO or
        ONNX Runtime does (torch then only normalises and labels, 15 ms per view, which a second spin-waiting
        thread made 100 ms of CPU on the shared machine)."""
        return 1 if self.onnx is not None else self.threads()

    def threads(self) -> int:
        """CPU threads for inference: ``params.threads``, else the step's budget (``TWINKIT_THREADS``), else 0
        (the library's default)."""
        from twinkit.threads import BUDGET_ENV

        return self.params.threads or int(os.environ.get(BUDGET_ENV) or 0)

    def __repr__(self) -> str:
        return (f"EfficientViTModel(weights={self.weights_path}, device={self.device}, runtime={self.runtime}, "
                f"params={self.params})")

    def _network_input(self, batch: np.ndarray):
        """``(b, h, w, 3)`` uint8 -> the normalised network input ``(b, 3, nh, nw)`` float32 (torch)."""
        import torch
        import torch.nn.functional as F

        b, h, w, _ = batch.shape
        if not batch.flags.writeable:  # torch.from_numpy warns on read-only arrays (e.g. from PIL)
            batch = batch.copy()
        x = torch.from_numpy(batch).to(self.device).permute(0, 3, 1, 2).float()
        nh, nw = network_size(h, w, self.params.input_long_side_px, self.params.size_multiple_px)
        if (nh, nw) != (h, w):
            x = F.interpolate(x, size=(nh, nw), mode="bilinear", align_corners=False, antialias=nh < h or nw < w)
        return (x - self._mean) / self._std

    def _run_net(self, x):
        """Normalised input -> stride-8 logits (torch), on OpenVINO, ONNX Runtime or torch."""
        import torch

        if self.onnx is not None:
            return torch.from_numpy(self.onnx(x.numpy()))
        return self.net(x.contiguous(memory_format=self._memory_format))

    def _low_logits(self, batch: np.ndarray):
        """``(b, h, w, 3)`` uint8 -> logits ``(b, 19, nh/8, nw/8)`` float32 (torch), mirror-averaged with flip_tta."""
        x = self._network_input(batch)
        logits = self._run_net(x)
        if self.params.flip_tta:  # mirror image: the network is not exactly mirror-symmetric
            logits = 0.5 * (logits + self._run_net(x.flip(-1).contiguous()).flip(-1))
        return logits

    def predict(self, images) -> np.ndarray:
        """``images (b, h, w, 3) uint8 RGB -> (b, h, w) uint8`` CityScapes trainIds."""
        import torch

        from twinkit_efficientvit.upsample import upsample_argmax

        batch = as_batch(images)
        out = np.empty(batch.shape[:3], dtype=np.uint8)
        with torch_threads(self._torch_threads()), torch.inference_mode():
            for sl in chunks(len(batch), self.batch_size):
                out[sl] = upsample_argmax(self._low_logits(batch[sl]), batch.shape[1:3]).cpu().numpy()
        return out

    def predict_proba(self, images) -> np.ndarray:
        """``images (b, h, w, 3) uint8 RGB -> (b, 19, h, w) float16`` softmax probabilities."""
        import torch
        import torch.nn.functional as F

        batch = as_batch(images)
        b, h, w, _ = batch.shape
        out = np.empty((b, len(self.classes), h, w), dtype=np.float16)
        with torch_threads(self._torch_threads()), torch.inference_mode():
            for sl in chunks(b, self.batch_size):
                logits = self._low_logits(batch[sl]).contiguous(memory_format=torch.channels_last)
                up = F.interpolate(logits, size=(h, w), mode="bilinear", align_corners=False)
                out[sl] = up.softmax(1).to(torch.float16).cpu().numpy()
        return out


def build_efficientvit(params: EfficientViTParams | None = None) -> EfficientViTModel:
    """EfficientViT-Seg-B0 CityScapes (0.7 M parameters, 75.7 mIoU); default image model."""
    return EfficientViTModel(params or EfficientViTParams())
