"""Closing a hole in the ground: the one hole closer of the street domain.

A hole is a closed loop of a mesh's open border (vertex ids in the order
:func:`twinkit.mesh.topology.boundary_loops` gives: the hole on the left of the walk, i.e. clockwise
seen from above for a hole in an up-facing surface). Everything is in the site frame: metres, z up;
"seen from above" means the xy plane.

- :func:`close_hole`: the closer. A constrained Delaunay triangulation (the ``pythoncdt`` library)
  of the loop seen from above with the loop's edges fixed, and, in the ``ground`` mode, points on a
  ``cell_m`` grid inside it at the ground's height: the border keeps its own heights, the inside follows
  the ground instead of spanning the border (a car's cut-off feet stand above the road). The ``border``
  mode (no ``ground_z``, or ``cell_m`` 0) triangulates the loop's own vertices alone.
- :func:`span`: the border mode, for a loop :func:`close_hole` cannot take or with no ground to
  follow: the loop's vertices alone, at the ring's heights (a fan where it is star-shaped seen from
  above, else ear clipping, else a fan).
- :func:`fan`: the named fall-back for a loop no triangulation of its outline can take (it crosses
  itself seen from above, or two of its vertices stand on one vertical line): a fan round the loop's
  centroid closes the border whatever its shape, some triangles overlapping, at the ring's heights.
- :func:`fan_fill`: the fan on a :class:`~twinkit.mesh.Mesh` with its attributes, for holes anywhere on a
  surface (pin-holes after simplification, a wall's small holes, seams between tiles), not seen from above.
- :func:`patch`: the named mode for ground to cover that no loop of open border bounds (a footprint
  left uncovered because its hole ran off the scan, a spot a ray at the ground falls through): the
  Delaunay triangulation seen from above of nearby border vertices and of new points on the ground,
  keeping the triangles the caller selects.
- :func:`stitch`: the named mode for the ground fill of occlusion shadows: cells to cover, joined to the
  mesh's open border nearby (no loop needed: the border's edges are fixed edges of one CDT).
- :func:`grid_patch`: the named mode for a fill on its own grid, not joined to the mesh (the ground
  fill with ``stitch`` off).
- :func:`close_ground_holes`: every hole of a mesh that lies on the ground and is small enough, each
  closed by :func:`close_hole` at the heights of its own border.

The faces returned index ``vertices`` and then the new vertices (ids ``>= len(vertices)``, in order),
counter-clockwise seen from above (their normals face up).
"""
from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from twinkit.mesh.core import Mesh

log = logging.getLogger(__name__)

#: ground_z: (k, 2) float64 xy in metres -> (k,) float64 ground height in metres
GroundZ = Callable[[np.ndarray], np.ndarray]


def close_hole(vertices: np.ndarray, loop: np.ndarray, ground_z: GroundZ | None = None,
               cell_m: float = 0.10) -> tuple[np.ndarray, np.ndarray] | None:
    """Close one hole: the constrained Delaunay triangulation, seen from above, of the ``loop``'s vertices
    (``vertices`` (n, 3) float, ``loop`` (m,) int ids), its edges fixed, and (when ``ground_z`` is given and
    ``cell_m`` > 0) of points on a ``cell_m`` grid inside it, at least 0.4 ``cell_m`` from the border, at
    height ``ground_z(xy)``. Returns (faces (f, 3) int64, new vertices (k, 3) float64); None when the loop
    seen from above is no simple polygon (it crosses itself, or two of its vertices share an xy within
    0.1 mm), so :func:`fan` is left."""
    import pythoncdt as cdt
    from scipy.spatial import cKDTree

    loop = np.asarray(loop, np.int64)
    if len(loop) < 3:
        return None
    xy = vertices[loop, :2].astype(np.float64)
    if len(np.unique(np.round(xy / 1e-4).astype(np.int64), axis=0)) < len(xy):
        return None  # two border vertices on one vertical line: not a simple polygon seen from above
    g = np.zeros((0, 2))
    if ground_z is not None and cell_m > 0:
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        gx = np.arange(lo[0] + cell_m / 2, hi[0], cell_m)
        gy = np.arange(lo[1] + cell_m / 2, hi[1], cell_m)
        g = np.c_[np.repeat(gx, len(gy)), np.tile(gy, len(gx))] if len(gx) and len(gy) else g
        if len(g):
            g = g[inside_polygon(g, xy)]
        if len(g):
            d, _ = cKDTree(xy).query(g)
            g = g[d >= 0.4 * cell_m]
    pts = np.vstack([xy, g])
    n = len(loop)
    edges = np.c_[np.arange(n), (np.arange(n) + 1) % n].astype(np.uintc)
    tri = cdt.Triangulation(cdt.VertexInsertionOrder.AUTO, cdt.IntersectingConstraintEdges.NOT_ALLOWED, 0.0)
    try:
        tri.insert_vertices(np.ascontiguousarray(pts))
        tri.insert_edges(np.ascontiguousarray(edges))
        tri.erase_outer_triangles_and_holes()
    except Exception:  # noqa: BLE001 - crossing border edges: not a simple polygon
        return None
    if tri.vertices_count() != len(pts):
        return None
    t = np.asarray(tri.triangles_array()["vertices"], np.int64).reshape(-1, 3)
    if len(t) == 0:
        return None
    a, b, c = pts[t[:, 0]], pts[t[:, 1]], pts[t[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    t = np.where((area < 0)[:, None], t[:, [0, 2, 1]], t)
    used = np.unique(t[t >= n]) if (t >= n).any() else np.zeros(0, np.int64)
    ids = np.empty(len(pts), np.int64)
    ids[:n] = loop
    ids[used] = len(vertices) + np.arange(len(used))
    new = (np.c_[pts[used], np.asarray(ground_z(pts[used]), np.float64)] if len(used) and ground_z is not None
           else np.zeros((0, 3)))
    return ids[t], new


def fan(vertices: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Close a loop whatever its shape: triangles (centroid, loop[i+1], loop[i]) round one new vertex at the
    mean of the loop's vertices (the loop walked backwards: counter-clockwise seen from above for a hole in
    an up-facing surface). Returns (faces (m, 3) int64, the centroid (1, 3) float64); the centroid's id is
    ``len(vertices)``."""
    loop = np.asarray(loop, np.int64)
    ccw = loop[::-1]
    nb = np.roll(np.arange(len(ccw)), -1)
    faces = np.stack([np.full(len(ccw), len(vertices)), ccw, ccw[nb]], axis=1)
    return faces, vertices[loop].mean(axis=0)[None]


def span(vertices: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Close a hole at its ring's own heights, from the loop's vertices alone (the border mode, for a loop
    :func:`close_hole` cannot take or with no ground to follow): a :func:`fan` round the centroid where the
    loop is star-shaped seen from above, else ear clipping of its outline (a vertex the loop passes twice,
    or two on one vertical line, do not block an ear), else, for an outline that crosses itself, the fan
    anyway (some triangles overlap). Returns (faces (f, 3), new vertices (0 or 1, 3)) like
    :func:`close_hole`; None when the loop is no hole seen from above.

    Ear clipping stays beside the CDT here: on the demo (29 Nov 2026) the CDT of the loop alone let 19 more
    of 39,005 rays at the ground under the lifted objects miss it by over 5 cm (``fill_cell_m`` 0), and a
    fan instead of ear clipping on the 7 loops the CDT cannot take (they pinch or cross themselves) made
    18 more faces face down (default)."""
    loop = np.asarray(loop, np.int64)
    if not is_hole_from_above(vertices, loop):
        return None  # not a hole in an up-facing surface (an island's outline, the scan's outer edge)
    ccw = loop[::-1]
    p = vertices[ccw, :2]
    faces, _ = fan(vertices, loop)
    c = vertices[ccw].mean(axis=0)
    e0 = p - c[:2]
    e1 = p[np.roll(np.arange(len(ccw)), -1)] - c[:2]
    if ((e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]) > 1e-9).all():
        return faces, c[None]  # star-shaped: every fan triangle counter-clockwise seen from above
    tri = _ear_clip(p, ccw)
    if tri is not None and len(tri):
        return ccw[tri], np.zeros((0, 3))
    return faces, c[None]


def _ear_clip(p: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray | None:
    """Triangles (k, 3) of indices into ``p`` (n, 2), a counter-clockwise simple polygon; None when
    the outline is not simple enough to clip."""
    n = len(p)
    idx = list(range(n))
    tris: list[tuple[int, ...]] = []
    ids = np.arange(n) if ids is None else np.asarray(ids)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(idx) > 3 and guard < 4 * n * n:
        m = len(idx)
        clipped = False
        pts = p[idx]
        for k in range(m):
            guard += 1
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % m]
            a, b, c = p[i0], p[i1], p[i2]
            if cross(a, b, c) <= 1e-12:
                continue  # reflex or flat corner
            # no other outline vertex inside the ear (vectorised)
            q = pts
            d1 = (b[0] - a[0]) * (q[:, 1] - a[1]) - (b[1] - a[1]) * (q[:, 0] - a[0])
            d2 = (c[0] - b[0]) * (q[:, 1] - b[1]) - (c[1] - b[1]) * (q[:, 0] - b[0])
            d3 = (a[0] - c[0]) * (q[:, 1] - c[1]) - (a[1] - c[1]) * (q[:, 0] - c[0])
            inside = (d1 > -1e-12) & (d2 > -1e-12) & (d3 > -1e-12)
            inside[[(k - 1) % m, k, (k + 1) % m]] = False
            # the ear's own vertices met again on the outline (a pinch) and coincident points do not block
            own = ids[np.asarray(idx)]
            inside &= (own != ids[i0]) & (own != ids[i1]) & (own != ids[i2])
            inside &= np.linalg.norm(q - b, axis=1) > 1e-9
            if inside.any():
                continue
            tris.append((i0, i1, i2))
            del idx[k]
            clipped = True
            break
        if not clipped:
            return None
    if len(idx) == 3:
        tris.append(tuple(idx))
    return np.asarray(tris, np.int64)


def fan_fill(mesh: Mesh, loops: list[np.ndarray], face_fill: int = -1, recompute_normals: bool = True) -> Mesh:
    """The :func:`fan` of each boundary loop (vertex indices in boundary order) added to ``mesh``, for holes
    anywhere on a surface (pin-holes an edge collapse left, a wall's small holes, a seam between tiles): a
    triangle as one face, a longer loop a fan round a new centroid vertex whose attributes are the loop's
    mean. Face attributes of the new faces get ``face_fill`` (integers) or 0. Vertex normals, if any, are
    recomputed from the faces unless ``recompute_normals`` is false (new vertices then get the mean)."""
    from twinkit.mesh.core import vertex_normals

    if not loops:
        return mesh
    assert mesh.faces is not None  # a mesh, not a cloud
    new_v: list[np.ndarray] = []
    new_f: list[np.ndarray] = []
    new_attrs: dict[str, list[np.ndarray]] = {k: [] for k in mesh.attrs}
    nv = mesh.n_vertices
    for lp in loops:
        if len(lp) == 3:
            new_f.append(np.asarray([[lp[2], lp[1], lp[0]]], np.int64))
            continue
        faces, centre = fan(mesh.vertices, lp)
        faces[:, 0] = nv + len(new_v)
        new_v.append(centre[0])
        for k, a in mesh.attrs.items():
            val = a[lp].astype(np.float64).mean(axis=0)
            new_attrs[k].append(val.astype(a.dtype) if a.dtype.kind == "f" else np.rint(val).astype(a.dtype))
        new_f.append(np.roll(faces[::-1], -1, axis=0)[:, [1, 2, 0]])  # (loop[i+1], loop[i], centre), i = 0, 1, ...
    verts = np.vstack([mesh.vertices] + ([np.asarray(new_v)] if new_v else []))
    attrs = {}
    for k, a in mesh.attrs.items():
        attrs[k] = np.concatenate([a, np.asarray(new_attrs[k], dtype=a.dtype).reshape((-1,) + a.shape[1:])]) if new_v else a
    faces_new = np.vstack(new_f).astype(np.int64)
    face_attrs = {k: np.concatenate([a, np.full((len(faces_new),) + a.shape[1:],
                                                face_fill if a.dtype.kind == "i" else 0, a.dtype)])
                  for k, a in mesh.face_attrs.items()}
    faces = np.vstack([mesh.faces, faces_new])
    out = Mesh(vertices=verts, faces=faces, attrs=attrs, face_attrs=face_attrs, comments=list(mesh.comments))
    if recompute_normals and "normals" in out.attrs:
        out.attrs["normals"] = vertex_normals(out.vertices, faces)
    return out


def patch(vertices: np.ndarray, border: np.ndarray, xy: np.ndarray, z: np.ndarray,
          keep: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Cover ground no loop bounds: the Delaunay triangulation, seen from above, of the ``border`` vertices
    ((b,) ids into ``vertices`` (n, 3): the patch shares them, so it joins the mesh where the border's edges
    are Delaunay edges) and of new points ``xy`` (k, 2) at heights ``z`` (k,); of its triangles, those
    ``keep`` selects (a function of their corners seen from above (t, 3, 2) -> (t,) bool). Returns (faces
    (f, 3) int64 counter-clockwise seen from above, the new vertices they use (u, 3) float64, the faces'
    centres seen from above (f, 2)), or None when there is no triangle to keep.

    The triangulation is scipy's (Qhull), not the CDT: the points lie on a grid, so many are cocircular,
    and on the lift's test of a hole whose border is no simple loop the CDT's choice of diagonals let
    8 more of 6,561 rays at the ground miss it by over 5 cm."""
    from scipy.spatial import Delaunay

    border = np.asarray(border, np.int64)
    nb, nv = len(border), len(vertices)
    p2 = np.vstack([vertices[border, :2], xy])
    try:
        tri = Delaunay(p2).simplices
    except Exception:  # noqa: BLE001 - fewer than 3 points, or all on a line
        return None
    tc2 = p2[tri]
    sel = keep(tc2)
    tri = tri[sel]
    if len(tri) == 0:
        return None
    e1, e2 = tc2[sel, 1] - tc2[sel, 0], tc2[sel, 2] - tc2[sel, 0]
    cw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    tri[cw] = tri[cw][:, [0, 2, 1]]
    used = np.unique(tri)
    ids = np.empty(len(p2), np.int64)
    ids[:nb] = border
    new_pts = used[used >= nb]
    ids[new_pts] = nv + np.arange(len(new_pts))
    zs = np.concatenate([vertices[border, 2], z])
    return ids[tri], np.c_[p2[new_pts], zs[new_pts]], p2[tri].mean(axis=1)


def stitch(vertices: np.ndarray, faces: np.ndarray, border: np.ndarray, xy: np.ndarray, z: np.ndarray,
           keep: Callable[[np.ndarray, np.ndarray], np.ndarray], min_gap_m: float,
           workers: int = -1, report: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cover ground cells joined to a mesh (``vertices`` (m, 3), ``faces`` (f, 3)): the constrained Delaunay
    triangulation, seen from above, of the open ``border`` (e, 2) (vertex-id pairs, fixed edges; one 2D
    vertex per position within 1 mm, so a vertical border edge counts once; border edges that cross seen
    from above are resolved, the crossing at the height of the nearest input vertex) and of new points
    ``xy`` (k, 2) at heights ``z`` (k,), less those within ``min_gap_m`` of the border (slivers). Of its
    triangles, those ``keep`` selects (a function of their centres (t, 3) and longest edge seen from above
    (t,) -> (t,) bool), counter-clockwise seen from above, less the faces that would break the surface (a
    directed edge used twice, an edge of three faces). Returns (new vertices (u, 3), faces (n, 3) indexing
    ``vertices`` then the new vertices).

    Where the CDT cannot resolve a crossing of border edges (it computes the crossing outside both edges in
    floating point: edges crossing at a near-zero angle, or close to a third edge's end), the two edges the
    library names are left free and the triangulation is made again, a pair at a time; should that not do,
    every border edge that crosses or touches another's interior, and at last all (the surface filter above
    still drops faces that break the mesh).
    A warning and ``report["border_edges_freed"]`` say how many edges were left free."""
    from scipy.spatial import cKDTree

    from .cdt import cdt_freeing

    v, f = vertices, np.asarray(faces)
    m = int(v.shape[0])
    border = np.asarray(border, np.int64).reshape(-1, 2)
    gxy, gz = np.asarray(xy, np.float64).reshape(-1, 2), np.asarray(z, np.float64)
    rep_id, e = _border_from_above(v, border)
    bxy = v[rep_id, :2]
    # the cells' centres, less those too close to the border (slivers)
    if len(bxy):
        mids = np.vstack([bxy, 0.5 * (bxy[e[:, 0]] + bxy[e[:, 1]])]) if len(e) else bxy
        dmin, _ = cKDTree(mids).query(gxy, workers=workers)
        far = dmin >= min_gap_m
        gxy, gz = gxy[far], gz[far]
    pts = np.vstack([bxy, gxy]).astype(np.float64)
    zs = np.r_[v[rep_id, 2], gz]
    nb = len(bxy)
    if len(pts) < 3:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    tri, bad, first_error = cdt_freeing(pts, e)
    if first_error is not None:
        log.warning("ground fill: the triangulation could not resolve crossing border edges (%s); %d of %d border "
                    "edges left free", first_error, int(bad.sum()), len(e))
        if report is not None:
            report["border_edges_freed"] = int(bad.sum())
    va = tri.vertices_array()
    allxy = np.c_[va["x"], va["y"]] if va.dtype.names else np.asarray(va, np.float64).reshape(-1, 2)
    if len(allxy) > len(pts):  # crossings of border edges seen from above: height of the nearest input vertex
        _, near = cKDTree(pts).query(allxy[len(pts):])
        zs = np.r_[zs, zs[near]]
    t = np.asarray(tri.triangles_array()["vertices"], np.int64).reshape(-1, 3)
    p3 = np.c_[allxy, zs]
    a, b, d = p3[t[:, 0]], p3[t[:, 1]], p3[t[:, 2]]
    cen = (a + b + d) / 3.0
    edge2d = np.max(np.stack([np.linalg.norm((b - a)[:, :2], axis=1), np.linalg.norm((d - b)[:, :2], axis=1),
                              np.linalg.norm((a - d)[:, :2], axis=1)]), axis=0)
    sel = keep(cen, edge2d)
    t = t[sel]
    # counter-clockwise seen from above
    a, b, d = allxy[t[:, 0]], allxy[t[:, 1]], allxy[t[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0])
    t = np.where((area < 0)[:, None], t[:, [0, 2, 1]], t)
    t = t[np.abs(area) > 1e-12]
    return _join(f, m, rep_id, t, p3[nb:])


def _join(faces: np.ndarray, m: int, rep_id: np.ndarray, t: np.ndarray, new_points: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """The triangles ``t`` (n, 3) over the border representatives (``rep_id`` (b,) mesh ids, the first b
    triangulation vertices) and ``new_points`` (k, 3) as faces of the mesh (``faces``, ``m`` vertices), less
    those that would break the surface (:func:`_bad_new_faces`, up to four rounds); returns (the new
    vertices the kept faces use (u, 3), the faces indexing the mesh's vertices then those)."""
    n_new = len(new_points)
    nf = np.r_[rep_id, m + np.arange(n_new)][t]  # border vertices are the mesh's own, the others new
    for _ in range(4):
        if not len(nf):
            break
        bad = _bad_new_faces(np.vstack([faces, nf]), len(faces))
        if not bad.any():
            break
        nf = nf[~bad]
    used = np.unique(nf[nf >= m]) - m
    remap = np.full(n_new, -1, np.int64)
    remap[used] = np.arange(len(used))
    nf = np.where(nf >= m, m + remap[np.maximum(nf - m, 0)], nf)
    return new_points[used], nf


def _border_from_above(v: np.ndarray, border: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``border`` (e, 2) seen from above: one vertex per 2D position within 1 mm (a vertical border edge
    has both ends at one xy), (its representative mesh vertex ids (b,), the edges between them (e', 2) as
    indices into those ids, each once, none of zero length)."""
    bids = np.unique(border)
    key = np.round(v[bids, :2] / 1e-3).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    local = np.full(len(v), -1, np.int64)
    local[bids] = inv.ravel()
    e = local[border]
    e = e[e[:, 0] != e[:, 1]]
    return bids[first], np.unique(np.sort(e, axis=1), axis=0)


def _bad_new_faces(faces: np.ndarray, n_old: int) -> np.ndarray:
    """Among ``faces[n_old:]``, those that break the surface: a directed edge already used by another face
    (overlapping or flipped) or an edge shared by more than two faces."""
    from twinkit.mesh.topology import edge_face_incidence

    n = len(faces)
    he = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2).astype(np.int64)
    fid = np.repeat(np.arange(n), 3)
    _, uinv, ucnt = edge_face_incidence(faces)
    uinv = uinv.ravel()
    # a directed half-edge is its undirected edge and which way it runs along it
    dkey = 2 * uinv + (he[:, 0] < he[:, 1])
    dcnt = np.bincount(dkey, minlength=2 * len(ucnt))
    bad_he = (dcnt[dkey] > 1) | (ucnt[uinv] > 2)
    bad = np.zeros(n, bool)
    bad[fid[bad_he]] = True
    bad[:n_old] = False
    return bad[n_old:]


def grid_patch(cells: np.ndarray, z: np.ndarray, lo: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The named mode for a fill on its own grid, not joined to the mesh (the ground fill with ``stitch``
    off): a vertex at the centre of every ``cells`` (ny, nx) bool cell (x = ``lo[0]`` + (i + 0.5) ``cell_m``,
    y likewise, height ``z`` (ny, nx)), two triangles per 2 x 2 block of them (one where exactly three are
    there), counter-clockwise seen from above. Returns (vertices (k, 3) of the cells the triangles use,
    faces (f, 3) indexing them)."""
    jj, ii = np.nonzero(cells)
    centres = np.c_[lo[0] + (ii + 0.5) * cell_m, lo[1] + (jj + 0.5) * cell_m, z[jj, ii]]
    vid = np.full(cells.shape, -1, np.int64)
    vid[jj, ii] = np.arange(len(jj))
    v00, v10, v01, v11 = vid[:-1, :-1], vid[:-1, 1:], vid[1:, :-1], vid[1:, 1:]
    tris = []
    full = (v00 >= 0) & (v10 >= 0) & (v01 >= 0) & (v11 >= 0)
    tris.append(np.c_[v00[full], v10[full], v11[full]])
    tris.append(np.c_[v00[full], v11[full], v01[full]])
    for a_, b_, c_, miss in ((v00, v10, v11, v01), (v00, v11, v01, v10), (v00, v10, v01, v11), (v10, v11, v01, v00)):
        three = (a_ >= 0) & (b_ >= 0) & (c_ >= 0) & (miss < 0)
        tris.append(np.c_[a_[three], b_[three], c_[three]])
    pf = np.vstack(tris).astype(np.int64)
    used = np.unique(pf)
    remap = np.full(len(jj), -1, np.int64)
    remap[used] = np.arange(len(used))
    return centres[used], remap[pf] if len(pf) else pf


def is_hole_from_above(vertices: np.ndarray, loop: np.ndarray) -> bool:
    """Whether ``loop`` runs as a hole in an up-facing surface does (clockwise seen from above, a positive
    area walked backwards); an island's outline, the scan's outer edge or an object's open bottom do not."""
    p = vertices[np.asarray(loop)[::-1], :2]
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) > 0


def inside_polygon(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test: (k,) bool for (k, 2) points against one ring (m, 2)."""
    x, y = p[:, 0][:, None], p[:, 1][:, None]
    x1, y1 = poly[:, 0][None, :], poly[:, 1][None, :]
    x2, y2 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    cross = ((y1 > y) != (y2 > y)) & (x < (x2 - x1) * (y - y1) / np.where(y2 == y1, 1e-300, y2 - y1) + x1)
    return (cross.sum(axis=1) % 2) == 1


def border_heights(border: np.ndarray, k: int = 4) -> GroundZ:
    """z(xy) inside a hole: the inverse-distance weighted height of the ``k`` nearest of the ``border``
    vertices (m, 3)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(border[:, :2])
    k = min(k, len(border))

    def z(xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        if len(xy) == 0:
            return np.zeros(0)
        d, i = tree.query(xy, k=k)
        d, i = np.atleast_2d(d).reshape(len(xy), -1), np.atleast_2d(i).reshape(len(xy), -1)
        w = 1.0 / np.maximum(d, 1e-6) ** 2
        return (w * border[i, 2]).sum(axis=1) / w.sum(axis=1)

    return z


def close_ground_holes(vertices: np.ndarray, faces: np.ndarray, ground_z: GroundZ, *, max_extent_m: float = 8.0,
                       max_rise_m: float = 0.5, level_m: float = 0.3, cell_m: float = 0.10,
                       skip: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], dict]:
    """Close every hole of the ground that the scan did not leave: a closed loop of open border (a hole
    enclosed by surface, so never the site's edge) at most ``max_extent_m`` across seen from above (the
    ground fill's limit: a wider gap is an unscanned area and stays open), lying on the ground (its
    border's median height above ``ground_z(xy)``, the carriageway level, at most ``level_m``: a pavement
    on its kerb; none of it above ``max_rise_m``: a wall or a car body is no ground), and open towards
    the sky (:func:`is_hole_from_above`). Each is closed by :func:`close_hole` on a ``cell_m`` grid whose
    points take the heights of the nearest border vertices (:func:`border_heights`: a hole on a pavement
    is closed at the pavement's height, one across a kerb keeps both levels). Loops listed in ``skip`` (a
    bool mask over vertices: any border vertex marked) are left to the caller.

    Returns (new vertices (k, 3), new faces (f, 3) indexing the old and new vertices, the closed loops,
    a report: ``closed``, ``closed_m`` (their border's length), ``left_open_m`` by reason)."""
    from twinkit.mesh.topology import boundary_loops

    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    loops = boundary_loops(f) if len(f) else []
    add_v: list[np.ndarray] = []
    add_f: list[np.ndarray] = []
    done: list[np.ndarray] = []
    rep: dict = {"closed": 0, "closed_m": 0.0, "left_open_m": {}}
    nv = len(v)

    def left(why: str, ln: float) -> None:
        rep["left_open_m"][why] = round(rep["left_open_m"].get(why, 0.0) + ln, 3)

    for lp in loops:
        ln = float(np.linalg.norm(v[lp] - v[np.roll(lp, -1)], axis=1).sum())
        if skip is not None and skip[lp].any():
            continue
        xy = v[lp, :2]
        if float(np.ptp(xy, axis=0).max()) > max_extent_m:
            left("wider_than_the_fill_limit", ln)
            continue
        h = v[lp, 2] - np.asarray(ground_z(xy), np.float64)
        if float(np.median(np.abs(h))) > level_m or float(np.abs(h).max()) > max_rise_m:
            left("not_on_the_ground", ln)
            continue
        if not is_hole_from_above(v, lp):
            left("not_a_hole_seen_from_above", ln)
            continue
        res = close_hole(np.vstack([v] + add_v) if add_v else v, lp, border_heights(v[lp]), cell_m)
        if res is None:
            left("not_simple_seen_from_above", ln)
            continue
        fn, new = res
        add_f.append(fn)
        if len(new):
            add_v.append(new)
        done.append(lp)
        rep["closed"] += 1
        rep["closed_m"] = round(rep["closed_m"] + ln, 3)
    new_v = np.vstack(add_v) if add_v else np.zeros((0, 3))
    new_f = np.vstack(add_f).astype(np.int64) if add_f else np.zeros((0, 3), np.int64)
    assert new_f.size == 0 or new_f.max() < nv + len(new_v)
    return new_v, new_f, done, rep
