"""Topology of triangle meshes: connected components, edge incidence, boundary loops, hole fans.

All functions take (m, 3) int face arrays or a :class:`~twinkit.mesh.core.Mesh`; vertex ids are
indices into ``Mesh.vertices``.
"""
from __future__ import annotations

import numpy as np

from .core import Mesh, compact, vertex_normals


def remove_vertices(mesh: Mesh, drop: np.ndarray) -> Mesh:
    """Drop the vertices flagged by ``drop`` ((n,) bool) and every face that uses one."""
    keep_faces = ~drop[mesh.faces].any(axis=1)
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


def edge_face_incidence(faces: np.ndarray):
    """Undirected edges as sorted pairs: (unique edges (e, 2), edge id per face-edge (m, 3), counts (e,))."""
    e = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    es = np.sort(e, axis=1)
    key = es[:, 0].astype(np.int64) * (int(faces.max()) + 1) + es[:, 1]
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    edges = np.stack([uniq // (int(faces.max()) + 1), uniq % (int(faces.max()) + 1)], axis=1)
    return edges, inv.reshape(-1, 3), counts


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


def fan_fill(mesh: Mesh, loops: list[np.ndarray], face_fill: int = -1, recompute_normals: bool = True) -> Mesh:
    """Close each given boundary loop (vertex indices in boundary order): a triangle as one face,
    longer loops with a fan around a new centroid vertex whose attributes are the loop's mean.
    Face attributes of the new faces get ``face_fill`` (integers) or 0. Vertex normals, if any, are
    recomputed from the faces unless ``recompute_normals`` is false (new vertices then get the mean)."""
    if not loops:
        return mesh
    new_v, new_f, new_attrs = [], [], {k: [] for k in mesh.attrs}
    nv = mesh.n_vertices
    for lp in loops:
        if len(lp) == 3:
            new_f.append([lp[2], lp[1], lp[0]])
            continue
        c = nv + len(new_v)
        new_v.append(mesh.vertices[lp].mean(axis=0))
        for k, a in mesh.attrs.items():
            val = a[lp].astype(np.float64).mean(axis=0)
            new_attrs[k].append(val.astype(a.dtype) if a.dtype.kind == "f" else np.rint(val).astype(a.dtype))
        nb = np.roll(lp, -1)
        new_f.extend(np.stack([nb, lp, np.full(len(lp), c)], axis=1).tolist())
    verts = np.vstack([mesh.vertices] + ([np.asarray(new_v)] if new_v else []))
    attrs = {}
    for k, a in mesh.attrs.items():
        attrs[k] = np.concatenate([a, np.asarray(new_attrs[k], dtype=a.dtype).reshape((-1,) + a.shape[1:])]) if new_v else a
    faces_new = np.asarray(new_f, np.int64)
    face_attrs = {k: np.concatenate([a, np.full((len(faces_new),) + a.shape[1:],
                                                face_fill if a.dtype.kind == "i" else 0, a.dtype)])
                  for k, a in mesh.face_attrs.items()}
    out = Mesh(vertices=verts, faces=np.vstack([mesh.faces, faces_new]), attrs=attrs, face_attrs=face_attrs,
               comments=list(mesh.comments))
    if recompute_normals and "normals" in out.attrs:
        out.attrs["normals"] = vertex_normals(out.vertices, out.faces)
    return out
