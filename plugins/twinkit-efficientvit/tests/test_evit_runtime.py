"""The fast paths of efficientvit_b0: labels from stride-8 logits cell by cell, and ONNX Runtime against torch."""
from __future__ import annotations

import os

import numpy as np
import pytest

from twinkit.errors import InputError

torch = pytest.importorskip("torch")


def _torch_labels(logits, size):
    import torch.nn.functional as F

    return F.interpolate(logits, size=size, mode="bilinear", align_corners=False).argmax(1).to(torch.uint8)


@pytest.mark.parametrize("shape,size", [((2, 19, 8, 12), (64, 96)), ((1, 19, 64, 128), (512, 1024)),
                                        ((1, 5, 7, 9), (28, 36)), ((1, 19, 3, 5), (12, 20)),
                                        ((1, 19, 6, 6), (50, 50)), ((1, 19, 8, 12), (24, 36))])
def test_upsample_argmax_equals_torch(shape, size):
    """Even integer factors take the cell-wise path, the rest torch's; both give torch's labels."""
    from twinkit_efficientvit.upsample import upsample_argmax

    g = torch.Generator().manual_seed(sum(shape))
    rough = torch.randn(*shape, generator=g)  # every cell mixed
    smooth = torch.nn.functional.interpolate(torch.randn(shape[0], shape[1], 2, 3, generator=g) * 4, size=shape[2:],
                                             mode="bicubic", align_corners=False)  # regions, as a real view
    for logits in (rough, smooth):
        got = upsample_argmax(logits, size)
        assert got.dtype == torch.uint8 and tuple(got.shape) == (shape[0], *size)
        assert float((got != _torch_labels(logits, size)).float().mean()) <= 1e-4


def test_upsample_argmax_wrong_cell_would_show():
    """A cell whose corners disagree is blended, not filled: one class peak in a corner reaches its pixels."""
    from twinkit_efficientvit.upsample import upsample_argmax

    logits = torch.zeros(1, 3, 4, 4)
    logits[0, 0] = 1.0
    logits[0, 2, 1, 1] = 5.0  # one low-res pixel of class 2
    got = upsample_argmax(logits, (32, 32))
    ref = _torch_labels(logits, (32, 32))
    assert torch.equal(got, ref)
    assert int((got == 2).sum()) == int((ref == 2).sum()) > 64  # more than its own 8x8 block


def _need_onnxruntime(backend: str = "onnxruntime"):
    from twinkit_efficientvit import onnx_net

    if not onnx_net.available(backend):
        pytest.skip(f"{backend} and onnx are not installed")


def test_onnxruntime_labels_agree_with_torch(evit_weights, lund_images, onnx_cache):
    """The ONNX Runtime network gives torch's labels on real photos (at most 0.1 % of pixels differ; measured
    0.0000 % on lund_street, 0.0003 % on demo views) and its logits to 5e-3 on a fixed image."""
    _need_onnxruntime()
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit
    from twinkit_efficientvit.onnx_net import check_against

    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu", batch_size=2)
    ort_model = build_efficientvit(EfficientViTParams(runtime="onnxruntime", **kw))
    torch_model = build_efficientvit(EfficientViTParams(runtime="torch", **kw))
    assert ort_model.runtime == "onnxruntime" and torch_model.runtime == "torch"
    assert ort_model.onnx.path.parent == onnx_cache  # written into the cache, never beside the weights
    assert check_against(torch_model.net, ort_model.onnx.sess) < 5e-3
    _, images = lund_images
    sub = images[[0, 9, 18, 27]]  # 1024x768
    differ = float((ort_model.predict(sub) != torch_model.predict(sub)).mean())
    assert differ <= 1e-3, differ
    odd = np.ascontiguousarray(images[:1, 5:400, 7:600])  # resized inside to another network size
    assert float((ort_model.predict(odd) != torch_model.predict(odd)).mean()) <= 1e-3


def test_openvino_labels_agree_with_torch_in_float32(evit_weights, lund_images, onnx_cache):
    """OpenVINO runs the same exported file in float32 and gives torch's labels on real photos (at most 0.1 % of
    pixels differ; measured 0.0000 % on lund_street, 0.0002 % on demo views); its logits are within 5e-3 of
    torch's."""
    _need_onnxruntime("openvino")
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit
    from twinkit_efficientvit.onnx_net import check_against

    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu", batch_size=1)
    ov_model = build_efficientvit(EfficientViTParams(runtime="openvino", **kw))
    torch_model = build_efficientvit(EfficientViTParams(runtime="torch", **kw))
    assert ov_model.runtime == "openvino" and ov_model.onnx.sess.backend == "openvino"
    assert check_against(torch_model.net, ov_model.onnx.sess) < 5e-3
    _, images = lund_images
    sub = images[[0, 9, 18, 27]]
    assert float((ov_model.predict(sub) != torch_model.predict(sub)).mean()) <= 1e-3
    odd = np.ascontiguousarray(images[:1, 5:400, 7:600])  # another network size: the file's shapes are dynamic
    assert float((ov_model.predict(odd) != torch_model.predict(odd)).mean()) <= 1e-3


def test_auto_prefers_openvino_then_onnxruntime_then_torch(evit_weights, onnx_cache, monkeypatch):
    """On a CPU, auto takes the first installed of OpenVINO and ONNX Runtime; with neither, torch; an explicit
    runtime whose package is missing says what to install."""
    _need_onnxruntime("openvino")
    _need_onnxruntime("onnxruntime")
    from twinkit_efficientvit import onnx_net
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu")
    assert build_efficientvit(EfficientViTParams(**kw)).runtime == "openvino"
    real = onnx_net.available
    monkeypatch.setattr(onnx_net, "available", lambda backend="onnxruntime": backend != "openvino" and real(backend))
    assert build_efficientvit(EfficientViTParams(**kw)).runtime == "onnxruntime"
    with pytest.raises(InputError, match="pip install openvino onnx"):
        build_efficientvit(EfficientViTParams(runtime="openvino", **kw))


def test_onnx_export_is_cached_and_a_damaged_file_replaced(evit_weights, onnx_cache):
    _need_onnxruntime()
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu", runtime="onnxruntime")
    path = build_efficientvit(EfficientViTParams(**kw)).onnx.path
    stamp = path.stat().st_mtime_ns
    assert build_efficientvit(EfficientViTParams(**kw)).onnx.path == path
    assert path.stat().st_mtime_ns == stamp  # used again, not exported again
    path.write_bytes(b"not an onnx file")
    model = build_efficientvit(EfficientViTParams(**kw))
    assert model.runtime == "onnxruntime" and path.stat().st_size > 1_000_000


def test_runtime_choice_without_onnxruntime(evit_weights, monkeypatch):
    """auto falls back to torch when neither OpenVINO nor ONNX Runtime is installed; an explicit onnxruntime says
    what to install."""
    from twinkit_efficientvit import onnx_net
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    monkeypatch.setattr(onnx_net, "available", lambda backend="onnxruntime": False)
    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu")
    assert build_efficientvit(EfficientViTParams(**kw)).runtime == "torch"
    with pytest.raises(InputError, match="pip install onnxruntime onnx"):
        build_efficientvit(EfficientViTParams(runtime="onnxruntime", **kw))


def test_threads_follow_the_step_budget(evit_weights, monkeypatch):
    from twinkit.threads import BUDGET_ENV
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    monkeypatch.setenv(BUDGET_ENV, "3")
    model = build_efficientvit(EfficientViTParams(weights_path=str(evit_weights), device="cpu", runtime="torch"))
    assert model.threads() == 3
    model.params.threads = 1
    assert model.threads() == 1
    assert os.environ[BUDGET_ENV] == "3"
