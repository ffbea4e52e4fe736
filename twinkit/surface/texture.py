"""Texture-atlas helpers shared by the texture bakers (pointcloud's colour bake, photo's projection).

- :func:`rasterize`: the texel centres covered by each UV triangle, with barycentric weights;
- :func:`fill_empty_texels`: empty texels take the colour of the nearest filled one (no seams
  or mip-map bleeding of the background);
- :func:`write_png`: the atlas image.

Atlas convention: ``uv`` per corner (m, 3, 2) in [0, 1], v up (OBJ); image rows run top-down, so
texel (row, col) has its centre at u = (col + 0.5) / size, v = 1 - (row + 0.5) / size.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

#: colour of texels no triangle reaches and of atlases without colour source
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
    """Save an (h, w, 3) uint8 image as PNG (zlib level ``compress_level``: fast, large)."""
    from PIL import Image

    Image.fromarray(img).save(str(path), compress_level=compress_level)
