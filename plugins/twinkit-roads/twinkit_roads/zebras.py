"""Painted zebra crossings found in the scan: white stripes on the ground seen from straight above.

A zebra is a row of parallel white bars (stripes) laid across the walking direction of the crossing:
each bar is long along the walking direction and narrow across it, the bars repeat at a fixed spacing.
``white_raster`` paints the mesh from above with its vertex colours and keeps the white pixels of the
ground; ``zebras_in_mask`` finds the bars (connected white pieces of a bar's size and shape) and groups
parallel, evenly spaced bars into zebras. Frames: site frame, metres; rasters on a
:class:`twinkit_roads.mesh2d.Grid` (row 0 at the top = y maximum).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .mesh2d import Grid


#: metres: the top view is looked at in tiles this wide, each with a rim this wide around it
TILE_M, MARGIN_M = 80.0, 16.0


@dataclass
class Zebra:
    """A painted zebra: ``centre`` (2,) site-frame xy; ``axis`` (2,) unit walking direction (across the bars,
    which lie along the traffic); ``length_m`` its extent along ``axis`` (from the first bar's outer edge to
    the last's), ``width_m`` its extent across (the bars' length); ``bars`` how many stripes."""

    centre: np.ndarray
    axis: np.ndarray
    length_m: float
    width_m: float
    bars: int
    bar_centres: list = field(default_factory=list)

    def polygon(self) -> np.ndarray:
        """(4, 2) site-frame corners of the painted area, counter-clockwise."""
        a = np.asarray(self.axis, float)
        n = np.array([-a[1], a[0]])
        hl, hw = self.length_m / 2, self.width_m / 2
        c = np.asarray(self.centre, float)
        return np.array([c - a * hl - n * hw, c + a * hl - n * hw, c + a * hl + n * hw, c - a * hl + n * hw])

    def to_json(self) -> dict:
        return {"centre": [round(float(v), 3) for v in self.centre], "axis": [round(float(v), 4) for v in self.axis],
                "length_m": round(self.length_m, 3), "width_m": round(self.width_m, 3), "bars": self.bars}


@dataclass
class Bar:
    """One white stripe: centre (2,) site frame, unit long axis (2,), length and width (m), area (m^2)."""

    centre: np.ndarray
    axis: np.ndarray
    length: float
    width: float
    area: float


def white_raster(v: np.ndarray, f: np.ndarray, colors: np.ndarray, grid: Grid, ground: np.ndarray | None = None,
                 min_grey: float = 170.0, max_chroma: float = 45.0, min_contrast: float = 45.0) -> np.ndarray:
    """(h, w) bool: the pixels of ``grid`` whose top-most face is ground (``ground`` (m,) bool per face; all
    faces when None) and painted white: mean vertex colour (``colors`` (n, 3) 0..255) at least ``min_grey``,
    its channels within ``max_chroma`` of each other, and ``min_contrast`` brighter than the median grey of
    the ground pixels (the asphalt)."""
    from .mesh2d import top_faces

    faces = np.arange(len(f)) if ground is None else np.flatnonzero(ground)
    top = top_faces(v, f, grid, faces)
    hit = top >= 0
    out = np.zeros(top.shape, bool)
    if not hit.any():
        return out
    col = np.asarray(colors, float)[f[faces[top[hit]]]].mean(1)  # (k, 3) per pixel
    grey = col.mean(1)
    chroma = col.max(1) - col.min(1)
    base = float(np.median(grey))
    out[hit] = (grey >= min_grey) & (chroma <= max_chroma) & (grey >= base + min_contrast)
    return out


def _bar(pix_xy: np.ndarray, res: float) -> Bar:
    """The oriented box of one white piece's pixel centres (k, 2), site frame."""
    c = pix_xy.mean(0)
    d = pix_xy - c
    w_, vec = np.linalg.eigh(d.T @ d / max(len(d), 1))
    ax = vec[:, 1]
    if ax[0] < 0 or (abs(ax[0]) < 1e-9 and ax[1] < 0):
        ax = -ax
    along, across = d @ ax, d @ np.array([-ax[1], ax[0]])
    length = float(np.ptp(along)) + res
    width = float(np.ptp(across)) + res
    mid = c + ax * (along.max() + along.min()) / 2 + np.array([-ax[1], ax[0]]) * (across.max() + across.min()) / 2
    return Bar(mid, ax, length, width, len(pix_xy) * res * res)


def find_bars(mask: np.ndarray, grid: Grid, min_len_m: float = 0.7, max_len_m: float = 8.0,
              min_wid_m: float = 0.25, max_wid_m: float = 1.0, min_fill: float = 0.4) -> list[Bar]:
    """The white pieces of ``mask`` (8-connected) shaped like a zebra's bar: length and width in the given
    ranges (metres) and filling at least ``min_fill`` of their oriented box."""
    from scipy import ndimage

    lab, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    bars: list[Bar] = []
    if n == 0:
        return bars
    rows, cols = np.nonzero(lab)
    ids = lab[rows, cols]
    order = np.argsort(ids, kind="stable")
    rows, cols, ids = rows[order], cols[order], ids[order]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    min_px = min_len_m * min_wid_m * min_fill / grid.res ** 2
    for r, c in zip(np.split(rows, cuts), np.split(cols, cuts)):
        if len(r) < min_px:
            continue
        xy = np.stack([grid.x0 + (c + 0.5) * grid.res, grid.y0 - (r + 0.5) * grid.res], 1)
        b = _bar(xy, grid.res)
        if (min_len_m <= b.length <= max_len_m and min_wid_m <= b.width <= max_wid_m
                and b.area >= min_fill * b.length * b.width):
            bars.append(b)
    return bars


def _neighbours(a: Bar, b: Bar, max_angle_deg: float, min_gap_m: float, max_gap_m: float, max_shift_m: float) -> bool:
    """Two bars of one zebra: parallel, side by side (apart across their axis by a bar spacing), not shifted
    along it by more than ``max_shift_m``."""
    if abs(float(np.dot(a.axis, b.axis))) < math.cos(math.radians(max_angle_deg)):
        return False
    d = b.centre - a.centre
    across = abs(float(d @ np.array([-a.axis[1], a.axis[0]])))
    along = abs(float(d @ a.axis))
    return min_gap_m <= across <= max_gap_m and along <= max_shift_m


def group_bars(bars: list[Bar], min_bars: int = 3, max_angle_deg: float = 12.0, min_gap_m: float = 0.5,
               max_gap_m: float = 3.2, max_shift_m: float = 1.5) -> list[Zebra]:
    """Zebras: groups (connected through neighbouring pairs, see :func:`_neighbours`) of at least
    ``min_bars`` bars; each zebra's box spans its bars along and across their mean axis, the walking
    direction being across the bars."""
    n = len(bars)
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if _neighbours(bars[i], bars[j], max_angle_deg, min_gap_m, max_gap_m, max_shift_m):
                parent[root(i)] = root(j)
    groups: dict[int, list[Bar]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(bars[i])
    out = []
    for g in groups.values():
        if len(g) < min_bars:
            continue
        ref = g[0].axis
        ax = np.sum([b.axis * (1 if np.dot(b.axis, ref) >= 0 else -1) * b.area for b in g], 0)
        ax = ax / np.linalg.norm(ax)
        nrm = np.array([-ax[1], ax[0]])
        c0 = np.mean([b.centre for b in g], 0)
        lo_a = min(float((b.centre - c0) @ ax) - b.length / 2 for b in g)
        hi_a = max(float((b.centre - c0) @ ax) + b.length / 2 for b in g)
        lo_n = min(float((b.centre - c0) @ nrm) - b.width / 2 for b in g)
        hi_n = max(float((b.centre - c0) @ nrm) + b.width / 2 for b in g)
        centre = c0 + ax * (lo_a + hi_a) / 2 + nrm * (lo_n + hi_n) / 2
        walk = nrm if nrm[0] > 0 or (abs(nrm[0]) < 1e-9 and nrm[1] > 0) else -nrm
        out.append(Zebra(centre, walk, hi_n - lo_n, hi_a - lo_a, len(g), [b.centre for b in g]))
    return out


def zebras_in_mask(mask: np.ndarray, grid: Grid, min_bars: int = 3) -> list[Zebra]:
    """The zebras of a white-paint mask ((h, w) bool on ``grid``): :func:`find_bars` then :func:`group_bars`."""
    return group_bars(find_bars(mask, grid), min_bars=min_bars)


def find_zebras(v: np.ndarray, f: np.ndarray, colors: np.ndarray | None, labels: np.ndarray | None,
                raster_m: float = 0.05, min_bars: int = 3, ground_classes: tuple[int, ...] = (0,)) -> list[Zebra]:
    """The painted zebras of a mesh: ``v`` (n, 3) vertices, ``f`` (m, 3) faces, ``colors`` (n, 3) vertex
    colours (none: no zebra can be seen, []), ``labels`` (n,) per-vertex class ids or None; the ground is the
    faces whose vertices' majority class is in ``ground_classes`` (all faces without labels) and whose
    normal points up (within about 25 degrees)."""
    from .mesh2d import face_normals_z

    if colors is None or len(f) == 0:
        return []
    up = np.abs(face_normals_z(v, f)) >= 0.9
    if labels is not None:
        lab = np.asarray(labels)[f]
        on = np.isin(lab, np.asarray(ground_classes)).sum(1) >= 2
        up &= on
    if not up.any():
        return []
    cen = v[f, :2].mean(1)
    lo, hi = cen[up].min(0), cen[up].max(0)
    out: list[Zebra] = []
    # tiles of TILE_M with a MARGIN_M rim (a zebra whose centre lies in a tile's core is found whole there):
    # a large site's top view would not fit in memory at 5 cm
    for x0 in np.arange(lo[0], hi[0] + 1e-9, TILE_M):
        for y0 in np.arange(lo[1], hi[1] + 1e-9, TILE_M):
            core = (x0, y0, x0 + TILE_M, y0 + TILE_M)
            sel = up & (cen[:, 0] >= x0 - MARGIN_M) & (cen[:, 0] < core[2] + MARGIN_M) & \
                (cen[:, 1] >= y0 - MARGIN_M) & (cen[:, 1] < core[3] + MARGIN_M)
            if not sel.any():
                continue
            grid = Grid.around(cen[sel], raster_m, pad=1.0)
            for z in zebras_in_mask(white_raster(v, f, colors, grid, sel), grid, min_bars=min_bars):
                if core[0] <= z.centre[0] < core[2] and core[1] <= z.centre[1] < core[3]:
                    out.append(z)
    return out
