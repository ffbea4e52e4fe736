"""Objects above the ground and the shape cues read from them (the ``SHAPE_CUES`` of context.py).

The vertices above the highest curb that are not ground, split into the connected parts of the mesh
they form (:func:`objects_above_ground`), each with its top, bottom, footprint and horizontal slices;
:func:`shape_cues` turns them into per-vertex masks (``column``, ``mounted`` with ``plate`` / ``box``,
``low``, ``narrow``, ``slender``) that :func:`context.geometric_context` adds to its cues. Site frame,
metres, z up; the thresholds are :class:`context.ContextOptions`'.
"""
from __future__ import annotations

import numpy as np

from .context import SHAPE_CUES, ContextOptions


def _extent_2d(xy: np.ndarray, key: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(major, minor) horizontal extent of each group ``key`` of points ``xy``, measured along the
    group's principal axes (a diagonal wall is as thin as one along x)."""
    cnt = np.maximum(np.bincount(key, minlength=n), 1).astype(np.float64)
    d = xy - np.column_stack([np.bincount(key, xy[:, 0], n) / cnt, np.bincount(key, xy[:, 1], n) / cnt])[key]
    sxx, syy, sxy = (np.bincount(key, d[:, 0] * d[:, 0], n), np.bincount(key, d[:, 1] * d[:, 1], n),
                     np.bincount(key, d[:, 0] * d[:, 1], n))
    ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)[key]
    u = d[:, 0] * np.cos(ang) + d[:, 1] * np.sin(ang)
    w = -d[:, 0] * np.sin(ang) + d[:, 1] * np.cos(ang)

    def span(a):
        hi, lo = np.full(n, -np.inf), np.full(n, np.inf)
        np.maximum.at(hi, key, a)
        np.minimum.at(lo, key, a)
        return np.where(np.isfinite(hi), hi - lo, 0.0)

    a, b = span(u), span(w)
    return np.maximum(a, b), np.minimum(a, b)


def _thickness(p: np.ndarray, key: np.ndarray, n: int) -> np.ndarray:
    """Extent of each group of 3D points along its direction of least spread (a plate: its thickness)."""
    out = np.zeros(n)
    order = np.argsort(key, kind="stable")
    bounds = np.searchsorted(key[order], np.arange(n + 1))
    for g in range(n):
        q = p[order[bounds[g]:bounds[g + 1]]]
        if len(q) < 4:
            continue
        q = q - q.mean(axis=0)
        _, vec = np.linalg.eigh(q.T @ q)
        t = q @ vec[:, 0]
        out[g] = t.max() - t.min()
    return out


def objects_above_ground(vertices: np.ndarray, height: np.ndarray, above: np.ndarray, edges: np.ndarray,
                         opt: ContextOptions | None = None) -> dict:
    """The connected parts of the mesh among the ``above`` vertices (above the ground) and their shape.

    Returns per vertex ``object`` (id, -1 outside any object) and ``slice_major`` / ``slice_minor``
    (horizontal extent of the object's ``slice_m`` slice at the vertex's height), and per object
    ``top``, ``bottom`` (heights above the ground), ``footprint_major`` / ``footprint_minor``,
    ``thin_span`` (metres of height where its slice is at most ``column_width_m`` across) and
    ``crown`` (a slice ``crown_m`` wide both ways)."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    opt = opt or ContextOptions()
    v = np.asarray(vertices, np.float64)
    n = len(v)
    obj = np.full(n, -1, np.int64)
    idx = np.nonzero(above)[0]
    res = {"object": obj, "slice_major": np.zeros(n), "slice_minor": np.zeros(n), "n_objects": 0}
    if len(idx) == 0:
        return res
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    # vertices at one position (duplicated along a texture seam, or where separately built parts
    # meet) are one: link each to the first of its millimetre cell
    q = np.floor(v[idx] / 1e-3).astype(np.int64)
    _, first, inv = np.unique(q, axis=0, return_index=True, return_inverse=True)
    dup = idx[first[inv.ravel()]] != idx
    e = np.vstack([e, np.column_stack([idx[dup], idx[first[inv.ravel()]][dup]])])
    e = e[above[e[:, 0]] & above[e[:, 1]]]
    graph = sparse.csr_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    _, oid = np.unique(comp[idx], return_inverse=True)
    no = int(oid.max()) + 1
    obj[idx] = oid
    h = height[idx]
    top, bottom = np.full(no, -np.inf), np.full(no, np.inf)
    np.maximum.at(top, oid, h)
    np.minimum.at(bottom, oid, h)
    fmaj, fmin = _extent_2d(v[idx, :2], oid, no)
    band = np.floor(h / opt.slice_m).astype(np.int64)
    _, skey = np.unique(oid * (int(band.max()) + 1) + band, return_inverse=True)
    ns = int(skey.max()) + 1
    smaj, smin = _extent_2d(v[idx, :2], skey, ns)
    s_obj = np.zeros(ns, np.int64)
    s_obj[skey] = oid
    thin_s = smaj <= opt.column_width_m
    res.update(n_objects=no, top=top, bottom=bottom, footprint_major=fmaj, footprint_minor=fmin,
               thin_span=np.bincount(s_obj, thin_s.astype(np.float64), no) * opt.slice_m,
               crown=np.bincount(s_obj, (smin >= opt.crown_m).astype(np.float64), no) > 0)
    res["slice_major"][idx] = smaj[skey]
    res["slice_minor"][idx] = smin[skey]
    return res


def _touches_larger(v: np.ndarray, o: np.ndarray, items: np.ndarray, ob: dict, opt: ContextOptions) -> np.ndarray:
    """(n_objects,) bool: the ``items`` with a vertex of a larger object (footprint over ``compact_m``:
    a facade, a crown) within ``clear_m`` in 3D: a fragment of that object the mesh split off (a
    window frame, a balcony, a bough), not a free-standing sign or signal head."""
    big = np.zeros(len(o), bool)
    inside = o >= 0
    big[inside] = ob["footprint_major"][o[inside]] > opt.compact_m
    out = np.zeros(len(items), bool)
    if not big.any():
        return out
    c = opt.cell_m
    lo = v.min(axis=0)
    vox = np.floor((v - lo) / c).astype(np.int64) + 2
    dims = vox.max(axis=0) + 3
    key = lambda q: (q[:, 0] * dims[1] + q[:, 1]) * dims[2] + q[:, 2]  # noqa: E731
    big_keys = np.unique(key(vox[big]))
    sel = np.zeros(len(o), bool)
    sel[inside] = items[o[inside]]
    iv, io = vox[sel], o[sel]
    r = int(np.ceil(opt.clear_m / c))
    for dx in range(-r, r + 1):
        for dy in range(-r, r + 1):
            for dz in range(-r, r + 1):
                q = key(iv + [dx, dy, dz])
                at = np.minimum(np.searchsorted(big_keys, q), len(big_keys) - 1)
                hit = big_keys[at] == q
                out[io[hit]] = True
    return out


def shape_cues(vertices: np.ndarray, height: np.ndarray, above: np.ndarray, edges: np.ndarray,
               opt: ContextOptions | None = None) -> dict:
    """Per-vertex masks of the shape cues (``column``, ``mounted`` with ``plate`` / ``box``, ``low``,
    ``narrow``) from :func:`objects_above_ground`."""
    from scipy.ndimage import binary_dilation

    opt = opt or ContextOptions()
    v = np.asarray(vertices, np.float64)
    n = len(v)
    ob = objects_above_ground(v, height, above, edges, opt)
    out = {c: np.zeros(n, bool) for c in SHAPE_CUES + ("plate", "box")}
    out["objects"] = ob["n_objects"]
    if not ob["n_objects"]:
        return out
    o = ob["object"]
    inside = o >= 0
    oi = o[inside]
    h = height
    # column: a thin slice of a tall object with a long bare shaft and no crown, not under a canopy
    post = (ob["top"] >= opt.column_top_m) & (ob["thin_span"] >= opt.column_span_m) & ~ob["crown"]
    bulky = ob["crown"] | (ob["footprint_minor"] >= opt.crown_m)
    if post.any() and bulky.any():
        # a tree trunk whose crown the mesh keeps apart (or a post under a canopy): a crown's cells
        # above head height cover it
        lo = v[:, :2].min(axis=0)
        ij = np.floor((v[:, :2] - lo) / opt.cell_m).astype(np.int64)
        grid = np.zeros(tuple(ij.max(axis=0) + 1), bool)
        cano = inside.copy()
        cano[inside] = bulky[oi] & (h[inside] >= opt.column_top_m)
        grid[ij[cano, 0], ij[cano, 1]] = True
        grid = binary_dilation(grid)
        hit = np.zeros(ob["n_objects"], bool)
        sel = inside.copy()
        sel[inside] = post[oi]
        hit[o[sel][grid[ij[sel, 0], ij[sel, 1]]]] = True
        post &= ~hit
    thin = ob["slice_major"] <= opt.column_width_m
    out["column"][inside] = post[oi] & thin[inside]
    # mounted: the wider slices of a post, or a compact object that floats free, at mounting height
    floats = ((ob["bottom"] >= opt.float_m) & (ob["footprint_major"] <= opt.compact_m)
              & (ob["top"] - ob["bottom"] <= opt.compact_m))
    if floats.any():
        floats &= ~_touches_larger(v, o, floats, ob, opt)
    at = (h >= opt.mount_min_m) & (h <= opt.mount_max_m)
    m = np.zeros(n, bool)
    m[inside] = at[inside] & ((post[oi] & ~thin[inside]) | floats[oi])
    out["mounted"] = m
    if m.any():
        mo = o[m]
        ids, key = np.unique(mo, return_inverse=True)
        t = _thickness(v[m], key, len(ids))
        plate = t[key] < opt.plate_m
        out["plate"][np.nonzero(m)[0][plate]] = True
        out["box"][np.nonzero(m)[0][~plate]] = True
    out["low"][inside] = ob["top"][oi] < opt.low_top_m
    out["narrow"][inside] = ob["footprint_minor"][oi] < opt.narrow_m
    out["slender"][inside] = (ob["top"][oi] < opt.low_top_m) & (ob["footprint_minor"][oi] < opt.hedge_min_m)
    return out
