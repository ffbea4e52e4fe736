"""The shipped 3D classifier: a small multi-layer perceptron over :mod:`.features`, run in plain numpy.

The model is two files beside this module: ``geometry_model.npz`` (the layers ``W0, b0, W1, b1, ...``
(float32), the feature normalisation ``mean``/``std`` (float32, one per feature)) and ``geometry_model.json``
(the feature names, the classes (trainIds) of the output columns, the training recipe and the validation
scores it reached). ``python -m twinkit_segmentation.geometry.train`` writes both.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twinkit.cityscapes import N_CLASSES

MODEL_DIR = Path(__file__).parent
MODEL_NAME = "geometry_model"
#: the ground model shipped beside it: road, sidewalk and terrain alone, trained on captures whose intensity
#: follows each surface's material (:func:`.classify.split_ground`)
GROUND_MODEL_NAME = "ground_model"

@dataclass
class GeometryModel:
    """A loaded MLP: ``layers`` [(W (in, out) float32, b (out,) float32), ...] with ReLU between them,
    ``mean``/``std`` (k,) the feature normalisation, ``classes`` (c,) trainIds of the outputs,
    ``feature_names`` the features it expects (in order), ``meta`` the rest of the JSON, ``logit_shift`` (c,)
    float32 added to the outputs before the softmax (the class-prior correction :func:`.train.prior_shift` chose;
    None for a model without one)."""

    layers: list
    mean: np.ndarray
    std: np.ndarray
    classes: np.ndarray
    feature_names: list
    meta: dict = field(default_factory=dict)
    logit_shift: np.ndarray | None = None

    def columns(self) -> np.ndarray | None:
        """Indices into :func:`.features.feature_names`' columns of the features this model reads, in its order;
        None when it reads them all as they are. A model trained before features were added reads its own
        columns of the newer matrix. Raises ValueError naming the first feature the code no longer computes."""
        from .features import feature_names

        names = feature_names()
        if list(self.feature_names) == names:
            return None
        missing = [n for n in self.feature_names if n not in names]
        if missing:
            raise ValueError(f"the 3D classifier's model reads features this code does not compute ({missing[0]}, "
                             f"{len(missing)} in all); retrain it (python -m twinkit_segmentation.geometry.train)")
        return np.array([names.index(n) for n in self.feature_names])

    def proba(self, values: np.ndarray, chunk: int = 200_000, prior: bool = True) -> np.ndarray:
        """(m, k) features (all of :func:`.features.feature_names`, or the model's own) -> (m, 19) float32 class
        probabilities (columns of classes it never predicts: 0); ``prior`` False leaves out :attr:`logit_shift`
        (the class balance the network was trained with)."""
        if np.ndim(values) == 2 and np.shape(values)[1] != len(self.mean):
            cols = self.columns()
            values = np.asarray(values)[:, cols] if cols is not None else values
        out = np.zeros((len(values), N_CLASSES), np.float32)
        for a in range(0, len(values), chunk):
            x = (np.asarray(values[a:a + chunk], np.float32) - self.mean) / self.std
            for i, (w, b) in enumerate(self.layers):
                x = x @ w + b
                if i < len(self.layers) - 1:
                    np.maximum(x, 0, out=x)
            if prior and self.logit_shift is not None:
                x += self.logit_shift
            x -= x.max(axis=1, keepdims=True)
            np.exp(x, out=x)
            x /= x.sum(axis=1, keepdims=True)
            out[a:a + chunk, self.classes] = x
        return out


def save_model(path_stem: Path, layers, mean, std, classes, feature_names, meta: dict) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` and ``<stem>.json``; returns both paths."""
    path_stem = Path(path_stem)
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {"mean": np.asarray(mean, np.float32), "std": np.asarray(std, np.float32)}
    for i, (w, b) in enumerate(layers):
        arrays[f"W{i}"] = np.asarray(w, np.float32)
        arrays[f"b{i}"] = np.asarray(b, np.float32)
    npz = path_stem.with_suffix(".npz")
    np.savez_compressed(npz, **arrays)
    js = path_stem.with_suffix(".json")
    js.write_text(json.dumps({**meta, "classes": [int(c) for c in classes], "feature_names": list(feature_names)},
                             indent=1) + "\n")
    return npz, js


def model_problem(path_stem: str | Path) -> str | None:
    """One line saying what is missing of the model ``<stem>.json`` + ``<stem>.npz`` and how to fix it; None when
    both are there."""
    stem = Path(path_stem).expanduser().with_suffix("")
    missing = [str(stem.with_suffix(s)) for s in (".json", ".npz") if not stem.with_suffix(s).is_file()]
    if not missing:
        return None
    return (f"no 3D classifier model at {stem}: {' and '.join(missing)} missing; give the stem (the path without "
            ".npz/.json) of a model python -m twinkit_segmentation.geometry.train wrote, or leave the parameter "
            "empty for the shipped one")


def load_model(path_stem: str | Path | None = None, default: str = MODEL_NAME) -> GeometryModel:
    """Load ``<stem>.npz`` + ``<stem>.json`` (default: the model ``default`` shipped beside this module).
    Raises :class:`twinkit.errors.InputError` naming the files when either is missing (:func:`model_problem`)."""
    from twinkit.errors import InputError

    stem = Path(path_stem) if path_stem else MODEL_DIR / default
    stem = stem.with_suffix("")
    problem = model_problem(stem)
    if problem:
        raise InputError(problem)
    meta = json.loads(stem.with_suffix(".json").read_text())
    with np.load(stem.with_suffix(".npz")) as z:
        n = sum(1 for k in z.files if k.startswith("W"))
        layers = [(z[f"W{i}"], z[f"b{i}"]) for i in range(n)]
        mean, std = z["mean"], z["std"]
    shift = meta.get("prior", {}).get("logit_shift")
    return GeometryModel(layers=layers, mean=mean, std=std, classes=np.asarray(meta.pop("classes"), np.int64),
                         feature_names=meta.pop("feature_names"), meta=meta,
                         logit_shift=None if shift is None else np.asarray(shift, np.float32))
