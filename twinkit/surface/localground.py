"""The local ground under a surface: a height grid of the lowest broad up-facing surface.

``LocalGround(vertices, normals, window_m=3.0)`` rasterises the up-facing vertices (normal z at
least ``up_normal_z``) on a grid of ``cell_m``, keeps the lowest per cell, and takes the grey
*opening* of that grid with a square window of ``window_m`` (a minimum filter, then a maximum
filter of the same size). An opening removes every raised thing whose footprint cannot hold the
window (a car roof, a bus, a bench, a hedge, a sidewalk narrower than the window) and keeps
planes and slopes as they are (the opening of a ramp is the ramp), so on a sloped street the
ground does not sink below the surface the way a plain window minimum does. Cells without any
up-facing vertex (under a car, inside a facade's footprint) take the nearest cell's value.

``height(points)`` is each point's height above that ground. Choose ``window_m`` by the physical
size of what must not count as ground: wider than a vehicle is wide (a bus is 2.55 m) for
"height above the local ground"; wider than a sidewalk for "height above the carriageway".

``steps(min_step_m, radius_m, max_step_m)`` marks the grid cells that stand ``min_step_m`` to
``max_step_m`` above the lowest surface within ``radius_m`` (``foot(radius_m)``): the top edge of a
curb (a step of 5-30 cm within a few decimetres), not a road's slope or camber (2-8 % rises 1-4 cm
over half a metre). ``near(cells, points, radius_m)`` tells which points lie near marked cells.

Used by the segmentation plugin's 3D context (docs/segmentation.md); the export plugin's
``lift_movables`` has its own ground grid (a window minimum) and could use this one instead.
"""
from __future__ import annotations

import numpy as np


class LocalGround:
    def __init__(self, vertices: np.ndarray, normals: np.ndarray, window_m: float = 3.0, cell_m: float = 0.25,
                 up_normal_z: float = 0.85):
        from scipy.ndimage import distance_transform_edt, grey_dilation, grey_erosion

        v = np.asarray(vertices, np.float64)
        nz = np.asarray(normals, np.float64)[:, 2]
        if len(v) == 0:
            raise ValueError("LocalGround needs at least one vertex")
        self.cell = c = float(cell_m)
        self.lo = v[:, :2].min(axis=0) - c
        ij = self._ij(v[:, :2])
        self.nx, self.ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2
        flat = ij[:, 1] * self.nx + ij[:, 0]
        up = nz >= up_normal_z
        zmin = np.full(self.nx * self.ny, np.inf)
        np.minimum.at(zmin, flat[up], v[up, 2])
        zmin = zmin.reshape(self.ny, self.nx)
        has = np.isfinite(zmin)
        if not has.any():  # nothing faces up: the lowest point is the ground
            zmin[:] = float(v[:, 2].min())
            has[:] = True
        else:
            _, (iy, ix) = distance_transform_edt(~has, return_indices=True)
            zmin = zmin[iy, ix]
        self.surface = zmin  # lowest up-facing surface per cell (filled)
        self.has_surface = has
        w = max(1, int(round(window_m / c)) | 1)
        self.window_m = float(window_m)
        self.z = grey_dilation(grey_erosion(zmin, size=(w, w), mode="nearest"), size=(w, w), mode="nearest")

    def _ij(self, xy: np.ndarray) -> np.ndarray:
        return np.floor((np.asarray(xy, np.float64) - self.lo) / self.cell).astype(np.int64)

    def _cells(self, xy):
        ij = self._ij(np.asarray(xy, np.float64).reshape(-1, 2))
        return np.clip(ij[:, 1], 0, self.ny - 1), np.clip(ij[:, 0], 0, self.nx - 1)

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Ground height under each (x, y)."""
        j, i = self._cells(xy)
        return self.z[j, i]

    def height(self, points: np.ndarray) -> np.ndarray:
        """Height of each point above the local ground (negative: below it)."""
        p = np.asarray(points, np.float64)
        return p[:, 2] - self.at(p[:, :2])

    def foot(self, radius_m: float = 0.5) -> np.ndarray:
        """(ny, nx): the lowest surface within ``radius_m`` of each cell (the foot of a step there)."""
        from scipy.ndimage import grey_erosion

        r = max(1, int(round(radius_m / self.cell)))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        return grey_erosion(self.surface, footprint=(xx ** 2 + yy ** 2) <= r * r, mode="nearest")

    def steps(self, min_step_m: float = 0.05, radius_m: float = 0.5, max_step_m: float = np.inf) -> np.ndarray:
        """(ny, nx) bool: cells whose lowest up-facing surface stands ``min_step_m`` to ``max_step_m``
        above the lowest surface within ``radius_m`` (the upper edge of a step such as a curb)."""
        rise = self.surface - self.foot(radius_m)
        return self.has_surface & (rise >= min_step_m) & (rise <= max_step_m)

    def near(self, cells: np.ndarray, points: np.ndarray, radius_m: float) -> np.ndarray:
        """(n,) bool: a marked cell lies within ``radius_m`` of each point."""
        from scipy.ndimage import distance_transform_edt

        if not cells.any():
            return np.zeros(len(points), bool)
        d = distance_transform_edt(~cells) * self.cell
        j, i = self._cells(np.asarray(points)[:, :2])
        return d[j, i] <= radius_m
