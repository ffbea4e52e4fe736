"""Ground truth on another surface: the label of the nearest ground-truth face, for any set of points.

A site with a ground-truth mesh (the demo site) carries CityScapes trainIds per face and per vertex;
:func:`transfer_labels` moves them onto the reconstructed mesh's vertices (the segmentation's
``transfer_gt_labels`` step: its reference ``gt_labels.npy``, and export_demo's stand-in ``labels.npy``).
"""
from __future__ import annotations

import numpy as np


def transfer_labels(gt_vertices: np.ndarray, gt_faces: np.ndarray, points: np.ndarray, *,
                    face_labels: np.ndarray | None = None, vertex_labels: np.ndarray | None = None,
                    threads: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Label each point with the ground truth at its closest point on the ground-truth surface.

    ``gt_vertices`` (n, 3) and ``points`` (q, 3) in one frame (metres), ``gt_faces`` (m, 3). With
    ``face_labels`` (m,) the label is the closest face's; else, with ``vertex_labels`` (n,), that of the
    closest face's corner nearest the closest point (per-vertex labels are constant inside a class).
    Returns (labels (q,) uint8, distance to the surface (q,) float32, metres); the caller decides how far
    is too far to trust.
    """
    from twinkit.surface.closest import Surface

    if face_labels is None and vertex_labels is None:
        raise ValueError("transfer_labels needs face_labels or vertex_labels")
    gt_faces = np.asarray(gt_faces)
    fid, closest, dist = Surface(gt_vertices, gt_faces, threads).nearest(np.asarray(points))
    if face_labels is not None:
        return np.asarray(face_labels)[fid].astype(np.uint8), dist
    tri = gt_faces[fid]
    d = np.linalg.norm(gt_vertices[tri] - closest.astype(np.float64)[:, None, :], axis=2)
    return np.asarray(vertex_labels)[tri[np.arange(len(tri)), d.argmin(axis=1)]].astype(np.uint8), dist
