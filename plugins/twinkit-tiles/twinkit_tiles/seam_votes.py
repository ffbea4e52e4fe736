"""The tiles' votes near the seams: each tile's verdict, under the exact trim, on its own full-resolution
surface, deciding the trim of the merged mesh's band vertices alike on both sides of a seam
(see :func:`twinkit_tiles.seam_trim.trim_seam_bands`)."""
from __future__ import annotations

import numpy as np

from .edges import near_planes


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
