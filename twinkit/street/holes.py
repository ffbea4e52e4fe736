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
- :func:`fan`: the named fall-back for a loop no triangulation of its outline can take (it crosses
  itself seen from above, or two of its vertices stand on one vertical line): a fan round the loop's
  centroid closes the border whatever its shape, some triangles overlapping, at the ring's heights.
- :func:`close_ground_holes`: every hole of a mesh that lies on the ground and is small enough, each
  closed by :func:`close_hole` at the heights of its own border.

The faces returned index ``vertices`` and then the new vertices (ids ``>= len(vertices)``, in order),
counter-clockwise seen from above (their normals face up).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

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
    new = np.c_[pts[used], np.asarray(ground_z(pts[used]), np.float64)] if len(used) else np.zeros((0, 3))
    return ids[t], new


def fan(vertices: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Close a loop whatever its shape: triangles (centroid, loop[i+1], loop[i]) round one new vertex at the
    mean of the loop's vertices (the loop walked backwards: counter-clockwise seen from above for a hole in
    an up-facing surface). Returns (faces (m, 3) int64, the centroid (1, 3) float64); the centroid's id is
    ``len(vertices)``."""
    ccw = np.asarray(loop, np.int64)[::-1]
    nb = np.roll(np.arange(len(ccw)), -1)
    faces = np.stack([np.full(len(ccw), len(vertices)), ccw, ccw[nb]], axis=1)
    return faces, vertices[ccw].mean(axis=0)[None]


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
    rep = {"closed": 0, "closed_m": 0.0, "left_open_m": {}}
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
