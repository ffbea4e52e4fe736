"""The constrained Delaunay triangulation seen from above with fixed edges (the ``pythoncdt`` library), for
:func:`twinkit.street.holes.stitch`, and what to do where the library cannot resolve two crossing edges (it
computes their crossing outside both in floating point: near-parallel edges, a crossing a hair from a third
edge's end; met on the merged mesh of the full-density ``large`` site):

- :func:`cdt`: the triangulation, crossings resolved, super triangle erased;
- :func:`cdt_freeing`: :func:`cdt`, leaving free first the edges the library's error names, then every edge in
  conflict, then all;
- :func:`edges_in_conflict`: the edges that cross another's interior or end on it.
"""
from __future__ import annotations

import numpy as np


def cdt(pts: np.ndarray, e: np.ndarray):
    """The CDT of ``pts`` (n, 2) with the edges ``e`` (k, 2) fixed, crossings resolved, super triangle erased."""
    import pythoncdt

    tri = pythoncdt.Triangulation(pythoncdt.VertexInsertionOrder.AUTO,
                                  pythoncdt.IntersectingConstraintEdges.TRY_RESOLVE, 0.0)
    tri.insert_vertices(np.ascontiguousarray(pts))
    if len(e):
        tri.insert_edges(np.ascontiguousarray(e.astype(np.uintc)))
    tri.erase_super_triangle()
    return tri


def cdt_freeing(pts: np.ndarray, e: np.ndarray, max_tries: int = 20):
    """:func:`cdt`, freeing the edges it cannot resolve: (triangulation, (k,) bool the edges left free, the
    first error's first line or None when all edges went in). First the two edges its error names (``...
    constraint edges (a, b) and (c, d) ...``), a pair at a time, up to ``max_tries`` retries (the crossings it
    can resolve stay resolved); then every edge that crosses or touches another (:func:`edges_in_conflict`);
    then all."""
    import re

    free = np.zeros(len(e), bool)
    key = {(int(a), int(b)): k for k, (a, b) in enumerate(np.sort(e, axis=1))}
    first: str | None = None
    for _ in range(max_tries + 1):
        try:
            return cdt(pts, e[~free]), free, first
        except RuntimeError as err:
            first = first or str(err).splitlines()[0]
            named = [key.get((min(int(a), int(b)), max(int(a), int(b))), -1)
                     for a, b in re.findall(r"\((\d+), (\d+)\)", str(err))]
            named = [k for k in named if k >= 0 and not free[k]]
            if not named:
                break
            free[np.asarray(named, np.int64)] = True
    free |= edges_in_conflict(pts, e)
    try:
        return cdt(pts, e[~free]), free, first
    except RuntimeError:
        free[:] = True
        return cdt(pts, e[:0]), free, first


def edges_in_conflict(p: np.ndarray, e: np.ndarray, tol_m: float = 1e-6) -> np.ndarray:
    """Which edges ``e`` (k, 2) (ids into ``p`` (n, 2)) cross another edge's interior or have an end within
    ``tol_m`` of it: (k,) bool. Edges that only share an end are not in conflict."""
    bad = np.zeros(len(e), bool)
    if len(e) < 2:
        return bad
    a, b = p[e[:, 0]], p[e[:, 1]]
    # candidate pairs: edges whose boxes (grown by tol_m) share a cell of a grid about twice the median length
    cell = max(2.0 * float(np.median(np.linalg.norm(b - a, axis=1))), 10 * tol_m)
    lo = np.floor((np.minimum(a, b) - tol_m) / cell).astype(np.int64)
    hi = np.floor((np.maximum(a, b) + tol_m) / cell).astype(np.int64)
    span = hi - lo + 1
    n = span[:, 0] * span[:, 1]
    eid = np.repeat(np.arange(len(e)), n)
    k = np.arange(len(eid)) - np.repeat(np.cumsum(n) - n, n)
    cx = lo[eid, 0] + k % span[eid, 0]
    cy = lo[eid, 1] + k // span[eid, 0]
    order = np.lexsort((cy, cx))
    eid, key = eid[order], np.c_[cx[order], cy[order]]
    starts = np.r_[0, np.nonzero((np.diff(key, axis=0) != 0).any(axis=1))[0] + 1, len(eid)]
    out = []
    for s0, s1 in zip(starts[:-1], starts[1:]):
        if s1 - s0 > 1:
            g = eid[s0:s1]
            u, w = np.triu_indices(len(g), 1)
            out.append(np.c_[g[u], g[w]])
    if not out:
        return bad
    pairs = np.unique(np.sort(np.vstack(out), axis=1), axis=0)
    i, j = pairs[:, 0], pairs[:, 1]

    def orient(o, u, w):
        return (u[:, 0] - o[:, 0]) * (w[:, 1] - o[:, 1]) - (u[:, 1] - o[:, 1]) * (w[:, 0] - o[:, 0])

    def end_on(q, qid, s, t, sid, tid):
        # q lies within tol of the segment s-t's interior and is neither of its ends
        d = t - s
        ln2 = np.maximum((d * d).sum(axis=1), 1e-300)
        u = ((q - s) * d).sum(axis=1) / ln2
        dist = np.abs(orient(s, t, q)) / np.sqrt(ln2)
        return (qid != sid) & (qid != tid) & (u > 0) & (u < 1) & (dist <= tol_m)

    ai, bi, aj, bj = a[i], b[i], a[j], b[j]
    ei, ej = e[i], e[j]
    distinct = (ei[:, :, None] != ej[:, None, :]).all(axis=(1, 2))
    o1, o2 = orient(ai, bi, aj), orient(ai, bi, bj)
    o3, o4 = orient(aj, bj, ai), orient(aj, bj, bi)
    cross = distinct & (o1 * o2 < 0) & (o3 * o4 < 0)
    touch = (end_on(aj, ej[:, 0], ai, bi, ei[:, 0], ei[:, 1]) | end_on(bj, ej[:, 1], ai, bi, ei[:, 0], ei[:, 1])
             | end_on(ai, ei[:, 0], aj, bj, ej[:, 0], ej[:, 1]) | end_on(bi, ei[:, 1], aj, bj, ej[:, 0], ej[:, 1]))
    hit = cross | touch
    bad[i[hit]] = True
    bad[j[hit]] = True
    return bad
