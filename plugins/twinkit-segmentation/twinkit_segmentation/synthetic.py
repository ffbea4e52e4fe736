"""Small street scenes made by code (tests, benchmarks, docs examples)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

CLASS_RGB = {0: (90, 90, 95), 1: (170, 165, 160), 2: (150, 100, 70), 5: (200, 200, 200), 13: (30, 40, 160), 8: (40, 140, 40)}


def grid(x0, x1, y0, y1, z, step):
    xs = np.linspace(x0, x1, max(2, int(round((x1 - x0) / step)) + 1))
    ys = np.linspace(y0, y1, max(2, int(round((y1 - y0) / step)) + 1))
    gx, gy = np.meshgrid(xs, ys)
    v = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    nx = len(xs)
    i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    f = np.concatenate([np.column_stack([a, a + 1, a + nx + 1]), np.column_stack([a, a + nx + 1, a + nx])])
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    return v, f, n


def box(lo, hi, step, bottom=False):
    """Box with a separate vertex set per side (clean normals), sides subdivided by ``step``;
    without its bottom unless asked (like a scan, which never sees it)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    vs, fs, ns = [], [], []
    off = 0
    for axis in range(3):
        for side, val in ((-1, lo[axis]), (1, hi[axis])):
            if axis == 2 and side < 0 and not bottom:
                continue
            u, w = [a for a in range(3) if a != axis]
            v2, f2, _ = grid(lo[u], hi[u], lo[w], hi[w], 0.0, step)
            v = np.zeros_like(v2)
            v[:, u], v[:, w], v[:, axis] = v2[:, 0], v2[:, 1], val
            # orient outward: grid normal is +axis for (u, w) in cyclic order
            cyclic = (u, w) in ((0, 1), (1, 2), (2, 0))
            if (side > 0) != cyclic:
                f2 = f2[:, ::-1]
            n = np.zeros_like(v)
            n[:, axis] = side
            vs.append(v), fs.append(f2 + off), ns.append(n)
            off += len(v)
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(ns)


def facade(x0, x1, y, height, step, facing):
    """A vertical wall along x at ``y`` from the ground to ``height``, normal ``(0, facing, 0)``."""
    v2, f, _ = grid(x0, x1, 0.0, height, 0.0, step)
    v = np.column_stack([v2[:, 0], np.full(len(v2), y), v2[:, 1]])
    return v, (f if facing < 0 else f[:, ::-1]), np.tile([0.0, float(facing), 0.0], (len(v), 1))


def street_scene(step=0.5):
    """A 40 m x 40 m street: road strip, two sidewalks, two buildings, poles, cars, a tree-ish box.

    Returns vertices, faces, normals, per-face labels."""
    parts = [
        (grid(-20, 20, -5, 5, 0.0, step), 0),
        (grid(-20, 20, 5, 10, 0.0, step), 1),
        (grid(-20, 20, -10, -5, 0.0, step), 1),
        (facade(-18, 18, 10, 8, step, -1), 2),  # building fronts: a scan sees the street side only
        (facade(-18, 18, -10, 10, step, 1), 2),
        (box((-6, 6, 0), (-5.7, 6.3, 4), 0.25), 5),
        (box((8, -6.3, 0), (8.3, -6, 4), 0.25), 5),
        (box((-12, -4, 0), (-8, -2.2, 1.5), 0.3), 13),
        (box((4, 2, 0), (8, 3.8, 1.5), 0.3), 13),
        (box((12, 6.5, 0), (14, 8.5, 3), 0.4), 8),
    ]
    vs, fs, ns, ls = [], [], [], []
    off = 0
    for (v, f, n), lab in parts:
        vs.append(v), fs.append(f + off), ns.append(n), ls.append(np.full(len(f), lab, np.uint8))
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(ns), np.concatenate(ls)


def write_scene(folder: Path, step=0.5):
    """textured_mesh.ply (+ .png) and gt_mesh.ply of :func:`street_scene` into ``folder``."""
    from PIL import Image

    from twinkit.artefacts import write_gt_mesh, write_textured_mesh
    from twinkit.mesh import Mesh

    folder.mkdir(parents=True, exist_ok=True)
    v, f, n, flab = street_scene(step)
    classes = sorted(CLASS_RGB)
    # texture: one 16x16 colour tile per class, with a little pattern
    tile = 16
    tex = np.zeros((tile, tile * len(classes), 3), np.uint8)
    rng = np.random.default_rng(0)
    for i, c in enumerate(classes):
        tex[:, i * tile:(i + 1) * tile] = np.clip(np.array(CLASS_RGB[c]) + rng.integers(-12, 12, (tile, tile, 3)), 0, 255)
    Image.fromarray(tex).save(folder / "textured_mesh.png")
    col = {c: i for i, c in enumerate(classes)}
    uc = (np.array([col[int(c)] for c in flab]) + 0.5) / len(classes)
    uv = np.zeros((len(f), 3, 2), np.float32)
    uv[:, :, 0] = uc[:, None] + np.array([-0.2, 0.0, 0.2]) / len(classes)
    uv[:, :, 1] = np.array([0.3, 0.7, 0.5])
    vlab = np.zeros(len(v), np.uint8)
    vlab[f.reshape(-1)] = np.repeat(flab, 3)
    vcol = np.array([CLASS_RGB[int(c)] for c in vlab], np.uint8)
    write_textured_mesh(folder / "textured_mesh.ply", Mesh(
        vertices=v, faces=f, attrs={"normals": n, "colors": vcol},
        face_attrs={"texcoord": uv.reshape(-1, 6)}, comments=["TextureFile textured_mesh.png"]))
    write_gt_mesh(folder / "gt_mesh.ply", Mesh(vertices=v, faces=f, attrs={"label": vlab},
                                               face_attrs={"label": np.asarray(flab, np.uint8)}))
    return folder / "textured_mesh.ply", folder / "gt_mesh.ply", vlab


def egl_available() -> bool:
    """Whether moderngl can open a headless EGL context here (Mesa llvmpipe is enough)."""
    try:
        import moderngl

        ctx = moderngl.create_context(standalone=True, backend="egl")
        ctx.release()
        return True
    except Exception:
        return False
