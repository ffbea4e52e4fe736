"""The QA picture: the mesh seen from straight above, with the lanes drawn over it."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_qa(mesh_path: Path, lines: list[dict], before: list[dict] | None, out: Path, px_per_m: float = 20.0,
            max_px: int = 4096, truth: list[np.ndarray] | None = None) -> None:
    """Orthographic top view of the mesh (vertex colours), lane borders (white), centre lines (red);
    the network before alignment as thin yellow centre lines, the true centre lines (if known) in cyan."""
    from PIL import Image, ImageDraw

    from .mesh2d import picture_grid, read_mesh, rasterize

    mesh = read_mesh(mesh_path)
    xy = mesh.v[:, :2]
    grid, res = picture_grid(xy, px_per_m, max_px)
    if mesh.rgb is not None:
        cols = mesh.rgb[mesh.f].mean(1).astype(np.uint8)
    else:  # no colours: shade by height
        z = mesh.v[mesh.f, 2].mean(1)
        g = np.clip((z - np.percentile(z, 2)) / max(np.ptp(z), 1e-6) * 200 + 40, 0, 255).astype(np.uint8)
        cols = np.stack([g, g, g], 1)
    img = Image.fromarray(rasterize(mesh, grid, colours=cols, mode="RGB"))
    d = ImageDraw.Draw(img)
    w = max(1, int(round(0.08 / res)))

    def poly(p, fill, width):
        q = [tuple(v) for v in grid.to_px(p)]
        if len(q) >= 2:
            d.line(q, fill=fill, width=width)

    for t in truth or []:
        poly(np.asarray(t)[:, :2], (0, 220, 255), w)
    for ln in before or []:
        poly(ln["centre"], (255, 220, 0), max(1, w // 2))
    for ln in lines:
        poly(ln["left"], (255, 255, 255), w)
        poly(ln["right"], (255, 255, 255), w)
    for ln in lines:
        poly(ln["centre"], (230, 20, 20), w)
    # legend and scale bar
    d.rectangle([8, 8, 330, 92], fill=(0, 0, 0))
    d.text((16, 14), "white: lane borders (aligned)", fill=(255, 255, 255))
    d.text((16, 30), "red: lane centre lines (aligned)", fill=(230, 20, 20))
    d.text((16, 46), "yellow: centre lines before alignment", fill=(255, 220, 0))
    if truth:
        d.text((16, 62), "cyan: true centre lines", fill=(0, 220, 255))
    bar = 10.0 / res
    d.line([(16, 84), (16 + bar, 84)], fill=(255, 255, 255), width=3)
    d.text((22 + bar, 76), "10 m", fill=(255, 255, 255))
    img.save(out)
