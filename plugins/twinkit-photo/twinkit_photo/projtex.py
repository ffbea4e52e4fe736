"""Texture from the photos: every texel of a UV-mapped mesh takes its colour from the photos that see it.

For each face, the photos that see its centre unoccluded (a ray cast from the photo against the mesh)
are ranked by how well they see it: ``cos(angle to the face normal) / distance``, so a close, frontal
view beats a far, grazing one. With ``consistency_views`` > ``max_views``, the photos whose colour of the
face disagrees with the consensus of the face's best ``consistency_views`` photos are left out first (an
occluder the mesh lacks: ``_consistent``). Each texel is then projected into the face's best ``max_views`` photos,
checked for occlusion again (a texel can be hidden where its face's centre is not), and the photos'
colours are blended with weights ``score ** sharpness``: 0 (the step's default) averages them alike, which
after the consistency check is nearer the surface's own colour than any one photo (noise, exposure, glare
differ per photo); a large sharpness lets the best view dominate. Texels no photo sees keep the colour
they had (the bake from the dense cloud).
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
    small: np.ndarray | None = None  # the photo at half size (made when first needed)


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
                    views: list[PhotoView], *, max_views: int = 6, min_cos: float = 0.15, max_dist_m: float = 40.0,
                    sharpness: float = 0.0, margin_px: float = 2.0, tol_m: float = 0.03, tol_rel: float = 0.002,
                    consistency_views: int = 0, consistency_levels: float = 45.0,
                    threads: int = 0, progress=None) -> tuple[np.ndarray, dict]:
    """Return (texture (s, s, 3) uint8, info): ``base`` with every texel a photo sees replaced by the blend of
    its best photos. ``uv`` per face corner (m, 3, 2) in [0, 1], v up; ``base`` the current texture (s, s, 3)."""
    vis = _Visibility(vertices, faces, threads)
    m = len(faces)
    k = max(1, int(max_views))
    nc = max(k, int(consistency_views))  # candidates kept per face for the photo-consistency check
    # 1. per face: the photos that see its centre, ranked
    best_cam, best_score, best_col = _rank_views(vertices, faces, views, vis, nc, k, min_cos=min_cos,
                                                 max_dist_m=max_dist_m, margin_px=margin_px, tol_m=tol_m,
                                                 tol_rel=tol_rel, progress=progress)
    seen_faces = int((best_cam[:, 0] >= 0).sum())
    rejected = 0
    if nc > k:
        best_cam, best_score, rejected = _consistent(best_cam, best_score, best_col, k, float(consistency_levels))
    else:
        best_cam, best_score = best_cam[:, :k], best_score[:, :k]
    # 2. per texel: blend the face's best photos
    out, texels, n_got = _blend(vertices, faces, uv, base, views, vis, best_cam, best_score, k, sharpness,
                                tol_m, tol_rel, progress)
    views_used = np.bincount(best_cam[best_cam[:, 0] >= 0, 0], minlength=len(views))
    info = {"photos": len(views), "faces_seen": seen_faces, "faces_seen_ratio": round(seen_faces / max(m, 1), 4),
            "texels": texels, "texels_from_photos": n_got,
            "texels_from_photos_ratio": round(n_got / max(texels, 1), 4),
            "views_rejected_inconsistent": int(rejected),
            "best_view_faces": {views[i].name: int(c) for i, c in enumerate(views_used) if c}}
    return out, info


def _rank_views(vertices, faces, views: list[PhotoView], vis: _Visibility, nc: int, k: int, *, min_cos: float,
                max_dist_m: float, margin_px: float, tol_m: float, tol_rel: float, progress):
    """Per face, the ``nc`` photos that see its centre unoccluded, best first by cos(view angle) / distance:
    (photo index (m, nc) int64, -1 = none; score (m, nc) float32; the face's colour in each (m, nc, 3) float32,
    filled only when ``nc > k``, for the consistency check)."""
    tri = vertices[faces]
    cen = tri.mean(1)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    m = len(faces)
    best_cam = np.full((m, nc), -1, np.int64)
    best_score = np.zeros((m, nc), np.float32)
    best_col = np.zeros((m, nc, 3), np.float32)
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
        # insert into the per-face top-nc lists
        sc = np.concatenate([best_score[idx], score[:, None]], 1)
        cam = np.concatenate([best_cam[idx], np.full((len(idx), 1), ci)], 1)
        order = np.argsort(-sc, axis=1)[:, :nc]
        best_score[idx] = np.take_along_axis(sc, order, 1)
        best_cam[idx] = np.take_along_axis(cam, order, 1)
        if nc > k:
            col = np.concatenate([best_col[idx], _face_colour(v, tri[idx])[:, None]], 1)
            best_col[idx] = np.take_along_axis(col, order[:, :, None], 1)
    return best_cam, best_score, best_col


def _blend(vertices, faces, uv, base, views: list[PhotoView], vis: _Visibility, best_cam, best_score, k: int,
           sharpness: float, tol_m: float, tol_rel: float, progress) -> tuple[np.ndarray, int, int]:
    """Every texel projected into its face's best ``k`` photos (occlusion checked again), their colours
    blended with weights score ** sharpness. (texture (s, s, 3) uint8, texels, texels from the photos)."""
    from twinkit.surface.texture import rasterize

    size = base.shape[0]
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
    return out, texels, int(got.sum())


# where a face's colour is read in a photo: its centre and six points around it (barycentric coordinates), so
# the colour is the face's own average whatever the distance it is seen from
_FACE_SAMPLES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.2, 0.2, 0.6],
                          [0.4, 0.4, 0.2], [0.4, 0.2, 0.4], [0.2, 0.4, 0.4]])


def _face_colour(v: PhotoView, tri: np.ndarray) -> np.ndarray:
    """The mean colour (n, 3) of faces ``tri`` (n, 3, 3) in photo ``v``: seven points spread over each face,
    read from the photo at half size (area-averaged). A fixed block of pixels would not do: it covers a
    near face's detail but a far face and its surroundings, so near and far photos would disagree."""
    if v.small is None:
        import cv2

        h, w = v.image.shape[:2]
        v.small = cv2.resize(v.image, (max(1, w // 2), max(1, h // 2)), interpolation=cv2.INTER_AREA)
    X = np.einsum("sk,nkd->nsd", _FACE_SAMPLES, tri).reshape(-1, 3)
    px, _z = _project(v, X)
    hs, ws = v.small.shape[:2]
    q = np.clip(px / 2.0, 0.5, [ws - 0.5, hs - 0.5])
    return _sample(v.small, q).reshape(len(tri), len(_FACE_SAMPLES), 3).mean(1)


def _consistent(cams, scores, cols, k: int, levels: float):
    """Per face, the ``k`` best-scored candidate photos whose colour of the face agrees with the consensus of
    all its candidates (Waechter et al. 2014's photo-consistency check): an occluder the mesh lacks -- a
    tree, a parked car or a walker in front of a façade in some photos only -- gives those photos a colour
    the others do not see. The consensus is a mean shift in RGB (Gaussian kernel of ``levels`` / 2, five
    rounds) from the candidate colour with the most support around it, each candidate weighted by its
    score over the best one's, so that many far, grazing photos do not outvote the close ones. (On the
    demo a fence reconstructed as a sheet is seen against the sky from afar and against the grass behind
    it from close by: unweighted, the sky won, -1.2 dB.) A candidate farther than ``levels`` from the
    consensus is dropped. Faces with fewer than three candidates, or where fewer than two would stay, keep
    them all (no majority to judge by)."""
    m, nc = cams.shape
    have = cams >= 0
    cnt = have.sum(1)
    # a candidate's say in the consensus: its score relative to the face's best
    sw = np.where(have, scores / np.maximum(scores[:, :1], 1e-12), 0.0)
    sig2 = (0.5 * levels) ** 2
    # start from the candidate colour with the most weighted support around it (the densest mode), not from
    # the mean, which two disagreeing groups put between them
    start = np.zeros(m, np.int64)
    for a in range(0, m, 65536):  # (faces, nc, nc) distances, a chunk of faces at a time
        c = cols[a:a + 65536]
        pair = ((c[:, :, None, :] - c[:, None, :, :]) ** 2).sum(-1)
        support = (sw[a:a + 65536, None, :] * np.exp(-pair / (2 * sig2))).sum(2)
        start[a:a + 65536] = np.argmax(np.where(have[a:a + 65536], support, -1.0), axis=1)
    mu = np.take_along_axis(cols, start[:, None, None], 1)[:, 0]
    for _ in range(5):
        d2 = ((cols - mu[:, None]) ** 2).sum(-1)
        wgt = sw * np.exp(-d2 / (2 * sig2))
        mu = (cols * wgt[..., None]).sum(1) / np.maximum(wgt.sum(1), 1e-12)[:, None]
    d = np.sqrt(((cols - mu[:, None]) ** 2).sum(-1))
    keep = have & (d <= levels)
    judged = (cnt >= 3) & (keep.sum(1) >= 2)
    keep = np.where(judged[:, None], keep, have)
    rejected = int((have & ~keep).sum())
    # the kept candidates first, by score (the lists are sorted by score already)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :k]
    c2 = np.take_along_axis(np.where(keep, cams, -1), order, 1)
    s2 = np.take_along_axis(np.where(keep, scores, 0.0), order, 1).astype(np.float32)
    return c2, s2, rejected



# --------------------------------------------------------------------------- the photo_texture step's inputs

def read_textured_mesh(src):
    """A baked, UV-mapped mesh (bake_texture's PLY) and its texture: (Mesh, uv (F, 3, 2) float64, texture
    (H, W, 3) uint8). InputError without per-face texture coordinates or the texture image beside it."""
    from pathlib import Path

    from PIL import Image
    from twinkit import InputError
    from twinkit.mesh import read_ply

    src = Path(src)
    try:
        mesh = read_ply(src)
    except Exception as exc:  # noqa: BLE001 - any parse error is the file's fault
        raise InputError(f"{src}: cannot read the textured mesh ({exc}); re-run the texture step") from None
    tc = mesh.face_attrs.get("texcoord")
    png_name = next((c.split(None, 1)[1] for c in mesh.comments if c.startswith("TextureFile")), src.stem + ".png")
    png = src.parent / png_name
    if tc is None or mesh.faces is None or not png.exists():
        raise InputError(f"{src}: needs per-face texture coordinates and its texture image ({png.name}) beside it; "
                         f"give it the output of bake_texture")
    uv = np.asarray(tc, np.float64).reshape(-1, 3, 2)
    base = np.asarray(Image.open(png).convert("RGB"))
    return mesh, uv, base


def photo_views(cameras: list[dict], photos_dir) -> list[PhotoView]:
    """The site-frame cameras (cameras_site.json rows) with their photos loaded; K rescaled where a photo's
    size differs from the camera's."""
    from pathlib import Path

    from PIL import Image
    from twinkit import InputError

    views = []
    for c in cameras:
        path = Path(photos_dir) / c["image"]
        try:
            img = np.asarray(Image.open(path).convert("RGB"))
        except OSError as exc:
            raise InputError(f"{path}: cannot read the photo ({exc}); re-export or remove it") from None
        K = np.asarray(c["K"], float)
        if img.shape[1] != int(c["width"]) or img.shape[0] != int(c["height"]):
            sx, sy = img.shape[1] / float(c["width"]), img.shape[0] / float(c["height"])
            K = np.diag([sx, sy, 1.0]) @ K
        views.append(PhotoView(c["image"], K, np.asarray(c["R_world_from_camera"], float),
                               np.asarray(c["center"], float), img))
    return views
