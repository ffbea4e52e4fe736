"""deeplab_edgetpu_tflite: the optional third model (skips without ai-edge-litert or ../shared)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ai_edge_litert", reason="optional dependency ai-edge-litert is not installed")


def test_deeplab_tflite_on_lund(lund_images, tflite_weights):
    from twinkit_efficientvit.tflite import DeepLabTFLiteParams, build_deeplab_tflite

    model = build_deeplab_tflite(DeepLabTFLiteParams(weights_path=str(tflite_weights), threads=1))
    _, images = lund_images
    labels = model.predict(images)
    assert labels.shape == images.shape[:3] and labels.dtype == np.uint8 and labels.max() < 19
    h, w = labels.shape[1:]
    road = [float((lab[int(0.85 * h):, int(0.4 * w):int(0.6 * w)] == 0).mean()) for lab in labels]
    upper = [float(np.isin(lab[: int(0.05 * h)], [2, 8, 10]).mean()) for lab in labels]
    # a coarser model: road is as clear as with EfficientViT, the top rows only on average
    # (it calls much of this sky "building", some "traffic sign" or "train")
    assert min(road) > 0.75, road
    assert np.mean(upper) > 0.7, upper
    proba = model.predict_proba(images[:1])
    assert proba.shape == (1, 19, h, w) and proba.dtype == np.float16
    assert np.array_equal(proba.argmax(1), labels[:1])


def test_deeplab_tflite_missing_file(tmp_path):
    from twinkit.errors import InputError
    from twinkit_efficientvit.tflite import DeepLabTFLiteParams, build_deeplab_tflite

    with pytest.raises(InputError, match="does not exist"):
        build_deeplab_tflite(DeepLabTFLiteParams(weights_path=str(tmp_path / "x.tflite")))
