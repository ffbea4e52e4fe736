"""Pieces shared by every image model in this package (numpy-only at import time).

Contract of an image-model object (what ``twinkit_register_image_models`` builders return):

- ``classes``: the 19 CityScapes trainId names, index = trainId;
- ``predict(images (b, h, w, 3) uint8 RGB) -> (b, h, w) uint8`` trainIds at input
  resolution (255 = a pixel whose best class has no CityScapes counterpart);
- ``predict_proba(images) -> (b, 19, h, w) float16`` class probabilities.
"""
from __future__ import annotations

import contextlib
import re
from typing import Iterator

import numpy as np

from twinkit import cityscapes  # noqa: E402  (numpy-only, like this module)

#: CityScapes trainId -> name (index = trainId; the shared definition, twinkit.cityscapes).
CITYSCAPES_CLASSES: list[str] = list(cityscapes.NAMES)
N_CLASSES = cityscapes.N_CLASSES
IGNORE_ID = cityscapes.IGNORE

#: CityScapes class name -> other names for it (lower case, words separated by one space), and
#: :data:`LABEL_SYNONYMS`, every such name -> its trainId.
#: Covers the spellings of CityScapes-, ADE20K-, COCO-stuff- and Mapillary-style label sets.
_SPELLINGS: dict[str, tuple[str, ...]] = {
    "road": ("street", "roadway", "road route", "route", "lane marking general"),
    "sidewalk": ("pavement", "sidewalk pavement", "footway"),
    "building": ("house", "skyscraper", "edifice"),
    "wall": (),
    "fence": ("fencing", "guard rail", "railing"),
    "pole": ("utility pole", "street light", "streetlight", "street lamp"),
    "traffic light": ("traffic signal", "traffic light front"),
    "traffic sign": ("traffic sign front", "stop sign"),
    "vegetation": ("tree", "plant", "flora", "palm", "palm tree"),
    "terrain": ("grass", "earth", "ground", "field", "dirt", "sand"),
    "sky": (),
    "person": ("pedestrian", "people", "individual"),
    "rider": ("bicyclist", "motorcyclist", "other rider"),
    "car": ("automobile", "auto", "van"),
    "truck": ("lorry",),
    "bus": ("autobus",),
    "train": ("on rails", "tram"),
    "motorcycle": ("motorbike", "minibike"),
    "bicycle": ("bike",),
}
LABEL_SYNONYMS: dict[str, int] = {spelling: cityscapes.ID[name] for name, more in _SPELLINGS.items()
                                   for spelling in (name, *more)}


def normalise_label(name: str) -> str:
    """``"Traffic_Light"`` -> ``"traffic light"``."""
    return re.sub(r"\s+", " ", re.sub(r"[_\-]", " ", str(name).lower())).strip()


def cityscapes_id_for(name: str, extra: dict[str, int] | None = None) -> int:
    """CityScapes trainId for a label name, or :data:`IGNORE_ID` if it has none.

    ``extra`` (normalised name -> trainId, or -1/255 to ignore) overrides the table.
    Names listing alternatives (``"person;individual"``, ``"road, route"``) match if
    any alternative does.
    """
    table = {normalise_label(k): int(v) for k, v in (extra or {}).items()}
    full = normalise_label(name)
    for candidate in [full] + [normalise_label(p) for p in re.split(r"[;,/]", str(name)) if p.strip()]:
        if candidate in table:
            v = table[candidate]
            return v if 0 <= v < N_CLASSES else IGNORE_ID
        if candidate in LABEL_SYNONYMS:
            return LABEL_SYNONYMS[candidate]
    return IGNORE_ID


def label_lookup(id2label: dict[int, str], extra: dict[str, int] | None = None) -> np.ndarray:
    """Model class index -> CityScapes trainId (uint8, 255 = unmapped), as an array.

    A model with exactly 19 generic names (``LABEL_0`` ...) is taken to be in
    CityScapes trainId order.
    """
    n = max(int(k) for k in id2label) + 1 if id2label else 0
    names = {int(k): v for k, v in id2label.items()}
    if n == N_CLASSES and all(re.fullmatch(r"label_\d+", str(names.get(i, "")).lower()) for i in range(n)) and not extra:
        return np.arange(N_CLASSES, dtype=np.uint8)
    return np.array([cityscapes_id_for(names.get(i, ""), extra) for i in range(n)], dtype=np.uint8)


def as_batch(images) -> np.ndarray:
    """Check and return images as a C-contiguous ``(b, h, w, 3)`` uint8 array."""
    arr = np.asarray(images)
    if arr.ndim != 4 or arr.shape[-1] != 3:
        raise ValueError(f"images must be (b, h, w, 3) RGB, got shape {arr.shape}; add a batch axis with images[None]")
    if arr.dtype != np.uint8:
        raise ValueError(f"images must be uint8 RGB (0-255), got dtype {arr.dtype}")
    if arr.shape[0] == 0 or arr.shape[1] == 0 or arr.shape[2] == 0:
        raise ValueError(f"images must not be empty, got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def network_size(h: int, w: int, long_side_px: int, multiple_px: int) -> tuple[int, int]:
    """Network input size for an ``h x w`` image: long side scaled to ``long_side_px``
    (0 = keep the size), each side rounded to the nearest multiple of ``multiple_px`` (at least one)."""
    scale = 1.0 if long_side_px <= 0 else long_side_px / max(h, w)
    m = max(1, int(multiple_px))

    def rnd(v: float) -> int:
        return max(m, int(round(v / m)) * m)

    return rnd(h * scale), rnd(w * scale)


def chunks(n: int, size: int) -> Iterator[slice]:
    size = max(1, int(size))
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


@contextlib.contextmanager
def torch_threads(threads: int):
    """Run with ``torch.set_num_threads(threads)`` (0 = leave torch's setting), restoring it after."""
    import torch

    old = torch.get_num_threads()
    if threads and threads > 0 and threads != old:
        torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        if torch.get_num_threads() != old:
            torch.set_num_threads(old)


def resolve_device(device: str):
    """``"auto"`` -> cuda if available else cpu; ``"cpu"``/``"cuda"``/``"cuda:1"`` as given."""
    import torch

    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError(f"device={device!r} was asked for but torch sees no CUDA GPU; use device=cpu or auto")
    return torch.device(device)


def probs_to_cityscapes(probs, lookup: np.ndarray):
    """Sum model-class probabilities ``(b, L, h, w)`` (torch) into 19 CityScapes channels.

    Classes mapped to 255 are dropped (their mass is not redistributed).
    """
    import torch

    if np.array_equal(lookup, np.arange(N_CLASSES)):
        return probs
    b, _, h, w = probs.shape
    out = torch.zeros((b, N_CLASSES, h, w), dtype=probs.dtype, device=probs.device)
    idx = torch.as_tensor(lookup.astype(np.int64), device=probs.device)
    keep = idx < N_CLASSES
    out.index_add_(1, idx[keep], probs[:, keep])
    return out
