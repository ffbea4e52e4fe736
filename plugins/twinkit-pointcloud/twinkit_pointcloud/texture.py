"""Bake the dense mesh's vertex colours into a texture atlas of the simplified mesh.

CPU transfer: every texel covered by a triangle of the atlas is mapped to its 3D position on
the simplified mesh, the closest point of the dense surface is found (BVH, open3d
RaycastingScene) and the dense vertex colours are interpolated there. Empty texels are then
filled from the nearest covered texel (so seams and mip-maps do not bleed background).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

NEUTRAL_GREY = 128


def rasterize(uv: np.ndarray, size_px: int, max_candidates: int = 4_000_000):
    """Yield (face ids (k,), barycentric (k, 3) float32, pixel rows (k,), pixel cols (k,)) for the
    texel centres covered by each UV triangle (``uv`` (m, 3, 2) in [0, 1], v up)."""
    px = np.empty_like(uv)
    px[..., 0] = uv[..., 0] * size_px
    px[..., 1] = (1.0 - uv[..., 1]) * size_px
    x0 = np.clip(np.floor(px[..., 0].min(axis=1) - 0.5), 0, size_px - 1).astype(np.int64)
    x1 = np.clip(np.ceil(px[..., 0].max(axis=1) - 0.5), 0, size_px - 1).astype(np.int64)
    y0 = np.clip(np.floor(px[..., 1].min(axis=1) - 0.5), 0, size_px - 1).astype(np.int64)
    y1 = np.clip(np.ceil(px[..., 1].max(axis=1) - 0.5), 0, size_px - 1).astype(np.int64)
    bw, bh = x1 - x0 + 1, y1 - y0 + 1
    cnt = bw * bh
    csum = np.cumsum(cnt)
    start = 0
    m = len(uv)
    while start < m:
        base = csum[start - 1] if start else 0
        end = int(np.searchsorted(csum, base + max_candidates, side="right"))
        end = max(end, start + 1)
        f = np.arange(start, end)
        c = cnt[f]
        fid = np.repeat(f, c)
        local = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        col = x0[fid] + local % bw[fid]
        row = y0[fid] + local // bw[fid]
        p = np.stack([col + 0.5, row + 0.5], axis=1)
        a, b, cc = px[fid, 0], px[fid, 1], px[fid, 2]
        v0, v1, v2 = b - a, cc - a, p - a
        d00 = np.einsum("ij,ij->i", v0, v0)
        d01 = np.einsum("ij,ij->i", v0, v1)
        d11 = np.einsum("ij,ij->i", v1, v1)
        d20 = np.einsum("ij,ij->i", v2, v0)
        d21 = np.einsum("ij,ij->i", v2, v1)
        den = d00 * d11 - d01 * d01
        good = np.abs(den) > 1e-18
        den = np.where(good, den, 1.0)
        w1 = (d11 * d20 - d01 * d21) / den
        w2 = (d00 * d21 - d01 * d20) / den
        w0 = 1.0 - w1 - w2
        eps = 1e-6
        inside = good & (w0 >= -eps) & (w1 >= -eps) & (w2 >= -eps)
        bary = np.stack([w0, w1, w2], axis=1)[inside].astype(np.float32)
        yield fid[inside], np.clip(bary, 0, 1), row[inside], col[inside]
        start = end


def bake_colors(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, size_px: int,
                dense_vertices: np.ndarray | None, dense_faces: np.ndarray | None, dense_colors: np.ndarray | None,
                threads: int = 0, progress=None) -> tuple[np.ndarray, dict]:
    """Return (image (size, size, 3) uint8, info). Without dense colours the texture is neutral grey."""
    img = np.zeros((size_px, size_px, 3), np.uint8)
    filled = np.zeros((size_px, size_px), bool)
    info: dict = {"texels_baked": 0}
    surf = None
    if dense_colors is not None:
        from .surface import Surface

        surf = Surface(dense_vertices, dense_faces, threads)
    dist_sum = 0.0
    chunks = rasterize(uv, size_px)
    if progress is not None:
        chunks = progress(chunks)
    for fid, bary, row, col in chunks:
        if len(fid) == 0:
            continue
        tri = faces[fid]
        pos = np.zeros((len(fid), 3))
        for i in range(3):
            pos += bary[:, i:i + 1] * vertices[tri[:, i]]
        if surf is not None:
            dfid, dbary, dist = surf.closest(pos)
            colv = surf.interpolate(dense_colors, dfid, dbary)
            img[row, col] = np.clip(np.rint(colv), 0, 255).astype(np.uint8)
            dist_sum += float(dist.sum())
        else:
            img[row, col] = NEUTRAL_GREY
        filled[row, col] = True
        info["texels_baked"] += int(len(fid))
    covered = int(filled.sum())
    info["coverage"] = covered / size_px ** 2
    if surf is not None and info["texels_baked"]:
        info["mean_transfer_distance_m"] = dist_sum / info["texels_baked"]
    fill_empty_texels(img, filled)
    return img, info


def fill_empty_texels(img: np.ndarray, filled: np.ndarray, tile: int = 4096, halo: int = 64) -> None:
    """Give every empty texel the colour of the nearest filled one (in tiles, bounded memory)."""
    from scipy.ndimage import distance_transform_edt

    if filled.all() or not filled.any():
        if not filled.any():
            img[:] = NEUTRAL_GREY
        return
    H, W = filled.shape
    src = img.copy()
    for y in range(0, H, tile):
        for x in range(0, W, tile):
            ya, yb = max(0, y - halo), min(H, y + tile + halo)
            xa, xb = max(0, x - halo), min(W, x + tile + halo)
            f = filled[ya:yb, xa:xb]
            if f.all():
                continue
            if not f.any():
                img[y:y + tile, x:x + tile][~filled[y:y + tile, x:x + tile]] = NEUTRAL_GREY
                continue
            idx = distance_transform_edt(~f, return_distances=False, return_indices=True)
            sub = src[ya:yb, xa:xb][idx[0], idx[1]]
            ty, tx = y - ya, x - xa
            h, w = min(tile, H - y), min(tile, W - x)
            tgt = img[y:y + h, x:x + w]
            empty = ~filled[y:y + h, x:x + w]
            tgt[empty] = sub[ty:ty + h, tx:tx + w][empty]


def write_png(path: Path, img: np.ndarray, compress_level: int = 1) -> None:
    from PIL import Image

    Image.fromarray(img).save(str(path), compress_level=compress_level)


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, texture_name: str,
              normals: np.ndarray | None = None, material: str = "twinkit_texture") -> None:
    """OBJ + MTL beside it (same stem); ``uv`` per corner (m, 3, 2), v up; texture file next to it."""
    path = Path(path)
    mtl = path.with_suffix(".mtl")
    mtl.write_text(f"# twinkit-pointcloud\nnewmtl {material}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n"
                   f"map_Kd {texture_name}\n")
    m = len(faces)
    # share vt between corners with identical UVs (corners of the same chart)
    flat = np.round(uv.reshape(-1, 2), 7)
    uniq, inv = np.unique(flat, axis=0, return_inverse=True)
    inv = inv.reshape(m, 3)
    with open(path, "w") as fh:
        fh.write(f"# twinkit-pointcloud textured mesh: {len(vertices)} vertices, {m} faces\n")
        fh.write(f"mtllib {mtl.name}\n")
        np.savetxt(fh, vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(fh, uniq, fmt="vt %.7f %.7f")
        if normals is not None:
            np.savetxt(fh, normals, fmt="vn %.4f %.4f %.4f")
        fh.write(f"usemtl {material}\n")
        f1 = faces + 1
        t1 = inv + 1
        if normals is not None:
            arr = np.stack([f1[:, 0], t1[:, 0], f1[:, 0], f1[:, 1], t1[:, 1], f1[:, 1], f1[:, 2], t1[:, 2], f1[:, 2]], axis=1)
            np.savetxt(fh, arr, fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")
        else:
            arr = np.stack([f1[:, 0], t1[:, 0], f1[:, 1], t1[:, 1], f1[:, 2], t1[:, 2]], axis=1)
            np.savetxt(fh, arr, fmt="f %d/%d %d/%d %d/%d")


def read_obj(path: Path) -> dict:
    """Minimal OBJ reader for round-trip tests: vertices, uv, faces (v and vt indices), mtllib."""
    path = Path(path)
    v, vt, fv, ft = [], [], [], []
    mtllib = None
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(a) for a in line.split()[1:4]])
            elif line.startswith("vt "):
                vt.append([float(a) for a in line.split()[1:3]])
            elif line.startswith("f "):
                parts = [p.split("/") for p in line.split()[1:]]
                fv.append([int(p[0]) - 1 for p in parts])
                ft.append([int(p[1]) - 1 for p in parts])
            elif line.startswith("mtllib"):
                mtllib = line.split(None, 1)[1].strip()
    return {"vertices": np.asarray(v), "uv": np.asarray(vt), "faces": np.asarray(fv, np.int64),
            "face_uv": np.asarray(ft, np.int64), "mtllib": mtllib}
