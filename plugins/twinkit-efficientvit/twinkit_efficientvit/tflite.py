"""Image model ``deeplab_edgetpu_tflite``: Google's EdgeTPU-DeepLab-slim (int8 TFLite, CityScapes).

Needs the optional package ``ai-edge-litert`` (``pip install 'twinkit-efficientvit[tflite]'``).
The network has a fixed 513x513 uint8 RGB input and outputs an argmax map of CityScapes
trainIds, so :meth:`predict_proba` returns one-hot "probabilities".
By default each image is stretched to 513x513 and the prediction resized back
(nearest neighbour) to the input size; ``resize_mode="pad"`` keeps the aspect ratio
and pads with mid-grey instead. On the lund_street photos stretching gave clearly
better labels (the model mistakes much of a padded frame's sky for "train" or
"traffic sign"); even so this model labels most sky as "building" there.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.errors import InputError

from twinkit_efficientvit.common import CITYSCAPES_CLASSES, IGNORE_ID, N_CLASSES, as_batch
from twinkit.ranges import param

WEIGHTS_FILE = "deeplab_mobilenet_edgetpu_slim_cityscapes_quant.tflite"
WEIGHTS_SHA256 = "322fe29945cb1693f426952f2a330ab67ea5678545ddee6f2548e0cfd0ca03e5"
OFFICIAL = (f"Google EdgeTPU-DeepLab-slim CityScapes, {WEIGHTS_FILE} (TensorFlow DeepLab model zoo; "
            "no automatic download: place the file yourself)")
SIZE = 513


@dataclass
class DeepLabTFLiteParams:
    """Parameters of image model ``deeplab_edgetpu_tflite``."""

    weights_path: str = param("", path=True,
                              help="The .tflite model file, or a folder holding it; empty = search the default "
                                   "model folders, as for efficientvit_b0 (no automatic download).")
    weights_sha256: str = param("",
                                help="Expected sha256 of the model file; empty = the known file's hash when "
                                     "weights_path is empty, no check for a given path.")
    threads: int = param(0, ge=0, help="Interpreter CPU threads; 0 = the runtime's default.")
    resize_mode: str = param("stretch", choices=("stretch", "pad"),
                             help="How an image becomes the model's 513x513 input: stretch it, or pad it (aspect "
                                  "ratio kept, grey padding).")


def litert_available() -> bool:
    try:
        from ai_edge_litert.interpreter import Interpreter  # noqa: F401
    except ImportError:
        return False
    return True


class DeepLabTFLiteModel:
    classes = list(CITYSCAPES_CLASSES)

    def __init__(self, params: DeepLabTFLiteParams):
        from twinkit_efficientvit.weights import resolve_weights

        try:
            from ai_edge_litert.interpreter import Interpreter
        except ImportError as exc:
            raise InputError(
                "image model deeplab_edgetpu_tflite needs the 'ai-edge-litert' package: "
                "pip install 'twinkit-efficientvit[tflite]'"
            ) from exc
        if params.resize_mode not in ("stretch", "pad"):
            raise ValueError(f"resize_mode must be 'stretch' or 'pad', got {params.resize_mode!r}")
        self.params = params
        self.weights_path = resolve_weights(
            WEIGHTS_FILE, params.weights_path, params.weights_sha256, WEIGHTS_SHA256, OFFICIAL,
            url="", download_if_missing=False,
        )
        try:
            self.interp = Interpreter(model_path=str(self.weights_path),
                                      num_threads=params.threads if params.threads > 0 else None)
            self.interp.allocate_tensors()
        except Exception as exc:
            raise InputError(f"weights file {self.weights_path} is not a usable TFLite model: {exc}") from exc
        inp = self.interp.get_input_details()[0]
        if tuple(inp["shape"]) != (1, SIZE, SIZE, 3) or inp["dtype"] != np.uint8:
            raise InputError(f"{self.weights_path}: expected a 1x{SIZE}x{SIZE}x3 uint8 input, got {inp['shape']} {inp['dtype']}")
        self._in = inp["index"]
        self._out = self.interp.get_output_details()[0]["index"]

    def __repr__(self) -> str:
        return f"DeepLabTFLiteModel(weights={self.weights_path}, threads={self.params.threads})"

    def _one(self, image: np.ndarray) -> np.ndarray:
        from PIL import Image

        h, w, _ = image.shape
        if self.params.resize_mode == "stretch":
            nh = nw = SIZE
        else:
            scale = SIZE / max(h, w)
            nh, nw = max(1, round(h * scale)), max(1, round(w * scale))
        canvas = np.full((SIZE, SIZE, 3), 128, dtype=np.uint8)
        canvas[:nh, :nw] = np.asarray(Image.fromarray(image).resize((nw, nh), Image.BILINEAR))
        self.interp.set_tensor(self._in, canvas[None])
        self.interp.invoke()
        labels = self.interp.get_tensor(self._out)[0, :nh, :nw]
        labels = np.where((labels >= 0) & (labels < N_CLASSES), labels, IGNORE_ID).astype(np.uint8)
        return np.asarray(Image.fromarray(labels).resize((w, h), Image.NEAREST))

    def predict(self, images) -> np.ndarray:
        """``images (b, h, w, 3) uint8 RGB -> (b, h, w) uint8`` trainIds (one image per invoke)."""
        batch = as_batch(images)
        return np.stack([self._one(im) for im in batch])

    def predict_proba(self, images) -> np.ndarray:
        """One-hot ``(b, 19, h, w) float16`` (the network outputs only its argmax)."""
        labels = self.predict(images)
        out = (labels[:, None] == np.arange(N_CLASSES, dtype=np.uint8)[None, :, None, None])
        return out.astype(np.float16)


def build_deeplab_tflite(params: DeepLabTFLiteParams | None = None) -> DeepLabTFLiteModel:
    """EdgeTPU-DeepLab-slim CityScapes, int8 TFLite, 513x513 (needs ai-edge-litert)."""
    return DeepLabTFLiteModel(params or DeepLabTFLiteParams())
