"""Meshes seen from above: rasterising faces, the road-surface mask.

A mesh here is the core's arrays: ``v`` (n, 3) float64 vertices, metres, site frame, and ``f`` (m, 3) int
triangles, as :class:`twinkit.mesh.Mesh` holds them (``vertices``, ``faces``; read through
:func:`twinkit.artefacts.read_textured_mesh`)."""
from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from twinkit import InputError
from twinkit.cityscapes import ROAD
from twinkit.mesh import face_areas


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


def top_faces(v: np.ndarray, f: np.ndarray, grid: Grid, faces: np.ndarray | None = None) -> np.ndarray:
    """The face each pixel of ``grid`` sees from above, of the triangles ``f`` of vertices ``v`` (site frame):
    (h, w) int64 positions in ``faces`` (indices into ``f``, all when None), -1 where none. The top surface
    wins (painter's order by mean height); the scanline edge rule of :func:`twinkit.mesh.raster.face_raster`
    (the pixels the roads' masks were first drawn with)."""
    from twinkit.mesh.raster import face_raster

    ff = f if faces is None else f[np.asarray(faces, np.int64)]
    return face_raster(v, ff, grid.x0, grid.y0, grid.res, (grid.h, grid.w),
                       order=v[ff, 2].mean(1) if len(ff) else None, rule="scanline")


def rasterize(v: np.ndarray, f: np.ndarray, grid: Grid, faces: np.ndarray | None = None,
              colours: np.ndarray | None = None) -> np.ndarray:
    """The faces ``faces`` of ``f`` seen from above (:func:`top_faces`): (h, w) uint8, 1 where a face is, 0
    elsewhere; with ``colours`` ((len(faces), 3) 0..255, a row per face) an (h, w, 3) uint8 picture, (40, 40,
    40) elsewhere."""
    top = top_faces(v, f, grid, faces)
    hit = top >= 0
    if colours is None:
        return hit.astype(np.uint8)
    img = np.full((grid.h, grid.w, 3), 40, np.uint8)
    img[hit] = np.asarray(colours).astype(np.int64)[top[hit]].astype(np.uint8)
    return img

def face_normals_z(v: np.ndarray, f: np.ndarray, fidx: np.ndarray | None = None) -> np.ndarray:
    """(k,) float64 z component of the unit normals of the faces ``fidx`` of ``f`` (all when None); 0 for a
    degenerate face."""
    f = f if fidx is None else f[fidx]
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1)
    return np.where(ln > 0, n[:, 2] / np.maximum(ln, 1e-12), 0.0)


def road_faces(v: np.ndarray, f: np.ndarray, labels: np.ndarray | None,
               curb_tol_m: float = 0.07) -> tuple[np.ndarray, str]:
    """Faces of the road surface (indices into ``f``) and how they were found: from per-vertex labels when
    given (two road corners of three), else from the ground.

    Without labels: the up-facing faces on the carriageway level, below the curbs (``level_faces``). It
    also takes low terrain and driveways; the fit is robust to that.
    """
    if labels is not None:
        labels = np.asarray(labels).reshape(-1)
        if len(labels) != len(v):
            raise InputError(f"labels.npy has {len(labels)} entries but the mesh has {len(v)} vertices; "
                             "segment this mesh (the textured one) again")
        lv = labels[f]
        sel = np.flatnonzero((lv == ROAD).sum(1) >= 2)
        return sel, "labels"
    return level_faces(v, f, curb_tol_m), "ground"


def level_faces(v: np.ndarray, f: np.ndarray, curb_tol_m: float = 0.07) -> np.ndarray:
    """Up-facing faces on the carriageway level: the ground below its curbs. The one test of the carriageway
    level for align_roads' ground fallback and road_source=scan.

    First the flat-street test: within ``curb_tol_m`` of the lowest ground within 9 m (``LocalGround``).
    A real street slopes along its length and is cambered across (Lille: the crown 15 cm above the gutter,
    a drain 20 cm lower still), and there that test keeps a sliver or the gutters: when it keeps less than
    three quarters of the ground that the step test finds low, the step test decides (``step_pieces``: the ground cut into
    pieces at its steps, a piece low when no piece next to it lies lower across a step). The step test
    alone joins road and sidewalk wherever a curb is ramped (crossings, driveways), which is why it is
    second: on the demo it widened the derived roads by 4 m."""
    nz = face_normals_z(v, f)
    up = np.flatnonzero(nz > 0.9)
    if len(up) == 0:
        raise InputError("the mesh has no upward-facing faces; cannot find the ground")
    flat = up[nz[up] > 0.95]
    win = flat
    if len(flat):  # the face centres' local lowest level: 1 m cells' minima, the minimum over 9 m raised to
        # the 9 m window's 10th percentile less the tolerance (a deep hole does not pull it down)
        from twinkit.street.ground import LocalGround

        cen = v[f[flat]].mean(1)
        g = LocalGround(cen, cell_m=1.0, window="min", window_m=9.0, odd_window=False, pad_cells=0, floor_pct=10,
                        floor_below_m=curb_tol_m)
        win = flat[g.height() < curb_tol_m]
    steps = _step_level(v, f, up, curb_tol_m)
    area = face_areas(v, f)
    if area[win].sum() >= 0.75 * area[steps].sum():
        return win
    return steps


def _step_level(v, f, up, curb_tol_m: float) -> np.ndarray:
    """The step test: faces ``up`` on pieces of the ground that no neighbouring piece lies below."""
    cen = v[f[up]].mean(1)
    edge = float(np.median(np.linalg.norm(v[f[up, 1]] - v[f[up, 0]], axis=1)))
    res = float(np.clip(2.0 * edge, 0.2, 0.5))
    grid = Grid.around(cen[:, :2], res, pad=1.0)
    px = np.floor(grid.to_px(cen[:, :2])).astype(int)
    z = np.full((grid.h, grid.w), np.inf)
    np.minimum.at(z, (px[:, 1], px[:, 0]), cen[:, 2])
    piece, low = step_pieces(z, res, max(0.5 * curb_tol_m, 0.16 * res))
    return up[low[piece[px[:, 1], px[:, 0]]]]


def step_pieces(z: np.ndarray, res: float, step_m: float, min_area_m2: float = 1.0, veto_area_m2: float = 10.0,
                veto_share: float = 0.25):
    """Pieces of a height raster ``z`` (inf where empty) between its steps, and which lie low.

    Returns ``(piece, low)``: ``piece`` (h, w) int, 0 for empty cells and the cells of a step, 1..n the
    pieces; ``low`` (n + 1,) bool by piece id: no neighbouring piece lies more than ``step_m`` below it
    where they meet (the heights compared on both sides of the step, within 3 cells of it, so a slope does
    not count). Pieces under ``min_area_m2`` are not low (bits of objects, noise). Only a neighbour of at
    least ``veto_area_m2``, or ``veto_share`` of the piece's own area when that is less, counts: a recessed
    doorstep, a drain or a light well a step below a street does not lift the street off the carriageway
    level (docs/roads.md, the step test)."""
    from scipy import ndimage

    fin = np.isfinite(z)
    zz = np.where(fin, z, 0.0)
    barrier = np.zeros_like(fin)
    for ax in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[ax], b[ax] = slice(0, -1), slice(1, None)
        jump = fin[tuple(a)] & fin[tuple(b)] & (np.abs(zz[tuple(a)] - zz[tuple(b)]) > step_m)
        barrier[tuple(a)] |= jump
        barrier[tuple(b)] |= jump
    # a curb line broken for a cell by noise is still a curb
    barrier = ndimage.binary_closing(barrier, np.ones((3, 3), bool)) & fin
    piece, n = ndimage.label(fin & ~barrier)
    low = np.zeros(n + 1, bool)
    if n == 0:
        return piece, low
    area = ndimage.sum(np.ones_like(z), piece, np.arange(n + 1)) * res * res
    big = np.flatnonzero(area >= min_area_m2)
    big = big[big > 0]
    low[big] = True
    boxes = ndimage.find_objects(piece)
    ring_r = 3
    st = np.ones((2 * ring_r + 1, 2 * ring_r + 1), bool)
    for k in big:
        sl = boxes[k - 1]
        r0, r1 = max(sl[0].start - ring_r - 1, 0), min(sl[0].stop + ring_r + 1, z.shape[0])
        c0, c1 = max(sl[1].start - ring_r - 1, 0), min(sl[1].stop + ring_r + 1, z.shape[1])
        pc = piece[r0:r1, c0:c1]
        me = pc == k
        zc = zz[r0:r1, c0:c1]
        ring = ndimage.binary_dilation(me, st) & ~me & (pc > 0)
        for other in np.unique(pc[ring]):
            if area[other] < max(min_area_m2, min(veto_area_m2, veto_share * area[k])):
                continue
            theirs = ring & (pc == other)
            mine = me & ndimage.binary_dilation(theirs, st)
            if mine.any() and float(np.median(zc[mine]) - np.median(zc[theirs])) > step_m:
                low[k] = False  # a neighbour lies lower across a step: this piece is above the carriageway
                break
    return piece, low


def road_mask(v: np.ndarray, f: np.ndarray, fidx: np.ndarray, grid: Grid, close_m: float = 1.0) -> np.ndarray:
    """(h, w) bool road mask of the faces ``fidx`` on ``grid``; small gaps closed and enclosed holes (cars,
    markings mislabelled) filled."""
    from scipy import ndimage

    m = rasterize(v, f, grid, fidx) > 0
    r = max(1, int(round(close_m / grid.res)))
    st = np.ones((2 * r + 1, 2 * r + 1), bool)
    m = ndimage.binary_closing(m, structure=st, border_value=0)
    m = ndimage.binary_fill_holes(m)
    m = ndimage.binary_opening(m, structure=np.ones((3, 3), bool))
    return m

