"""Bake the dense mesh's vertex colours into a texture atlas of the simplified mesh.

CPU transfer: every texel covered by a triangle of the atlas is mapped to its 3D position on
the simplified mesh, the closest point of the dense surface is found (BVH, open3d
RaycastingScene) and the dense vertex colours are interpolated there. Empty texels are then
filled from the nearest covered texel (so seams and mip-maps do not bleed background).
The atlas helpers are shared: :mod:`twinkit.surface.texture`.
"""
from __future__ import annotations

import numpy as np

from twinkit.surface.texture import NEUTRAL_GREY, fill_empty_texels, put_texels, rasterize


def bake_colors(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, size_px: int,
                dense_vertices: np.ndarray | None, dense_faces: np.ndarray | None, dense_colors: np.ndarray | None,
                threads: int = 0, progress=None, surface=None) -> tuple[np.ndarray, dict]:
    """Return (image (size, size, 3) uint8, info). Without dense colours the texture is neutral grey.
    ``threads``: the closest-point queries' and the gap fill's threads (0: all cores for the queries);
    ``surface``: the dense mesh's :class:`~twinkit.surface.closest.Surface` when the caller has one."""
    from twinkit.surface.closest import barycentric_mix

    img = np.zeros((size_px, size_px, 3), np.uint8)
    filled = np.zeros((size_px, size_px), bool)
    info: dict = {"texels_baked": 0}
    surf = None
    if dense_colors is not None:
        from twinkit.surface.closest import Surface

        surf = surface if surface is not None else Surface(dense_vertices, dense_faces, threads)
        dense_colors = np.asarray(dense_colors).astype(np.float32, copy=False)
    dist_sum = 0.0
    chunks = rasterize(uv, size_px)
    if progress is not None:
        chunks = progress(chunks)
    for fid, bary, row, col in chunks:
        if len(fid) == 0:
            continue
        if surf is not None:
            pos = barycentric_mix(vertices, faces, fid, bary, np.float64)
            dfid, dbary, dist = surf.closest(pos)
            put_texels(img, filled, row, col, surf.interpolate(dense_colors, dfid, dbary))
            dist_sum += float(dist.sum())
        else:
            img[row, col] = NEUTRAL_GREY
            filled[row, col] = True
        info["texels_baked"] += int(len(fid))
    covered = int(filled.sum())
    info["coverage"] = covered / size_px ** 2
    if surf is not None and info["texels_baked"]:
        info["mean_transfer_distance_m"] = dist_sum / info["texels_baked"]
    fill_empty_texels(img, filled, threads=max(1, threads))
    return img, info
