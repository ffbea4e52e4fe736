"""EfficientViT-Seg-B0: strict load, real-photo sanity, batching, probabilities."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from twinkit.cityscapes import BUILDING, ROAD, SKY, VEGETATION

torch = pytest.importorskip("torch")


def test_architecture_matches_key_listing(keys_tsv):
    """Every name, shape and dtype in the published key listing, and nothing else."""
    from twinkit_efficientvit.model import efficientvit_seg_b0_cityscapes

    rows = [line.split("\t") for line in keys_tsv.read_text().splitlines() if line.strip()]
    expected = {name: (tuple(int(v) for v in shape.strip("()").split(",") if v.strip()), dtype) for name, shape, dtype in rows}
    got = {k: (tuple(v.shape), str(v.dtype)) for k, v in efficientvit_seg_b0_cityscapes().state_dict().items()}
    assert got == expected
    n_params = sum(p.numel() for p in efficientvit_seg_b0_cityscapes().parameters())
    assert 0.65e6 < n_params < 0.75e6  # "0.7 M parameters"


def test_strict_load(evit_weights):
    from twinkit_efficientvit.model import efficientvit_seg_b0_cityscapes

    state = torch.load(evit_weights, map_location="cpu", weights_only=True)["state_dict"]
    net = efficientvit_seg_b0_cityscapes()
    result = net.load_state_dict(state, strict=True)
    assert not result.missing_keys and not result.unexpected_keys
    with torch.inference_mode():
        out = net.eval()(torch.zeros(1, 3, 64, 96))
    assert out.shape == (1, 19, 8, 12)


def test_fused_network_matches_loaded(evit_weights):
    """The optimised (BatchNorm folded, channels-last) network gives the same logits."""
    from twinkit_efficientvit.model import efficientvit_seg_b0_cityscapes, fuse_for_inference

    net = efficientvit_seg_b0_cityscapes().eval()
    net.load_state_dict(torch.load(evit_weights, map_location="cpu", weights_only=True)["state_dict"], strict=True)
    fused = fuse_for_inference(copy.deepcopy(net)).to(memory_format=torch.channels_last)
    x = torch.randn(2, 3, 128, 192, generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        a, b = net(x), fused(x.contiguous(memory_format=torch.channels_last))
    assert torch.allclose(a, b, atol=2e-3, rtol=1e-3), (a - b).abs().max()


def test_lund_street_sanity(evit_model, lund_images):
    """On every lund_street photo: bottom-centre is road; the top rows are sky, building or vegetation."""
    names, images = lund_images
    assert len(names) == 29
    labels = evit_model.predict(images)
    assert labels.shape == images.shape[:3] and labels.dtype == np.uint8
    h, w = labels.shape[1:]
    report = []
    for name, lab in zip(names, labels):
        bottom = lab[int(0.85 * h):, int(0.4 * w):int(0.6 * w)]
        top = lab[: int(0.05 * h)]
        road = float((bottom == ROAD).mean())
        upper = float(np.isin(top, [SKY, BUILDING, VEGETATION]).mean())
        report.append((name, road, upper))
    bad = [(n, f"road {r:.2f}", f"sky/building/vegetation {u:.2f}") for n, r, u in report if r < 0.75 or u < 0.85]
    assert not bad, bad
    # and overall: most of the bottom-centre is road, most of the top is sky/building/vegetation
    assert np.mean([r for _, r, _ in report]) > 0.95
    assert np.mean([u for _, _, u in report]) > 0.95


def test_batched_equals_unbatched(evit_model_512, lund_images):
    _, images = lund_images
    sub = images[[0, 7, 14, 28, 3]]  # 5 images: a chunk of 4 + a chunk of 1
    batched = evit_model_512.predict(sub)
    single = np.concatenate([evit_model_512.predict(sub[i : i + 1]) for i in range(len(sub))])
    agree = float((batched == single).mean())
    assert agree > 0.9999, agree  # identical in practice; allow float-rounding ties


def test_predict_proba(evit_model_512, lund_images):
    _, images = lund_images
    sub = images[:2, ::2, ::2].copy()  # 384x512
    proba = evit_model_512.predict_proba(sub)
    assert proba.shape == (2, 19, 384, 512) and proba.dtype == np.float16
    sums = proba.astype(np.float32).sum(1)
    assert np.allclose(sums, 1.0, atol=5e-3)
    labels = evit_model_512.predict(sub)
    assert float((proba.argmax(1) == labels).mean()) > 0.999  # float16 ties may differ


def test_input_resizing_and_threads(evit_weights):
    """Odd sizes are resized to multiples of 32 inside, outputs come back at input size."""
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    model = build_efficientvit(EfficientViTParams(weights_path=str(evit_weights), threads=1, batch_size=2,
                                                  input_long_side_px=256, device="cpu"))
    before = torch.get_num_threads()
    images = np.random.default_rng(0).integers(0, 256, (3, 101, 203, 3), dtype=np.uint8)
    labels = model.predict(images)
    assert labels.shape == (3, 101, 203) and labels.dtype == np.uint8 and labels.max() < 19
    assert torch.get_num_threads() == before  # thread count restored after the call
    assert model.classes[0] == "road" and model.classes[10] == "sky" and len(model.classes) == 19
    with pytest.raises(ValueError, match=r"\(b, h, w, 3\)"):
        model.predict(images[0])
    with pytest.raises(ValueError, match="uint8"):
        model.predict(images.astype(np.float32))


def test_network_size_rounding():
    from twinkit_efficientvit.common import network_size

    assert network_size(768, 1024, 1024, 32) == (768, 1024)
    assert network_size(2128, 2832, 1024, 32) == (768, 1024)
    assert network_size(101, 203, 0, 32) == (96, 192)
    assert network_size(10, 10, 0, 32) == (32, 32)


def test_flip_tta_is_mirror_equivariant(evit_weights, lund_images):
    """With flip_tta the logits are averaged over the image and its mirror image, so the
    labels of a mirrored photo are the mirrored labels (without it they differ a little)."""
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    _, images = lund_images
    sub = np.ascontiguousarray(images[:2, ::4, ::4])  # 192x256
    kw = dict(weights_path=str(evit_weights), threads=1, device="cpu", input_long_side_px=256)
    tta = build_efficientvit(EfficientViTParams(flip_tta=True, **kw))
    plain = build_efficientvit(EfficientViTParams(**kw))
    a = tta.predict(sub)
    b = tta.predict(np.ascontiguousarray(sub[:, :, ::-1]))[:, :, ::-1]
    assert float((a == b).mean()) > 0.999  # float-rounding ties only
    assert float((a == plain.predict(sub)).mean()) > 0.8  # the same model, not another one
