"""The QA picture: the mesh seen from straight above, with the lanes drawn over it."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_qa(mesh_path: Path, lines: list[dict], before: list[dict] | None, out: Path, px_per_m: float = 20.0,
            max_px: int = 4096, truth: list[np.ndarray] | None = None) -> None:
    """Orthographic top view of the mesh (vertex colours), lane borders (white), centre lines (red);
    the network before alignment as thin yellow centre lines, the true centre lines (if known) in cyan."""
    from PIL import Image, ImageDraw

    from twinkit.artefacts import read_textured_mesh

    from .mesh2d import picture_grid, rasterize

    mesh = read_textured_mesh(mesh_path)
    xy = mesh.vertices[:, :2]
    grid, res = picture_grid(xy, px_per_m, max_px)
    if mesh.colors is not None:
        cols = mesh.colors[mesh.faces].mean(1).astype(np.uint8)
    else:  # no colours: shade by height
        z = mesh.vertices[mesh.faces, 2].mean(1)
        g = np.clip((z - np.percentile(z, 2)) / max(np.ptp(z), 1e-6) * 200 + 40, 0, 255).astype(np.uint8)
        cols = np.stack([g, g, g], 1)
    img = Image.fromarray(rasterize(mesh.vertices, mesh.faces, grid, colours=cols))
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
    legend(d, [("white: lane borders (aligned)", (255, 255, 255)), ("red: lane centre lines (aligned)", (230, 20, 20)),
               ("yellow: centre lines before alignment", (255, 220, 0))]
           + ([("cyan: true centre lines", (0, 220, 255))] if truth else []), res, width=330, slots=4)
    img.save(out)


def legend(d, rows: list[tuple[str, tuple]], m_per_px: float, width: int, slots: int) -> None:
    """A top-view picture's legend in the top-left corner: ``rows`` (text, colour) on black, room for
    ``slots`` rows, and a 10 m scale bar under them."""
    bar_y = 20 + 16 * slots
    d.rectangle([8, 8, width, bar_y + 8], fill=(0, 0, 0))
    for i, (text, colour) in enumerate(rows):
        d.text((16, 14 + 16 * i), text, fill=colour)
    bar = 10.0 / m_per_px
    d.line([(16, bar_y), (16 + bar, bar_y)], fill=(255, 255, 255), width=3)
    d.text((22 + bar, bar_y - 8), "10 m", fill=(255, 255, 255))


#: fill colours of the network picture by OpenDRIVE lane type (lower case); others: OTHER_COLOUR
LANE_COLOURS = {"driving": (95, 95, 100), "sidewalk": (205, 180, 140), "parking": (120, 110, 150),
                "biking": (150, 90, 90), "shoulder": (130, 130, 120), "border": (90, 120, 90)}
OTHER_COLOUR = (110, 130, 110)


def draw_network(xodr_text: str, out: Path, bounds: tuple[float, float, float, float] | None = None,
                 px_per_m: float = 4.0, max_px: int = 3000, title: str = "") -> dict:
    """Top view of an OpenDRIVE network without any mesh: every lane filled by its type (from carla.Map),
    driving-lane centre lines in white, junction lanes lighter, the site box (``bounds``) in yellow.
    Returns counts of what was drawn."""
    from PIL import Image, ImageDraw

    from .align import lane_lines
    from .evidence import lane_polygons
    from .mesh2d import picture_grid

    lanes = lane_polygons(xodr_text, 1.0)
    pts = [ln.left for ln in lanes] + [ln.right for ln in lanes]
    if bounds is not None:
        xmin, ymin, xmax, ymax = bounds
        pts.append(np.array([[xmin, ymin], [xmax, ymax]], float))
    if not pts:
        raise ValueError("no lanes to draw")
    grid, res = picture_grid(np.concatenate(pts), px_per_m, max_px)
    img = Image.new("RGB", (grid.w, grid.h), (24, 28, 24))
    d = ImageDraw.Draw(img)
    types: dict[str, int] = {}
    for ln in sorted(lanes, key=lambda ln: ln.type == "driving"):  # driving lanes on top
        ring = np.concatenate([ln.left, ln.right[::-1]])
        if len(ring) < 3:
            continue
        c = LANE_COLOURS.get(ln.type, OTHER_COLOUR)
        if ln.junction:
            c = tuple(min(255, v + 35) for v in c)
        d.polygon([tuple(p) for p in grid.to_px(ring)], fill=c)
        types[ln.type] = types.get(ln.type, 0) + 1
    w = max(1, int(round(0.15 / res)))
    for ln in lane_lines(xodr_text, 1.0, junctions=True):
        q = [tuple(p) for p in grid.to_px(ln["centre"])]
        if len(q) >= 2:
            d.line(q, fill=(250, 250, 250), width=w)
    if bounds is not None:
        (x0, y1), (x1, y0) = grid.to_px(np.array([[bounds[0], bounds[1]], [bounds[2], bounds[3]]]))
        d.rectangle([x0, y0, x1, y1], outline=(250, 210, 0), width=max(2, w))
    rows = [title] if title else []
    rows += [f"{k}: {v} lane segments" for k, v in sorted(types.items(), key=lambda kv: -kv[1])][:6]
    rows += ["white: driving-lane centre lines", "yellow: site box"]
    d.rectangle([8, 8, 300, 20 + 16 * len(rows)], fill=(0, 0, 0))
    for i, r in enumerate(rows):
        c = LANE_COLOURS.get(r.split(":")[0])
        d.text((16, 14 + 16 * i), r, fill=tuple(min(255, v + 90) for v in c) if c else (255, 255, 255))
    bar = 50.0 / res
    d.line([(16, grid.h - 20), (16 + bar, grid.h - 20)], fill=(255, 255, 255), width=3)
    d.text((22 + bar, grid.h - 28), "50 m", fill=(255, 255, 255))
    img.save(out)
    return {"lane_segments": sum(types.values()), "lane_types": types, "px": [grid.w, grid.h],
            "m_per_px": round(res, 4)}
