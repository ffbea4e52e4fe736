"""Meshes seen from above: reading PLY, rasterising faces, the road-surface mask."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twinkit import InputError

ROAD = 0  # CityScapes trainId of road


@dataclass
class Mesh:
    v: np.ndarray  # (n, 3) float64, site frame
    f: np.ndarray  # (m, 3) int
    rgb: np.ndarray | None  # (n, 3) uint8
    vlabel: np.ndarray | None  # (n,) per-vertex label if the file has one


def read_mesh(path: Path) -> Mesh:
    """PLY mesh in the site frame (twinkit.mesh.read_ply): vertices, triangles, colours and the
    per-vertex ``label`` when the file has one."""
    from twinkit.mesh import read_ply

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh not found")
    try:
        m = read_ply(path)
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"{path}: not a readable PLY mesh ({exc})") from None
    if m.faces is None:
        raise InputError(f"{path}: not a readable PLY mesh (no face element)")
    vlabel = np.asarray(m.attrs["label"]).astype(np.int32) if "label" in m.attrs else None
    return Mesh(m.vertices, m.faces, m.colors, vlabel)


@dataclass
class Grid:
    x0: float
    y0: float  # world coordinates of the top-left corner (x min, y max)
    res: float  # metres per pixel
    w: int
    h: int

    @classmethod
    def around(cls, xy: np.ndarray, res: float, pad: float = 2.0) -> "Grid":
        lo, hi = xy.min(0) - pad, xy.max(0) + pad
        return cls(float(lo[0]), float(hi[1]), res, int(np.ceil((hi[0] - lo[0]) / res)), int(np.ceil((hi[1] - lo[1]) / res)))

    def to_px(self, xy) -> np.ndarray:
        xy = np.asarray(xy, float)
        return np.stack([(xy[..., 0] - self.x0) / self.res, (self.y0 - xy[..., 1]) / self.res], -1)

    def sample(self, img: np.ndarray, xy) -> np.ndarray:
        """Nearest-pixel lookup; False/0 outside."""
        p = np.floor(self.to_px(xy)).astype(int)
        ok = (p[..., 0] >= 0) & (p[..., 0] < self.w) & (p[..., 1] >= 0) & (p[..., 1] < self.h)
        out = np.zeros(p.shape[:-1], img.dtype)
        out[ok] = img[p[..., 1][ok], p[..., 0][ok]]
        return out


def picture_grid(xy: np.ndarray, px_per_m: float, max_px: int) -> tuple[Grid, float]:
    """The grid of a top-view picture of points ``xy``: ``px_per_m`` pixels per metre, at most
    ``max_px`` pixels across (coarser for large sites), 2 m margin. Returns the grid and metres per pixel."""
    span = float(np.max(xy.max(0) - xy.min(0))) + 4.0
    res = max(1.0 / px_per_m, span / max_px)
    return Grid.around(xy, res), res


def rasterize(mesh: Mesh, grid: Grid, faces: np.ndarray | None = None, colours: np.ndarray | None = None,
              mode: str = "L") -> np.ndarray:
    """Draw faces seen from above (painter's order by height, so the top surface wins)."""
    from PIL import Image, ImageDraw

    fidx = np.arange(len(mesh.f)) if faces is None else np.asarray(faces)
    img = Image.new(mode, (grid.w, grid.h), 0 if mode == "L" else (40, 40, 40))
    if len(fidx) == 0:
        return np.asarray(img)
    tri = mesh.v[mesh.f[fidx]]
    order = np.argsort(tri[:, :, 2].mean(1), kind="stable")
    px = grid.to_px(tri[:, :, :2])
    draw = ImageDraw.Draw(img)
    if colours is None:
        for i in order:
            draw.polygon([tuple(q) for q in px[i]], fill=1)
    else:
        cols = [tuple(int(c) for c in col) for col in colours]
        for i in order:
            draw.polygon([tuple(q) for q in px[i]], fill=cols[i])
    return np.asarray(img)


def face_normals_z(mesh: Mesh, fidx=None) -> np.ndarray:
    f = mesh.f if fidx is None else mesh.f[fidx]
    a, b, c = mesh.v[f[:, 0]], mesh.v[f[:, 1]], mesh.v[f[:, 2]]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1)
    return np.where(ln > 0, n[:, 2] / np.maximum(ln, 1e-12), 0.0)


def road_faces(mesh: Mesh, labels: np.ndarray | None, curb_tol_m: float = 0.07, cell_m: float = 1.0,
               window_m: float = 9.0) -> tuple[np.ndarray, str]:
    """Faces of the road surface: from per-vertex labels when given, else from the ground.

    Without labels: faces facing up whose height is within ``curb_tol_m`` of the local lowest
    walkable level (the minimum of per-cell minima over ``window_m``), i.e. the carriageway below
    the curbs. It also takes low terrain and driveways; the fit is robust to that.
    """
    from scipy import ndimage

    if labels is not None:
        labels = np.asarray(labels).reshape(-1)
        if len(labels) != len(mesh.v):
            raise InputError(f"labels.npy has {len(labels)} entries but the mesh has {len(mesh.v)} vertices; "
                             "segment this mesh (the textured one) again")
        lv = labels[mesh.f]
        sel = np.flatnonzero((lv == ROAD).sum(1) >= 2)
        return sel, "labels"
    nz = face_normals_z(mesh)
    up = np.flatnonzero(nz > 0.95)
    if len(up) == 0:
        raise InputError("the mesh has no upward-facing faces; cannot find the ground")
    cz = mesh.v[mesh.f[up], 2].mean(1)
    cxy = mesh.v[mesh.f[up], :2].mean(1)
    lo = cxy.min(0)
    ij = np.floor((cxy - lo) / cell_m).astype(int)
    shape = tuple(ij.max(0) + 1)
    zmin = np.full(shape, np.inf)
    np.minimum.at(zmin, (ij[:, 0], ij[:, 1]), cz)
    k = max(1, int(round(window_m / cell_m)))
    level = ndimage.minimum_filter(zmin, size=k, mode="nearest")
    # robust: ignore isolated deep holes by taking a low percentile of the neighbourhood instead of the minimum
    finite = np.where(np.isfinite(zmin), zmin, np.nan)
    pct = ndimage.generic_filter(np.nan_to_num(finite, nan=np.nanmax(finite)), lambda a: np.percentile(a, 10),
                                 size=k, mode="nearest")
    level = np.maximum(level, pct - curb_tol_m)
    sel = up[cz - level[ij[:, 0], ij[:, 1]] < curb_tol_m]
    return sel, "ground"


def road_mask(mesh: Mesh, fidx: np.ndarray, grid: Grid, close_m: float = 1.0) -> np.ndarray:
    """Boolean road mask; small gaps closed and enclosed holes (cars, markings mislabelled) filled."""
    from scipy import ndimage

    m = rasterize(mesh, grid, fidx) > 0
    r = max(1, int(round(close_m / grid.res)))
    st = np.ones((2 * r + 1, 2 * r + 1), bool)
    m = ndimage.binary_closing(m, structure=st, border_value=0)
    m = ndimage.binary_fill_holes(m)
    m = ndimage.binary_opening(m, structure=np.ones((3, 3), bool))
    return m

