"""Where the 3D-context cues fire on a point cloud with normals (a real scan without labels).

    .venv/bin/python plugins/twinkit-segmentation/bench/shape_cues_cloud.py \
        [--cloud ../shared/data/pointclouds/lille_street_small_normals.ply] [--out docs/img/shape_cues_lille.png]

Runs :func:`twinkit_segmentation.context.geometric_context` with the ``backproject`` defaults on the
points (normals flipped to face up where they point down; a point cloud has no faces, so the
objects are the connected parts of a neighbour graph: points closer than ``--link-m``, a few
times the scan's point spacing). Prints the objects and the share of points each cue flags;
writes a picture: a top view of all cues and a side view of the objects (columns red, mounted
items yellow (plates) / orange (boxes), low objects green, narrow ones blue, low and slender ones
purple, other objects grey; later colours drawn over earlier ones).
Nothing is scored (no labels) and nothing is tuned here.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cloud", default=str(REPO.parent / "shared/data/pointclouds/lille_street_small_normals.ply"))
    ap.add_argument("--link-m", type=float, default=0.15, help="neighbour graph: points closer than this are linked")
    ap.add_argument("--out", default="", help="PNG to write (none: no picture)")
    a = ap.parse_args(argv)
    os.environ.setdefault("TWINKIT_PLUGINS", "builtins,segmentation")
    import time

    from scipy.spatial import cKDTree

    from twinkit.mesh import read_mesh
    from twinkit_segmentation.context import CUES, geometric_context
    from twinkit_segmentation.backproject_parts import BackprojectParams, context_options

    m = read_mesh(a.cloud)
    v = np.asarray(m.vertices, np.float64)
    nrm = m.attrs.get("normals")
    if nrm is None:
        raise SystemExit(f"{a.cloud}: no normals; estimate them first (e.g. twinkit's read_cloud step)")
    nrm = np.asarray(nrm, np.float64)
    nrm = nrm * np.where(nrm[:, 2] < 0, -1.0, 1.0)[:, None]
    t0 = time.perf_counter()
    edges = np.array(sorted(cKDTree(v).query_pairs(a.link_m)), np.int64).reshape(-1, 2)
    t1 = time.perf_counter()
    ctx = geometric_context(v, nrm, context_options(BackprojectParams()), edges)
    t2 = time.perf_counter()
    print(f"{a.cloud}: {len(v):,} points, {len(edges):,} links ({t1 - t0:.1f} s), context {t2 - t1:.1f} s, "
          f"{ctx['objects']:,} objects above the ground")
    for c in CUES + ("plate", "box"):
        print(f"  {c}: {int(ctx[c].sum()):,} points ({100 * ctx[c].mean():.1f} %)")
    if a.out:
        picture(v, ctx, Path(a.out))
        print(f"wrote {a.out}")
    return 0


def picture(v: np.ndarray, ctx: dict, out: Path) -> None:
    from PIL import Image

    h = ctx["height"]
    obj = (h > 0.30) & ~ctx["ground"]
    col = np.full((len(v), 3), 235, np.uint8)
    layers = [(obj, (150, 150, 150)), (ctx["low"], (60, 170, 60)), (ctx["narrow"], (60, 110, 230)),
              (ctx["slender"], (170, 60, 200)),
              (ctx["column"], (220, 30, 30)), (ctx["plate"], (240, 210, 0)), (ctx["box"], (255, 130, 0))]
    for mask, c in layers:
        col[mask] = c
    # principal horizontal axis of the scan: the side view looks across it
    xy = v[:, :2] - v[:, :2].mean(axis=0)
    _, vec = np.linalg.eigh(xy.T @ xy)
    u, w = xy @ vec[:, 1], xy @ vec[:, 0]
    px = 0.07  # metres per pixel

    def raster(a, b, sel, order):
        i = ((a - a.min()) / px).astype(int)
        j = ((b.max() - b) / px).astype(int)
        img = np.full((j.max() + 1, i.max() + 1, 3), 255, np.uint8)
        idx = np.nonzero(sel)[0]
        idx = idx[np.argsort(order[idx])]  # later points drawn on top
        img[j[idx], i[idx]] = col[idx]
        return img

    rank = np.zeros(len(v))
    for k, (mask, _) in enumerate(layers):
        rank[mask] = k + 1
    top = raster(u, w, np.ones(len(v), bool), rank + h * 1e-3)
    side = raster(u, h, obj, rank - w * 1e-3)
    gap = np.full((8, max(top.shape[1], side.shape[1]), 3), 255, np.uint8)
    pad = lambda im: np.pad(im, ((0, 0), (0, gap.shape[1] - im.shape[1]), (0, 0)), constant_values=255)  # noqa: E731
    Image.fromarray(np.vstack([pad(top), gap, pad(side)])).save(out)


if __name__ == "__main__":
    sys.exit(main())
