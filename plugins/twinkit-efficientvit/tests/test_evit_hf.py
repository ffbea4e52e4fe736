"""hf_segformer offline: tiny randomly initialised SegFormer / Mask2Former saved to a temp folder."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.errors import InputError

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

from twinkit_efficientvit.common import CITYSCAPES_CLASSES, IGNORE_ID, label_lookup  # noqa: E402
from twinkit_efficientvit.hf import HFParams, build_hf  # noqa: E402

# model labels in a different order than CityScapes, plus one label with no CityScapes counterpart
LABELS = ["sky", "Road", "side_walk", "building", "tree", "car", "person", "ceiling", "traffic-light", "bicycle"]
EXPECTED = [10, 0, 255, 2, 8, 13, 11, 255, 6, 18]  # "side_walk" -> "side walk" is not a known name


def _processor_class(name: str):
    # transformers >= 5 offers a PIL backend that needs no torchvision; older versions use the plain class
    return getattr(transformers, name + "Pil", None) or getattr(transformers, name)


@pytest.fixture(scope="module")
def tiny_segformer(tmp_path_factory):
    from transformers import SegformerConfig, SegformerForSemanticSegmentation

    folder = tmp_path_factory.mktemp("tiny_segformer")
    config = SegformerConfig(
        num_channels=3, num_encoder_blocks=2, depths=[1, 1], sr_ratios=[2, 1], hidden_sizes=[8, 16],
        patch_sizes=[7, 3], strides=[4, 2], num_attention_heads=[1, 1], mlp_ratios=[2, 2],
        decoder_hidden_size=16, id2label=dict(enumerate(LABELS)), label2id={n: i for i, n in enumerate(LABELS)},
    )
    torch.manual_seed(0)
    SegformerForSemanticSegmentation(config).save_pretrained(folder)
    _processor_class("SegformerImageProcessor")(size={"height": 64, "width": 64}).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny_mask2former(tmp_path_factory):
    from transformers import Mask2FormerConfig, Mask2FormerForUniversalSegmentation, SwinConfig

    folder = tmp_path_factory.mktemp("tiny_mask2former")
    backbone = SwinConfig(image_size=64, patch_size=4, embed_dim=16, depths=[1, 1, 1, 1], num_heads=[1, 1, 2, 2],
                          window_size=4, out_features=["stage1", "stage2", "stage3", "stage4"])
    config = Mask2FormerConfig(
        backbone_config=backbone, feature_size=32, mask_feature_size=32, hidden_dim=32, encoder_feedforward_dim=64,
        dim_feedforward=64, encoder_layers=1, decoder_layers=2, num_attention_heads=2, num_queries=8,
        id2label=dict(enumerate(CITYSCAPES_CLASSES)), label2id={n: i for i, n in enumerate(CITYSCAPES_CLASSES)},
        use_pretrained_backbone=False,
    )
    torch.manual_seed(0)
    Mask2FormerForUniversalSegmentation(config).save_pretrained(folder)
    _processor_class("Mask2FormerImageProcessor")(size={"height": 64, "width": 96}).save_pretrained(folder)
    return folder


def _images(b=3, h=50, w=70, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (b, h, w, 3), dtype=np.uint8)


def test_label_mapping_by_name():
    lut = label_lookup(dict(enumerate(LABELS)))
    assert lut.tolist() == EXPECTED
    assert label_lookup(dict(enumerate(LABELS)), {"side_walk": 1, "tree": -1}).tolist()[2:5] == [1, 2, 255]
    assert label_lookup({i: f"LABEL_{i}" for i in range(19)}).tolist() == list(range(19))
    assert label_lookup({0: "person;individual;someone", 1: "road, route"}).tolist() == [11, 0]


def test_tiny_segformer(tiny_segformer):
    model = build_hf(HFParams(model=str(tiny_segformer), threads=1, batch_size=2, device="cpu"))
    assert model.model_type == "segformer" and model.classes == CITYSCAPES_CLASSES
    images = _images()
    labels = model.predict(images)
    assert labels.shape == (3, 50, 70) and labels.dtype == np.uint8
    assert set(np.unique(labels)) <= set(EXPECTED)  # only mapped ids or 255
    proba = model.predict_proba(images)
    assert proba.shape == (3, 19, 50, 70) and proba.dtype == np.float16
    sums = proba.astype(np.float32).sum(1)
    assert (sums <= 1.0 + 1e-2).all() and (sums > 0).all()  # unmapped labels' mass dropped
    # batching: per-image results equal
    single = np.concatenate([model.predict(images[i : i + 1]) for i in range(3)])
    assert np.array_equal(single, labels)
    single_p = np.concatenate([model.predict_proba(images[i : i + 1]) for i in range(3)])
    assert np.allclose(single_p.astype(np.float32), proba.astype(np.float32), atol=2e-3)
    # where the predicted label is mapped, it is the argmax of the CityScapes probabilities
    # (a random model is nearly uniform, so compare values, not argmax: float16 makes ties)
    mapped = labels != IGNORE_ID
    at_label = np.take_along_axis(proba.astype(np.float32), np.where(mapped, labels, 0)[:, None].astype(np.int64), 1)[:, 0]
    assert (at_label[mapped] >= proba.astype(np.float32).max(1)[mapped] - 2e-3).all()


def test_tiny_segformer_own_resize(tiny_segformer):
    model = build_hf(HFParams(model=str(tiny_segformer), threads=1, input_long_side_px=96, device="cpu"))
    labels = model.predict(_images(2, 61, 117))
    assert labels.shape == (2, 61, 117) and labels.dtype == np.uint8


def test_tiny_mask2former(tiny_mask2former):
    model = build_hf(HFParams(model=str(tiny_mask2former), threads=1, batch_size=2, device="cpu"))
    assert model.model_type == "mask2former"
    images = _images()
    labels = model.predict(images)
    assert labels.shape == (3, 50, 70) and labels.dtype == np.uint8 and labels.max() < 19
    proba = model.predict_proba(images)
    assert proba.shape == (3, 19, 50, 70) and proba.dtype == np.float16
    assert np.allclose(proba.astype(np.float32).sum(1), 1.0, atol=1e-2)
    single = np.concatenate([model.predict(images[i : i + 1]) for i in range(3)])
    assert np.array_equal(single, labels)


def test_missing_model_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(InputError, match="could not load Hugging Face model"):
        build_hf(HFParams(model="no-such-org/no-such-model-for-twinkit", local_files_only=True))


def test_no_mappable_label_is_a_clear_error(tmp_path):
    from transformers import SegformerConfig, SegformerForSemanticSegmentation

    cfg = SegformerConfig(num_encoder_blocks=1, depths=[1], sr_ratios=[1], hidden_sizes=[8], patch_sizes=[7],
                          strides=[4], num_attention_heads=[1], mlp_ratios=[2], decoder_hidden_size=8,
                          id2label={0: "ceiling", 1: "floor"}, label2id={"ceiling": 0, "floor": 1})
    SegformerForSemanticSegmentation(cfg).save_pretrained(tmp_path)
    _processor_class("SegformerImageProcessor")(size={"height": 32, "width": 32}).save_pretrained(tmp_path)
    with pytest.raises(InputError, match="label_map"):
        build_hf(HFParams(model=str(tmp_path), device="cpu"))
