"""Ray casting against the ground-truth mesh (open3d RaycastingScene): hits, colours, renders.

Lighting model (used for the point colours and the photos, never for the
mesh texture, which stays albedo): ambient sky light plus a sun from the
south-west at 45 degrees elevation, with cast shadows.
"""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import IGNORE
from twinkit.mesh import Mesh
from twinkit_demo_site.textures import Atlas
from twinkit_demo_site.weathering import apply_weathering

SUN_DIR = np.array([-0.45, -0.55, 0.70])
SUN_DIR = SUN_DIR / np.linalg.norm(SUN_DIR)


class Tracer:
    def __init__(self, mesh: Mesh, atlas: Atlas, threads: int | None = None, weathering: float = 0.0,
                 seed: int = 0):
        import open3d as o3d

        self.weathering = float(weathering)
        self.seed = int(seed)

        self.o3d = o3d
        self.mesh = mesh
        self.atlas = atlas
        self.atlas_f = atlas.image.astype(np.float32)
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=int(threads or 0))
        self.scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                                 o3d.core.Tensor(mesh.faces.astype(np.uint32)))
        v = mesh.vertices[mesh.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        self.face_normals = (n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-20)).astype(np.float32)
        self.face_uv = mesh.attrs["uv"][mesh.faces].astype(np.float32)  # (m, 3, 2)
        self.face_labels = mesh.face_attrs["label"]

    # ------------------------------------------------------------------ primitives
    def cast(self, origins: np.ndarray, dirs: np.ndarray):
        """Cast rays (n, 3) float32 -> t_hit (n,) float32 (inf = miss), prim (n,) int64, bary (n, 2)."""
        rays = np.concatenate([origins, dirs], 1).astype(np.float32)
        ans = self.scene.cast_rays(self.o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy()
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        bary = ans["primitive_uvs"].numpy()
        prim[~np.isfinite(t)] = -1
        return t, prim, bary

    def closest_faces(self, points: np.ndarray) -> np.ndarray:
        """Index of the nearest triangle for each point (n, 3)."""
        ans = self.scene.compute_closest_points(self.o3d.core.Tensor(points.astype(np.float32)))
        return ans["primitive_ids"].numpy().astype(np.int64)

    def albedo(self, prim: np.ndarray, bary: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Surface colour (n, 3) float32 in [0, 1] at hits: the texture, times the world-space
        weathering at ``points`` (n, 3) when the tracer has some (see :mod:`weathering`)."""
        uv3 = self.face_uv[prim]
        b = bary.astype(np.float32)
        uv = uv3[:, 0] * (1 - b[:, :1] - b[:, 1:]) + uv3[:, 1] * b[:, :1] + uv3[:, 2] * b[:, 1:]
        col = self._sample(uv)
        if points is not None and self.weathering > 0:
            col = apply_weathering(col, points, self.weathering, self.seed)
        return col

    def _sample(self, uv: np.ndarray) -> np.ndarray:
        img = self.atlas_f
        h, w = img.shape[:2]
        flat = img.reshape(-1, 3)
        x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1.001).astype(np.float32)
        y = np.clip((1.0 - uv[:, 1]) * h - 0.5, 0, h - 1.001).astype(np.float32)
        x0 = x.astype(np.int32)
        y0 = y.astype(np.int32)
        fx = (x - x0)[:, None]
        fy = (y - y0)[:, None]
        i00 = y0 * w + x0
        a = np.take(flat, i00, axis=0)
        a += (np.take(flat, i00 + 1, axis=0) - a) * fx
        c = np.take(flat, i00 + w, axis=0)
        c += (np.take(flat, i00 + w + 1, axis=0) - c) * fx
        a += (c - a) * fy
        a *= 1.0 / 255.0
        return a

    def facing_normals(self, prim: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Face normals flipped to face the incoming ray."""
        n = self.face_normals[prim]
        flip = (n[:, 0] * dirs[:, 0] + n[:, 1] * dirs[:, 1] + n[:, 2] * dirs[:, 2]) > 0
        n[flip] *= -1
        return n

    def shade(self, points: np.ndarray, normals: np.ndarray, albedo: np.ndarray, shadows: bool = True) -> np.ndarray:
        """Lit colour (n, 3) float32 in [0, 1]."""
        sd = SUN_DIR.astype(np.float32)
        ndl = np.clip(normals[:, 0] * sd[0] + normals[:, 1] * sd[1] + normals[:, 2] * sd[2], 0, None)
        lit = ndl > 0
        if shadows and lit.any():
            o = points[lit] + normals[lit] * 0.01
            rays = np.concatenate([o, np.broadcast_to(SUN_DIR.astype(np.float32), o.shape)], 1).astype(np.float32)
            occ = self.scene.test_occlusions(self.o3d.core.Tensor(rays)).numpy().astype(bool)
            v = np.ones(len(points), np.float32)
            v[np.nonzero(lit)[0][occ]] = 0.0
            ndl = ndl * v
        sky = 0.52 + 0.12 * np.clip(normals[:, 2], 0, 1)
        light = sky[:, None] * np.array([0.93, 0.97, 1.05], np.float32) + (0.62 * ndl)[:, None] * np.array([1.05, 1.0, 0.93], np.float32)
        return np.clip(albedo * light, 0, 1)

    # ------------------------------------------------------------------ pinhole render
    def render(self, K: np.ndarray, R_wc: np.ndarray, c_w: np.ndarray, width: int, height: int,
               supersample: int = 1, shadows: bool = True):
        """Render an OpenCV pinhole view (world-from-camera rotation ``R_wc``, centre ``c_w``).

        Returns rgb (h, w, 3) uint8, label (h, w) uint8 trainId (255 = sky), depth (h, w) float32 (z, metres; inf sky).
        Labels and depth come from the pixel-centre ray; colour averages the centre ray and ``supersample``^2 more.
        """
        s = int(supersample)
        offs = [(0.5, 0.5)]
        if s > 1:
            offs += [((i + 0.5) / s, (j + 0.5) / s) for j in range(s) for i in range(s)]
        Kinv = np.linalg.inv(K).astype(np.float32)
        Rf = np.asarray(R_wc, np.float32)
        n = width * height
        rgb_acc = np.zeros((n, 3), np.float32)
        label = depth = None
        rays = np.empty((n, 6), np.float32)
        rays[:, :3] = np.asarray(c_w, np.float32)
        for k, (ox, oy) in enumerate(offs):
            u, v = np.meshgrid(np.arange(width, dtype=np.float32) + ox, np.arange(height, dtype=np.float32) + oy)
            dc = _rows_times(np.stack([u.ravel(), v.ravel(), np.ones(n, np.float32)], 1), Kinv)
            inv = 1.0 / np.sqrt(dc[:, 0] ** 2 + dc[:, 1] ** 2 + dc[:, 2] ** 2)
            dc *= inv[:, None]
            dw = _rows_times(dc, Rf)
            rays[:, 3:] = dw
            ans = self.scene.cast_rays(self.o3d.core.Tensor(rays))
            t = ans["t_hit"].numpy()
            prim = ans["primitive_ids"].numpy()
            hi = np.flatnonzero(np.isfinite(t))
            col = _sky(dw)
            if len(hi):
                ph = prim[hi].astype(np.int64)
                dh = dw[hi]
                p = rays[hi, :3] + dh * t[hi, None]
                nrm = self.facing_normals(ph, dh)
                col[hi] = self.shade(p, nrm, self.albedo(ph, ans["primitive_uvs"].numpy()[hi], p), shadows=shadows)
            rgb_acc += col
            if k == 0:
                label = np.full(n, IGNORE, np.uint8)  # sky: no surface, unlabelled
                label[hi] = self.face_labels[prim[hi]]
                depth = np.full(n, np.inf, np.float32)
                depth[hi] = t[hi] * dc[hi, 2]
        rgb = np.clip(rgb_acc * (255.0 / len(offs)) + 0.5, 0, 255).astype(np.uint8)
        return rgb.reshape(height, width, 3), label.reshape(height, width), depth.reshape(height, width)


def _rows_times(a: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``a @ M.T`` for (n, 3) x (3, 3) without numpy's slow small-matrix matmul path."""
    return a[:, 0:1] * M[:, 0] + a[:, 1:2] * M[:, 1] + a[:, 2:3] * M[:, 2]


def _sky(dirs: np.ndarray) -> np.ndarray:
    el = np.sqrt(np.clip(dirs[:, 2], 0, 1))[:, None]
    horizon = np.array([0.80, 0.86, 0.92], np.float32)
    zenith = np.array([0.38, 0.58, 0.86], np.float32)
    return horizon + (zenith - horizon) * el


def look_rotation(yaw: float, pitch: float) -> np.ndarray:
    """World-from-camera rotation (OpenCV: x right, y down, z forward) for a heading ``yaw``
    (radians from +x towards +y) and ``pitch`` (radians, up positive)."""
    f = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
    r = np.cross(f, [0, 0, 1.0])
    r /= np.linalg.norm(r)
    d = np.cross(f, r)
    return np.stack([r, d, f], 1)
