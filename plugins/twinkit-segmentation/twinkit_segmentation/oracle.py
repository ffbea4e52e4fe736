"""Image model ``oracle``: "predicts" the ground truth, to test sampling, rendering and back-projection exactly.

It reads the ground-truth label of the vertex each pixel sees (the renderer's per-pixel vertex
map) from a per-vertex label array (``gt_labels.npy``, handed over by ``predict_views``);
background pixels are sky. ``noise_fraction`` replaces that share of pixels by random classes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.cityscapes import N_CLASSES, SKY
from twinkit.errors import InputError
from twinkit.ranges import param


@dataclass
class OracleParams:
    noise_fraction: float = param(0.0, ge=0, le=1,
                                  help="Share of the pixels given a random class (to simulate a weaker 2D model); 0 "
                                       "= the ground truth as is.")
    seed: int = param(0, ge=0, help="Random seed of the noise.")


class OracleModel:
    needs_ground_truth = True
    needs_vertex_map = True

    def __init__(self, params: OracleParams):
        self.params = params
        self.labels = None
        self.rng = np.random.default_rng(params.seed)

    def set_ground_truth(self, labels: np.ndarray) -> None:
        self.labels = np.asarray(labels, dtype=np.uint8)

    def predict(self, images, vertex_maps=None) -> np.ndarray:
        if self.labels is None or vertex_maps is None:
            raise InputError("image_model=oracle needs per-vertex ground truth and the renders' vertex maps "
                             "(run it through predict_views with gt_labels.npy)")
        vm = np.asarray(vertex_maps)
        lut = np.append(self.labels, np.uint8(SKY))  # index -1 -> sky
        out = lut[np.where(vm >= 0, vm, len(self.labels))]
        if self.params.noise_fraction > 0:
            flip = self.rng.random(out.shape) < self.params.noise_fraction
            out[flip] = self.rng.integers(0, N_CLASSES, size=int(flip.sum()), dtype=np.uint8)
        return out

    def predict_proba(self, images, vertex_maps=None) -> np.ndarray:
        lab = self.predict(images, vertex_maps)
        p = np.zeros((lab.shape[0], N_CLASSES) + lab.shape[1:], dtype=np.float16)
        for c in range(N_CLASSES):
            p[:, c] = lab == c
        return p


def build_oracle(params: OracleParams | None = None) -> OracleModel:
    """Ground-truth labels through the renderer's vertex map (tests the 3D side exactly)."""
    return OracleModel(params or OracleParams())
