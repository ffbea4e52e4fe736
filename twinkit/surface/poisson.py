"""Screened Poisson surface reconstruction.

Octree depth d gives voxels of ``scene_size * scale / 2**d`` (thesis table 3.1); give
``voxel_m`` instead of a depth to get the smallest depth whose voxel is at most that size.
"""
from __future__ import annotations

import math

import numpy as np

from twinkit.mesh import Mesh


def depth_for_voxel(points: np.ndarray, voxel_m: float, scale: float = 1.1) -> int:
    """Smallest octree depth whose finest voxel is <= ``voxel_m`` metres (clamped to 5..16)."""
    size = float((points.max(axis=0) - points.min(axis=0)).max()) * scale
    return int(min(16, max(5, math.ceil(math.log2(max(size, 1e-9) / voxel_m)))))


def voxel_for_depth(points: np.ndarray, depth: int, scale: float = 1.1) -> float:
    size = float((points.max(axis=0) - points.min(axis=0)).max()) * scale
    return size / 2 ** depth


def poisson_open3d(points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None = None, *,
                   depth: int = 11, scale: float = 1.1, point_weight: float = 4.0, samples_per_node: float = 1.5,
                   linear_fit: bool = False, threads: int = -1) -> Mesh:
    """open3d's screened Poisson (Kazhdan's PoissonRecon). Returns a mesh with per-vertex
    ``colors`` (interpolated from the points, when given) and ``density`` (octree depth of
    the samples that support the vertex; low = extrapolated)."""
    import open3d as o3d

    from twinkit.mesh import to_o3d_cloud

    pcd = to_o3d_cloud(points, normals, colors)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            pcd, depth=int(depth), scale=float(scale), linear_fit=bool(linear_fit), n_threads=int(threads),
            samples_per_node=float(samples_per_node), point_weight=float(point_weight))
    out = Mesh(vertices=np.asarray(mesh.vertices, np.float64), faces=np.asarray(mesh.triangles, np.int64))
    if colors is not None and mesh.has_vertex_colors():
        out.attrs["colors"] = np.clip(np.rint(np.asarray(mesh.vertex_colors) * 255), 0, 255).astype(np.uint8)
    out.attrs["density"] = np.asarray(dens, np.float32)
    return out


def poisson_pymeshlab(points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None = None, *,
                      depth: int = 11, scale: float = 1.1, point_weight: float = 4.0, samples_per_node: float = 1.5,
                      threads: int = 2) -> Mesh:
    """MeshLab's screened Poisson (the thesis's route); needs the optional ``pymeshlab``."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    kw = {}
    if colors is not None:
        kw["v_color_matrix"] = np.hstack([colors.astype(np.float64) / 255.0, np.ones((len(colors), 1))])
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(points, np.float64),
                               v_normals_matrix=np.ascontiguousarray(normals, np.float64), **kw))
    ms.generate_surface_reconstruction_screened_poisson(depth=int(depth), scale=float(scale),
                                                        pointweight=float(point_weight),
                                                        samplespernode=float(samples_per_node),
                                                        threads=int(threads), preclean=False)
    m = ms.current_mesh()
    out = Mesh(vertices=m.vertex_matrix().astype(np.float64), faces=m.face_matrix().astype(np.int64))
    if colors is not None and m.has_vertex_color():
        out.attrs["colors"] = np.clip(np.rint(m.vertex_color_matrix()[:, :3] * 255), 0, 255).astype(np.uint8)
    q = m.vertex_scalar_array() if m.has_vertex_scalar() else None
    if q is not None:
        out.attrs["density"] = np.asarray(q, np.float32)
    return out
