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
    threads: int = -1


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


def ground_grid(points: np.ndarray, normals: np.ndarray, opt: GroundFillOptions):
    """(classes (ny, nx) int8: 0 empty, 1 ground, 2 blocked; ground height (ny, nx); origin (2,))."""
    from scipy.ndimage import minimum_filter

    c = float(opt.cell_m)
    lo = points[:, :2].min(axis=0) - c
    ij = np.floor((points[:, :2] - lo) / c).astype(np.int64)
    nx, ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2
    flat = ij[:, 1] * nx + ij[:, 0]
    nz = normals[:, 2]
    up = nz >= opt.up_normal_z
    zmin = np.full(nx * ny, np.inf)
    np.minimum.at(zmin, flat[up], points[up, 2])
    # local lowest up-facing surface (rejects car roofs, tables, the tops of walls)
    w = max(3, int(round(opt.local_window_m / c)) | 1)
    zloc = minimum_filter(zmin.reshape(ny, nx), size=w, mode="nearest").ravel()
    is_ground_pt = up & (points[:, 2] <= zloc[flat] + opt.ground_tol_m)
    gz = np.full(nx * ny, np.inf)
    np.minimum.at(gz, flat[is_ground_pt], points[is_ground_pt, 2])
    ground = np.isfinite(gz)
    # blocking: near-horizontal normals above the ground level of the neighbourhood
    wall = (np.abs(nz) < opt.wall_normal_z) & (points[:, 2] > np.where(np.isfinite(zloc[flat]), zloc[flat], -np.inf)
                                                + opt.ground_tol_m)
    blocked = np.zeros(nx * ny, bool)
    blocked[flat[wall]] = True
    occupied = np.zeros(nx * ny, bool)
    occupied[flat] = True
    cls = np.zeros(nx * ny, np.int8)
    cls[occupied] = 2
    cls[ground] = 1
    cls[blocked] = 2
    return cls.reshape(ny, nx), gz.reshape(ny, nx), lo


def _holes(cls: np.ndarray, gz: np.ndarray, max_cells: int):
    """Empty cells with ground on both sides along x or along y (at most ``max_cells`` apart) and
    their height interpolated linearly between those ground cells: (mask, height)."""
    ny, nx = cls.shape
    est_sum = np.zeros((ny, nx))
    est_n = np.zeros((ny, nx))
    for axis in (0, 1):
        a = _first_nonempty(cls, axis, reverse=False)
        b = _first_nonempty(cls, axis, reverse=True)
        pos = np.indices((ny, nx))[axis]
        ok = (cls == 0) & (a >= 0) & (b >= 0) & ((b - a) <= max_cells)
        ia, ib = np.where(ok, a, 0), np.where(ok, b, 0)
        if axis == 0:
            ca, cb = cls[ia, np.arange(nx)[None, :]], cls[ib, np.arange(nx)[None, :]]
            za, zb = gz[ia, np.arange(nx)[None, :]], gz[ib, np.arange(nx)[None, :]]
        else:
            ca, cb = cls[np.arange(ny)[:, None], ia], cls[np.arange(ny)[:, None], ib]
            za, zb = gz[np.arange(ny)[:, None], ia], gz[np.arange(ny)[:, None], ib]
        ok &= (ca == 1) & (cb == 1)
        t = np.where(ok, (pos - ia) / np.maximum(ib - ia, 1), 0.0)
        za, zb = np.where(ok, za, 0.0), np.where(ok, zb, 0.0)
        est_sum += np.where(ok, za * (1 - t) + zb * t, 0.0)
        est_n += ok
    hole = est_n > 0
    return hole, np.where(hole, est_sum / np.maximum(est_n, 1), np.nan)


def fill_ground_holes(mesh: Mesh, points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None = None,
                      opt: GroundFillOptions | None = None, tree=None) -> tuple[Mesh, dict]:
    """Add grid patches over the ground's occlusion shadows; returns (mesh, report)."""
    from scipy.spatial import cKDTree

    opt = opt or GroundFillOptions()
    c = float(opt.cell_m)
    cls, gz, lo = ground_grid(points, normals, opt)
    ny, nx = cls.shape
    max_cells = int(opt.max_gap_m / c)
    hole = np.zeros((ny, nx), bool)
    hz = np.full((ny, nx), np.nan)
    n_ground = int((cls == 1).sum())
    for _ in range(max(1, int(opt.passes))):
        new, z = _holes(cls, gz, max_cells)
        if not new.any():
            break
        hole |= new
        hz[new] = z[new]
        cls, gz = cls.copy(), gz.copy()
        cls[new] = 1  # the next pass sees the cells filled so far as ground
        gz[new] = z[new]
    rep = {"cell_m": c, "ground_cells": n_ground, "hole_cells": int(hole.sum())}
    if not hole.any():
        rep.update(filled_cells=0, faces_added=0)
        return mesh, rep
    jj, ii = np.nonzero(hole)
    centres = np.c_[lo[0] + (ii + 0.5) * c, lo[1] + (jj + 0.5) * c, hz[jj, ii]]
    if mesh.n_faces:
        from .closest import Surface

        d = Surface(mesh.vertices, mesh.faces, opt.threads).distance(centres)
        fill = d > opt.keep_if_mesh_within_m
    else:
        fill = np.ones(len(centres), bool)
    vid = np.full((ny, nx), -1, np.int64)
    vid[jj[fill], ii[fill]] = np.arange(int(fill.sum()))
    # two triangles per 2 x 2 block of filled cells (one where exactly three are filled), counter-clockwise from above
    v00, v10, v01, v11 = vid[:-1, :-1], vid[:-1, 1:], vid[1:, :-1], vid[1:, 1:]
    tris = []
    full = (v00 >= 0) & (v10 >= 0) & (v01 >= 0) & (v11 >= 0)
    tris.append(np.c_[v00[full], v10[full], v11[full]])
    tris.append(np.c_[v00[full], v11[full], v01[full]])
    for a_, b_, c_, miss in ((v00, v10, v11, v01), (v00, v11, v01, v10), (v00, v10, v01, v11), (v10, v11, v01, v00)):
        three = (a_ >= 0) & (b_ >= 0) & (c_ >= 0) & (miss < 0)
        tris.append(np.c_[a_[three], b_[three], c_[three]])
    pf = np.vstack(tris).astype(np.int64)
    if len(pf) == 0:
        rep.update(filled_cells=0, faces_added=0)
        return mesh, rep
    used = np.unique(pf)
    remap = np.full(int(fill.sum()), -1, np.int64)
    remap[used] = np.arange(len(used))
    pv = centres[fill][used]
    pf = remap[pf] + mesh.n_vertices
    attrs = {}
    for k, arr in mesh.attrs.items():
        if k == "colors" and colors is not None:
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
    rep.update(filled_cells=int(len(pv)), faces_added=int(len(pf)), area_m2=round(float(len(pv) * c * c), 2))
    return out, rep
