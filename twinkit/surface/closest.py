"""Closest points on a triangle surface (open3d RaycastingScene, BVH on the CPU) and
attribute transfer by barycentric interpolation."""
from __future__ import annotations

import numpy as np

from .compiled import ahead


class Surface:
    """A triangle mesh for closest-point queries. vertices (n, 3) float64, faces (m, 3) int."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, threads: int = 0):
        import open3d as o3d

        self.vertices = vertices
        self.faces = np.asarray(faces, np.int64)
        #: threads of the BVH build and of the queries (0: all cores)
        self.threads = max(0, int(threads))
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=self.threads)
        self.scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
                                 o3d.core.Tensor(np.ascontiguousarray(faces, np.uint32)))

    def closest(self, query: np.ndarray, chunk: int = 2_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (q, 3) points: (face id (q,) int64, barycentric weights (q, 3) float32, distance (q,) float32)."""
        import open3d as o3d

        from .compiled import compiled

        q = len(query)
        fid = np.empty(q, np.int64)
        bary = np.empty((q, 3), np.float32)
        dist = np.empty(q, np.float32)
        loop = compiled(_closest_loop)
        for s in range(0, q, chunk):
            part = np.ascontiguousarray(query[s:s + chunk], np.float32)
            ans = self.scene.compute_closest_points(o3d.core.Tensor(part), nthreads=self.threads)
            ids = ans["primitive_ids"].numpy()
            uv = ans["primitive_uvs"].numpy()
            pts = ans["points"].numpy()
            e = s + len(part)
            if loop is not None:
                loop(ids, uv, pts, part, fid[s:e], bary[s:e], dist[s:e])
                continue
            fid[s:e] = ids
            bary[s:e, 0] = 1.0 - uv[:, 0] - uv[:, 1]
            bary[s:e, 1] = uv[:, 0]
            bary[s:e, 2] = uv[:, 1]
            dist[s:e] = np.linalg.norm(pts - part, axis=1)
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
            ans = self.scene.compute_closest_points(o3d.core.Tensor(part), nthreads=self.threads)
            fid[s:s + len(part)] = ans["primitive_ids"].numpy()
            pts[s:s + len(part)] = ans["points"].numpy()
            dist[s:s + len(part)] = np.linalg.norm(pts[s:s + len(part)] - part, axis=1)
        return fid, pts, dist

    def interpolate(self, values: np.ndarray, fid: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Per-vertex ``values`` (n, c) interpolated at (face id, barycentric) -> (q, c) float32."""
        return barycentric_mix(values, self.faces, fid, bary, np.float32)

    def distance(self, query: np.ndarray, chunk: int = 2_000_000) -> np.ndarray:
        """Unsigned distance (q,) float32 from points to the surface."""
        import open3d as o3d

        out = np.empty(len(query), np.float32)
        for s in range(0, len(query), chunk):
            part = np.ascontiguousarray(query[s:s + chunk], np.float32)
            out[s:s + len(part)] = self.scene.compute_distance(o3d.core.Tensor(part), nthreads=self.threads).numpy()
        return out


@ahead("(uint32[::1], float32[:, ::1], float32[:, ::1], float32[:, ::1], int64[::1], float32[:, ::1], float32[::1])")
def _closest_loop(ids, uv, pts, part, fid, bary, dist):
    """:meth:`Surface.closest`'s unpacking of open3d's answer, one point at a time (compiled): the same
    float32 arithmetic as its numpy lines (the distance's squares summed x, y, z in order)."""
    one = np.float32(1.0)
    for k in range(len(ids)):
        fid[k] = ids[k]
        u, v = uv[k, 0], uv[k, 1]
        bary[k, 0] = one - u - v
        bary[k, 1] = u
        bary[k, 2] = v
        dx, dy, dz = pts[k, 0] - part[k, 0], pts[k, 1] - part[k, 1], pts[k, 2] - part[k, 2]
        dist[k] = np.sqrt(dx * dx + dy * dy + dz * dz)


def barycentric_mix(values: np.ndarray, faces: np.ndarray, fid: np.ndarray, bary: np.ndarray,
                    dtype=np.float32) -> np.ndarray:
    """Per-vertex ``values`` (n, c) at points given by (face id (q,), barycentric (q, 3)) -> (q, c) ``dtype``:
    b0 v0 + b1 v1 + b2 v2 summed in that order in ``dtype`` (a compiled loop when numba is installed,
    else numpy; the same numbers)."""
    from .compiled import compiled

    vals = np.asarray(values).astype(dtype, copy=False)
    out = np.zeros((len(fid), vals.shape[1]), dtype)
    loop = compiled(_mix_loop)
    bary = np.asarray(bary)
    # float64 weights into float32 sums round after each product in numpy: that case stays numpy
    if loop is not None and len(fid) and (bary.dtype == np.float32 or np.dtype(dtype) == np.float64):
        loop(vals, np.asarray(faces), np.asarray(fid), bary, out)
        return out
    tri = faces[fid]
    for i in range(3):
        out += bary[:, i:i + 1] * vals[tri[:, i]]
    return out


@ahead("(float64[:, ::1], int64[:, ::1], int64[::1], float32[:, ::1], float64[:, ::1])",
       "(float32[:, ::1], int64[:, ::1], int64[::1], float32[:, ::1], float32[:, ::1])")
def _mix_loop(vals, faces, fid, bary, out):
    """``out[k] += bary[k, i] * vals[faces[fid[k], i]]`` for i = 0, 1, 2 (compiled)."""
    for k in range(len(fid)):
        f = fid[k]
        for j in range(out.shape[1]):
            acc = out[k, j]
            for i in range(3):
                acc += bary[k, i] * vals[faces[f, i], j]
            out[k, j] = acc
