"""The demo's ground: painter-ordered rectangles of asphalt, markings, paving, curbs and grass, rasterised on the
grid of their edges into textured, labelled cells, with the curbs' vertical faces where raised and lower cells
meet (:func:`paint_ground`; layout.py paints the rectangles)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from twinkit import cityscapes
from twinkit_demo_site.meshbuild import MAX_ASPECT, MeshBuilder

if TYPE_CHECKING:
    from twinkit_demo_site.layout import Dims

GROUND_KINDS = {  # kind -> (material, label, raised)
    "asphalt": ("asphalt", cityscapes.ROAD, False),
    "marking": ("marking", cityscapes.ROAD, False),
    "paving": ("paving", cityscapes.SIDEWALK, True),
    "curb": ("granite", cityscapes.SIDEWALK, True),
    "grass": ("grass", cityscapes.TERRAIN, True),
}
KIND_NAMES = ["none", *GROUND_KINDS]
GROUND_PERIOD_M = 4.0


def paint_ground(mb: MeshBuilder, rects: list[tuple[str, float, float, float, float]], d: Dims) -> None:
    """Rasterise painter-ordered rectangles on the rectilinear grid of their edges; emit cells and curb faces."""
    xs, ys, kind = _ground_grid(rects, d)
    raised = np.array([False] + [GROUND_KINDS[n][2] for n in KIND_NAMES[1:]])
    z = np.where(raised[kind], d.curb_m, 0.0)
    _ground_cells(mb, xs, ys, kind, z)
    _curb_faces(mb, xs, ys, kind, z, d)


def _ground_grid(rects: list[tuple[str, float, float, float, float]], d: Dims):
    """Cell edges ``xs`` (nx + 1,), ``ys`` (ny + 1,) in metres (the rectangles' edges and every GROUND_PERIOD_M) and
    ``kind`` (ny, nx) int64: the KIND_NAMES index of the last rectangle covering each cell centre (0 = none)."""
    H = d.half_m
    per = GROUND_PERIOD_M
    xs = {-H, H}
    ys = {-H, H}
    for _k, x0, x1, y0, y1 in rects:
        for v in (x0, x1):
            if -H < v < H:
                xs.add(round(v, 4))
        for v in (y0, y1):
            if -H < v < H:
                ys.add(round(v, 4))
    k = np.arange(math.ceil(-H / per), math.floor(H / per) + 1) * per
    xs |= {float(v) for v in k if -H < v < H}
    ys |= {float(v) for v in k if -H < v < H}
    xs = np.array(sorted(xs))
    ys = np.array(sorted(ys))
    cx = (xs[:-1] + xs[1:]) / 2
    cy = (ys[:-1] + ys[1:]) / 2
    kind = np.zeros((len(cy), len(cx)), np.int64)  # [j (y), i (x)]
    for name, x0, x1, y0, y1 in rects:
        mi = (cx > x0) & (cx < x1)
        mj = (cy > y0) & (cy < y1)
        kind[np.ix_(mj, mi)] = KIND_NAMES.index(name)
    return xs, ys, kind


def _ground_cells(mb: MeshBuilder, xs, ys, kind, z) -> None:
    """The horizontal ground cells at their height ``z`` (ny, nx): slivers one by one, the rest batched per kind."""
    per = GROUND_PERIOD_M
    J, I = np.nonzero(kind)
    wx = (xs[1:] - xs[:-1])[I]
    wy = (ys[1:] - ys[:-1])[J]
    thin = (wx > MAX_ASPECT * wy) | (wy > MAX_ASPECT * wx)
    for j, i in zip(J[thin], I[thin]):  # sliver cells: cut by MeshBuilder.quad
        mat, lab, _ = GROUND_KINDS[KIND_NAMES[kind[j, i]]]
        x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
        kx, ky = math.floor((x0 + x1) / 2 / per), math.floor((y0 + y1) / 2 / per)
        mb.quad([x0, y0, z[j, i]], [1, 0, 0], [0, 1, 0], x1 - x0, y1 - y0, mat, int(lab),
                (x0 / per - kx, y0 / per - ky), (x1 / per - kx, y1 / per - ky))
    J, I = J[~thin], I[~thin]
    for kid in np.unique(kind[J, I]):
        sel = kind[J, I] == kid
        j, i = J[sel], I[sel]
        x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
        zz = z[j, i]
        n = len(i)
        verts = np.stack([
            np.stack([x0, y0, zz], 1), np.stack([x1, y0, zz], 1), np.stack([x1, y1, zz], 1), np.stack([x0, y1, zz], 1)
        ], 1).reshape(-1, 3)
        kx = np.floor(((x0 + x1) / 2) / per)
        ky = np.floor(((y0 + y1) / 2) / per)
        s0, s1 = x0 / per - kx, x1 / per - kx
        t0, t1 = y0 / per - ky, y1 / per - ky
        st = np.stack([np.stack([s0, t0], 1), np.stack([s1, t0], 1), np.stack([s1, t1], 1), np.stack([s0, t1], 1)], 1).reshape(-1, 2)
        base = np.arange(n)[:, None] * 4
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], 1).reshape(-1, 3)
        mat, lab, _ = GROUND_KINDS[KIND_NAMES[kid]]
        mb.add(verts, st, faces, mat, lab)


def _curb_faces(mb: MeshBuilder, xs, ys, kind, z, d: Dims) -> None:
    """Vertical curb faces between neighbouring cells of different height, looking towards the lower one."""
    per = GROUND_PERIOD_M
    lab_of = np.array([0] + [GROUND_KINDS[n][1] for n in KIND_NAMES[1:]])
    quads = []  # (p0, p1 bottom edge, zlo, zhi, label)
    for axis in (0, 1):
        if axis == 0:  # neighbours along x
            a, b = kind[:, :-1], kind[:, 1:]
            za, zb = z[:, :-1], z[:, 1:]
        else:
            a, b = kind[:-1, :], kind[1:, :]
            za, zb = z[:-1, :], z[1:, :]
        m = (a > 0) & (b > 0) & (np.abs(za - zb) > 1e-9)
        for j, i in zip(*np.nonzero(m)):
            hi_is_a = za[j, i] > zb[j, i]
            lab = lab_of[a[j, i] if hi_is_a else b[j, i]]
            if axis == 0:
                xe = xs[i + 1]
                p, q = np.array([xe, ys[j]]), np.array([xe, ys[j + 1]])
            else:
                ye = ys[j + 1]
                p, q = np.array([xs[i + 1], ye]), np.array([xs[i], ye])
            if not hi_is_a:  # face must look towards the lower cell
                p, q = q, p
            quads.append((p, q, 0.0, d.curb_m, lab))
    for p, q, z0, z1, lab in quads:
        eu = np.array([q[0] - p[0], q[1] - p[1], 0.0])
        ln = float(np.linalg.norm(eu))
        mb.quad([p[0], p[1], z0], eu / ln, [0, 0, 1.0], ln, z1 - z0, "granite", int(lab),
                (0.0, 0.0), (min(ln / per, 1.0), (z1 - z0) / per))
