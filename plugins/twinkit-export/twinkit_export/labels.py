"""Ground-truth labels on the reconstructed mesh (stand-in until segmentation lands)."""
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


def transfer_labels(gt_vertices: np.ndarray, gt_faces: np.ndarray, gt_labels: np.ndarray,
                    query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Label each query point with the ground-truth label at its closest point on the GT surface.

    The label is that of the closest triangle's corner nearest to the closest point (per-vertex
    labels are constant inside a class). Returns (labels (q,) uint8, distances (q,) float32, metres).
    """
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(gt_vertices.astype(np.float32)), o3d.core.Tensor(gt_faces.astype(np.uint32)))
    res = scene.compute_closest_points(o3d.core.Tensor(query.astype(np.float32)))
    prim = res["primitive_ids"].numpy().astype(np.int64)
    pts = res["points"].numpy().astype(np.float64)
    tri = gt_faces[prim]  # (q, 3)
    d = np.linalg.norm(gt_vertices[tri] - pts[:, None, :], axis=2)
    corner = np.argmin(d, axis=1)
    lab = gt_labels[tri[np.arange(len(tri)), corner]]
    dist = np.linalg.norm(pts - query, axis=1).astype(np.float32)
    return lab.astype(np.uint8), dist
