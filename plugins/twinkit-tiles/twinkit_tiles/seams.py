"""Exact planar cuts of a tile mesh to its core, and zipper stitching of neighbouring tiles.

A tile is reconstructed on its padded box (core + overlap) and then cut to its core box with
:func:`cut_to_box`: triangles crossing a cut plane are split, and every border vertex lies
exactly on the plane (its coordinate along the plane's axis is set to the plane's value).
Two neighbouring tiles therefore meet on a shared plane with two border polylines that nearly
coincide (both tiles saw the same points in the overlap). :func:`stitch` joins them with a
strip of triangles (greedy shortest-diagonal zipper) so the merged mesh has no crack there.

:func:`merge_grid` merges a whole grid hierarchically: tiles of a row left to right along the
x planes, then the rows bottom to top along the y planes. The x-stitch strips end on the
y planes, so when rows are joined the corner where four tiles meet is closed by the same
zipper (no special case for corners).

Everything is numpy on :class:`twinkit.mesh.Mesh`; no extra dependency.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit.mesh import Mesh, compact

ON_PLANE_M = 5e-4  # a vertex this close to a cut plane is moved onto it (no sliver edges along the seam)


# ----------------------------------------------------------------------------- small helpers

def _interp_attr(arr: np.ndarray, a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Attribute of points at parameter t on edges a->b: linear for floats/colours, nearest for labels."""
    if arr.dtype.kind == "f":
        tt = t.reshape((-1,) + (1,) * (arr.ndim - 1))
        return (arr[a] * (1 - tt) + arr[b] * tt).astype(arr.dtype)
    if arr.dtype == np.uint8 and arr.ndim == 2:  # colours
        tt = t[:, None]
        return np.clip(np.rint(arr[a] * (1 - tt) + arr[b] * tt), 0, 255).astype(np.uint8)
    return np.where((t < 0.5).reshape((-1,) + (1,) * (arr.ndim - 1)), arr[a], arr[b])


def _edge_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    return lo * (1 << 32) + hi


def boundary_half_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half-edges (a, b) that belong to exactly one face, and the index of that face."""
    if len(faces) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    key = _edge_keys(he[:, 0], he[:, 1])
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    sel = counts[inv.ravel()] == 1
    return he[sel], np.repeat(np.arange(len(faces)), 3)[sel]


def edge_counts(faces: np.ndarray) -> dict:
    """Boundary edges (1 face) and non-manifold edges (> 2 faces) of a triangle mesh."""
    if len(faces) == 0:
        return {"edges": 0, "boundary_edges": 0, "non_manifold_edges": 0}
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    _, counts = np.unique(_edge_keys(he[:, 0], he[:, 1]), return_counts=True)
    return {"edges": int(len(counts)), "boundary_edges": int((counts == 1).sum()),
            "non_manifold_edges": int((counts > 2).sum())}


# ----------------------------------------------------------------------------- the cut

def cut_halfspace(mesh: Mesh, axis: int, value: float, keep: str) -> Mesh:
    """Keep the part of ``mesh`` with ``coord[axis] >= value`` (``keep='above'``) or ``<= value``
    (``keep='below'``). Triangles crossing the plane are split; new vertices are placed on the
    plane exactly (their ``axis`` coordinate is ``value``) and shared by the two faces of their edge.
    Attributes are interpolated (floats, colours) or taken from the nearer end (labels)."""
    if mesh.n_faces == 0:
        return mesh
    v = mesh.vertices.astype(np.float64, copy=True)
    s = v[:, axis] - value
    if keep == "below":
        s = -s
    elif keep != "above":
        raise ValueError("keep must be 'above' or 'below'")
    snap = np.abs(s) <= ON_PLANE_M
    v[snap, axis] = value
    s[snap] = 0.0
    f = mesh.faces
    sf = s[f]
    inside = (sf >= 0).all(axis=1) & ~(sf == 0).all(axis=1)
    cross = (sf > 0).any(axis=1) & (sf < 0).any(axis=1)
    keep_f = f[inside]
    keep_fa = {k: a[inside] for k, a in mesh.face_attrs.items()}
    attrs = dict(mesh.attrs)
    if cross.any():
        cf = f[cross]
        cfa = {k: a[cross] for k, a in mesh.face_attrs.items()}
        # one new vertex per crossing edge, shared by both faces of that edge
        ea = np.concatenate([cf[:, 0], cf[:, 1], cf[:, 2]])
        eb = np.concatenate([cf[:, 1], cf[:, 2], cf[:, 0]])
        straddle = (s[ea] * s[eb]) < 0
        lo, hi = np.minimum(ea, eb)[straddle], np.maximum(ea, eb)[straddle]
        pairs, inv = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True)
        a, b = pairs[:, 0], pairs[:, 1]
        t = s[a] / (s[a] - s[b])
        newv = v[a] + (v[b] - v[a]) * t[:, None]
        newv[:, axis] = value
        base = len(v)
        edge_vertex = np.full(len(ea), -1, np.int64)
        edge_vertex[straddle] = base + inv.ravel()
        nc = len(cf)
        ev = edge_vertex.reshape(3, nc).T  # ev[k, i]: new vertex on edge i -> i+1 of face k (or -1)
        tris, owner = [], []
        for k in range(nc):
            poly = []
            for i in range(3):
                vi = cf[k, i]
                if s[vi] >= 0:
                    poly.append(vi)
                if ev[k, i] >= 0:
                    poly.append(ev[k, i])
            for j in range(1, len(poly) - 1):
                tris.append((poly[0], poly[j], poly[j + 1]))
                owner.append(k)
        v = np.vstack([v, newv])
        attrs = {k: np.concatenate([arr, _interp_attr(arr, a, b, t)]) for k, arr in mesh.attrs.items()}
        if tris:
            owner = np.asarray(owner, np.int64)
            keep_f = np.vstack([keep_f, np.asarray(tris, np.int64)])
            keep_fa = {k: np.concatenate([keep_fa[k], cfa[k][owner]]) for k in keep_fa}
    out = Mesh(vertices=v, faces=keep_f, attrs=attrs, face_attrs=keep_fa, comments=list(mesh.comments))
    return compact(out)


def cut_to_box(mesh: Mesh, core: list) -> Mesh:
    """Cut a tile mesh to its core box ``[xmin, ymin, xmax, ymax]`` (``None`` = unbounded side,
    i.e. the outer border of the site: nothing is cut there)."""
    xmin, ymin, xmax, ymax = core
    for axis, val, keep in ((0, xmin, "above"), (0, xmax, "below"), (1, ymin, "above"), (1, ymax, "below")):
        if val is not None and mesh.n_faces:
            mesh = cut_halfspace(mesh, axis, float(val), keep)
    return mesh


# ----------------------------------------------------------------------------- chains on a plane

def plane_chains(mesh: Mesh, axis: int, value: float, tol: float = 1e-5) -> list[np.ndarray]:
    """Boundary polylines of ``mesh`` lying on the plane ``coord[axis] == value``, as vertex-index
    arrays following the faces' half-edge direction. A closed loop repeats its first vertex at the end."""
    he, _ = _plane_half_edges(mesh.vertices, mesh.faces, axis, value, tol)
    return _chains(he)


def _plane_half_edges(X: np.ndarray, faces: np.ndarray, axis: int, value: float, tol: float):
    """Boundary half-edges with both ends on the plane, and the index of their face."""
    on = np.abs(X[:, axis] - value) <= tol
    near = np.flatnonzero(on[faces].sum(axis=1) >= 2)  # every face with an edge on the plane
    he, fid = boundary_half_edges(faces[near])
    if len(he) == 0:
        return he, fid
    keep = on[he[:, 0]] & on[he[:, 1]]
    return he[keep], near[fid[keep]]


def _chains(he: np.ndarray) -> list[np.ndarray]:
    if len(he) == 0:
        return []
    nxt: dict[int, list[int]] = {}
    indeg: dict[int, int] = {}
    for a, b in he.tolist():
        nxt.setdefault(a, []).append(b)
        indeg[b] = indeg.get(b, 0) + 1
    chains = []

    def walk(start):
        chain = [start]
        cur = start
        while nxt.get(cur):
            cur = nxt[cur].pop()
            chain.append(cur)
            if cur == start:
                break
        return chain

    for s0 in [a for a in nxt if indeg.get(a, 0) == 0]:
        while nxt.get(s0):
            chains.append(np.asarray(walk(s0), np.int64))
    for s0 in list(nxt):
        while nxt.get(s0):
            chains.append(np.asarray(walk(s0), np.int64))
    return [c for c in chains if len(c) >= 2]


def _zipper(P: np.ndarray, Q: np.ndarray, X: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles between polylines P (half-edges P[i] -> P[i+1]) and Q (half-edges Q[j+1] -> Q[j]),
    both running the same way, choosing the shorter diagonal at each step. Orientation matches the
    faces on both sides (each border half-edge is used once, reversed)."""
    tris = []
    i = j = 0
    m, n = len(P), len(Q)
    while i < m - 1 or j < n - 1:
        if i == m - 1:
            adv_p = False
        elif j == n - 1:
            adv_p = True
        else:
            adv_p = np.sum((X[P[i + 1]] - X[Q[j]]) ** 2) <= np.sum((X[P[i]] - X[Q[j + 1]]) ** 2)
        if adv_p:
            tris.append((int(P[i + 1]), int(P[i]), int(Q[j])))
            i += 1
        else:
            tris.append((int(Q[j]), int(Q[j + 1]), int(P[i])))
            j += 1
    return tris


@dataclass
class SeamStats:
    axis: str
    value: float
    chains_a: int = 0
    chains_b: int = 0
    pairs: int = 0
    border_edges_a: int = 0
    border_edges_b: int = 0
    stitched_faces: int = 0
    rejected_faces: int = 0
    gap_mm: list = field(default_factory=list)

    def as_dict(self) -> dict:
        g = np.asarray(self.gap_mm, np.float64)
        return {"axis": self.axis, "value_m": round(self.value, 6), "chains_a": self.chains_a,
                "chains_b": self.chains_b, "pairs": self.pairs, "border_edges_a": self.border_edges_a,
                "border_edges_b": self.border_edges_b, "stitched_faces": self.stitched_faces,
                "rejected_faces": self.rejected_faces,
                "gap_mean_mm": round(float(g.mean()), 3) if len(g) else None,
                "gap_p95_mm": round(float(np.quantile(g, 0.95)), 3) if len(g) else None,
                "gap_max_mm": round(float(g.max()), 3) if len(g) else None}


def _concat(a: Mesh, b: Mesh) -> Mesh:
    names = [k for k in a.attrs if k in b.attrs and a.attrs[k].shape[1:] == b.attrs[k].shape[1:]]
    fnames = [k for k in a.face_attrs if k in b.face_attrs]
    return Mesh(vertices=np.vstack([a.vertices, b.vertices]),
                faces=np.vstack([a.faces, b.faces + a.n_vertices]),
                attrs={k: np.concatenate([a.attrs[k], b.attrs[k].astype(a.attrs[k].dtype)]) for k in names},
                face_attrs={k: np.concatenate([a.face_attrs[k], b.face_attrs[k].astype(a.face_attrs[k].dtype)])
                            for k in fnames},
                comments=list(a.comments))


def stitch(a: Mesh, b: Mesh, axis: int, value: float, max_gap_m: float = 0.1, tol: float = 1e-5,
           passes: int = 3) -> tuple[Mesh, SeamStats]:
    """Join mesh ``a`` (the side ``coord[axis] <= value``) and ``b`` (``>= value``), both cut exactly on
    the plane, into one mesh: their border polylines on the plane are paired by proximity and joined by
    a zipper strip. Strip triangles with an edge longer than ``max_gap_m`` are not made (that part stays
    open and is counted). Leftover pieces of border (where a pairing covered only part of a polyline)
    are paired again, up to ``passes`` times. Strip faces get face attribute ``tile = -1``."""
    st = SeamStats("xyz"[axis], float(value))
    if a.n_faces == 0 or b.n_faces == 0:
        m = a if b.n_faces == 0 else b
        return m, st
    merged = _concat(a, b)
    na_f, nb_f = a.n_faces, b.n_faces
    for k in range(passes):
        he, fid = _plane_half_edges(merged.vertices, merged.faces, axis, value, tol)
        ca = _chains(he[fid < na_f])
        cb = [c[::-1] for c in _chains(he[(fid >= na_f) & (fid < na_f + nb_f)])]  # reversed: same direction as a's
        if k == 0:
            st.chains_a, st.chains_b = len(ca), len(cb)
            st.border_edges_a = int(sum(len(c) - 1 for c in ca))
            st.border_edges_b = int(sum(len(c) - 1 for c in cb))
        if not ca or not cb:
            break
        T = _pair_and_zip(merged.vertices, ca, cb, axis, max_gap_m, st, first=(k == 0))
        if len(T) == 0:
            break
        T = _drop_duplicate_half_edges(merged.faces, T)
        if len(T) == 0:
            break
        st.stitched_faces += int(len(T))
        merged.faces = np.vstack([merged.faces, T])
        for name, arr in merged.face_attrs.items():
            fill = np.full((len(T),) + arr.shape[1:], -1 if arr.dtype.kind == "i" else 0, dtype=arr.dtype)
            merged.face_attrs[name] = np.concatenate([arr, fill])
    return merged, st


def _pair_and_zip(X, ca, cb, axis, max_gap_m, st, first: bool) -> np.ndarray:
    from scipy.spatial import cKDTree

    other = [k for k in range(3) if k != axis]
    va = np.concatenate(ca)
    vb = np.concatenate(cb)
    la = np.concatenate([np.full(len(c), i) for i, c in enumerate(ca)])
    lb = np.concatenate([np.full(len(c), i) for i, c in enumerate(cb)])
    ia = np.concatenate([np.arange(len(c)) for c in ca])
    ib = np.concatenate([np.arange(len(c)) for c in cb])
    ta, tb = cKDTree(X[va][:, other]), cKDTree(X[vb][:, other])
    da, na = tb.query(X[va][:, other], distance_upper_bound=max_gap_m)  # a vertex -> nearest b vertex
    db, nb = ta.query(X[vb][:, other], distance_upper_bound=max_gap_m)
    if first:
        st.gap_mm = (_polyline_gap(X[:, other], va, la, na, da, vb, lb) * 1000).tolist()
    new_tris: list[tuple[int, int, int]] = []
    for i, c in enumerate(ca):
        sel = (la == i) & np.isfinite(da)
        if not sel.any():
            continue
        for j in np.unique(lb[na[sel]]):
            q = cb[j]
            pa = ia[sel & (lb[np.minimum(na, len(vb) - 1)] == j)]
            selb = (lb == j) & np.isfinite(db)
            pb = ib[selb & (la[np.minimum(nb, len(va) - 1)] == i)]
            if len(pa) == 0 or len(pb) == 0:
                continue
            closed_a = c[0] == c[-1] and len(c) > 3
            closed_b = q[0] == q[-1] and len(q) > 3
            if closed_a and closed_b:
                P = c
                qq = q[:-1]
                k0 = int(np.argmin(np.sum((X[qq][:, other] - X[c[0]][other]) ** 2, axis=1)))
                Q = np.concatenate([np.roll(qq, -k0), [qq[k0]]])
            else:
                a0, a1, b0, b1 = int(pa.min()), int(pa.max()), int(pb.min()), int(pb.max())
                # extend a range to its chain's end when that end is within reach of the other range's end
                near = lambda u, v: float(np.linalg.norm(X[u] - X[v])) <= max_gap_m  # noqa: E731
                if a0 > 0 and near(c[0], q[b0]):
                    a0 = 0
                if b0 > 0 and near(q[0], c[a0]):
                    b0 = 0
                if a1 < len(c) - 1 and near(c[-1], q[b1]):
                    a1 = len(c) - 1
                if b1 < len(q) - 1 and near(q[-1], c[a1]):
                    b1 = len(q) - 1
                P, Q = c[a0: a1 + 1], q[b0: b1 + 1]
            if len(P) < 2 and len(Q) < 2:
                continue
            dp, dq = X[P[-1]] - X[P[0]], X[Q[-1]] - X[Q[0]]
            if len(P) > 2 and len(Q) > 2 and float(np.dot(dp, dq)) < 0:
                continue  # opposite directions: not the same surface
            st.pairs += 1
            new_tris.extend(_zipper(P, Q, X))
    if not new_tris:
        return np.zeros((0, 3), np.int64)
    T = np.asarray(new_tris, np.int64)
    degenerate = (T[:, 0] == T[:, 1]) | (T[:, 1] == T[:, 2]) | (T[:, 0] == T[:, 2])
    L = np.stack([np.linalg.norm(X[T[:, k]] - X[T[:, (k + 1) % 3]], axis=1) for k in range(3)], axis=1)
    too_long = L.max(axis=1) > max_gap_m * 1.5 + 1e-9
    st.rejected_faces += int((too_long & ~degenerate).sum())
    return T[~degenerate & ~too_long]


def _polyline_gap(Y, va, la, na, da, vb, lb) -> np.ndarray:
    """Distance from each border vertex of a to the nearest border segment of b (2D, in the plane),
    for the vertices that have a partner within range."""
    ok = np.isfinite(da)
    if not ok.any():
        return np.zeros(0)
    k = na[ok]
    p = Y[va[ok]]
    best = da[ok].copy()
    for d in (-1, 1):
        k2 = np.clip(k + d, 0, len(vb) - 1)
        same = lb[k2] == lb[k]
        a, b = Y[vb[k]], Y[vb[k2]]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18), 0, 1)
        dist = np.linalg.norm(a + ab * t[:, None] - p, axis=1)
        best = np.where(same, np.minimum(best, dist), best)
    return best


def _drop_duplicate_half_edges(faces: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Remove strip triangles that would reuse a half-edge already present (non-manifold or flipped)."""
    def hes(F):
        return np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1).reshape(-1, 2)

    touch = np.zeros(int(max(faces.max(), T.max())) + 1, bool)
    touch[T.ravel()] = True
    near = faces[touch[faces].sum(axis=1) >= 2]
    h = hes(near)
    used = set((h[:, 0].astype(np.int64) * (1 << 32) + h[:, 1]).tolist())
    th = hes(T)
    th = (th[:, 0].astype(np.int64) * (1 << 32) + th[:, 1]).reshape(-1, 3)
    keep = np.ones(len(T), bool)
    for k in range(len(T)):
        hk = th[k].tolist()
        if any(x in used for x in hk):
            keep[k] = False
            continue
        used.update(hk)
    return T[keep]


# ----------------------------------------------------------------------------- whole grid

def merge_grid(tiles: list[dict], meshes: list[Mesh], max_gap_m: float = 0.1, log=None) -> tuple[Mesh, list[dict]]:
    """Merge tile meshes cut to their cores. ``tiles[k]`` has ``ix``, ``iy`` and ``core``
    ``[xmin, ymin, xmax, ymax]`` (None on the site's outer border). Returns the merged mesh (face
    attribute ``tile``: tile index, -1 for stitch faces) and per-seam statistics."""
    by = {(int(t["ix"]), int(t["iy"])): k for k, t in enumerate(tiles)}
    nx = max(int(t["ix"]) for t in tiles) + 1
    ny = max(int(t["iy"]) for t in tiles) + 1
    seams = []
    for k, m in enumerate(meshes):
        m.face_attrs = {"tile": np.full(m.n_faces, k, np.int32)}
    rows = []
    for iy in range(ny):
        row = None
        for ix in range(nx):
            k = by.get((ix, iy))
            if k is None:
                continue
            m = meshes[k]
            if row is None:
                row = m
                continue
            x = float(tiles[k]["core"][0])
            row, st = stitch(row, m, 0, x, max_gap_m)
            seams.append(st.as_dict() | {"between": f"row {iy}: tiles x{ix - 1}|x{ix}"})
            if log:
                log.info("seam x=%.3f row %d: %d pairs, %d strip faces", x, iy, st.pairs, st.stitched_faces)
        rows.append((iy, row))
    merged = None
    for iy, row in rows:
        if row is None:
            continue
        if merged is None:
            merged = row
            continue
        k = next(by[(ix, iy)] for ix in range(nx) if (ix, iy) in by)
        y = float(tiles[k]["core"][1])
        merged, st = stitch(merged, row, 1, y, max_gap_m)
        seams.append(st.as_dict() | {"between": f"rows {iy - 1}|{iy}"})
        if log:
            log.info("seam y=%.3f: %d pairs, %d strip faces", y, st.pairs, st.stitched_faces)
    return merged, seams


def seam_planes(tiles: list[dict]) -> list[tuple[int, float]]:
    """The interior cut planes of a grid: (axis, value)."""
    planes = set()
    for t in tiles:
        xmin, ymin, _, _ = t["core"]
        if xmin is not None:
            planes.add((0, float(xmin)))
        if ymin is not None:
            planes.add((1, float(ymin)))
    return sorted(planes)


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


def seam_map_png(mesh: Mesh, planes: list[tuple[int, float]], runs: list[dict], path, title: str = "",
                 size_px: int = 1600) -> None:
    """Top view of the merged mesh for checking the seams: each tile's faces in its own colour (shaded
    by slope), stitch strips and fills dark, seam planes dashed, and every open run on a seam circled
    (red: facing surface, orange: the surface ends on the seam; strip-only border crossings are not
    marked)."""
    from PIL import Image, ImageDraw

    X, F = mesh.vertices, mesh.faces
    if F is None or len(F) == 0:
        return
    lo, hi = X[:, :2].min(axis=0), X[:, :2].max(axis=0)
    ext = max(float((hi - lo).max()), 1e-6)
    W = max(1, int(round(size_px * (hi[0] - lo[0]) / ext)))
    H = max(1, int(round(size_px * (hi[1] - lo[1]) / ext)))
    px = ext / (size_px - 1)
    tile = mesh.face_attrs.get("tile", np.zeros(len(F), np.int64))
    pal = np.array([[141, 211, 199], [255, 255, 179], [190, 186, 218], [251, 128, 114], [128, 177, 211],
                    [253, 180, 98], [179, 222, 105], [252, 205, 229], [217, 217, 217], [188, 128, 189],
                    [204, 235, 197], [255, 237, 111]], np.float64)
    col = np.where(tile[:, None] >= 0, pal[np.maximum(tile, 0) % len(pal)], np.array([[60.0, 60.0, 60.0]]))
    T = X[F]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    nn = np.linalg.norm(n, axis=1)
    col *= (0.55 + 0.45 * np.abs(n[:, 2]) / np.maximum(nn, 1e-12))[:, None]
    # samples: every vertex (in the colour of one of its faces), and one point per pixel of face area
    # (at least one per face)
    area_px = 0.5 * nn / px ** 2
    extra = np.minimum(np.ceil(area_px).astype(np.int64), 64)
    rng = np.random.default_rng(0)
    fi = np.repeat(np.arange(len(F)), extra)
    r1, r2 = np.sqrt(rng.random(len(fi))), rng.random(len(fi))
    S = T[fi, 0] * (1 - r1)[:, None] + T[fi, 1] * (r1 * (1 - r2))[:, None] + T[fi, 2] * (r1 * r2)[:, None]
    del T
    vf = np.full(len(X), -1, np.int64)
    vf[F.ravel()] = np.repeat(np.arange(len(F)), 3)
    used = vf >= 0
    S = np.vstack([S, X[used]])
    fi = np.concatenate([fi, vf[used]])
    c = np.clip(((S[:, 0] - lo[0]) / px).astype(np.int64), 0, W - 1)
    r = np.clip(((hi[1] - S[:, 1]) / px).astype(np.int64), 0, H - 1)
    pix = r * W + c
    order = np.lexsort((S[:, 2], pix))  # per pixel, the highest sample last
    last = np.r_[pix[order][1:] != pix[order][:-1], True]
    img = np.full((H * W, 3), 255, np.uint8)
    img[pix[order][last]] = np.clip(col[fi[order][last]], 0, 255).astype(np.uint8)
    img = img.reshape(H, W, 3)
    # close the pinholes between samples: an empty pixel takes a filled neighbour's colour (one pass)
    empty = (img == 255).all(axis=2)
    grown = img.copy()
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        src = np.roll(img, (dy, dx), axis=(0, 1))
        take = empty & ~(src == 255).all(axis=2) & (grown == 255).all(axis=2)
        grown[take] = src[take]
    im = Image.fromarray(grown)
    d = ImageDraw.Draw(im)
    for axis, val in planes:
        for s in np.arange(0.0, ext, 2.0):
            if axis == 0:
                x = (val - lo[0]) / px
                d.line([(x, s / px), (x, min(s + 1.0, ext) / px)], fill=(90, 90, 90), width=1)
            else:
                y = (hi[1] - val) / px
                d.line([(s / px, y), (min(s + 1.0, ext) / px, y)], fill=(90, 90, 90), width=1)
    colours = {"facing_surface": (220, 0, 0), "surface_ends": (255, 140, 0)}
    for run in runs:
        if run["kind"] not in colours:
            continue
        x, y = (run["centre"][0] - lo[0]) / px, (hi[1] - run["centre"][1]) / px
        rad = max(6.0, 0.5 * run["length_m"] / px + 4)
        d.ellipse([x - rad, y - rad, x + rad, y + rad], outline=colours[run["kind"]], width=2)
    if title:
        d.rectangle([0, 0, min(W, 8 + 6 * len(title)), 16], fill=(255, 255, 255))
        d.text((4, 3), title, fill=(0, 0, 0))
    im.save(str(path))


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


def close_seam_holes(mesh: Mesh, planes: list[tuple[int, float]], max_edges: int = 120,
                     tol_m: float = 1e-3) -> tuple[Mesh, int]:
    """Fill the small boundary loops left at the seams (where the two tiles' borders could not be
    paired, e.g. in trees or at the corner where four tiles meet): each loop with at most
    ``max_edges`` edges and at least one edge on a seam plane gets a fan around its centroid.
    Face attribute ``tile`` of the new faces is -1. Returns (mesh, loops closed)."""
    from twinkit.mesh import boundary_loops, fan_fill

    if max_edges < 3 or mesh.n_faces == 0 or not planes:
        return mesh, 0
    X = mesh.vertices
    on = np.zeros(mesh.n_vertices, bool)
    for axis, val in planes:
        on |= np.abs(X[:, axis] - val) <= tol_m
    loops = []
    for lp in boundary_loops(mesh.faces):
        if len(lp) > max_edges:
            continue
        nxt = np.roll(lp, -1)
        if (on[lp] & on[nxt]).any():
            # a loop through a pinch vertex (figure-8) is filled as its simple loops, so that no edge
            # gets more than two faces
            loops.extend(sub for sub in _simple_loops(lp) if len(sub) >= 3)
    return fan_fill(mesh, loops, face_fill=-1, recompute_normals=False), len(loops)


def _simple_loops(lp: np.ndarray) -> list[np.ndarray]:
    """Split a closed vertex loop that visits a vertex more than once into simple loops (same orientation)."""
    stack: list[int] = []
    pos: dict[int, int] = {}
    out = []
    for v in lp.tolist():
        if v in pos:
            i = pos[v]
            out.append(np.asarray(stack[i:], np.int64))
            for w in stack[i + 1:]:
                del pos[w]
            stack = stack[: i + 1]
        else:
            pos[v] = len(stack)
            stack.append(v)
    out.append(np.asarray(stack, np.int64))
    return out


def near_planes(X: np.ndarray, planes: list[tuple[int, float]], band_m: float) -> np.ndarray:
    """Bool mask of the rows of ``X`` within ``band_m`` of any of the planes."""
    m = np.zeros(len(X), bool)
    for axis, val in planes:
        m |= np.abs(X[:, axis] - val) <= band_m
    return m


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
    from scipy.spatial import cKDTree
    from twinkit.mesh import boundary_loops, components, fan_fill, remove_vertices
    from twinkit.surface.cleanup import CleanOptions, trim_mask, vertex_cloud_distance

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
    tree = cKDTree(P)
    idx = np.flatnonzero(inb)
    d = vertex_cloud_distance(X[idx], P, threads, tree)
    opt = CleanOptions(max_dist_m=max_dist_m, gap_dist_m=gap_dist_m, gap_plane_m=gap_plane_m, threads=threads)
    drop, _ = trim_mask(X[idx], d, P, N, opt, tree)
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
    # small components touching a band (pieces the trim cut off)
    if min_component_faces > 0 and mesh.n_faces:
        _, flab = components(mesh.n_vertices, mesh.faces)  # per-face component label
        size = np.bincount(flab)
        touch = np.zeros(len(size), bool)
        touch[flab[near_planes(mesh.vertices, planes, band_m)[mesh.faces].any(axis=1)]] = True
        small = touch & (size < min_component_faces)
        if small.any():
            from twinkit.mesh import compact

            rep["components_removed"] = int(small.sum())
            mesh = compact(mesh, ~small[flab])
    if hanging_tol_m > 0:
        vid = mesh.attrs.pop("_vid")
        mesh, rep["hanging_faces_removed"] = drop_hanging_faces(mesh, planes, hanging_tol_m, closed_before, vid)
    if max_hole_edges >= 3 and mesh.n_faces:
        inb = near_planes(mesh.vertices, planes, band_m)
        loops = []
        for lp in boundary_loops(mesh.faces):
            if len(lp) <= max_hole_edges and inb[lp].any():
                loops.extend(sub for sub in _simple_loops(lp) if len(sub) >= 3)
        if loops:
            mesh = fan_fill(mesh, loops, face_fill=-1, recompute_normals=False)
        rep["holes_closed"] = len(loops)
    return mesh, rep


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
    from twinkit.mesh import compact

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


def _apply_votes(Q: np.ndarray, drop: np.ndarray, votes: np.ndarray, planes, band_m: float, radius_m: float,
                 plane_m: float, reach_m: float, threads: int, rep: dict, chunk: int = 200_000) -> np.ndarray:
    """The tiles' verdicts on the band vertices ``Q`` (see ``trim_seam_bands``); returns the new drop mask.

    ``votes`` rows: x, y, z, nx, ny, nz[, keep, tile]. Only votes whose tangent plane the vertex lies
    within ``plane_m`` of count. A "keep" vote within ``radius_m`` keeps the vertex. With
    ``reach_m`` > 0 (and the keep / tile columns), each tile's nearest vote within ``reach_m`` gives
    that tile's verdict and the vertex is kept when some tile's verdict is "keep", dropped otherwise,
    whatever its own verdict: the simplified surface inherits the full-resolution surface's trim, as
    it does away from the seams, where each tile trims before it simplifies. ``chunk`` vertices are
    judged at a time (bounded memory)."""
    from scipy.spatial import cKDTree

    full = votes.shape[1] >= 8
    keepcol = votes[:, 6] > 0.5 if full else np.ones(len(votes), bool)
    if not full:
        reach_m = 0.0
    r = max(radius_m, reach_m)
    sel = near_planes(votes[:, :3], planes, band_m + r)
    V, vkeep = votes[sel], keepcol[sel]
    if not len(V) or r <= 0:
        return drop
    tree = cKDTree(V[:, :3])
    k = min(16 if reach_m > 0 else 8, len(V))
    near_keep = np.zeros(len(Q), bool)  # a "keep" vote within radius_m
    decided = np.zeros(len(Q), bool)  # some tile voted within reach_m
    says_keep = np.zeros(len(Q), bool)  # ... and some tile's nearest vote says "keep"
    for s in range(0, len(Q), chunk):
        q = Q[s:s + chunk]
        dv, iv = tree.query(q, k=k, distance_upper_bound=r, workers=threads)
        dv, iv = dv.reshape(len(q), k), iv.reshape(len(q), k)
        ok = np.isfinite(dv)
        j = np.where(ok, iv, 0)
        if plane_m > 0 and V.shape[1] >= 6:
            off = np.abs(np.einsum("ikj,ikj->ik", q[:, None, :] - V[j, :3], V[j, 3:6]))
            ok &= off <= plane_m
        if radius_m > 0:
            near_keep[s:s + chunk] = (ok & vkeep[j] & (dv <= radius_m)).any(axis=1)
        if reach_m > 0:
            ok &= dv <= reach_m
            tile = np.where(ok, V[j, 7], -1.0)
            first = ok.copy()  # the nearest usable vote of each tile
            for c in range(1, k):
                first[:, c] &= (tile[:, :c] != tile[:, c:c + 1]).all(axis=1)
            decided[s:s + chunk] = first.any(axis=1)
            says_keep[s:s + chunk] = (first & vkeep[j]).any(axis=1)
    keep = near_keep | (decided & says_keep)
    new = (drop | decided) & ~keep  # where a tile voted, the votes alone decide
    rep["vertices_kept_by_votes"] = int((drop & ~new).sum())
    rep["vertices_dropped_by_votes"] = int((~drop & new).sum())
    return new

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
