"""Plugin contract: entry point, registration, params as Hydra structured configs, palette."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import twinkit.plugins
from twinkit.plugins import build_component, load_registry
from twinkit.testing import check_plugin

NAMES = ("efficientvit_b0", "hf_segformer", "deeplab_edgetpu_tflite")


@pytest.fixture(autouse=True)
def only_this_plugin(monkeypatch):
    """Load just this package's entry point (other plugins in the environment may be half-installed)."""
    monkeypatch.setenv("TWINKIT_PLUGINS", "efficientvit")
    monkeypatch.setattr(twinkit.plugins, "_REGISTRY", load_registry())


def get_registry():
    return twinkit.plugins.get_registry()


def test_registered_through_entry_point():
    reg = get_registry()
    for name in NAMES:
        plugin = reg.get("image_model", name)
        assert plugin.distribution == "twinkit-efficientvit"
        check_plugin(plugin)
        assert dataclasses.is_dataclass(plugin.params)


def test_params_compose_as_structured_configs():
    from omegaconf import OmegaConf

    reg = get_registry()
    for name in NAMES:
        cfg = OmegaConf.structured(reg.get("image_model", name).params)
        assert "threads" in cfg
    hf = OmegaConf.merge(OmegaConf.structured(reg.get("image_model", "hf_segformer").params), {"label_map": {"tree": 8}})
    assert hf.label_map["tree"] == 8
    from omegaconf.errors import ConfigKeyError

    with pytest.raises(ConfigKeyError):  # a typo fails at composition
        OmegaConf.merge(OmegaConf.structured(reg.get("image_model", "efficientvit_b0").params), {"thread": 2})


def test_plugin_import_is_light():
    import subprocess
    import sys

    code = "import sys, twinkit_efficientvit.plugin; print('torch' in sys.modules, 'transformers' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_build_component_with_overrides(evit_weights):
    pytest.importorskip("torch")
    model = build_component("image_model", None, {"image_model": {"plugin": "efficientvit_b0", "threads": 1,
                                                                  "batch_size": 2, "weights_path": str(evit_weights)}})
    assert model.params.threads == 1 and model.params.batch_size == 2
    labels = model.predict(np.zeros((1, 64, 64, 3), dtype=np.uint8))
    assert labels.shape == (1, 64, 64)


def test_palette_png(tmp_path):
    from PIL import Image

    from twinkit_efficientvit.palette import CITYSCAPES_PALETTE, colorize, save_prediction_png

    labels = np.array([[0, 10], [255, 13]], dtype=np.uint8)
    rgb = colorize(labels)
    assert rgb.shape == (2, 2, 3) and tuple(rgb[0, 0]) == (128, 64, 128) and tuple(rgb[1, 0]) == (0, 0, 0)
    assert len(CITYSCAPES_PALETTE) == 19
    path = save_prediction_png(tmp_path / "p.png", np.repeat(np.repeat(labels, 20, 0), 20, 1))
    assert Image.open(path).size[1] >= 40
    path = save_prediction_png(tmp_path / "o.png", labels, image=np.zeros((2, 2, 3), np.uint8), legend=False)
    assert Image.open(path).size == (2, 2)
