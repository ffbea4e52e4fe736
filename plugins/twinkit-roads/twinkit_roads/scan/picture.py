"""scan_roads.png: the labelled mesh from above with the derived network and the lanes carla.Map reads."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .geometry import normals
from .model import Network


def draw_scan_roads(v, f, labels, net: Network, xodr_text: str, out: Path, px_per_m: float = 8.0,
                    max_px: int = 3000, truth: list | None = None, note: str | None = None) -> dict:
    """Top view of the labelled mesh (CityScapes colours, dimmed) with the derived network: the
    carriageway edges found (yellow), the lanes carla.Map reads from the OpenDRIVE (driving borders
    white, centre lines red, sidewalk lanes orange), the true centre lines if known (cyan)."""
    from PIL import Image, ImageDraw

    from twinkit.cityscapes import colorize

    from ..evidence import lane_polygons
    from ..mesh2d import picture_grid, rasterize

    grid, res = picture_grid(v[:, :2], px_per_m, max_px)
    if labels is not None:
        cols = (colorize(labels[f[:, 0]]).astype(float) * 0.6).astype(np.uint8)
    else:
        z = v[f, 2].mean(1)
        g = np.clip((z - np.percentile(z, 2)) / max(float(np.ptp(z)), 1e-6) * 150 + 40, 0, 255).astype(np.uint8)
        cols = np.stack([g, g, g], 1)
    img = Image.fromarray(rasterize(v, f, grid, colours=cols))
    d = ImageDraw.Draw(img)
    w = max(1, int(round(0.1 / res)))

    def line(p, fill, width):
        q = [tuple(map(float, x)) for x in grid.to_px(np.asarray(p)[:, :2])]
        if len(q) >= 2:
            d.line(q, fill=fill, width=width)

    lanes = lane_polygons(xodr_text, 0.5)
    for ln in lanes:
        if ln.type == "sidewalk" and len(ln.left) >= 2:
            ring = np.concatenate([ln.left, ln.right[::-1]])
            d.polygon([tuple(map(float, x)) for x in grid.to_px(ring)], outline=(255, 150, 40))
    from ..align import lane_lines

    lines = lane_lines(xodr_text, 1.0, junctions=True)
    for ln in lines:
        line(ln["left"], (255, 255, 255), max(1, w // 2))
        line(ln["right"], (255, 255, 255), max(1, w // 2))
    for t in truth or []:
        line(np.asarray(t), (0, 220, 255), w)
    for ln in lines:
        line(ln["centre"], (230, 20, 20), w)
    for arm in net.arms:
        nrm = normals(arm.xy)
        for sgn in (1, -1):
            line(arm.xy + sgn * nrm * arm.width_m / 2, (255, 230, 0), max(1, w // 2))
    bridges = net.stats.get("bridges") or []
    for b in bridges:
        line(np.array([b["from"], b["to"]]), (60, 255, 60), 3 * w)
    for nd in net.nodes.values():
        x, y = grid.to_px(np.asarray(nd["xy"]))
        r = 4
        d.ellipse([x - r, y - r, x + r, y + r], outline=(255, 0, 255), width=2)
    from ..qa import legend

    legend(d, [("roads from the scan (road_source=scan)", (255, 255, 255)),
               (f"yellow: carriageway edges ({net.stats.get('carriageway_from') or 'labels + curbs'})"[:60],
                (255, 230, 0)),
               ("white / red: lane borders / centre lines", (230, 20, 20)),
               ("orange: sidewalk lanes; magenta: nodes", (255, 150, 40))]
           + ([("cyan: true lane centre lines", (0, 220, 255))] if truth else [])
           + ([(f"green: {len(bridges)} gap(s) in the carriageway bridged", (60, 255, 60))] if bridges else []),
           res, width=360, slots=6)
    if note:  # why there is nothing to draw
        d.rectangle([8, img.size[1] - 30, min(img.size[0] - 8, 16 + 6 * len(note)), img.size[1] - 8], fill=(0, 0, 0))
        d.text((16, img.size[1] - 24), note, fill=(255, 80, 80))
    img.save(out)
    return {"px": list(img.size), "m_per_px": res, "lane_segments": len(lines)}
