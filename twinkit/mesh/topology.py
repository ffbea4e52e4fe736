"""Topology of triangle meshes: connected components, vertex and edge incidence, boundary loops, hole fans.

All functions take (m, 3) int face arrays or a :class:`~twinkit.mesh.core.Mesh`; vertex ids are
indices into ``Mesh.vertices``.
"""
from __future__ import annotations

import numpy as np

from .core import Mesh, compact
from twinkit.surface.compiled import ahead


def remove_vertices(mesh: Mesh, drop: np.ndarray) -> Mesh:
    """Drop the vertices flagged by ``drop`` ((n,) bool) and every face that uses one."""
    assert mesh.faces is not None  # a mesh, not a cloud
    keep_faces = np.asarray(~drop[mesh.faces].any(axis=1))
    return compact(mesh, keep_faces)


def components(n_vertices: int, faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components over shared vertices: (count, per-face label)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return 0, np.zeros(0, np.int64)
    i = np.concatenate([faces[:, 0], faces[:, 1]])
    j = np.concatenate([faces[:, 1], faces[:, 2]])
    g = coo_matrix((np.ones(len(i), bool), (i, j)), shape=(n_vertices, n_vertices))
    n, lab = connected_components(g, directed=False)
    return n, lab[faces[:, 0]]


def vertex_faces(faces: np.ndarray, n_vertices: int):
    """Sparse (n_vertices, m) incidence, CSR: row ``v`` holds the faces that use vertex ``v``
    (``vertex_faces(f, n)[vs].indices``: the faces around the vertices ``vs``)."""
    from scipy.sparse import csr_matrix

    m = len(faces)
    return csr_matrix((np.ones(3 * m, np.int8), (np.asarray(faces).ravel(), np.repeat(np.arange(m), 3))),
                      shape=(n_vertices, m))


def edge_face_incidence(faces: np.ndarray):
    """Undirected edges as sorted pairs: (unique edges (e, 2), edge id per face-edge (m, 3), counts (e,)).

    The edges come in the order of (smaller vertex, larger vertex). Compiled (``twinkit.surface.compiled``), the
    face-edges are bucketed by their smaller vertex and sorted within each bucket (a handful each), linear in
    the faces where numpy's ``unique`` sorts them all; the same three arrays either way."""
    from twinkit.surface.compiled import compiled

    faces = np.asarray(faces)
    fast = compiled(_edge_buckets) if len(faces) else None
    if fast is not None:
        edges, inv, counts = fast(np.ascontiguousarray(faces, dtype=np.int64), int(faces.max()) + 1)
        return edges, inv.reshape(-1, 3), counts
    e = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    es = np.sort(e, axis=1)
    key = es[:, 0].astype(np.int64) * (int(faces.max()) + 1) + es[:, 1]
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    edges = np.stack([uniq // (int(faces.max()) + 1), uniq % (int(faces.max()) + 1)], axis=1)
    return edges, inv.reshape(-1, 3), counts


@ahead("(int64[:, ::1], int64)")
def _edge_buckets(faces, n_vertices):
    """:func:`edge_face_incidence` as loops: the face-edges counted into buckets by their smaller vertex, each
    bucket sorted by the larger one (insertion sort), then numbered in that order."""
    m = faces.shape[0]
    lo = np.empty(3 * m, np.int64)
    hi = np.empty(3 * m, np.int64)
    for i in range(m):
        for k in range(3):
            a, b = faces[i, k], faces[i, (k + 1) % 3]
            if a > b:
                a, b = b, a
            lo[3 * i + k] = a
            hi[3 * i + k] = b
    start = np.zeros(n_vertices + 1, np.int64)
    for j in range(3 * m):
        start[lo[j] + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(3 * m, np.int64)
    for j in range(3 * m):
        order[fill[lo[j]]] = j
        fill[lo[j]] += 1
    inv = np.empty(3 * m, np.int64)
    edges = np.empty((3 * m, 2), np.int64)
    counts = np.zeros(3 * m, np.int64)
    n = 0
    for v in range(n_vertices):
        s, t = start[v], start[v + 1]
        for p in range(s + 1, t):  # insertion sort of the bucket by the larger vertex
            j = order[p]
            q = p - 1
            while q >= s and hi[order[q]] > hi[j]:
                order[q + 1] = order[q]
                q -= 1
            order[q + 1] = j
        prev = -1
        for p in range(s, t):
            j = order[p]
            if hi[j] != prev:
                edges[n, 0] = v
                edges[n, 1] = hi[j]
                n += 1
                prev = hi[j]
            inv[j] = n - 1
            counts[n - 1] += 1
    return edges[:n].copy(), inv, counts[:n].copy()


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops as arrays of vertex ids, oriented as in the faces (half-edge a->b)."""
    if len(faces) == 0:
        return []
    _, fe, counts = edge_face_incidence(faces)
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    b = he[counts[fe.ravel()] == 1]
    if len(b) == 0:
        return []
    nxt: dict[int, list[int]] = {}
    for a, c in b.tolist():
        nxt.setdefault(a, []).append(c)
    loops = []
    for start in list(nxt.keys()):
        while nxt.get(start):
            loop = [start]
            cur = nxt[start].pop()
            steps = 0
            while cur != start and steps < len(b):
                loop.append(cur)
                nx = nxt.get(cur)
                if not nx:
                    break
                cur = nx.pop()
                steps += 1
            if cur == start and len(loop) >= 3:
                loops.append(np.asarray(loop, np.int64))
    return loops


def bad_faces(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None,
              min_area_m2: float = 1e-12) -> tuple[np.ndarray, dict]:
    """Faces no exporter should get: (m,) bool mask of faces to drop, and the counts.

    - *degenerate*: a vertex index repeated in the face, or an area of at most ``min_area_m2``
      (collinear or coincident corners);
    - *duplicate*: the same three vertices as an earlier-kept face, in any order (same winding
      or reversed: back-to-back twins). Of each group one face is kept: the one whose face normal
      agrees best with its corners' vertex ``normals`` when given (the side the surface faces),
      else the first.

    Counts: ``{"degenerate_faces", "duplicate_faces", "back_to_back_faces"}`` (back-to-back: the
    dropped duplicates whose winding is reversed against the kept face; a subset of duplicates).
    """
    from .core import face_areas, face_normals

    f = np.asarray(faces, np.int64).reshape(-1, 3)
    m = len(f)
    drop = np.zeros(m, bool)
    if m == 0:
        return drop, {"degenerate_faces": 0, "duplicate_faces": 0, "back_to_back_faces": 0}
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = repeated | (face_areas(vertices, f) <= min_area_m2)
    drop |= degenerate
    live = np.nonzero(~degenerate)[0]
    srt = np.sort(f[live], axis=1)
    _, inv, counts = np.unique(srt, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    n_dup = n_b2b = 0
    if (counts > 1).any():
        # preference of each face within its group: agreement of its normal with the vertex normals
        if normals is not None:
            fn = face_normals(vertices, f[live])
            vn = np.asarray(normals, np.float64)[f[live]].sum(axis=1)
            score = np.einsum("ij,ij->i", fn, vn)
        else:
            score = np.zeros(len(live))
        # order: by group, best score first, then by position (stable: the first face wins ties)
        order = np.lexsort((np.arange(len(live)), -score, inv))
        g = inv[order]
        first = np.ones(len(order), bool)
        first[1:] = g[1:] != g[:-1]
        keeper = np.empty(counts.size, np.int64)
        keeper[g[first]] = order[first]
        dup = order[~first]
        drop[live[dup]] = True
        n_dup = int(len(dup))
        # reversed winding relative to the kept face: a cyclic rotation of the kept face's order cannot match
        kept = f[live[keeper[inv[dup]]]]
        mine = f[live[dup]]
        same = np.zeros(len(dup), bool)
        for r in range(3):
            same |= (np.roll(kept, r, axis=1) == mine).all(axis=1)
        n_b2b = int((~same).sum())
    return drop, {"degenerate_faces": int(degenerate.sum()), "duplicate_faces": n_dup, "back_to_back_faces": n_b2b}


def drop_bad_faces(mesh: Mesh, min_area_m2: float = 1e-12) -> tuple[Mesh, dict]:
    """``mesh`` without its degenerate and duplicate faces (see :func:`bad_faces`); vertices are kept
    (indices stay valid, so per-vertex data such as labels still lines up). Returns (mesh, counts)."""
    if mesh.faces is None or len(mesh.faces) == 0:
        return mesh, {"degenerate_faces": 0, "duplicate_faces": 0, "back_to_back_faces": 0}
    drop, counts = bad_faces(mesh.vertices, mesh.faces, mesh.normals, min_area_m2)
    if not drop.any():
        return mesh, counts
    keep = ~drop
    out = Mesh(vertices=mesh.vertices, faces=mesh.faces[keep], attrs=dict(mesh.attrs),
               face_attrs={k: v[keep] for k, v in mesh.face_attrs.items()}, comments=list(mesh.comments),
               texture=mesh.texture)
    return out, counts
