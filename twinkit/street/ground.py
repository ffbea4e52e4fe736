"""The local ground under a point: the one model of "how high is the ground here" (site frame, metres, z up).

A street's ground is its lowest broad surface: the carriageway, a pavement, a verge. Everything else (a car,
a bus, a bench, a hedge, a wall's top) stands on it. :class:`LocalGround` estimates it from sample points
(a cloud or mesh vertices) and answers, for any (x, y), the ground's height there (:meth:`LocalGround.at`),
and for any point its height above the ground (:meth:`LocalGround.height`). Its grids are the raster view.

Grid modes (every grid is (ny, nx), row j = y, column i = x, cell (j, i) spans
``origin + (i, j) * cell_m`` .. ``+ cell_m``; ``pad_cells`` empty cells lie around the samples):

1. **surface**: per cell, a statistic of the *candidates* (``up``: the up-facing samples; all samples
   by default): the lowest (``pct=0``) or the ``pct``-th percentile as the order statistic at index
   ``floor((count - 1) * pct / 100)`` of the cell's heights (no interpolation). Empty cells: inf.
2. **level**: the surface over a square window of ``window_m`` (rounded to whole cells; to an odd count
   with ``odd_window``; at least ``min_window_cells``), edges replicated:

   - ``window="min"``: the window's minimum. Cheap, and every raised thing narrower than the window
     drops out, but on a slope the level sinks below the surface by slope x window / 2.
     ``floor_pct``: the level is raised to the window's ``floor_pct``-th percentile (empty cells counted
     as the highest surface) less ``floor_below_m``, so a single deep cell (a drain) cannot pull it down.
   - ``window="opening"``: empty cells first take the nearest cell's surface, then the window's minimum,
     then the maximum over the same window (a grey opening): raised things narrower than the window
     drop out and planes and slopes stay as they are (the opening of a ramp is the ramp).
3. **ground** (optional, ``ground_tol_m``): the candidates no higher than ``ground_tol_m`` above the
   level are the ground points (:attr:`LocalGround.ground_points`); per cell their lowest
   (``ground_stat="lowest"``) or their mean (``"mean"``) height. Without ``ground_tol_m`` the ground is
   the level.
4. **fill** of the ground's empty cells: ``"none"`` (inf stays: no ground within reach), ``"nearest"``
   (the nearest cell with ground), ``"lowest"`` (the lowest surface of the whole grid). Where nothing
   could fill them, the lowest sample.

``if_none_up="all"``: when no sample is a candidate, every sample is one.

Disc mode (``window="disc"``, no grid): the ground under (x, y) is the ``pct``-th percentile (numpy's
linear interpolation) of the candidates' heights within ``window_m / 2`` of it; NaN where there is none.
For a few query points (a pole's foot), where a grid over the whole site would cost more than it answers.

The callers and their modes: the segmentation plugin's 3D context (opening, with :meth:`steps` for curbs),
the ground fill (min, ``ground_tol_m``, lowest), the export plugin's movables (min, ``ground_tol_m``,
mean, nearest), the watertight checks' height above ground (min over the cloud's up-facing points),
the roads plugin's road evidence (a percentile, min, lowest), its carriageway level (min with a
percentile floor), the point-cloud plugin's height shading (min over 3 cells), its signal finder (disc).
"""
from __future__ import annotations

import numpy as np

WINDOWS = ("min", "opening", "disc")
GROUND_STATS = ("lowest", "mean")
FILLS = ("none", "nearest", "lowest")


class LocalGround:
    """The local ground under points; see the module's docstring for the modes.

    ``points``: (n, 3) float, site frame, metres. ``up``: (n,) bool, the samples that may be ground
    (up-facing), or None for all. ``cover_xy``: (k, 2) more positions the grid must reach (the points
    that will be queried), or None. Raises ValueError for non-finite samples, a wrong shape, an unknown
    mode, or no sample at all (no point and nothing to cover).

    Grid attributes (not in disc mode): ``cell`` (m), ``lo`` (2,) the grid's origin (x, y), ``nx``,
    ``ny``; ``surface`` (ny, nx) the per-cell statistic (inf where empty; filled with the opening),
    ``has_surface`` (ny, nx) bool cells holding a candidate, ``level`` (ny, nx) the window's result,
    ``z`` (ny, nx) the ground (after the fill), ``has_z`` (ny, nx) bool cells with ground before the fill,
    ``ground_points`` (n,) bool (with ``ground_tol_m``; else None), ``window_cells`` (int), ``flat`` (n,)
    int64 each sample's cell as ``j * nx + i``.
    """

    def __init__(self, points: np.ndarray, up: np.ndarray | None = None, *, cell_m: float = 0.25,
                 window_m: float = 3.0, window: str = "opening", pct: float = 0.0, odd_window: bool = True,
                 min_window_cells: int = 1, pad_cells: int = 1, cover_xy: np.ndarray | None = None,
                 floor_pct: float | None = None, floor_below_m: float = 0.0, ground_tol_m: float | None = None,
                 ground_stat: str = "lowest", fill: str = "none", if_none_up: str = "none"):
        p = np.asarray(points, np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"LocalGround needs (n, 3) points, got shape {p.shape}")
        if not np.isfinite(p).all():
            raise ValueError("LocalGround: the points hold NaN or infinite coordinates")
        for name, val, allowed in (("window", window, WINDOWS), ("ground_stat", ground_stat, GROUND_STATS),
                                   ("fill", fill, FILLS), ("if_none_up", if_none_up, ("none", "all"))):
            if val not in allowed:
                raise ValueError(f"LocalGround: unknown {name} {val!r} (one of {', '.join(allowed)})")
        cand = np.ones(len(p), bool) if up is None else np.asarray(up, bool).reshape(-1)
        if len(cand) != len(p):
            raise ValueError(f"LocalGround: {len(cand)} up flags for {len(p)} points")
        if if_none_up == "all" and not cand.any():
            cand = np.ones(len(p), bool)
        self.points, self.candidates, self.window, self.pct = p, cand, window, float(pct)
        self.window_m = float(window_m)
        self._tree = None
        if window == "disc":
            if len(p) == 0:
                raise ValueError("LocalGround needs at least one point")
            return
        cover = None if cover_xy is None else np.asarray(cover_xy, np.float64).reshape(-1, 2)
        if len(p) == 0 and (cover is None or len(cover) == 0):
            raise ValueError("LocalGround needs at least one point")
        self.cell = c = float(cell_m)
        lows = [a.min(axis=0) for a in (p[:, :2], cover) if a is not None and len(a)]
        self.lo = (lows[0] if len(lows) == 1 else np.minimum(*lows)) - pad_cells * c
        ij = self._ij(p[:, :2])
        top = [a.max(axis=0) for a in (ij, None if cover is None else self._ij(cover)) if a is not None and len(a)]
        top = top[0] if len(top) == 1 else np.maximum(*top)
        self.nx, self.ny = int(top[0]) + 1 + pad_cells, int(top[1]) + 1 + pad_cells
        self.flat = flat = ij[:, 1] * self.nx + ij[:, 0]
        surface = self._surface(flat, p[:, 2], cand, self.pct)
        self.has_surface = has = np.isfinite(surface)
        w = int(round(window_m / c))
        self.window_cells = w = max(int(min_window_cells), (w | 1) if odd_window else w)
        if window == "opening":
            from scipy.ndimage import grey_dilation, grey_erosion

            surface = self._fill_nearest(surface, has)
            if not has.any():  # nothing faces up: every cell holds the lowest point
                self.has_surface = np.ones_like(has)
            level = grey_dilation(grey_erosion(surface, size=(w, w), mode="nearest"), size=(w, w), mode="nearest")
        else:
            from scipy.ndimage import minimum_filter

            level = minimum_filter(surface, size=w, mode="nearest")
            if floor_pct is not None and has.any():
                from scipy.ndimage import percentile_filter

                full = np.where(has, surface, surface[has].max())
                level = np.maximum(level, percentile_filter(full, floor_pct, size=w, mode="nearest") - floor_below_m)
        self.surface, self.level = surface, level
        self.ground_points = None
        if ground_tol_m is None:
            z = level.copy()
        else:
            self.ground_points = g = cand & (p[:, 2] <= level.ravel()[flat] + ground_tol_m)
            if ground_stat == "lowest":
                z = np.full(self.nx * self.ny, np.inf)
                np.minimum.at(z, flat[g], p[g, 2])
            else:
                s = np.zeros(self.nx * self.ny)
                n = np.zeros(self.nx * self.ny)
                np.add.at(s, flat[g], p[g, 2])
                np.add.at(n, flat[g], 1)
                z = np.where(n > 0, s / np.maximum(n, 1), np.inf)
            z = z.reshape(self.ny, self.nx)
        self.has_z = np.isfinite(z)
        if fill == "nearest":
            z = self._fill_nearest(z, self.has_z)
        elif fill == "lowest" and not self.has_z.all():
            z[~self.has_z] = surface[has].min() if has.any() else self._lowest()
        self.z = z

    # ------------------------------------------------------------------ building

    def _lowest(self) -> float:
        return float(self.points[:, 2].min()) if len(self.points) else 0.0

    def _fill_nearest(self, grid: np.ndarray, has: np.ndarray) -> np.ndarray:
        """Empty cells take the nearest cell's value (the lowest point where no cell has one)."""
        from scipy.ndimage import distance_transform_edt

        if not has.any():
            return np.full_like(grid, self._lowest())
        if has.all():
            return grid
        _, (iy, ix) = distance_transform_edt(~has, return_indices=True)
        return grid[iy, ix]

    def _surface(self, flat: np.ndarray, z: np.ndarray, cand: np.ndarray, pct: float) -> np.ndarray:
        """(ny, nx): per cell the lowest candidate (pct 0) or the order statistic at floor((k - 1) pct / 100)."""
        out = np.full(self.nx * self.ny, np.inf)
        if pct == 0:
            np.minimum.at(out, flat[cand], z[cand])
        elif cand.any():
            src = np.flatnonzero(cand)
            s = src[np.lexsort((z[src], flat[src]))]
            cid = flat[s]
            start = np.r_[0, np.flatnonzero(np.diff(cid)) + 1]
            cnt = np.diff(np.r_[start, len(s)])
            pick = start + np.floor((cnt - 1) * pct / 100.0).astype(int)
            out[cid[pick]] = z[s[pick]]
        return out.reshape(self.ny, self.nx)

    def _ij(self, xy: np.ndarray) -> np.ndarray:
        return np.floor((np.asarray(xy, np.float64) - self.lo) / self.cell).astype(np.int64)

    # ------------------------------------------------------------------ queries

    @property
    def tree(self):
        """scipy cKDTree over the candidates' (x, y) (disc mode; built on first use)."""
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.points[self.candidates, :2])
        return self._tree

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(j, i) int64 grid indices of each (x, y), clipped to the grid."""
        ij = self._ij(np.asarray(xy, np.float64).reshape(-1, 2))
        return np.clip(ij[:, 1], 0, self.ny - 1), np.clip(ij[:, 0], 0, self.nx - 1)

    def at(self, xy: np.ndarray) -> np.ndarray:
        """(k,) float64: the ground height under each (x, y) of ``xy`` (k, 2) (beyond the grid: its edge's).
        inf where the fill left a cell empty; in disc mode NaN where no candidate lies within reach."""
        if self.window == "disc":
            xy = np.asarray(xy, np.float64).reshape(-1, 2)
            zc = self.points[self.candidates, 2]
            out = np.full(len(xy), np.nan)
            for k, near in enumerate(self.tree.query_ball_point(xy, self.window_m / 2)):
                if near:
                    out[k] = float(np.percentile(zc[near], self.pct))
            return out
        j, i = self.cells(xy)
        return self.z[j, i]

    def height(self, points: np.ndarray | None = None) -> np.ndarray:
        """(n,) float64: each point's height above the local ground (negative: below it); without ``points``,
        each sample's the model was built from."""
        if points is None:
            p = self.points
            if self.window != "disc":
                return p[:, 2] - self.z.ravel()[self.flat]
        else:
            p = np.asarray(points, np.float64)
        return p[:, 2] - self.at(p[:, :2])

    # ------------------------------------------------------------------ steps (curbs) on the surface

    def foot(self, radius_m: float = 0.5) -> np.ndarray:
        """(ny, nx): the lowest surface within ``radius_m`` of each cell (the foot of a step there)."""
        from scipy.ndimage import grey_erosion

        r = max(1, int(round(radius_m / self.cell)))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        return grey_erosion(self.surface, footprint=(xx ** 2 + yy ** 2) <= r * r, mode="nearest")

    def steps(self, min_step_m: float = 0.05, radius_m: float = 0.5, max_step_m: float = np.inf) -> np.ndarray:
        """(ny, nx) bool: cells whose surface stands ``min_step_m`` to ``max_step_m`` above the lowest
        surface within ``radius_m`` (the upper edge of a step such as a curb)."""
        rise = self.surface - self.foot(radius_m)
        return self.has_surface & (rise >= min_step_m) & (rise <= max_step_m)

    def near(self, cells: np.ndarray, points: np.ndarray, radius_m: float) -> np.ndarray:
        """(n,) bool: a marked cell of ``cells`` (ny, nx) lies within ``radius_m`` of each point."""
        from scipy.ndimage import distance_transform_edt

        if not cells.any():
            return np.zeros(len(points), bool)
        d = distance_transform_edt(~cells) * self.cell
        j, i = self.cells(np.asarray(points)[:, :2])
        return d[j, i] <= radius_m
