"""Tile grid planning, the memory model, and the reconstruction of one tile.

Grid: the site's XY bounding box is split into ``nx`` x ``ny`` equal cores; each tile's padded box
is its core grown by ``overlap_m`` on every side. The outer sides of the border tiles are not cut
(their core is unbounded there, written as ``null``), so only interior planes become seams.

Memory model (measured with ``bench/calibrate_memory.py`` on open3d 0.20 Poisson, 1 thread; see
docs/tiles.md): the peak resident memory of a tile's reconstruction + clean-up is about
``SAFETY * (BASE_MB + MB_PER_MPOINT * points/1e6 + MB_PER_MFACE * faces/1e6)``, and the dense mesh has about
``FACES_PER_M2_AT_1CM / (voxel_m / 0.01)**2`` faces per square metre of XY area (capped by the
points: a tile cannot have many more faces than ``FACES_PER_POINT_MAX`` per point). The automatic
tile size is the largest square core whose padded tile fits the budget.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# measured coefficients (bench/calibrate_memory.py on 6 crops of the small demo cloud and the 9 tiles
# of the default demo cloud; fit within about +-20 %; see docs/tiles.md)
BASE_MB = 326.0
MB_PER_MPOINT = 188.0
MB_PER_MFACE = 668.0
FACES_PER_M2_AT_1CM = 18000.0  # dense faces per m^2 of XY at a 1 cm voxel (default demo cloud, voxel 0.02 m)
FACES_PER_POINT_MAX = 4.0  # the octree adapts to the samples: at most ~4 dense faces per point (measured 1.7-3.9)
SAFETY = 1.25  # the prediction is multiplied by this (the fit's largest under-estimate was 13 %)


def estimate_tile_mb(points: float, area_m2: float, voxel_m: float) -> float:
    """Predicted peak RSS (MiB) of one tile's Poisson + clean-up."""
    faces = min(FACES_PER_M2_AT_1CM * area_m2 / (voxel_m / 0.01) ** 2, FACES_PER_POINT_MAX * points)
    return SAFETY * (BASE_MB + MB_PER_MPOINT * points / 1e6 + MB_PER_MFACE * faces / 1e6)


@dataclass
class Grid:
    x0: float
    y0: float
    x1: float
    y1: float
    nx: int
    ny: int
    overlap_m: float
    xs: np.ndarray | None = None  # the grid lines (nx + 1 values); None = evenly spaced
    ys: np.ndarray | None = None

    def lines(self) -> tuple[np.ndarray, np.ndarray]:
        xs = self.xs if self.xs is not None else np.linspace(self.x0, self.x1, self.nx + 1)
        ys = self.ys if self.ys is not None else np.linspace(self.y0, self.y1, self.ny + 1)
        return np.asarray(xs, np.float64), np.asarray(ys, np.float64)

    def tiles(self) -> list[dict]:
        xs, ys = self.lines()
        out = []
        for iy in range(self.ny):
            for ix in range(self.nx):
                core = [float(xs[ix]) if ix > 0 else None, float(ys[iy]) if iy > 0 else None,
                        float(xs[ix + 1]) if ix < self.nx - 1 else None, float(ys[iy + 1]) if iy < self.ny - 1 else None]
                padded = [float(xs[ix]) - self.overlap_m, float(ys[iy]) - self.overlap_m,
                          float(xs[ix + 1]) + self.overlap_m, float(ys[iy + 1]) + self.overlap_m]
                out.append({"index": len(out), "ix": ix, "iy": iy, "core": core, "padded": padded})
        return out


def choose_grid(xy: np.ndarray, tile_m: float, overlap_m: float, memory_budget_gb: float, voxel_m: float,
                max_tiles: int = 1024) -> tuple[Grid, dict]:
    """Grid from a fixed core size ``tile_m`` (> 0), or the largest square core whose padded tile's
    predicted peak memory fits ``memory_budget_gb`` at the site's mean point density."""
    x0, y0 = xy.min(axis=0)
    x1, y1 = xy.max(axis=0)
    w, h = max(float(x1 - x0), 1e-6), max(float(y1 - y0), 1e-6)
    density = len(xy) / (w * h)  # points per m^2 of XY
    why = {}
    if tile_m <= 0:
        budget_mb = memory_budget_gb * 1024
        lo, hi = 1.0, max(w, h)
        # the densest cell decides: use the 95th percentile of a 10 m grid's density, not the mean
        cells = np.floor((xy - [x0, y0]) / 10.0).astype(np.int64)
        _, cnt = np.unique(cells, axis=0, return_counts=True)
        dens = max(density, float(np.quantile(cnt, 0.95)) / 100.0)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            side = mid + 2 * overlap_m
            if estimate_tile_mb(dens * side * side, side * side, voxel_m) <= budget_mb:
                lo = mid
            else:
                hi = mid
        tile_m = lo
        why = {"auto": True, "budget_mb": budget_mb, "density_pts_m2": round(dens, 2),
               "predicted_tile_mb": round(estimate_tile_mb(dens * (tile_m + 2 * overlap_m) ** 2,
                                                           (tile_m + 2 * overlap_m) ** 2, voxel_m), 1)}
    # a core may be up to 2 % larger than tile_m rather than adding a sliver row of tiles
    nx = max(1, math.ceil(w / tile_m - 0.02))
    ny = max(1, math.ceil(h / tile_m - 0.02))
    if nx * ny > max_tiles:
        from twinkit.errors import ConfigError

        raise ConfigError(f"plan_tiles: {nx} x {ny} tiles of {tile_m:.1f} m exceed max_tiles={max_tiles}; "
                          f"raise tile_m or memory_budget_gb")
    return Grid(float(x0), float(y0), float(x1), float(y1), nx, ny, float(overlap_m)), \
        why | {"tile_m": round(float(tile_m), 3), "nx": nx, "ny": ny, "mean_density_pts_m2": round(density, 2)}


def place_seams(coord: np.ndarray, upright: np.ndarray, lines: np.ndarray, search_m: float,
                step_m: float = 0.05, slab_m: float = 0.2) -> tuple[np.ndarray, list[dict]]:
    """Move each interior grid line by up to ``search_m`` to where the fewest upright surfaces cross it.

    ``coord``: the points' coordinate across the lines (x for the x lines); ``upright``: points on
    non-horizontal surfaces (poles, trunks, tree crowns, car sides, walls along the line). A seam
    through such an object is where two tiles' independent reconstructions disagree most (thin
    objects come out with different cross-sections), while flat ground is stitched cleanly; walls
    crossing the line count the same at every offset. The cost of an offset is the number of upright
    points within ``slab_m / 2`` of the line; ties go to the smallest move. The outer lines stay.
    Returns the new lines and a report per moved line."""
    out = np.asarray(lines, np.float64).copy()
    rep = []
    if search_m <= 0 or len(out) < 3:
        return out, rep
    c = coord[upright]
    offs = np.arange(-search_m, search_m + step_m / 2, step_m)
    for i in range(1, len(out) - 1):
        v = out[i]
        near = c[np.abs(c - v) <= search_m + slab_m]
        cost = np.array([np.count_nonzero(np.abs(near - (v + o)) <= slab_m / 2) for o in offs])
        best = np.flatnonzero(cost == cost.min())
        o = float(offs[best[np.argmin(np.abs(offs[best]))]])
        # keep every core at least 2 search widths wide (never move towards a neighbour that is too close)
        lo = min(0.0, out[i - 1] + 2 * search_m - v)
        hi = max(0.0, out[i + 1] - 2 * search_m - v)
        o = float(np.clip(o, lo, hi))
        k0 = int(np.argmin(np.abs(offs)))
        rep.append({"line": round(float(v), 3), "moved_m": round(o, 3), "upright_points_before": int(cost[k0]),
                    "upright_points_after": int(np.count_nonzero(np.abs(near - (v + o)) <= slab_m / 2))})
        out[i] = v + o
    return out, rep


def in_box(xy: np.ndarray, box: list) -> np.ndarray:
    return (xy[:, 0] >= box[0]) & (xy[:, 1] >= box[1]) & (xy[:, 0] <= box[2]) & (xy[:, 1] <= box[3])


def exact_voxel_poisson(points: np.ndarray, normals: np.ndarray, colors, voxel_m: float, *, min_scale: float = 1.1,
                        point_weight: float = 4.0, samples_per_node: float = 1.5, threads: int = 1):
    """open3d screened Poisson whose finest voxel is exactly ``voxel_m``: depth = smallest with
    size * 1.1 / 2**depth <= voxel_m, then the cube scale is raised so that size * scale / 2**depth
    equals ``voxel_m``. Every tile (and an untiled run) thus uses the same voxel, whatever its size.
    Returns (mesh, depth, scale)."""
    from twinkit.surface.poisson import poisson_open3d

    size = float((points.max(axis=0) - points.min(axis=0)).max())
    depth = int(min(16, max(5, math.ceil(math.log2(max(size, 1e-9) * min_scale / voxel_m)))))
    scale = voxel_m * 2 ** depth / max(size, 1e-9)
    mesh = poisson_open3d(points, normals, colors, depth=depth, scale=scale, point_weight=point_weight,
                          samples_per_node=samples_per_node, threads=threads)
    return mesh, depth, scale
