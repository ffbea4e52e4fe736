"""Holes in the ground of a rendered view: which background pixels are gaps in the mesh
(:func:`ground_holes`) and their fill with the nearest surface's colour (:func:`fill_from_nearest`).

Both run as loops compiled by numba (a dependency of this package; the compiled code is cached next to
the module) with exact integer squared distances; without numba they run on scipy's Euclidean distance
transform. The two give the same pixels: the nearest hit pixel is the one scipy's feature transform
picks (the smallest distance, then the smallest column, then the smallest row), and a distance ``d``
is within ``max_gap_px`` exactly when ``sqrt(d * d) <= max_gap_px`` in float64, as scipy compares it.
One case differs on purpose: when every pixel lies within ``max_gap_px`` of the surface, scipy's
transform of the grown mask (no zero left) measures from a phantom pixel above the top-left corner;
here every background pixel below the horizon is then a hole.
"""
from __future__ import annotations

import numpy as np

from twinkit.surface.compiled import ahead, compiled


@ahead("(boolean[:, ::1],)")
def _sq_dist_to(mask):
    """(h, w) int32: squared Euclidean distance from each pixel to the nearest True pixel of ``mask``;
    ``h * h + w * w + 1`` where ``mask`` has none. A vertical pass (distance to the nearest True pixel in
    the column, row by row so it reads memory in order), then per row the lower envelope of the parabolas
    ``(x - q)^2 + g(q)^2`` (Felzenszwalb and Huttenlocher's two-pass transform)."""
    h, w = mask.shape
    none = h + w + 1  # farther than any pixel: a column without a True pixel
    g = np.empty((h, w), np.int32)
    for x in range(w):
        g[0, x] = 0 if mask[0, x] else none
    for y in range(1, h):
        for x in range(w):
            g[y, x] = 0 if mask[y, x] else min(g[y - 1, x] + 1, none)
    for y in range(h - 2, -1, -1):
        for x in range(w):
            if g[y + 1, x] + 1 < g[y, x]:
                g[y, x] = g[y + 1, x] + 1
    out = np.empty((h, w), np.int32)
    far = h * h + w * w + 1
    v = np.empty(w, np.int64)  # columns of the parabolas on the envelope
    z = np.empty(w + 1, np.float64)  # where each one starts
    for y in range(h):
        k = -1
        for q in range(w):
            if g[y, q] >= none:
                continue
            fq = g[y, q] * g[y, q] + q * q
            while k >= 0:
                p = v[k]
                s = (fq - (g[y, p] * g[y, p] + p * p)) / (2.0 * (q - p))
                if s <= z[k]:
                    k -= 1
                else:
                    break
            k += 1
            v[k] = q
            z[k] = -np.inf if k == 0 else (fq - (g[y, v[k - 1]] * g[y, v[k - 1]] + v[k - 1] * v[k - 1])) / (
                2.0 * (q - v[k - 1]))
            z[k + 1] = np.inf
        if k < 0:
            for q in range(w):
                out[y, q] = far
            continue
        j = 0
        for q in range(w):
            while z[j + 1] < q:
                j += 1
            p = v[j]
            out[y, q] = (q - p) * (q - p) + g[y, p] * g[y, p]
    return out


@ahead("(uint8[:, :, ::1], int64[:], int64[:], boolean[:, ::1])",
       "(uint8[:, :, ::1], int64[::1], int64[::1], boolean[:, ::1])")
def _fill_nearest(rgb, holes_y, holes_x, hit):
    """Paint each hole pixel with the colour of its nearest ``hit`` pixel (ties: the smallest column, then
    the smallest row), searching squares that double in size until one holds a hit within its half-side."""
    h, w = hit.shape
    for i in range(len(holes_y)):
        y, x = holes_y[i], holes_x[i]
        k = 8
        while True:
            best, by, bx = -1, 0, 0
            for cx in range(max(x - k, 0), min(x + k + 1, w)):
                for cy in range(max(y - k, 0), min(y + k + 1, h)):
                    if hit[cy, cx]:
                        d = (cy - y) * (cy - y) + (cx - x) * (cx - x)
                        if best < 0 or d < best:
                            best, by, bx = d, cy, cx
            if (best >= 0 and best <= k * k) or (k >= h and k >= w):
                break
            k *= 2
        for c in range(rgb.shape[2]):
            rgb[y, x, c] = rgb[by, bx, c]


def _sq_dist_compiled():
    """:func:`_sq_dist_to` compiled (twinkit.surface.compiled: ~10x faster than scipy's transforms on a
    1024 x 512 view), or None without numba."""
    return compiled(_sq_dist_to)


def _fill_compiled():
    """:func:`_fill_nearest` compiled, or None without numba."""
    return compiled(_fill_nearest)


def _method(method: str) -> str:
    if method == "auto":
        return "numba" if _sq_dist_compiled() is not None else "scipy"
    if method == "numba" and _sq_dist_compiled() is None:
        raise RuntimeError("numba is not installed (pip install numba)")
    return method


def _within(max_gap_px: float) -> int:
    """The largest squared pixel distance ``n`` with ``sqrt(n) <= max_gap_px`` (-1 for a negative gap)."""
    if max_gap_px < 0:
        return -1
    n = int(max_gap_px * max_gap_px)
    while np.sqrt(float(n + 1)) <= max_gap_px:
        n += 1
    while n >= 0 and np.sqrt(float(n)) > max_gap_px:
        n -= 1
    return n


def ground_holes(hit: np.ndarray, below: np.ndarray, max_gap_px: float, method: str = "auto") -> np.ndarray:
    """Background pixels that are holes in the mesh: below the horizon (a street has ground under every
    downward ray, so it is never sky there) and inside a gap of the surface at most ``2 * max_gap_px``
    wide in some direction (a morphological closing of the hit mask). Wider background below the
    horizon is the world past the capture's edge and is left alone. ``method``: ``numba``, ``scipy`` or
    ``auto`` (numba when installed)."""
    if hit.all() or not hit.any():
        return np.zeros_like(hit)
    if _method(method) == "scipy":
        from scipy.ndimage import distance_transform_edt

        grown = distance_transform_edt(~hit) <= max_gap_px
        closed = distance_transform_edt(grown) > max_gap_px  # erode the grown mask back
        return closed & ~hit & below
    n = _within(max_gap_px)
    cand = ~hit & below
    if n < 0 or not cand.any():
        return np.zeros_like(hit)
    # a hole's closing looks at most 2 * max_gap_px away: work on the candidates' box grown by that much
    m = 2 * (int(np.sqrt(n)) + 1)
    rows, cols = np.flatnonzero(cand.any(axis=1)), np.flatnonzero(cand.any(axis=0))
    y0, y1 = max(rows[0] - m, 0), min(rows[-1] + m + 1, hit.shape[0])
    x0, x1 = max(cols[0] - m, 0), min(cols[-1] + m + 1, hit.shape[1])
    sub = np.ascontiguousarray(hit[y0:y1, x0:x1])
    sq_dist = _sq_dist_compiled()
    grown = sq_dist(sub) <= n
    out = np.zeros_like(hit)
    out[y0:y1, x0:x1] = (sq_dist(~grown) > n) & cand[y0:y1, x0:x1]
    return out


def fill_from_nearest(rgb: np.ndarray, holes: np.ndarray, hit: np.ndarray, method: str = "auto") -> int:
    """Paint ``holes`` pixels (in place) with the colour of the nearest ``hit`` pixel; returns how many."""
    n = int(holes.sum())
    if n == 0 or not hit.any():
        return 0
    if _method(method) == "scipy":
        from scipy.ndimage import distance_transform_edt

        _, (iy, ix) = distance_transform_edt(~hit, return_indices=True)
        rgb[holes] = rgb[iy[holes], ix[holes]]
        return n
    ys, xs = np.nonzero(holes)
    _fill_compiled()(rgb, ys, xs, np.ascontiguousarray(hit))
    return n
