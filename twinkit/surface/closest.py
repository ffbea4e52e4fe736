"""Closest points on a triangle surface (open3d RaycastingScene, BVH on the CPU) and
attribute transfer by barycentric interpolation."""
from __future__ import annotations

import numpy as np


class Surface:
    """A triangle mesh for closest-point queries. vertices (n, 3) float64, faces (m, 3) int."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, threads: int = 0):
        import open3d as o3d

        self.vertices = vertices
        self.faces = np.asarray(faces, np.int64)
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=max(0, int(threads)))
        self.scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
                                 o3d.core.Tensor(np.ascontiguousarray(faces, np.uint32)))

    def closest(self, query: np.ndarray, chunk: int = 2_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (q, 3) points: (face id (q,) int64, barycentric weights (q, 3) float32, distance (q,) float32)."""
        import open3d as o3d

        q = len(query)
        fid = np.empty(q, np.int64)
        bary = np.empty((q, 3), np.float32)
        dist = np.empty(q, np.float32)
        for s in range(0, q, chunk):
            part = np.ascontiguousarray(query[s:s + chunk], np.float32)
            ans = self.scene.compute_closest_points(o3d.core.Tensor(part))
            ids = ans["primitive_ids"].numpy().astype(np.int64)
            uv = ans["primitive_uvs"].numpy()
            pts = ans["points"].numpy()
            fid[s:s + len(part)] = ids
            bary[s:s + len(part), 0] = 1.0 - uv[:, 0] - uv[:, 1]
            bary[s:s + len(part), 1] = uv[:, 0]
            bary[s:s + len(part), 2] = uv[:, 1]
            dist[s:s + len(part)] = np.linalg.norm(pts - part, axis=1)
        return fid, bary, dist

    def nearest(self, query: np.ndarray, chunk: int = 2_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (q, 3) points: (face id (q,) int64, closest point (q, 3) float32, distance (q,) float32)."""
        import open3d as o3d

        q = len(query)
        fid = np.empty(q, np.int64)
        pts = np.empty((q, 3), np.float32)
        dist = np.empty(q, np.float32)
        for s in range(0, q, chunk):
            part = np.ascontiguousarray(query[s:s + chunk], np.float32)
            ans = self.scene.compute_closest_points(o3d.core.Tensor(part))
            fid[s:s + len(part)] = ans["primitive_ids"].numpy()
            pts[s:s + len(part)] = ans["points"].numpy()
            dist[s:s + len(part)] = np.linalg.norm(pts[s:s + len(part)] - part, axis=1)
        return fid, pts, dist

    def interpolate(self, values: np.ndarray, fid: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Per-vertex ``values`` (n, c) interpolated at (face id, barycentric) -> (q, c) float32."""
        tri = self.faces[fid]
        out = np.zeros((len(fid), values.shape[1]), np.float32)
        for i in range(3):
            out += bary[:, i:i + 1] * values[tri[:, i]].astype(np.float32)
        return out

    def distance(self, query: np.ndarray, chunk: int = 2_000_000) -> np.ndarray:
        """Unsigned distance (q,) float32 from points to the surface."""
        import open3d as o3d

        out = np.empty(len(query), np.float32)
        for s in range(0, len(query), chunk):
            part = np.ascontiguousarray(query[s:s + chunk], np.float32)
            out[s:s + len(part)] = self.scene.compute_distance(o3d.core.Tensor(part)).numpy()
        return out
