"""Ground-truth labels on the reconstructed mesh (stand-in until segmentation lands): the labelled PLY's reader;
the transfer itself is twinkit.street.truth."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def read_labelled_ply(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n,3) f64, faces (m,3) i64, labels (n,) u8) of a PLY with a per-vertex ``label``."""
    from twinkit.mesh import read_ply

    m = read_ply(path)
    key = next((k for k in ("label", "labels", "class", "class_id", "scalar_label") if k in m.attrs), None)
    if key is None:
        raise ValueError(f"{path}: no per-vertex label property (have {sorted(m.attrs)})")
    if m.faces is None:
        raise ValueError(f"{path}: no faces")
    return m.vertices, m.faces, np.asarray(m.attrs[key]).astype(np.uint8)
