"""Fixtures for the image-model tests.

Real data comes from ``../shared`` next to the repo root (model weights, lund_street
photos); every test that needs it skips with the reason when it is absent. Works
with ``--import-mode=importlib`` (test modules import nothing from here; they use fixtures).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

PLUGIN_DIR = Path(__file__).resolve().parents[1]
REPO_ROOT = PLUGIN_DIR.parents[1]
SHARED = (REPO_ROOT / ".." / "shared").resolve()
MODELS = SHARED / "models"
LUND = SHARED / "data" / "photos" / "lund_street"
EVIT_FILE = MODELS / "efficientvit_seg_b0_cityscapes.pt"
KEYS_TSV = MODELS / "efficientvit_seg_b0_cityscapes.keys.tsv"
TFLITE_FILE = MODELS / "deeplab_mobilenet_edgetpu_slim_cityscapes_quant.tflite"


def need(path: Path) -> Path:
    """Skip the calling test (with the reason) unless ``path`` exists."""
    if not path.exists():
        pytest.skip(f"needs {path} (the ../shared folder next to the repo); not present on this machine")
    return path


def load_lund(size=(1024, 768)) -> tuple[list[str], np.ndarray]:
    """All lund_street photos as ``(29, h, w, 3)`` uint8, resized to ``size`` (w, h), multiples of 32."""
    from PIL import Image

    files = sorted(need(LUND).glob("*.jpg"))
    images = []
    for f in files:
        im = Image.open(f).convert("RGB")
        if im.size != size:
            im = im.resize(size, Image.BILINEAR)
        images.append(np.asarray(im))
    return [f.name for f in files], np.stack(images)


@pytest.fixture(scope="session", autouse=True)
def onnx_cache(tmp_path_factory) -> Path:
    """The download cache (where the ONNX export goes) in a folder of this test session, not ~/.cache."""
    import os

    folder = tmp_path_factory.mktemp("cache")
    old = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(folder)
    yield folder / "twinkit" / "models"
    if old is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = old


@pytest.fixture(scope="session")
def evit_weights() -> Path:
    return need(EVIT_FILE)


@pytest.fixture(scope="session")
def keys_tsv() -> Path:
    return need(KEYS_TSV)


@pytest.fixture(scope="session")
def tflite_weights() -> Path:
    return need(TFLITE_FILE)


@pytest.fixture(scope="session")
def evit_model(evit_weights):
    pytest.importorskip("torch")
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    return build_efficientvit(EfficientViTParams(weights_path=str(evit_weights), threads=1, batch_size=4, device="cpu"))


@pytest.fixture(scope="session")
def evit_model_512(evit_weights):
    """The same model with the network input's long side at 512 px (cheaper tests)."""
    pytest.importorskip("torch")
    from twinkit_efficientvit.efficientvit import EfficientViTParams, build_efficientvit

    return build_efficientvit(EfficientViTParams(weights_path=str(evit_weights), threads=1, batch_size=4, device="cpu",
                                                 input_long_side_px=512))


@pytest.fixture(scope="session")
def lund_images():
    """(names, images (29, 768, 1024, 3) uint8)."""
    return load_lund()


_SHARED_FIXTURES = {"evit_weights", "keys_tsv", "tflite_weights", "evit_model", "evit_model_512", "lund_images"}


def pytest_collection_modifyitems(config, items):
    """Mark tests that read ../shared with the project's ``shared`` marker (``-m "not shared"`` skips them)."""
    here = Path(__file__).resolve().parent
    for item in items:
        if Path(str(item.fspath)).resolve().parent == here and _SHARED_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.shared)
