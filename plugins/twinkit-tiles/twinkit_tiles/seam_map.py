"""The seam map (``tile_seams.png``): the merged mesh from above, for checking the seams by eye."""
from __future__ import annotations

import numpy as np

from twinkit.mesh import Mesh


def seam_map_png(mesh: Mesh, planes: list[tuple[int, float]], runs: list[dict], path, title: str = "",
                 size_px: int = 1600) -> None:
    """Top view of the merged mesh for checking the seams: each tile's faces in its own colour (shaded
    by slope), stitch strips and fills dark, seam planes dashed, and every open run on a seam circled
    (red: facing surface, orange: the surface ends on the seam; strip-only border crossings are not
    marked)."""
    from PIL import Image, ImageDraw

    X, F = mesh.vertices, mesh.faces
    if F is None or len(F) == 0:
        return
    lo, hi = X[:, :2].min(axis=0), X[:, :2].max(axis=0)
    ext = max(float((hi - lo).max()), 1e-6)
    W = max(1, int(round(size_px * (hi[0] - lo[0]) / ext)))
    H = max(1, int(round(size_px * (hi[1] - lo[1]) / ext)))
    px = ext / (size_px - 1)
    tile = mesh.face_attrs.get("tile", np.zeros(len(F), np.int64))
    pal = np.array([[141, 211, 199], [255, 255, 179], [190, 186, 218], [251, 128, 114], [128, 177, 211],
                    [253, 180, 98], [179, 222, 105], [252, 205, 229], [217, 217, 217], [188, 128, 189],
                    [204, 235, 197], [255, 237, 111]], np.float64)
    col = np.where(tile[:, None] >= 0, pal[np.maximum(tile, 0) % len(pal)], np.array([[60.0, 60.0, 60.0]]))
    T = X[F]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    nn = np.linalg.norm(n, axis=1)
    col *= (0.55 + 0.45 * np.abs(n[:, 2]) / np.maximum(nn, 1e-12))[:, None]
    # samples: every vertex (in the colour of one of its faces), and one point per pixel of face area
    # (at least one per face)
    area_px = 0.5 * nn / px ** 2
    extra = np.minimum(np.ceil(area_px).astype(np.int64), 64)
    rng = np.random.default_rng(0)
    fi = np.repeat(np.arange(len(F)), extra)
    r1, r2 = np.sqrt(rng.random(len(fi))), rng.random(len(fi))
    S = T[fi, 0] * (1 - r1)[:, None] + T[fi, 1] * (r1 * (1 - r2))[:, None] + T[fi, 2] * (r1 * r2)[:, None]
    del T
    vf = np.full(len(X), -1, np.int64)
    vf[F.ravel()] = np.repeat(np.arange(len(F)), 3)
    used = vf >= 0
    S = np.vstack([S, X[used]])
    fi = np.concatenate([fi, vf[used]])
    c = np.clip(((S[:, 0] - lo[0]) / px).astype(np.int64), 0, W - 1)
    r = np.clip(((hi[1] - S[:, 1]) / px).astype(np.int64), 0, H - 1)
    pix = r * W + c
    order = np.lexsort((S[:, 2], pix))  # per pixel, the highest sample last
    last = np.r_[pix[order][1:] != pix[order][:-1], True]
    img = np.full((H * W, 3), 255, np.uint8)
    img[pix[order][last]] = np.clip(col[fi[order][last]], 0, 255).astype(np.uint8)
    img = img.reshape(H, W, 3)
    # close the pinholes between samples: an empty pixel takes a filled neighbour's colour (one pass)
    empty = (img == 255).all(axis=2)
    grown = img.copy()
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        src = np.roll(img, (dy, dx), axis=(0, 1))
        take = empty & ~(src == 255).all(axis=2) & (grown == 255).all(axis=2)
        grown[take] = src[take]
    im = Image.fromarray(grown)
    d = ImageDraw.Draw(im)
    for axis, val in planes:
        for s in np.arange(0.0, ext, 2.0):
            if axis == 0:
                x = (val - lo[0]) / px
                d.line([(x, s / px), (x, min(s + 1.0, ext) / px)], fill=(90, 90, 90), width=1)
            else:
                y = (hi[1] - val) / px
                d.line([(s / px, y), (min(s + 1.0, ext) / px, y)], fill=(90, 90, 90), width=1)
    colours = {"facing_surface": (220, 0, 0), "surface_ends": (255, 140, 0)}
    for run in runs:
        if run["kind"] not in colours:
            continue
        x, y = (run["centre"][0] - lo[0]) / px, (hi[1] - run["centre"][1]) / px
        rad = max(6.0, 0.5 * run["length_m"] / px + 4)
        d.ellipse([x - rad, y - rad, x + rad, y + rad], outline=colours[run["kind"]], width=2)
    if title:
        d.rectangle([0, 0, min(W, 8 + 6 * len(title)), 16], fill=(255, 255, 255))
        d.text((4, 3), title, fill=(0, 0, 0))
    im.save(str(path))
