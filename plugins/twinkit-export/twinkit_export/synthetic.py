"""A small labelled, textured street made by code (tests and the benchmark).

A height-field grid in the site frame (metres, z up) with a road strip along x, sidewalks either
side, terrain beyond, a raised "building" block, a few "pole", "car" and unlabelled vertices, and
a few lone vertices whose label differs from all their neighbours. UVs cover the grid; the texture
is a procedural image of ``texture_px`` pixels. With ``bad_faces``, faces a real reconstruction
has too are appended: back-to-back twins (reversed winding), a same-winding duplicate and
degenerate faces (a repeated vertex) -- see :data:`BAD_FACES`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from twinkit.cityscapes import BUILDING, CAR, IGNORE, POLE, ROAD, SIDEWALK, TERRAIN, TRAFFIC_SIGN

#: what ``make_street(bad_faces=True)`` appends: {kind: count}
BAD_FACES = {"back_to_back": 3, "same_winding_duplicate": 1, "degenerate": 2}


def make_street(nx: int = 40, ny: int = 30, size_m: float = 40.0, seed: int = 0, bad_faces: bool = False):
    """Returns (vertices (n,3) f64, faces (m,3) i64, uv (n,2) f32, labels (n,) u8)."""
    rng = np.random.default_rng(seed)
    xs = np.linspace(-size_m / 2, size_m / 2, nx)
    ys = np.linspace(-size_m * ny / nx / 2, size_m * ny / nx / 2, ny)
    gx, gy = np.meshgrid(xs, ys)
    gz = 0.02 * np.sin(gx * 0.7) * np.cos(gy * 0.5)
    labels = np.full(gx.shape, TERRAIN, np.uint8)
    half = ys.max()
    labels[np.abs(gy) < 0.45 * half] = SIDEWALK
    labels[np.abs(gy) < 0.30 * half] = ROAD
    bld = (gx > size_m * 0.2) & (gy > 0.6 * half)
    labels[bld] = BUILDING
    gz = np.where(bld, 6.0, gz)
    pole = (np.abs(gx + size_m * 0.3) < size_m / nx * 0.6) & (np.abs(gy - 0.4 * half) < half / ny * 1.5)
    labels[pole] = POLE
    car = (np.abs(gx) < size_m * 0.08) & (np.abs(gy + 0.1 * half) < 0.08 * half)
    labels[car] = CAR
    gz = np.where(car, 1.4, gz)
    verts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    lab = labels.ravel().copy()
    # unlabelled corner patch and a few lone vertices with a label none of their neighbours has
    lab[(gx.ravel() < -size_m * 0.45) & (gy.ravel() < -0.8 * half)] = IGNORE
    interior = np.nonzero((np.abs(gx.ravel()) < size_m * 0.15) & (np.abs(gy.ravel()) < 0.25 * half) & (lab == ROAD))[0]
    lone = rng.choice(interior, size=min(3, len(interior)), replace=False)
    lab[lone] = TRAFFIC_SIGN
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    if bad_faces:
        twins = faces[[5, 17, 200]][:, [0, 2, 1]]  # back-to-back: same corners, reversed winding
        dup = faces[[40]][:, [1, 2, 0]]  # the same face again, rotated
        degen = np.array([[a[3], a[3], b[3]], [a[9], b[9], b[9]]])
        faces = np.concatenate([faces, twins, dup, degen])
    uv = np.column_stack([(gx.ravel() - xs[0]) / (xs[-1] - xs[0]),
                          (gy.ravel() - ys[0]) / (ys[-1] - ys[0])]).astype(np.float32)
    return verts, faces.astype(np.int64), uv, lab


def texture_image(px: int, seed: int = 0) -> np.ndarray:
    """(px, px, 3) uint8 procedural texture (stripes and noise)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, px, dtype=np.float32)
    u, v = np.meshgrid(t, t)
    img = np.empty((px, px, 3), np.uint8)
    img[..., 0] = (127 + 100 * np.sin(u * 40)).astype(np.uint8)
    img[..., 1] = (127 + 100 * np.cos(v * 30)).astype(np.uint8)
    img[..., 2] = rng.integers(0, 255, (px, px), dtype=np.uint8) // 4 + 96
    return img


def write_obj(path: Path, verts: np.ndarray, faces: np.ndarray, uv: np.ndarray, texture_px: int = 256,
              seed: int = 0) -> Path:
    """Write ``path`` (.obj) + .mtl + .png like the texture step does (twinkit.mesh.write_obj, per-vertex UVs);
    returns the OBJ path."""
    from PIL import Image

    from twinkit.mesh import write_obj as write_mesh_obj

    path = Path(path)
    Image.fromarray(texture_image(texture_px, seed)).save(path.with_suffix(".png"))
    write_mesh_obj(path, verts, faces, uv, f"{path.stem}.png", comment="synthetic street", mtl_comment=None,
                   uv_decimals=6)
    return path
