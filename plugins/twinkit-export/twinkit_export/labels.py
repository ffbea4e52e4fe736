"""Ground-truth labels on the reconstructed mesh (stand-in until segmentation lands): the labelled PLY's reader;
the transfer itself is twinkit.street.truth."""
from __future__ import annotations

import numpy as np


def labelled_arrays(m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n,3) f64, faces (m,3) i64, labels (n,) u8) of a ground-truth mesh (``gt_mesh.ply`` read by
    :func:`twinkit.artefacts.read_gt_mesh`) with a per-vertex ``label``; ValueError without one."""
    key = next((k for k in ("label", "labels", "class", "class_id", "scalar_label") if k in m.attrs), None)
    if key is None:
        raise ValueError(f"no per-vertex label property (have {sorted(m.attrs)})")
    if m.faces is None or not len(m.faces):
        raise ValueError("no faces")
    return m.vertices, m.faces, np.asarray(m.attrs[key]).astype(np.uint8)
