"""Colours for a mesh whose cloud had none, so the views the 2D model reads are not flat grey silhouettes.

A colourless cloud used to give a uniform grey texture; the renderer is unlit, so every view was one grey
shape on the sky and the 2D model guessed (Lille: facades road 49 %, vegetation 40 %, building ~0 %).
The bake step now gives the dense mesh's vertices a grey level before baking (``BakeParams.colourless``):

* ``intensity``: the points' return intensity (LAS/E57/PLY ``intensity``), nearest point per vertex,
  stretched between its 2nd and 98th percentiles, times the ``shaded`` light so the geometry still shows;
* ``shaded``: a fixed light: a sky from above plus a sun from the south-west at 45 degrees
  (Lambert on the vertex normals averaged over ``SMOOTH_RADIUS_M``), so the ground is light, walls
  differ by the way they face, and undersides are dark, as an untextured rendering would look;
* ``height``: the shaded grey tinted by the height above the local ground (ground grey, low objects
  warm, high ones cool), so a wall and a tree top read differently;
* ``grey``: the old uniform grey.

``auto`` picks ``intensity`` when the cloud has it, else the mode measured best with the real 2D model
on the demo site with its colours removed (docs/pointcloud.md, "Clouds without colour").
The texture then shows that grey: an untextured twin looks like a clay model rather than a flat one.
"""
from __future__ import annotations

import numpy as np

#: direction towards the sun (site frame, z up): south-west, 45 degrees high
SUN = np.array([-0.5, -0.5, 0.7071])
SKY, SUN_W, FLOOR = 0.45, 0.45, 0.12  # light from above, from the sun, and the floor of the dark side

MODES = ("auto", "intensity", "shaded", "height", "grey")
#: what ``auto`` uses without intensity (measured: docs/pointcloud.md "Clouds without colour")
AUTO_WITHOUT_INTENSITY = "shaded"


def _unit(n: np.ndarray) -> np.ndarray:
    n = np.asarray(n, dtype=np.float64)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(ln > 0, n / np.maximum(ln, 1e-12), 0.0)


def light(normals: np.ndarray) -> np.ndarray:
    """Brightness 0..1 per vertex under the fixed sky and sun."""
    n = _unit(normals)
    sky = 0.5 + 0.5 * n[:, 2]
    sun = np.clip(n @ (SUN / np.linalg.norm(SUN)), 0.0, None)
    return np.clip(FLOOR + SKY * sky + SUN_W * sun, 0.0, 1.0)


#: the light uses normals averaged over about this radius: a scan's surface noise (a few mm on a facade)
#: lit by per-vertex normals is a bumpy pattern the 2D model reads as foliage (Lille: facades 86 %
#: vegetation); averaged, a wall is one flat shade as a painted wall would be
SMOOTH_RADIUS_M = 0.5
#: the ``height`` tint's ground: the lowest vertex within a 3 x 3 block of cells this wide (LocalGround)
GROUND_CELL_M = 2.0


def smooth_normals(vertices: np.ndarray, faces: np.ndarray | None, normals: np.ndarray,
                   radius_m: float = SMOOTH_RADIUS_M) -> np.ndarray:
    """``normals`` averaged along the mesh's edges until they reach about ``radius_m`` (a diffusion:
    ``(radius / median edge)^2`` rounds of neighbour averaging, at most 400)."""
    n = _unit(normals)
    if faces is None or len(faces) == 0 or radius_m <= 0:
        return n
    import scipy.sparse as sp

    f = np.asarray(faces, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    edge = float(np.median(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1))) or radius_m
    iters = int(min(400, max(1, round((radius_m / edge) ** 2))))
    nv = len(v)
    a = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(nv, nv)).tocsr()
    a = a + sp.identity(nv, format="csr")
    deg = np.asarray(a.sum(axis=1)).ravel()
    a = sp.diags(1.0 / np.maximum(deg, 1)) @ a
    out = n.copy()
    for _ in range(iters):
        out = a @ out
    return _unit(out)


def stretch(x: np.ndarray, lo_q: float = 0.02, hi_q: float = 0.98) -> np.ndarray:
    """``x`` mapped to 0..1 between its percentiles (NaN -> 0.5)."""
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    if not ok.any():
        return np.full(len(x), 0.5)
    lo, hi = np.quantile(x[ok], [lo_q, hi_q])
    out = (x - lo) / max(hi - lo, 1e-12)
    return np.clip(np.where(ok, out, 0.5), 0.0, 1.0)


def vertex_colours(mode: str, vertices: np.ndarray, normals: np.ndarray,
                   intensity: np.ndarray | None = None, faces: np.ndarray | None = None) -> np.ndarray:
    """uint8 RGB per vertex for a colourless mesh (see the module's docstring); with ``faces`` the light
    uses normals smoothed over ``SMOOTH_RADIUS_M``."""
    n = len(vertices)
    if mode == "grey":
        return np.full((n, 3), 128, np.uint8)
    shade = light(smooth_normals(vertices, faces, normals) if faces is not None else normals)
    if mode == "intensity":
        if intensity is None:
            raise ValueError("intensity mode without intensities")
        g = (0.25 + 0.75 * stretch(intensity)) * (0.35 + 0.65 * shade)
        rgb = np.repeat(g[:, None], 3, axis=1)
    elif mode == "shaded":
        rgb = np.repeat((0.15 + 0.8 * shade)[:, None], 3, axis=1)
    elif mode == "height":
        from twinkit.street.ground import LocalGround

        v = np.asarray(vertices, dtype=np.float64)
        ground = LocalGround(v, cell_m=GROUND_CELL_M, window="min", window_m=3 * GROUND_CELL_M, pad_cells=0)
        h = np.clip(ground.height() / 8.0, 0.0, 1.0)
        base = 0.15 + 0.8 * shade
        tint = np.stack([1.0 + 0.25 * np.sin(np.pi * h), 1.0 - 0.1 * h, 1.0 - 0.25 * np.sin(np.pi * h) + 0.3 * h],
                        axis=1)
        ground = (h < 0.03)[:, None]
        rgb = base[:, None] * np.where(ground, 1.0, tint)
    else:
        raise ValueError(f"unknown colourless mode {mode!r} (one of {', '.join(MODES)})")
    return np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8)
