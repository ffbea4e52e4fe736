"""Conversions to open3d geometry (open3d is imported when called)."""
from __future__ import annotations

import numpy as np

from .core import Mesh


def to_o3d_mesh(mesh: Mesh):
    """``open3d.geometry.TriangleMesh`` of ``mesh`` (vertex colours when present)."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.ascontiguousarray(mesh.vertices, np.float64)),
                                  o3d.utility.Vector3iVector(np.ascontiguousarray(mesh.faces, np.int32)))
    if mesh.colors is not None:
        m.vertex_colors = o3d.utility.Vector3dVector(mesh.colors.astype(np.float64) / 255.0)
    return m


def to_o3d_cloud(points: np.ndarray, normals: np.ndarray | None = None, colors: np.ndarray | None = None):
    """``open3d.geometry.PointCloud`` of (n, 3) points with optional (n, 3) normals and uint8 colours."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points, np.float64)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals, np.float64))
    if colors is not None:
        pcd.colors = o3d.utility.Vector3dVector(colors.astype(np.float64) / 255.0)
    return pcd
