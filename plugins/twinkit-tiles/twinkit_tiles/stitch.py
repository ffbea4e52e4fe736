"""Zipper stitching of neighbouring tiles, merging of the whole grid, and the small holes left at the seams.

Two neighbouring tiles, cut exactly on a shared plane (:mod:`twinkit_tiles.cut`), meet there with two
border polylines that nearly coincide. :func:`stitch` joins them with a strip of triangles (greedy
shortest-diagonal zipper) so the merged mesh has no crack there.

:func:`merge_grid` merges a whole grid hierarchically: tiles of a row left to right along the
x planes, then the rows bottom to top along the y planes. The x-stitch strips end on the
y planes, so when rows are joined the corner where four tiles meet is closed by the same
zipper (no special case for corners).

Strip faces (and the fans of :func:`close_seam_holes`) get face attribute ``tile = -1``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinkit.mesh import Mesh

from .edges import _chains, _plane_half_edges, _simple_loops


def plane_chains(mesh: Mesh, axis: int, value: float, tol: float = 1e-5) -> list[np.ndarray]:
    """Boundary polylines of ``mesh`` lying on the plane ``coord[axis] == value``, as vertex-index
    arrays following the faces' half-edge direction. A closed loop repeats its first vertex at the end."""
    he, _ = _plane_half_edges(mesh.vertices, mesh.faces, axis, value, tol)
    return _chains(he)


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


def close_seam_holes(mesh: Mesh, planes: list[tuple[int, float]], max_edges: int = 120,
                     tol_m: float = 1e-3) -> tuple[Mesh, int]:
    """Fill the small boundary loops left at the seams (where the two tiles' borders could not be
    paired, e.g. in trees or at the corner where four tiles meet): each loop with at most
    ``max_edges`` edges and at least one edge on a seam plane gets a fan around its centroid.
    Face attribute ``tile`` of the new faces is -1. Returns (mesh, loops closed)."""
    from twinkit.mesh import boundary_loops
    from twinkit.street.holes import fan_fill

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
