"""The ground under the movable objects: its height on a grid, seen from the mesh's up-facing vertices
(site frame, metres, z up)."""
from __future__ import annotations

import numpy as np

from .options import LiftOptions


class GroundGrid:
    """Ground height on a regular grid of ``opt.cell_m``: the up-facing vertices (normal z >= ``up_normal_z``)
    no higher than ``ground_tol_m`` above the lowest up-facing vertex within ``ground_window_m`` are ground;
    a cell's ground height is their mean; cells without ground (under a car's roof) take the nearest ground
    cell's height. ``vertices`` (n, 3) and ``normals`` (n, 3) float; :meth:`at` gives the height (k,) at
    xy (k, 2)."""

    def __init__(self, vertices: np.ndarray, normals: np.ndarray, opt: LiftOptions):
        from scipy.ndimage import distance_transform_edt, minimum_filter

        c = float(opt.cell_m)
        self.c = c
        self.lo = vertices[:, :2].min(axis=0) - c
        ij = self._ij(vertices[:, :2])
        self.nx, self.ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2
        flat = ij[:, 1] * self.nx + ij[:, 0]
        up = normals[:, 2] >= opt.up_normal_z
        zmin = np.full(self.nx * self.ny, np.inf)
        np.minimum.at(zmin, flat[up], vertices[up, 2])
        w = max(3, int(round(opt.ground_window_m / c)) | 1)
        zloc = minimum_filter(zmin.reshape(self.ny, self.nx), size=w, mode="nearest").ravel()
        g = up & (vertices[:, 2] <= zloc[flat] + opt.ground_tol_m)
        s = np.zeros(self.nx * self.ny)
        n = np.zeros(self.nx * self.ny)
        np.add.at(s, flat[g], vertices[g, 2])
        np.add.at(n, flat[g], 1)
        gz = np.where(n > 0, s / np.maximum(n, 1), np.nan).reshape(self.ny, self.nx)
        self.has_ground = n.reshape(self.ny, self.nx) > 0
        if not self.has_ground.any():
            gz[:] = float(np.min(vertices[:, 2])) if len(vertices) else 0.0
        else:
            _, (iy, ix) = distance_transform_edt(~self.has_ground, return_indices=True)
            gz = gz[iy, ix]
        self.z = gz

    def _ij(self, xy: np.ndarray) -> np.ndarray:
        return np.floor((xy - self.lo) / self.c).astype(np.int64)

    def at(self, xy: np.ndarray) -> np.ndarray:
        ij = self._ij(np.asarray(xy, float).reshape(-1, 2))
        i = np.clip(ij[:, 0], 0, self.nx - 1)
        j = np.clip(ij[:, 1], 0, self.ny - 1)
        return self.z[j, i]
