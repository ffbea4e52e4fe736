"""One view's votes per vertex, for the vertices it sees only (predict_views sums them into vertex_votes.npy).

A view sees a few percent of a site's vertices; building a ``(vertices x 19)`` array per view and
normalising all of it cost about as much CPU as the 2D model on the small demo (110 ms per view,
on a loaded machine; this way 52 ms). :func:`view_votes` counts in a compact table of the seen vertices and gives the same numbers,
bit for bit, as the full-size count: the same integer counts, the same divisions, added in the same
view order.
"""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import N_CLASSES


def view_votes(vertex_map: np.ndarray, n_vertices: int, labels: np.ndarray | None = None,
               proba: np.ndarray | None = None, per_view: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(seen vertex ids (k,) sorted, votes (k, 19) float64) of one view.

    ``vertex_map`` (h, w) int: the vertex each pixel sees, -1 none; ``labels`` (h, w) trainIds (pixels of
    255 or any id >= 19 do not vote) or ``proba`` (19, h, w) class probabilities (soft votes). With
    ``per_view`` each seen vertex's votes sum to 1 (one vote per view), else one vote per pixel.
    """
    vm = vertex_map.reshape(-1)
    hit = vm >= 0
    if proba is None:
        if labels is None:
            raise ValueError("view_votes needs labels or proba")
        lab = labels.reshape(-1)[hit].astype(np.int64)
        ok = lab < N_CLASSES
        verts, lab = vm[hit][ok], lab[ok]
    else:
        verts = vm[hit]
    seen = np.flatnonzero(np.bincount(verts, minlength=n_vertices))
    lut = np.zeros(n_vertices, dtype=np.int64)
    lut[seen] = np.arange(len(seen))
    loc = lut[verts]
    k = len(seen)
    if proba is None:
        vv = np.bincount(loc * N_CLASSES + lab, minlength=k * N_CLASSES).reshape(k, N_CLASSES).astype(np.float64)
    else:
        p = proba.reshape(N_CLASSES, -1)[:, hit]
        vv = np.stack([np.bincount(loc, weights=p[c], minlength=k) for c in range(N_CLASSES)], axis=1)
    if per_view:  # a close-up covers a vertex with hundreds of pixels, a far view with one
        tot = vv.sum(axis=1, keepdims=True)
        vv = np.divide(vv, tot, out=np.zeros_like(vv), where=tot > 0)
    return seen, vv
