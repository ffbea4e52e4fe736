"""Statistics of the merged mesh on its seams: open edges on the seam planes (cracks), classified by what
lies across the plane and joined into runs; tile faces outside their core (doubled surface); open border
near the seams vs. near control lines, per metre of surface cut."""
from __future__ import annotations

import numpy as np

from twinkit.mesh import Mesh

from .edges import _chains, boundary_half_edges


def seam_boundary_edges(mesh: Mesh, planes: list[tuple[int, float]], tol_m: float = 1e-3,
                        tile_faces_only: bool = False) -> int:
    """Boundary edges with both ends within ``tol_m`` of an interior seam plane (cracks).
    ``tile_faces_only``: count only the tiles' borders (:func:`_tile_border`), not the strip edges
    that cross from one tile's border to the other's where the mesh's own outer border passes the seam."""
    he, fid = boundary_half_edges(mesh.faces)
    if len(he) == 0 or not planes:
        return 0
    if tile_faces_only and "tile" in mesh.face_attrs:
        he = he[_tile_border(mesh, he, fid)]
    X = mesh.vertices
    hit = np.zeros(len(he), bool)
    for axis, val in planes:
        hit |= (np.abs(X[he[:, 0], axis] - val) <= tol_m) & (np.abs(X[he[:, 1], axis] - val) <= tol_m)
    return int(hit.sum())


def _tile_border(mesh: Mesh, he: np.ndarray, fid: np.ndarray) -> np.ndarray:
    """Which open half-edges ``he`` (of faces ``fid``) are a tile's border: every edge of a tile face
    (face attribute ``tile >= 0``), and the first edge of a stitch strip or fill face (``tile < 0``).
    The zipper makes (P[i+1], P[i], q) and (Q[j], Q[j+1], p), a fan fill (loop[i+1], loop[i], centre):
    the first edge runs along a tile's border, and open it is that border left bare, a crack like a
    tile face's own edge. A strip's other two edges go from one tile's border to the other's; open,
    they are where the mesh's own outer border passes the seam."""
    tile = mesh.face_attrs.get("tile")
    if tile is None:
        return np.ones(len(fid), bool)
    along = (mesh.faces[fid, 0] == he[:, 0]) & (mesh.faces[fid, 1] == he[:, 1])
    return (tile[fid] >= 0) | along


def _open_seam_edges(mesh: Mesh, planes: list[tuple[int, float]], reach_m: float, tol_m: float) -> dict:
    """Every open half-edge lying on a seam plane, with what tells a crack from a border crossing:
    ``plane`` (index into ``planes``), ``tile_face`` (the edge is a tile's border: an edge of a tile
    face, or the along-the-border edge of a stitch strip or fill face; not one crossing the gap between
    the tiles), and for those ``facing`` (the mesh across the plane has a vertex within ``reach_m``
    of the edge's midpoint)."""
    from scipy.spatial import cKDTree

    he, fid = boundary_half_edges(mesh.faces)
    out = {"he": np.zeros((0, 2), np.int64), "plane": np.zeros(0, np.int64), "tile_face": np.zeros(0, bool),
           "facing": np.zeros(0, bool)}
    if len(he) == 0 or not planes:
        return out
    X = mesh.vertices
    is_tile = _tile_border(mesh, he, fid)
    cen = X[mesh.faces[fid]].mean(axis=1)
    parts = {k: [] for k in out}
    for p, (axis, val) in enumerate(planes):
        on = (np.abs(X[he[:, 0], axis] - val) <= tol_m) & (np.abs(X[he[:, 1], axis] - val) <= tol_m)
        if not on.any():
            continue
        idx = np.flatnonzero(on)
        mid = X[he[idx]].mean(axis=1)
        off = cen[idx, axis] - val
        side = np.where(np.abs(off) <= tol_m, 0.0, np.sign(off))  # the side of the plane the edge's face is on
        slab = np.abs(X[:, axis] - val) <= reach_m
        near = {}  # near[s]: surface within reach_m strictly on side s of the plane
        sel = is_tile[idx]
        for sgn in (-1.0, 1.0):
            near[sgn] = np.zeros(len(idx), bool)
            there = slab & ((X[:, axis] - val) * sgn > tol_m)
            if sel.any() and there.any():
                d, _ = cKDTree(X[there]).query(mid[sel], distance_upper_bound=reach_m)
                near[sgn][sel] = np.isfinite(d)
        # a tile face's edge faces surface when the other side has some; a strip's or fill's edge (its face
        # lies in the plane) when both sides have (the tile it hangs on, and the one whose border is bare)
        facing = np.where(side < 0, near[1.0], np.where(side > 0, near[-1.0], near[1.0] & near[-1.0])) & sel
        parts["he"].append(he[idx])
        parts["plane"].append(np.full(len(idx), p, np.int64))
        parts["tile_face"].append(is_tile[idx])
        parts["facing"].append(facing)
    return {k: np.concatenate(v) if v else out[k] for k, v in parts.items()}


def seam_border_length(mesh: Mesh, planes: list[tuple[int, float]], tol_m: float = 1e-3) -> float:
    """Total length of the open edges lying on the seam planes (metres)."""
    he, _ = boundary_half_edges(mesh.faces)
    if len(he) == 0 or not planes:
        return 0.0
    X = mesh.vertices
    hit = np.zeros(len(he), bool)
    for axis, val in planes:
        hit |= (np.abs(X[he[:, 0], axis] - val) <= tol_m) & (np.abs(X[he[:, 1], axis] - val) <= tol_m)
    return float(np.linalg.norm(X[he[hit, 0]] - X[he[hit, 1]], axis=1).sum())


def classify_open_seam_edges(mesh: Mesh, planes: list[tuple[int, float]], reach_m: float = 0.2,
                             tol_m: float = 1e-3) -> dict:
    """Split the open seam edges of tile faces (the cracks counted by ``seam_boundary_edges``) by what
    lies across the plane: ``facing_surface`` when the mesh on the other side has a vertex within
    ``reach_m`` of the edge (a real gap between two surfaces), ``surface_ends`` when it has none (the
    neighbouring tile trimmed that surface away, so the mesh's own edge falls on the seam)."""
    e = _open_seam_edges(mesh, planes, reach_m, tol_m)
    t = e["tile_face"]
    return {"facing_surface": int((t & e["facing"]).sum()), "surface_ends": int((t & ~e["facing"]).sum()),
            "reach_m": reach_m}


def open_seam_runs(mesh: Mesh, planes: list[tuple[int, float]], reach_m: float = 0.2, tol_m: float = 1e-3) -> list[dict]:
    """The open edges on the seam planes as connected runs (polylines in a plane), longest first: where
    each lies (``plane``, ``centre``), its ``length_m`` and ``edges`` (and those of tile faces:
    ``tile_edges``, ``tile_edges_length_m``, of which ``facing_edges`` / ``facing_length_m`` face
    surface), and its ``kind``: ``facing_surface``
    (a tile's border with the other tile's surface across: a crack), ``surface_ends`` (a tile's border
    with nothing across: the mesh ends on the seam) or ``border_crossing`` (only edges of stitch strips
    and fills: the mesh's own outer border crossing the seam)."""
    e = _open_seam_edges(mesh, planes, reach_m, tol_m)
    X = mesh.vertices
    runs = []
    for p, (axis, val) in enumerate(planes):
        sel = np.flatnonzero(e["plane"] == p)
        if len(sel) == 0:
            continue
        key = {(int(a), int(b)): i for i, (a, b) in zip(sel.tolist(), e["he"][sel].tolist())}
        for ch in _chains(e["he"][sel]):
            idx = [key[(int(a), int(b))] for a, b in zip(ch[:-1], ch[1:]) if (int(a), int(b)) in key]
            if not idx:
                continue
            idx = np.asarray(idx)
            P = X[ch]
            t, f = e["tile_face"][idx], e["facing"][idx]
            kind = "facing_surface" if (t & f).any() else ("surface_ends" if t.any() else "border_crossing")
            H = e["he"][idx]
            L = np.linalg.norm(X[H[:, 0]] - X[H[:, 1]], axis=1)
            runs.append({"plane": ["xyz"[axis], round(float(val), 4)], "centre": np.round(P.mean(axis=0), 3).tolist(),
                         "length_m": round(float(L.sum()), 4), "edges": int(len(idx)), "tile_edges": int(t.sum()),
                         "tile_edges_length_m": round(float(L[t].sum()), 4), "facing_edges": int((t & f).sum()),
                         "facing_length_m": round(float(L[t & f].sum()), 4), "kind": kind})
    runs.sort(key=lambda r: -r["length_m"])
    return runs


def faces_outside_core(mesh: Mesh, tiles: list[dict], tol_m: float = 1e-5) -> int:
    """Doubled-surface check: tile faces whose centroid lies outside their own tile's core box."""
    if "tile" not in mesh.face_attrs:
        return 0
    t = mesh.face_attrs["tile"]
    c = mesh.vertices[mesh.faces].mean(axis=1)
    bad = 0
    for k, tile in enumerate(tiles):
        sel = t == k
        if not sel.any():
            continue
        xmin, ymin, xmax, ymax = tile["core"]
        cc = c[sel]
        out = np.zeros(len(cc), bool)
        if xmin is not None:
            out |= cc[:, 0] < xmin - tol_m
        if xmax is not None:
            out |= cc[:, 0] > xmax + tol_m
        if ymin is not None:
            out |= cc[:, 1] < ymin - tol_m
        if ymax is not None:
            out |= cc[:, 1] > ymax + tol_m
        bad += int(out.sum())
    return bad


def _slab_fraction(sa: np.ndarray, sb: np.ndarray, band_m: float) -> np.ndarray:
    """Fraction of each segment (signed plane distances ``sa`` -> ``sb``) lying within ``band_m`` of the plane."""
    d = sb - sa
    flat = np.abs(d) < 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-band_m - sa) / d, (band_m - sa) / d
    lo = np.clip(np.minimum(t1, t2), 0.0, 1.0)
    hi = np.clip(np.maximum(t1, t2), 0.0, 1.0)
    return np.where(flat, (np.abs(sa) <= band_m).astype(np.float64), np.maximum(hi - lo, 0.0))


def _section_length(X: np.ndarray, F: np.ndarray, axis: int, val: float) -> float:
    """Length of the mesh's cross-section by the plane ``coord[axis] == val`` (faces lying in it excluded)."""
    s = X[:, axis][F] - val
    cut = (s.min(axis=1) < 0) & (s.max(axis=1) > 0)
    if not cut.any():
        return 0.0
    T, s = X[F[cut]], s[cut]
    pts = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = s[:, i], s[:, j]
        cross = (a < 0) != (b < 0)
        t = np.where(cross, a / np.where(cross, a - b, 1.0), np.nan)
        pts.append(T[:, i] + (T[:, j] - T[:, i]) * t[:, None])
    P = np.stack(pts, axis=1)  # (n, 3 edges, 3); exactly two edges cross (a vertex on the plane: one, skipped)
    ok = np.isfinite(P[:, :, 0]).sum(axis=1) == 2
    P = P[ok]
    fin = np.isfinite(P[:, :, 0])
    first = np.argmax(fin, axis=1)
    last = 2 - np.argmax(fin[:, ::-1], axis=1)
    idx = np.arange(len(P))
    return float(np.linalg.norm(P[idx, first] - P[idx, last], axis=1).sum())


def open_near_lines(mesh: Mesh, planes: list[tuple[int, float]], band_m: float = 0.1) -> dict:
    """How much open border lies near the given vertical planes, for comparing seams with lines where
    there is no seam (control planes, or the same planes on an untiled mesh): the length of boundary
    edges within ``band_m`` of the planes (the part of each edge inside the slab), per metre of surface
    the planes cut (the mesh's cross-section length, taken ``band_m`` / 2 either side of each plane so
    that faces lying in a seam plane do not count). A seam adds no cracks when its figure is no higher
    than that of the control planes."""
    return open_near_line_sets(mesh, {"lines": planes}, band_m)["lines"]


def open_near_line_sets(mesh: Mesh, sets: dict, band_m: float = 0.1) -> dict:
    """:func:`open_near_lines` for several sets of planes (e.g. seams and controls), finding the mesh's
    boundary once. Returns one result per key of ``sets``."""
    res = {k: {"planes": len(pl), "band_m": band_m, "open_m": 0.0, "section_m": 0.0, "open_per_section": None}
           for k, pl in sets.items()}
    if mesh.n_faces == 0:
        return res
    X, F = mesh.vertices, mesh.faces
    he, _ = boundary_half_edges(F)
    L = np.linalg.norm(X[he[:, 0]] - X[he[:, 1]], axis=1) if len(he) else np.zeros(0)
    for key, planes in sets.items():
        if not planes:
            continue
        open_m = section = 0.0
        for axis, val in planes:
            if len(he):
                open_m += float((L * _slab_fraction(X[he[:, 0], axis] - val, X[he[:, 1], axis] - val, band_m)).sum())
            section += 0.5 * (_section_length(X, F, axis, val - band_m / 2) +
                              _section_length(X, F, axis, val + band_m / 2))
        res[key].update(open_m=round(open_m, 3), section_m=round(section, 3),
                        open_per_section=round(open_m / section, 5) if section > 0 else None)
    return res
