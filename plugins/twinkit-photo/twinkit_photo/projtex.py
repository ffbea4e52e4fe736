"""Texture from the photos: every texel of a UV-mapped mesh takes its colour from the photos that see it.

For each face, the photos that see its centre unoccluded (a ray cast from the photo against the mesh)
are ranked by how well they see it: ``cos(angle to the face normal) / distance``, so a close, frontal
view beats a far, grazing one. Each texel is then projected into the face's best ``max_views`` photos,
checked for occlusion again (a texel can be hidden where its face's centre is not), and the photos'
colours are blended with weights ``score ** sharpness``: the best view dominates (sharp texture), the
others soften the seams where the best view changes from one face to the next. Texels no photo sees
keep the colour they had (the bake from the dense cloud).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class PhotoView:
    name: str
    K: np.ndarray  # 3x3 at the photo's own size
    R_wc: np.ndarray  # world-from-camera rotation (OpenCV camera)
    C: np.ndarray  # centre, site frame
    image: np.ndarray  # (h, w, 3) uint8


def _project(v: PhotoView, X: np.ndarray):
    """Pixel coordinates (n, 2) (continuous, pixel (i, j) spans [i, i+1)) and depth (n,) of points X (n, 3)."""
    xc = (X - v.C) @ v.R_wc  # R_wc.T @ (X - C), row-wise
    z = xc[:, 2]
    zs = np.where(z > 1e-6, z, 1e-6)
    u = v.K[0, 0] * xc[:, 0] / zs + v.K[0, 2]
    w = v.K[1, 1] * xc[:, 1] / zs + v.K[1, 2]
    return np.stack([u, w], 1), z


def _sample(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear colour (n, 3) float32 at continuous pixel coordinates (inside the image)."""
    h, w = img.shape[:2]
    x = np.clip(uv[:, 0] - 0.5, 0, w - 1.001)
    y = np.clip(uv[:, 1] - 0.5, 0, h - 1.001)
    x0 = x.astype(np.int64)
    y0 = y.astype(np.int64)
    fx = (x - x0)[:, None].astype(np.float32)
    fy = (y - y0)[:, None].astype(np.float32)
    a = img[y0, x0].astype(np.float32) * (1 - fx) + img[y0, x0 + 1].astype(np.float32) * fx
    b = img[y0 + 1, x0].astype(np.float32) * (1 - fx) + img[y0 + 1, x0 + 1].astype(np.float32) * fx
    return a * (1 - fy) + b * fy


class _Visibility:
    """Occlusion tests against the mesh itself (open3d RaycastingScene)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, threads: int):
        import open3d as o3d

        self.o3d = o3d
        self.scene = o3d.t.geometry.RaycastingScene(nthreads=int(threads or 0))
        self.scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),
                                 o3d.core.Tensor(faces.astype(np.uint32)))

    def visible(self, C: np.ndarray, X: np.ndarray, tol_m: float, tol_rel: float) -> np.ndarray:
        d = X - C
        dist = np.linalg.norm(d, axis=1)
        rays = np.empty((len(X), 6), np.float32)
        rays[:, :3] = C
        rays[:, 3:] = d / np.maximum(dist, 1e-9)[:, None]
        t = self.scene.cast_rays(self.o3d.core.Tensor(rays))["t_hit"].numpy()
        return t >= dist - (tol_m + tol_rel * dist)


def project_texture(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, base: np.ndarray,
                    views: list[PhotoView], *, max_views: int = 3, min_cos: float = 0.15, max_dist_m: float = 40.0,
                    sharpness: float = 4.0, margin_px: float = 2.0, tol_m: float = 0.03, tol_rel: float = 0.002,
                    threads: int = 0, progress=None) -> tuple[np.ndarray, dict]:
    """Return (texture (s, s, 3) uint8, info): ``base`` with every texel a photo sees replaced by the blend of
    its best photos. ``uv`` per face corner (m, 3, 2) in [0, 1], v up; ``base`` the current texture (s, s, 3)."""
    from twinkit.surface.texture import rasterize

    size = base.shape[0]
    vis = _Visibility(vertices, faces, threads)
    tri = vertices[faces]
    cen = tri.mean(1)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    m = len(faces)
    k = max(1, int(max_views))
    best_cam = np.full((m, k), -1, np.int64)
    best_score = np.zeros((m, k), np.float32)
    # 1. per face: the photos that see its centre, ranked
    it = range(len(views))
    if progress is not None:
        it = progress(it, total=len(views), desc="photo visibility")
    for ci in it:
        v = views[ci]
        h, w = v.image.shape[:2]
        px, z = _project(v, cen)
        d = cen - v.C
        dist = np.linalg.norm(d, axis=1)
        cos = np.abs((d * nrm).sum(1)) / np.maximum(dist, 1e-9)  # Poisson meshes' normals may face either way
        cand = ((z > 0.2) & (dist < max_dist_m) & (cos > min_cos) & (px[:, 0] >= margin_px) & (px[:, 0] < w - margin_px)
                & (px[:, 1] >= margin_px) & (px[:, 1] < h - margin_px))
        idx = np.flatnonzero(cand)
        if len(idx) == 0:
            continue
        ok = vis.visible(v.C, cen[idx], tol_m, tol_rel)
        idx = idx[ok]
        score = (cos[idx] / dist[idx]).astype(np.float32)
        # insert into the per-face top-k lists
        sc = np.concatenate([best_score[idx], score[:, None]], 1)
        cam = np.concatenate([best_cam[idx], np.full((len(idx), 1), ci)], 1)
        order = np.argsort(-sc, axis=1)[:, :k]
        best_score[idx] = np.take_along_axis(sc, order, 1)
        best_cam[idx] = np.take_along_axis(cam, order, 1)
    seen_faces = int((best_cam[:, 0] >= 0).sum())
    # 2. per texel: blend the face's best photos
    out = base.copy()
    acc_w = np.zeros((size, size), np.float32)
    acc_c = np.zeros((size, size, 3), np.float32)
    texels = 0
    chunks = rasterize(uv, size)
    if progress is not None:
        chunks = progress(chunks, desc="project photos")
    for fid, bary, row, col in chunks:
        if len(fid) == 0:
            continue
        texels += len(fid)
        t = faces[fid]
        pos = (bary[:, 0:1] * vertices[t[:, 0]] + bary[:, 1:2] * vertices[t[:, 1]] + bary[:, 2:3] * vertices[t[:, 2]])
        for s in range(k):
            cams = best_cam[fid, s]
            for ci in np.unique(cams[cams >= 0]):
                sel = np.flatnonzero(cams == ci)
                v = views[ci]
                h, w = v.image.shape[:2]
                px, z = _project(v, pos[sel])
                inside = (z > 0.2) & (px[:, 0] >= 0.5) & (px[:, 0] < w - 0.5) & (px[:, 1] >= 0.5) & (px[:, 1] < h - 0.5)
                sel, px = sel[inside], px[inside]
                if len(sel) == 0:
                    continue
                ok = vis.visible(v.C, pos[sel], tol_m, tol_rel)
                sel, px = sel[ok], px[ok]
                if len(sel) == 0:
                    continue
                wgt = best_score[fid[sel], s] ** sharpness
                colr = _sample(v.image, px)
                r_, c_ = row[sel], col[sel]  # a texel centre lies in one triangle: no repeats within a batch
                acc_w[r_, c_] += wgt
                acc_c[r_, c_] += colr * wgt[:, None]
    got = acc_w > 0
    out[got] = np.clip(np.rint(acc_c[got] / acc_w[got][:, None]), 0, 255).astype(np.uint8)
    n_got = int(got.sum())
    views_used = np.bincount(best_cam[best_cam[:, 0] >= 0, 0], minlength=len(views))
    info = {"photos": len(views), "faces_seen": seen_faces, "faces_seen_ratio": round(seen_faces / max(m, 1), 4),
            "texels": texels, "texels_from_photos": n_got,
            "texels_from_photos_ratio": round(n_got / max(texels, 1), 4),
            "best_view_faces": {views[i].name: int(c) for i, c in enumerate(views_used) if c}}
    return out, info
