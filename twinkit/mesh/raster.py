"""Top-down raster of a triangle mesh in vectorised numpy: which face each pixel sees from above.

Grid convention (the roads' ``Grid``): ``x0, y0`` are the world coordinates (site frame, metres) of the
grid's top-left corner (x minimum, y maximum), ``res`` metres per pixel, ``shape`` (rows, cols); pixel
(row, col) covers x in [x0 + col res, x0 + (col + 1) res) and y in (y0 - (row + 1) res, y0 - row res].
In pixel units a vertex lies at ((x - x0) / res, (y0 - y) / res).

Where faces overlap, the one with the largest ``order`` key wins (ties: the later face): painter's order
with the key ascending; pass the faces' mean height for "the top-most surface".

Two edge rules (``rule``):

- ``"centre"``: a face covers a pixel when the pixel's centre lies inside its projection or on its
  boundary (closed triangle, within 1e-9 pixel); faces that project to a line or a point cover nothing.
- ``"scanline"``: the rule of the roads' masks and pictures (it gives the pixels of Pillow's
  ``ImageDraw.polygon`` fill, found by experiment and checked pixel for pixel in the tests). The vertices
  are cut to whole pixels (towards zero); each pixel row y from the face's top vertex row to its bottom
  vertex row is filled from the left boundary's x at height y rounded half up to the right boundary's x
  rounded half down (the boundary's x computed in float32 from each edge's first corner); a top or bottom
  row that holds one vertex alone also fills towards the next row's span (up to the pixel before the
  next row's boundary x rounded half up), so thin faces stay connected. It covers about half a pixel
  more on every side than ``"centre"``, and lines and points too.
"""
from __future__ import annotations

import numpy as np

RULES = ("centre", "scanline")


def face_raster(xy: np.ndarray, faces: np.ndarray, x0: float, y0: float, res: float, shape: tuple[int, int],
                order: np.ndarray | None = None, rule: str = "centre", max_candidates: int = 4_000_000) -> np.ndarray:
    """The index of the face each pixel sees from above, -1 where none: (rows, cols) int64.

    ``xy`` (n, 2) or (n, 3) float vertices (site frame, metres; only x, y are used), ``faces`` (m, 3) int
    vertex indices, ``order`` (m,) float key (the largest wins; default: the face index, so the last face
    wins), ``rule`` one of :data:`RULES` (see the module). Work goes in chunks of at most
    ``max_candidates`` (face, pixel) pairs."""
    if rule not in RULES:
        raise ValueError(f"rule must be one of {RULES}, not {rule!r}")
    h, w = int(shape[0]), int(shape[1])
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    if len(faces) == 0 or h <= 0 or w <= 0:
        return np.full((max(h, 0), max(w, 0)), -1, np.int64)
    xy = np.asarray(xy, np.float64)
    px = (xy[faces, 0] - x0) / res  # (m, 3) pixel units, pixel (row, col) spans [col, col + 1) x [row, row + 1)
    py = (y0 - xy[faces, 1]) / res
    key = np.arange(len(faces), dtype=np.float64) if order is None else np.asarray(order, np.float64)
    by_rank = np.argsort(key, kind="stable")  # painter's order: a later rank is drawn over an earlier one
    rank = np.empty(len(faces), np.int64)
    rank[by_rank] = np.arange(len(faces))
    best = np.full(h * w, -1, np.int64)  # the winning face's rank per pixel
    hits = _centre_hits(px - 0.5, py - 0.5, h, w, max_candidates) if rule == "centre" else \
        _scanline_hits(np.trunc(px), np.trunc(py), h, w, max_candidates)
    for pix, fi in hits:
        np.maximum.at(best, pix, rank[fi])
    out = np.full(h * w, -1, np.int64)
    hit = best >= 0
    out[hit] = by_rank[best[hit]]
    return out.reshape(h, w)


def face_mask(xy: np.ndarray, faces: np.ndarray, x0: float, y0: float, res: float, shape: tuple[int, int],
              rule: str = "centre") -> np.ndarray:
    """(rows, cols) bool: the pixels any of ``faces`` covers (grid and rules as :func:`face_raster`)."""
    return face_raster(xy, faces, x0, y0, res, shape, rule=rule) >= 0


def _chunks(cnt: np.ndarray, max_candidates: int):
    """Slices of consecutive items whose counts sum to at most ``max_candidates`` (at least one item)."""
    csum = np.cumsum(cnt)
    start = 0
    while start < len(cnt):
        base = csum[start - 1] if start else 0
        end = max(int(np.searchsorted(csum, base + max_candidates, side="right")), start + 1)
        yield slice(start, end)
        start = end


def _centre_hits(px, py, h, w, max_candidates):
    """(flat pixel index, face) pairs of the centre rule; ``px``, ``py`` (m, 3) with pixel centres on integers."""
    cx0 = np.clip(np.ceil(px.min(1) - 1e-9), 0, w).astype(np.int64)
    cx1 = np.clip(np.floor(px.max(1) + 1e-9), -1, w - 1).astype(np.int64)
    cy0 = np.clip(np.ceil(py.min(1) - 1e-9), 0, h).astype(np.int64)
    cy1 = np.clip(np.floor(py.max(1) + 1e-9), -1, h - 1).astype(np.int64)
    area2 = (px[:, 1] - px[:, 0]) * (py[:, 2] - py[:, 0]) - (px[:, 2] - px[:, 0]) * (py[:, 1] - py[:, 0])
    live = np.flatnonzero((cx1 >= cx0) & (cy1 >= cy0) & (area2 != 0))
    bw, bh = cx1[live] - cx0[live] + 1, cy1[live] - cy0[live] + 1
    for sl in _chunks(bw * bh, max_candidates):
        sel, cw = live[sl], bw[sl]
        cnt = cw * bh[sl]
        fi = np.repeat(np.arange(len(sel)), cnt)
        k = np.arange(len(fi)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        col = cx0[sel][fi] + k % cw[fi]
        row = cy0[sel][fi] + k // cw[fi]
        ax, ay = px[sel][fi], py[sel][fi]
        s = np.sign(area2[sel])[fi]
        inside = np.ones(len(fi), bool)
        for a, b in ((0, 1), (1, 2), (2, 0)):  # each edge function, signed so that the inside is >= 0
            e = (ax[:, b] - ax[:, a]) * (row - ay[:, a]) - (ay[:, b] - ay[:, a]) * (col - ax[:, a])
            inside &= s * e >= -1e-9 * np.hypot(ax[:, b] - ax[:, a], ay[:, b] - ay[:, a])
        yield row[inside] * w + col[inside], sel[fi[inside]]


def _row_extent(tx, ty, y):
    """Per face, the left and right x of the boundary at pixel row ``y`` (m,) (NaN where the row misses
    the face): each edge from its first corner in float32, a horizontal edge by both its ends."""
    f4 = np.float32
    lo = np.full(len(tx), np.inf)
    hi = np.full(len(tx), -np.inf)
    yf = y.astype(f4)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        xa, ya, xb, yb = tx[:, a], ty[:, a], tx[:, b], ty[:, b]
        on = (np.minimum(ya, yb) <= y) & (y <= np.maximum(ya, yb))
        flat = ya == yb
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (xb - xa).astype(f4) / (yb - ya).astype(f4)
            x = (xa.astype(f4) + (yf - ya.astype(f4)) * slope).astype(np.float64)
        for v, ok in ((x, on & ~flat), (xa, on & flat), (xb, on & flat)):
            lo = np.where(ok, np.minimum(lo, v), lo)
            hi = np.where(ok, np.maximum(hi, v), hi)
    miss = lo > hi
    lo[miss], hi[miss] = np.nan, np.nan
    return lo, hi


def _scanline_hits(tx, ty, h, w, max_candidates):
    """(flat pixel index, face) pairs of the scanline rule; ``tx``, ``ty`` (m, 3) whole-pixel vertices."""
    ylo, yhi = ty.min(1), ty.max(1)
    # rows that hold one vertex alone at the top or bottom reach towards the next row's span
    def lone(yrow):
        at = ty == yrow[:, None]
        n_at = at.sum(1)
        same = np.ones(len(tx), bool)
        for a, b in ((0, 1), (1, 2), (0, 2)):
            both = at[:, a] & at[:, b]
            same &= ~both | (tx[:, a] == tx[:, b])
        return (yhi > ylo) & (n_at >= 1) & same

    reach = []  # per end row: whether it reaches, the right end's and the left end's stop
    for end, nxt in ((ylo, ylo + 1), (yhi, yhi - 1)):
        nlo, nhi = _row_extent(tx, ty, nxt)
        reach.append((end, lone(end), np.floor(nlo + 0.5) - 1, np.floor(nhi + 0.5) + 1))
    r0 = np.clip(ylo, 0, None).astype(np.int64)
    r1 = np.clip(yhi, None, h - 1).astype(np.int64)
    nrow = np.maximum(r1 - r0 + 1, 0)
    live = np.flatnonzero(nrow > 0)
    for sl in _chunks(nrow[live], max(1, max_candidates // 16)):
        sel = live[sl]
        cnt = nrow[sel]
        fi = np.repeat(np.arange(len(sel)), cnt)
        row = r0[sel][fi] + np.arange(len(fi)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ftx, fty = tx[sel][fi], ty[sel][fi]
        lo, hi = _row_extent(ftx, fty, row.astype(np.float64))
        a = np.trunc(lo + 0.5)  # half up (a C cast: towards zero, which only matters left of the grid)
        b = np.ceil(hi - 0.5)  # half down
        for end, is_lone, right_stop, left_stop in reach:
            here = (row == end[sel][fi]) & is_lone[sel][fi]
            a = np.where(here, np.minimum(a, left_stop[sel][fi]), a)
            b = np.where(here, np.maximum(b, right_stop[sel][fi]), b)
        a = np.clip(np.nan_to_num(a, nan=w), 0, None)
        b = np.clip(np.nan_to_num(b, nan=-1), None, w - 1)
        n = np.maximum(b - a + 1, 0).astype(np.int64)
        keep = np.flatnonzero(n > 0)
        if len(keep) == 0:
            continue
        n, a, row, fi = n[keep], a[keep].astype(np.int64), row[keep], fi[keep]
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        yield np.repeat(row * w + a, n) + k, sel[np.repeat(fi, n)]
