"""Filling the occlusion shadows of the ground (road, sidewalk) that no scan line reached.

A parked car or a bicycle hides a patch of sidewalk from a street scanner. The cloud has no
point there, so Poisson has nothing to interpolate and the trimming removes what it guessed.
This module fills such patches on a 2.5D grid:

1. every grid cell (``cell_m``) is classified from the points in it: *ground* (points whose
   normal faces up, no higher than ``ground_tol_m`` above the lowest up-facing point within a
   few metres), *blocked* (points with a near-horizontal normal above the ground: a facade, a
   car's side, a fence, a pole) or *empty*;
2. an empty cell is a hole when, looking along x and along y, the first non-empty cell on both
   sides is ground and the two are at most ``max_gap_m`` apart: a shadow between ground cells.
   The two sides' heights differ by at most a kerb step plus a street's steepest slope over the gap
   (``kerb_step_m`` + ``max_slope`` x gap): a flat roof, a hedge's top or a car roof that passes for
   ground where no lower ground lies within the local window is not ramped up to.
   The inside of a building (walls on every side) and the land outside the scan (nothing on
   one side) are never filled;
3. (``passes`` times, the cells filled so far counting as ground) its height is interpolated linearly between those two ground cells (mean of the x and y
   estimates where both exist);
4. cells where the mesh already has surface within ``keep_if_mesh_within_m`` of that height
   are left as they are; the others become a grid patch (vertices at cell centres, two
   triangles per 2 x 2 block of hole cells) that is added to the mesh, with colours from the
   nearest ground point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.mesh import Mesh
from twinkit.street.holes import grid_patch, stitch


@dataclass
class GroundFillOptions:
    cell_m: float = 0.10
    max_gap_m: float = 8.0
    up_normal_z: float = 0.85  # a point is up-facing when its normal's z is at least this
    wall_normal_z: float = 0.5  # ... near-horizontal normal (|z| below this) and above the ground: blocking
    ground_tol_m: float = 0.25  # up-facing points this far above the local lowest are not ground (car roofs)
    local_window_m: float = 4.0
    keep_if_mesh_within_m: float = 0.05
    passes: int = 3  # later passes treat the cells filled before as ground (shadows seen along one axis)
    diagonal_gap_m: float = 3.0  # after the passes, one more: an empty cell between ground cells at most this far
    #                              apart along either diagonal is a shadow too. Where the ground's edge runs askew to
    #                              the grid (a sweep's far range) rows and columns fill up to a staircase, and a
    #                              lane's edge falls through its notches; the notches lie between two steps along
    #                              the diagonal. Short, and once, so it closes notches and grows nothing (along 8 m
    #                              diagonals in every pass the fill reached 41 % further into a sweep's far range).
    #                              0: off
    threads: int = -1
    # joining the fill to the reconstructed surface (``stitch``): the fill is one constrained Delaunay
    # triangulation (2D, seen from above) of the cells' centres and the mesh's open border near them,
    # with that border as fixed edges, so the new triangles share the mesh's own border vertices
    stitch: bool = True
    cover_band_m: float = 0.30  # a cell / triangle is already covered when the mesh passes this close above or below
    border_rise_m: float = 0.50  # open-border vertices up to this far above the local ground are joined (curb tops,
    #                              the skirt of a car); higher border (façades, canopies) is left alone
    stitch_reach_cells: int = 2  # the joining reaches this many cells past the filled ones
    under_objects: bool = True  # (with stitch) also the ground beneath objects that stand on it (a bush in its
    #                             tree pit, a parked car, a bollard): blocked cells with ground on both sides
    #                             within max_gap_m; where the object's own surface comes within cover_band_m
    #                             of the ground it is kept, elsewhere the ground runs on beneath it
    under_rise_m: float = 0.9  # ... sides more than this above the lowest ground within max_gap_m are no ground
    under_max_top_m: float = 2.8  # ... objects no taller than this (vehicles up to a van, bushes, people, bollards)
    under_clearance_m: float = 1.5  # ... or hanging at least this high (canopies, awnings)
    kerb_step_m: float = 0.3  # ... the two sides may differ by a kerb step
    max_slope: float = 0.15  # ... plus this slope over the gap (steeper than any street)
    sliver_max_m: float = 0.10  # (with stitch) closed shells this thin (volume / area seen from above) lying on the
    #                             ground the fill covers are taken out before it: Poisson's skin around a lone scan
    #                             line whose surroundings the trim removed. Left in, the fill stops short of it on
    #                             every side (its top is surface, its outline no open border to join) and leaves
    #                             a slit along it that a wheel falls through. 0: kept
    smooth_cells: int = 0  # the shadows' heights: the median over this many cells square of the filled and
    #                        ground cells around (0: off; the clean step turns it on for ground sampled in rings).
    #                        Each shadow cell's height is interpolated along its row and its column; where the
    #                        ground is rings of single points, neighbouring rows end on different rings or on a
    #                        noise point and one row or column stands a few cm proud, a streak one cell wide that a
    #                        wheel feels. Measured ground cells, and the ground beneath objects, keep their heights


def _first_nonempty(cls: np.ndarray, axis: int, reverse: bool):
    """For every cell, the index (along ``axis``) of the nearest non-empty cell strictly before it
    (after it with ``reverse``), -1 if none."""
    a = np.moveaxis(cls, axis, -1)
    n = a.shape[-1]
    idx = np.arange(n)
    if reverse:
        a = a[..., ::-1]
    has = a != 0
    last = np.where(has, idx, -1)
    last = np.maximum.accumulate(last, axis=-1)
    prev = np.concatenate([np.full(last.shape[:-1] + (1,), -1), last[..., :-1]], axis=-1)  # strictly before
    if reverse:
        prev = np.where(prev >= 0, n - 1 - prev, -1)[..., ::-1]
    return np.moveaxis(prev, -1, axis)


def cell_classes(points: np.ndarray, normals: np.ndarray, opt: GroundFillOptions, with_local: bool = False):
    """(classes (ny, nx) int8: 0 empty, 1 ground, 2 blocked; ground height (ny, nx); origin (2,)); with
    ``with_local`` also the local lowest up-facing height (ny, nx) (inf where none within the window) and,
    per cell, the lowest and the highest blocking point above it (inf / -inf where none).
    The ground is :class:`twinkit.street.ground.LocalGround`'s window minimum over ``local_window_m``
    (rejects car roofs, tables, the tops of walls), its ground points within ``ground_tol_m`` of it."""
    from twinkit.street.ground import LocalGround

    nz = normals[:, 2]
    g = LocalGround(points, nz >= opt.up_normal_z, cell_m=opt.cell_m, window="min", window_m=opt.local_window_m,
                    min_window_cells=3, ground_tol_m=opt.ground_tol_m, ground_stat="lowest", fill="none")
    nx, ny, lo = g.nx, g.ny, g.lo
    flat = g.flat
    zloc = g.level.ravel()
    ground = g.has_z.ravel()
    # blocking: near-horizontal normals above the ground level of the neighbourhood
    wall = (np.abs(nz) < opt.wall_normal_z) & (points[:, 2] > np.where(np.isfinite(zloc[flat]), zloc[flat], -np.inf)
                                                + opt.ground_tol_m)
    blocked = np.zeros(nx * ny, bool)
    blocked[flat[wall]] = True
    if with_local:  # per blocked cell, the lowest and highest blocking point above the local ground
        hb = points[wall, 2] - zloc[flat[wall]]
        bmin = np.full(nx * ny, np.inf)
        bmax = np.full(nx * ny, -np.inf)
        np.minimum.at(bmin, flat[wall], hb)
        np.maximum.at(bmax, flat[wall], hb)
    occupied = np.zeros(nx * ny, bool)
    occupied[flat] = True
    cls = np.zeros(nx * ny, np.int8)
    cls[occupied] = 2
    cls[ground] = 1
    cls[blocked] = 2
    if with_local:
        return (cls.reshape(ny, nx), g.z, lo, g.level, bmin.reshape(ny, nx), bmax.reshape(ny, nx))
    return cls.reshape(ny, nx), g.z, lo


def _skew(a: np.ndarray, anti: bool, pad) -> np.ndarray:
    """``a`` (ny, nx) sheared so that its diagonals become columns: cell (i, j) goes to column j - i + ny - 1
    (``anti``: i + j); the cells that fall outside the grid are ``pad``."""
    ny, nx = a.shape
    out = np.full((ny, nx + ny - 1), pad, dtype=a.dtype)
    i, j = np.indices((ny, nx))
    out[i, i + j if anti else j - i + ny - 1] = a
    return out


def _unskew(b: np.ndarray, shape: tuple[int, int], anti: bool) -> np.ndarray:
    """The grid (``shape``) back from a sheared ``b`` (``_skew``)."""
    ny, nx = shape
    i, j = np.indices((ny, nx))
    return b[i, i + j if anti else j - i + ny - 1]


def _between(cls: np.ndarray, gz: np.ndarray, max_cells: int, max_rise: tuple[float, float] | None,
             step: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Along axis 0: the empty cells with ground on both sides at most ``max_cells`` apart, and their heights
    interpolated between those two ground cells ((mask, estimate)); ``step``: the length of one step along
    axis 0 in cell sides (sqrt 2 on a sheared diagonal), for the rise allowed over the distance."""
    ny, nx = cls.shape
    a = _first_nonempty(cls, 0, reverse=False)
    b = _first_nonempty(cls, 0, reverse=True)
    pos = np.indices((ny, nx))[0]
    ok = (cls == 0) & (a >= 0) & (b >= 0) & ((b - a) <= max_cells)
    ia, ib = np.where(ok, a, 0), np.where(ok, b, 0)
    cols = np.arange(nx)[None, :]
    ok &= (cls[ia, cols] == 1) & (cls[ib, cols] == 1)
    za, zb = gz[ia, cols], gz[ib, cols]
    if max_rise is not None:
        with np.errstate(invalid="ignore"):
            rise = np.abs(np.where(ok, zb - za, 0.0))
        ok &= rise <= max_rise[0] + max_rise[1] * step * np.abs(ib - ia)
    t = np.where(ok, (pos - ia) / np.maximum(ib - ia, 1), 0.0)
    with np.errstate(invalid="ignore"):
        est = np.where(ok, za * (1 - t) + zb * t, 0.0)
    return ok, est


def _holes(cls: np.ndarray, gz: np.ndarray, max_cells: int, max_rise: tuple[float, float] | None = None,
           diagonal: bool = False):
    """Empty cells with ground on both sides along x or along y (``diagonal``: along either diagonal instead), at
    most ``max_cells`` (cell lengths) apart, and their height interpolated linearly between those ground cells
    (the mean over the directions that find both): (mask, height). ``max_rise`` (step, slope per cell): the two
    sides may differ in height by at most step + slope * distance."""
    shape = cls.shape
    est_sum = np.zeros(shape)
    est_n = np.zeros(shape)
    if diagonal:
        n = int(max_cells / np.sqrt(2.0))
        for anti in (False, True):
            ok, est = _between(_skew(cls, anti, 0), _skew(gz, anti, np.nan), n, max_rise, np.sqrt(2.0))
            est_sum += _unskew(est, shape, anti)
            est_n += _unskew(ok, shape, anti)
    else:
        for t in (False, True):
            ok, est = _between(cls.T if t else cls, gz.T if t else gz, max_cells, max_rise)
            est_sum += est.T if t else est
            est_n += ok.T if t else ok
    hole = est_n > 0
    return hole, np.where(hole, est_sum / np.maximum(est_n, 1), np.nan)


def _fill_passes(cls: np.ndarray, gz: np.ndarray, max_cells: int, diagonal_cells: int, max_rise, passes: int,
                 skip: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """The shadows (``_holes``) in ``passes`` rounds, the cells filled so far counting as ground in the next, then
    one round along the diagonals up to ``diagonal_cells`` (0: none); ``skip`` cells are never filled. Returns
    (filled, height, how many cells the diagonal round filled)."""
    filled = np.zeros(cls.shape, bool)
    height = np.full(cls.shape, np.nan)
    rounds = [(max_cells, False)] * max(1, int(passes)) + ([(diagonal_cells, True)] if diagonal_cells > 0 else [])
    settled = False  # nothing more along rows and columns: on to the diagonal round
    n_diagonal = 0
    for cells, diagonal in rounds:
        if settled and not diagonal:
            continue
        new, z = _holes(cls, gz, cells, max_rise=max_rise, diagonal=diagonal)
        new &= ~filled if skip is None else ~(filled | skip)
        if not new.any():
            settled = True
            continue
        filled |= new
        height[new] = z[new]
        n_diagonal += int(new.sum()) if diagonal else 0
        cls, gz = cls.copy(), gz.copy()
        cls[new] = 1
        gz[new] = z[new]
    return filled, height, n_diagonal


def smooth_heights(height: np.ndarray, fill: np.ndarray, ground_z: np.ndarray, ground: np.ndarray, size: int,
                   chunk: int = 400_000) -> np.ndarray:
    """``height`` (ny, nx) with each ``fill`` cell's value replaced by the median over the ``size`` x ``size``
    cells around it of the fill's heights and the ``ground`` cells' own heights (``ground_z``); other cells as
    they are. ``size`` below 2: unchanged."""
    if size < 2 or not fill.any():
        return height
    from numpy.lib.stride_tricks import sliding_window_view

    k = int(size) // 2
    vals = np.where(fill, height, np.where(ground, ground_z, np.nan))
    win = sliding_window_view(np.pad(vals, k, constant_values=np.nan), (2 * k + 1, 2 * k + 1))
    jj, ii = np.nonzero(fill)
    out = height.copy()
    for s in range(0, len(jj), chunk):
        j, i = jj[s:s + chunk], ii[s:s + chunk]
        out[j, i] = np.nanmedian(win[j, i].reshape(len(j), -1), axis=1)
    return out


def _cover(scene, xy: np.ndarray, z: np.ndarray, band: float) -> np.ndarray:
    """True where the mesh in ``scene`` crosses the vertical segment from ``z - band`` to ``z + band`` at ``xy``."""
    import open3d as o3d

    if len(xy) == 0:
        return np.zeros(0, bool)
    rays = np.zeros((len(xy), 6), np.float32)
    rays[:, :2] = xy
    rays[:, 2] = z + band
    rays[:, 5] = -1.0
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return t <= 2 * band


def ground_slivers(vertices: np.ndarray, faces: np.ndarray, cover: np.ndarray, height: np.ndarray, lo: np.ndarray,
                   cell_m: float, max_thick_m: float, band_m: float) -> tuple[np.ndarray, int]:
    """(faces (f,) bool, how many components): the mesh's connected components that are thin closed shells on
    the ground: their faces seen from above at least half as much facing down as up (a shell, not a sheet),
    their volume over their area seen from above at most ``max_thick_m``, and every vertex over a ``cover``
    cell (ny, nx) within ``band_m`` of its ``height``."""
    from twinkit.mesh.topology import components

    if len(faces) == 0:
        return np.zeros(0, bool), 0
    k, comp = components(len(vertices), faces)
    t = vertices[faces]
    o = t[:, 0]
    e1, e2 = t[:, 1] - o, t[:, 2] - o
    seen = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])  # area seen from above, signed: > 0 faces up
    up = np.bincount(comp, np.clip(seen, 0, None), k)
    down = np.bincount(comp, np.clip(-seen, 0, None), k)
    base = np.full((k, 3), np.inf)
    np.minimum.at(base, comp, t.min(axis=1))  # each component's volume about its own corner (less round-off)
    a, b, c = (t[:, i] - base[comp] for i in range(3))
    vol = np.abs(np.bincount(comp, np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0, k))
    thin = (up > 0) & (down >= 0.5 * up) & (vol <= max_thick_m * np.maximum(up, 1e-12))
    if not thin.any():
        return np.zeros(len(faces), bool), 0
    ny, nx = cover.shape
    ij = np.floor((vertices[:, :2] - lo) / cell_m).astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
    ij[~inside] = 0
    on = inside & cover[ij[:, 1], ij[:, 0]] & (np.abs(vertices[:, 2] - height[ij[:, 1], ij[:, 0]]) <= band_m)
    thin &= np.bincount(comp, ~on[faces].all(axis=1), k) == 0
    return thin[comp], int(thin.sum())


def _without_slivers(mesh: Mesh, cover: np.ndarray, height: np.ndarray, lo: np.ndarray, opt: GroundFillOptions,
                     rep: dict) -> Mesh:
    """The mesh less its :func:`ground_slivers` over the cells the fill covers (the fill runs over them)."""
    from twinkit.mesh import compact

    assert mesh.faces is not None  # a mesh, not a cloud
    drop, n = ground_slivers(mesh.vertices, mesh.faces, cover, height, lo, float(opt.cell_m), opt.sliver_max_m,
                             opt.cover_band_m)
    rep["slivers_removed"] = {"components": n, "faces": int(drop.sum())}
    return compact(mesh, ~drop) if n else mesh


def _stitched_fill(mesh: Mesh, cand: np.ndarray, height: np.ndarray, zloc: np.ndarray, lo: np.ndarray,
                   opt: GroundFillOptions, rep: dict):
    """The fill joined to the mesh: (new vertices (k, 3), new faces (f, 3) indexing ``mesh.vertices`` then the
    new vertices). ``cand``: cells to cover (ny, nx) bool, ``height`` their ground height."""
    assert mesh.faces is not None  # a mesh, not a cloud
    from scipy.ndimage import binary_dilation

    from .closest import Surface

    c = float(opt.cell_m)
    ny, nx = cand.shape
    v = mesh.vertices
    scene = Surface(v, mesh.faces, opt.threads).scene
    jj, ii = np.nonzero(cand)
    gxy = np.c_[lo[0] + (ii + 0.5) * c, lo[1] + (jj + 0.5) * c]
    gz = height[jj, ii]
    free = ~_cover(scene, gxy, gz, opt.cover_band_m)
    jj, ii, gxy, gz = jj[free], ii[free], gxy[free], gz[free]
    cells = np.zeros((ny, nx), bool)
    cells[jj, ii] = True
    rep["uncovered_cells"] = int(cells.sum())
    if not cells.any():
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    reach = max(1, int(opt.stitch_reach_cells))
    zone = binary_dilation(cells, structure=np.ones((3, 3), bool), iterations=reach)

    def cell_of(xy):
        ij = np.floor((xy - lo) / c).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        ij[~ok] = 0
        return ij, ok

    # the mesh's open border near the filled cells, at ground level
    f = mesh.faces
    he = np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1).reshape(-1, 2).astype(np.int64)
    m = int(v.shape[0])
    ukey = np.minimum(he[:, 0], he[:, 1]) * m + np.maximum(he[:, 0], he[:, 1])
    _, uinv, ucnt = np.unique(ukey, return_inverse=True, return_counts=True)
    border = he[ucnt[uinv] == 1]
    bv = np.unique(border)
    ij, ok = cell_of(v[bv, :2])
    ref = np.where(ok, zloc[ij[:, 1], ij[:, 0]], np.inf)
    dz = v[bv, 2] - ref
    level = np.zeros(m, bool)
    level[bv] = np.isfinite(ref) & (dz <= opt.border_rise_m) & (dz >= -opt.border_rise_m)
    inzone = np.zeros(m, bool)
    inzone[bv] = ok & zone[ij[:, 1], ij[:, 0]]
    border = border[level[border].all(axis=1) & inzone[border].any(axis=1)]

    def keep(cen: np.ndarray, edge2d: np.ndarray) -> np.ndarray:
        cij, cok = cell_of(cen[:, :2])
        sel = cok & zone[cij[:, 1], cij[:, 0]] & (edge2d <= 5 * c)
        sel[sel] = ~_cover(scene, cen[sel, :2], cen[sel, 2], opt.cover_band_m)
        return sel

    newv, nf = stitch(v, f, border, gxy, gz, keep, 0.4 * c, opt.threads, rep)
    rep["border_vertices_joined"] = int(len(np.unique(nf[nf < m])))
    return newv, nf


def fill_ground_holes(mesh: Mesh, points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None = None,
                      opt: GroundFillOptions | None = None, tree=None) -> tuple[Mesh, dict]:
    """Add grid patches over the ground's occlusion shadows; returns (mesh, report)."""
    assert mesh.faces is not None  # a mesh, not a cloud
    opt = opt or GroundFillOptions()
    c = float(opt.cell_m)
    cls, gz, lo, zloc, bmin, bmax = cell_classes(points, normals, opt, with_local=True)
    cls0, gz0 = cls, gz
    ny, nx = cls.shape
    max_cells = int(opt.max_gap_m / c)
    diag_cells = int(opt.diagonal_gap_m / c)
    rise = (opt.kerb_step_m, opt.max_slope * c)
    n_ground = int((cls == 1).sum())
    hole, hz, n_diag = _fill_passes(cls, gz, max_cells, diag_cells, rise, opt.passes)
    cls = np.where(hole, 1, cls).astype(np.int8)  # the cells filled count as ground beneath objects too
    gz = np.where(hole, hz, gz)
    rep = {"cell_m": c, "ground_cells": n_ground, "hole_cells": int(hole.sum()), "diagonal_cells": n_diag}
    if opt.stitch and mesh.n_faces:
        # cells to cover: the shadows, and ground cells the trimmed mesh no longer covers
        cand = hole | (cls0 == 1)
        height = np.where(hole, hz, gz0)
        if opt.under_objects:
            # beneath objects: blocked cells count as empty, the cells filled so far as ground. Only ground
            # that is truly the ground bounds them: up-facing surface within ``under_rise_m`` of the lowest
            # in a ``max_gap_m`` window (a canopy with no ground seen under it is no side), and the two
            # sides differ no more than a kerb step plus a street's steepest slope over the gap
            from scipy.ndimage import minimum_filter

            w = max(3, int(round(opt.max_gap_m / c)) | 1)
            zwide = minimum_filter(np.where(cls == 1, gz, np.inf), size=w, mode="nearest")
            # an object lets the ground run beneath it when it is low (a car, a bush, a bollard: its top at most
            # under_max_top_m) or hangs overhead (a canopy: its lowest point at least under_clearance_m up);
            # a building's walls stand on the ground and rise higher, so its inside is never filled
            low = (bmax <= opt.under_max_top_m) | (bmin >= opt.under_clearance_m)
            see = np.where((cls == 2) & low, 0, cls).astype(np.int8)
            see[(cls == 1) & ~(gz <= zwide + opt.under_rise_m)] = 0
            under, uz, n_diag_under = _fill_passes(see, gz, max_cells, diag_cells, rise, opt.passes, skip=cand)
            rep["diagonal_cells"] += n_diag_under
            rep["under_object_cells"] = int(under.sum())
            cand = cand | under
            height = np.where(under, uz, height)
        height = smooth_heights(height, hole, gz0, cls0 == 1, opt.smooth_cells)
        if opt.sliver_max_m > 0:
            # over the measured ground, the shadows and beneath canopies; not where a low object stands (a
            # bicycle's wheels leave a shell as thin on the ground)
            on = hole | (cls0 == 1) | (cand & (bmin >= opt.under_clearance_m))
            mesh = _without_slivers(mesh, on, height, lo, opt, rep)
        pv, pf = _stitched_fill(mesh, cand, height, zloc, lo, opt, rep)
        if len(pf) == 0:
            rep.update(filled_cells=0, faces_added=0)
            return mesh, rep
        return _append(mesh, pv, pf, points, colors, tree, opt, rep)
    if not hole.any():
        rep.update(filled_cells=0, faces_added=0)
        return mesh, rep
    hz = smooth_heights(hz, hole, gz0, cls0 == 1, opt.smooth_cells)
    jj, ii = np.nonzero(hole)
    centres = np.c_[lo[0] + (ii + 0.5) * c, lo[1] + (jj + 0.5) * c, hz[jj, ii]]
    if mesh.n_faces:
        from .closest import Surface

        assert mesh.faces is not None  # a mesh, not a cloud
        d = Surface(mesh.vertices, mesh.faces, opt.threads).distance(centres)
        fill = d > opt.keep_if_mesh_within_m
    else:
        fill = np.ones(len(centres), bool)
    cells = np.zeros((ny, nx), bool)
    cells[jj[fill], ii[fill]] = True
    pv, pf = grid_patch(cells, hz, lo, c)
    if len(pf) == 0:
        rep.update(filled_cells=0, faces_added=0)
        return mesh, rep
    pf = pf + mesh.n_vertices
    return _append(mesh, pv, pf, points, colors, tree, opt, rep)


def _append(mesh: Mesh, pv: np.ndarray, pf: np.ndarray, points, colors, tree, opt: GroundFillOptions,
            rep: dict) -> tuple[Mesh, dict]:
    """The mesh with new vertices ``pv`` (colour of the nearest point, normal up) and faces ``pf``."""
    assert mesh.faces is not None  # a mesh, not a cloud
    from scipy.spatial import cKDTree

    from twinkit.mesh import face_areas

    attrs = {}
    for k, arr in mesh.attrs.items():
        if k == "colors" and colors is not None and len(pv):
            t = tree if tree is not None else cKDTree(points)
            _, near = t.query(pv, workers=opt.threads)
            add = colors[near].astype(arr.dtype)
        elif k == "normals":
            add = np.tile(np.array([0, 0, 1], arr.dtype), (len(pv), 1))
        else:
            add = np.zeros((len(pv),) + arr.shape[1:], arr.dtype)
        attrs[k] = np.concatenate([arr, add])
    face_attrs = {k: np.concatenate([a, np.zeros((len(pf),) + a.shape[1:], a.dtype)])
                  for k, a in mesh.face_attrs.items()}
    out = Mesh(vertices=np.vstack([mesh.vertices, pv]), faces=np.vstack([mesh.faces, pf]), attrs=attrs,
               face_attrs=face_attrs, comments=list(mesh.comments))
    area = float(face_areas(out.vertices, np.asarray(pf, np.int64)).sum()) if len(pf) else 0.0
    rep.update(filled_cells=int(len(pv)), faces_added=int(len(pf)), area_m2=round(area, 2))
    return out, rep
