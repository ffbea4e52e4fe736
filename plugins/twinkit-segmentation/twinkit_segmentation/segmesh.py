"""Segmentation's own helpers on a :class:`twinkit.mesh.Mesh` (mesh I/O itself is twinkit.mesh's).

Conventions: vertices ``(n, 3) float64`` in the site frame (metres, z up), faces ``(m, 3) int64``,
colours ``(n, 3) uint8``, labels ``(n,) uint8`` CityScapes trainIds (255 = unlabelled), kept
in ``Mesh.attrs["label"]`` (per vertex) or ``Mesh.face_attrs["label"]`` (per face).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit import cityscapes
from twinkit.mesh import Mesh, write_colored_ply


def unit_normals(mesh: Mesh) -> np.ndarray:
    """(n, 3) float64 unit vertex normals: the stored ones, else area-weighted face normals summed per
    vertex (summed corner by corner in face order, as the segment graph weights were tuned with)."""
    if mesh.normals is not None:
        n = mesh.normals.astype(np.float64)
    else:
        v, f = mesh.vertices, mesh.faces
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        n = np.zeros_like(v)
        for c in range(3):
            np.add.at(n, f[:, c], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.maximum(norm, 1e-12)


def vertex_labels(mesh: Mesh) -> np.ndarray | None:
    """(n,) uint8 per-vertex ``label``, or None."""
    lab = mesh.attrs.get("label")
    return None if lab is None else np.asarray(lab).astype(np.uint8)


def face_labels(mesh: Mesh) -> np.ndarray | None:
    """(m,) uint8 per-face ``label``, or None."""
    lab = mesh.face_attrs.get("label")
    return None if lab is None else np.asarray(lab).astype(np.uint8)


def random_colors(n: int, seed: int = 0) -> np.ndarray:
    """Distinct-looking random colours for segment ids."""
    rng = np.random.default_rng(seed)
    return rng.integers(40, 256, size=(n, 3), dtype=np.uint8)


def write_labels_ply(path: Path, mesh: Mesh, labels: np.ndarray, comment: str = "") -> None:
    """The mesh with CityScapes palette vertex colours and the trainId as ``label``."""
    write_colored_ply(path, mesh.vertices, mesh.faces, cityscapes.colorize(labels), labels=labels,
                      comment=comment or "twinkit-segmentation labels: vertex colour = CityScapes palette, label = trainId (255 = none)")
