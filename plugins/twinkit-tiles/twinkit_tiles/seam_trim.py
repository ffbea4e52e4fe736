"""The distance trim near the seams, applied once to the merged mesh (the tiles trimmed only loosely
there), and the removal of faces left hanging on a seam edge whose other side the trim removed.
"""
from __future__ import annotations

import numpy as np

from twinkit.mesh import Mesh, compact

from .edges import _simple_loops, near_planes
from .seam_votes import _apply_votes


def trim_seam_bands(mesh: Mesh, planes: list[tuple[int, float]], points: np.ndarray, normals, band_m: float,
                    max_dist_m: float, gap_dist_m: float = 0.0, gap_plane_m: float = 0.02,
                    min_component_faces: int = 200, max_hole_edges: int = 60, threads: int = 1,
                    votes: np.ndarray | None = None, vote_radius_m: float = 0.0,
                    vote_plane_m: float = 0.05, vote_reach_m: float = 0.15,
                    hanging_tol_m: float = 0.0) -> tuple[Mesh, dict]:
    """The distance trim of the clean-up (``max_dist_m``, and the gap rule when ``normals`` are given),
    applied once to the merged mesh within ``band_m`` of the seams, where the tiles trimmed only
    loosely: a surface that ends near a seam then ends at the same place on both sides, instead of
    where each tile's own vertices happened to fall. Then the small components and holes that
    touch the bands are removed / closed as the tiles did. Only the points near the bands are used.

    ``votes``: rows (x, y, z, nx, ny, nz, keep, tile): each tile's own full-resolution surface near
    its core's interior sides (its neighbours' side included), with that surface's normal and its
    verdict under the same trim. Without them the verdict rests on the simplified tiles' vertices
    alone, and two tiles whose surfaces sit a couple of centimetres apart in sparse data (one on the
    points' tangent planes, one just off them) get opposite verdicts: a hole that ends straight
    along the seam. With ``vote_reach_m`` > 0 each tile's nearest vote within reach (whose tangent
    plane the vertex lies within ``vote_plane_m`` of) is that tile's verdict, and a place is kept
    when either tile's surface there passes, on both sides of the seam alike (``_apply_votes``).
    Rows of six columns are "keep" votes only, for the ``vote_radius_m`` rule.

    ``hanging_tol_m`` > 0: after the trim and the small components, the faces left hanging on a seam
    edge whose other side the trim removed are removed too (:func:`drop_hanging_faces`; an edge
    within ``hanging_tol_m`` of a plane is on it), so that the trim's boundary crosses a seam and
    never runs along it."""
    from twinkit.mesh import remove_vertices

    rep = {"band_m": band_m, "vertices_in_band": 0, "vertices_trimmed": 0, "vertices_kept_by_votes": 0,
           "vertices_dropped_by_votes": 0, "components_removed": 0, "hanging_faces_removed": 0, "holes_closed": 0}
    X = mesh.vertices
    inb = near_planes(X, planes, band_m)
    if not inb.any() or mesh.n_faces == 0:
        return mesh, rep
    near = near_planes(points, planes, band_m + max(gap_dist_m, max_dist_m) + 0.05)
    P = points[near]
    N = normals[near] if normals is not None else None
    if len(P) == 0:
        return mesh, rep
    idx = np.flatnonzero(inb)
    drop = _band_drop(X[idx], P, N, max_dist_m, gap_dist_m, gap_plane_m, threads)
    if votes is not None and len(votes) and (vote_radius_m > 0 or vote_reach_m > 0):
        drop = _apply_votes(X[idx], drop, votes, planes, band_m, vote_radius_m, vote_plane_m, vote_reach_m,
                            threads, rep)
    full = np.zeros(len(X), bool)
    full[idx[drop]] = True
    rep.update(vertices_in_band=int(len(idx)), vertices_trimmed=int(full.sum()))
    if hanging_tol_m > 0:  # the tile-border edges on the seams that are closed before the trim
        vid = np.arange(mesh.n_vertices)
        _, ids, op = _open_along_border(mesh, planes, hanging_tol_m, vid)
        closed_before = ids[~op]
        mesh = _with_attr(mesh, "_vid", vid)
    mesh = remove_vertices(mesh, full)
    if min_component_faces > 0 and mesh.n_faces:
        mesh = _drop_small_band_components(mesh, planes, band_m, min_component_faces, rep)
    if hanging_tol_m > 0:
        vid = mesh.attrs.pop("_vid")
        mesh, rep["hanging_faces_removed"] = drop_hanging_faces(mesh, planes, hanging_tol_m, closed_before, vid)
    if max_hole_edges >= 3 and mesh.n_faces:
        mesh, rep["holes_closed"] = _close_band_holes(mesh, planes, band_m, max_hole_edges)
    return mesh, rep


def _band_drop(Xb: np.ndarray, P: np.ndarray, N: np.ndarray | None, max_dist_m: float, gap_dist_m: float,
               gap_plane_m: float, threads: int) -> np.ndarray:
    """The clean-up's distance trim (and gap rule with normals ``N``) of the band vertices ``Xb`` (k, 3)
    against the points ``P`` near the bands: (k,) bool, True = drop."""
    from scipy.spatial import cKDTree
    from twinkit.surface.cleanup import CleanOptions, trim_mask, vertex_cloud_distance

    tree = cKDTree(P)
    d = vertex_cloud_distance(Xb, P, threads, tree)
    opt = CleanOptions(max_dist_m=max_dist_m, gap_dist_m=gap_dist_m, gap_plane_m=gap_plane_m, threads=threads)
    drop, _ = trim_mask(Xb, d, P, N, opt, tree)
    return drop


def _drop_small_band_components(mesh: Mesh, planes, band_m: float, min_faces: int, rep: dict) -> Mesh:
    """Remove the components under ``min_faces`` faces that touch a band (pieces the trim cut off);
    their count goes to ``rep["components_removed"]``."""
    from twinkit.mesh import components

    _, flab = components(mesh.n_vertices, mesh.faces)  # per-face component label
    size = np.bincount(flab)
    touch = np.zeros(len(size), bool)
    touch[flab[near_planes(mesh.vertices, planes, band_m)[mesh.faces].any(axis=1)]] = True
    small = touch & (size < min_faces)
    if small.any():
        rep["components_removed"] = int(small.sum())
        mesh = compact(mesh, ~small[flab])
    return mesh


def _close_band_holes(mesh: Mesh, planes, band_m: float, max_hole_edges: int) -> tuple[Mesh, int]:
    """Fan-fill the holes of at most ``max_hole_edges`` edges that touch a band: (mesh, holes closed)."""
    from twinkit.mesh import boundary_loops
    from twinkit.street.holes import fan_fill

    inb = near_planes(mesh.vertices, planes, band_m)
    loops = []
    for lp in boundary_loops(mesh.faces):
        if len(lp) <= max_hole_edges and inb[lp].any():
            loops.extend(sub for sub in _simple_loops(lp) if len(sub) >= 3)
    if loops:
        mesh = fan_fill(mesh, loops, face_fill=-1, recompute_normals=False)
    return mesh, len(loops)


def _along_border(mesh: Mesh, planes, tol_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The half-edges that run along a tile's border on a seam plane, and their faces: the edges of
    tile faces with both ends on one plane, and the first edge of stitch strip and fill faces (the
    same edges :func:`_tile_border` counts as cracks when open). Third value: every face with two
    vertices on a plane, the only faces that can hold such an edge or its twin."""
    F, X = mesh.faces, mesh.vertices
    tile = mesh.face_attrs.get("tile")
    hes, fids, near = [], [], []
    for axis, val in planes:
        on = np.abs(X[:, axis] - val) <= tol_m
        cand = np.flatnonzero(on[F].sum(axis=1) >= 2)
        near.append(cand)
        for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
            e = F[cand][:, [i, j]]
            ok = on[e[:, 0]] & on[e[:, 1]]
            if tile is not None and k > 0:
                ok &= tile[cand] >= 0
            hes.append(e[ok])
            fids.append(cand[ok])
    if not hes:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(hes), np.concatenate(fids), np.unique(np.concatenate(near))


def _with_attr(mesh: Mesh, name: str, arr: np.ndarray) -> Mesh:
    """The same mesh (arrays shared) with one more vertex attribute."""
    return Mesh(vertices=mesh.vertices, faces=mesh.faces, attrs=dict(mesh.attrs) | {name: arr},
                face_attrs=mesh.face_attrs, comments=list(mesh.comments))


def _edge_ids(he: np.ndarray, vid: np.ndarray, directed: bool = False) -> np.ndarray:
    """One int64 per edge, from the vertices' ids ``vid`` (below 2^31); undirected unless ``directed``."""
    a, b = vid[he[:, 0]].astype(np.int64), vid[he[:, 1]].astype(np.int64)
    if directed:
        return (a << 31) + b
    return (np.minimum(a, b) << 31) + np.maximum(a, b)


def _open_along_border(mesh: Mesh, planes, tol_m: float, vid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tile-border half-edges on the seams (:func:`_along_border`): their faces, their undirected
    edge ids under ``vid`` and whether each is open (no face holds the opposite half-edge)."""
    he, fid, near = _along_border(mesh, planes, tol_m)
    Fn = mesh.faces[near]
    every = _edge_ids(np.concatenate([Fn[:, [0, 1]], Fn[:, [1, 2]], Fn[:, [2, 0]]]), vid, directed=True)
    return fid, _edge_ids(he, vid), ~np.isin(_edge_ids(he[:, ::-1], vid, directed=True), every)


def drop_hanging_faces(mesh: Mesh, planes, tol_m: float, closed_before: np.ndarray, vid: np.ndarray,
                       rounds: int = 4) -> tuple[Mesh, int]:
    """Remove the faces left hanging on a seam: a face whose tile-border edge on a seam plane is open
    now but had a face on its other side before the trim (``closed_before``: edge ids under the
    pre-trim vertex ids ``vid``, one per vertex of ``mesh``). The trim removed the other tile's side
    there and kept this one, so the surface would end exactly on the seam; without the face the
    trim's boundary crosses the seam like it crosses any other line. Removing a strip face can bare
    the along-edge of a fill face beside it, hence a few ``rounds``. Edges that were open before the
    trim (where the zipper could not pair the borders) are left open and counted.
    Returns (mesh, faces removed). ``vid`` rides through the removals as a temporary vertex
    attribute, which the returned mesh no longer has."""

    mesh = _with_attr(mesh, "_vid", vid)
    removed = 0
    for _ in range(rounds):
        fid, ids, op = _open_along_border(mesh, planes, tol_m, mesh.attrs["_vid"])
        bad = op & np.isin(ids, closed_before)
        if not bad.any():
            break
        keep = np.ones(mesh.n_faces, bool)
        keep[fid[bad]] = False
        mesh = compact(mesh, keep)
        removed += int((~keep).sum())
    del mesh.attrs["_vid"]
    return mesh, removed
