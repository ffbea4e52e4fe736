"""Meshes made by code for the mesh and surface tests."""
from __future__ import annotations

import numpy as np

from twinkit.mesh import Mesh


def grid_mesh(n=30, size=1.0, z=0.0):
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    v = np.c_[x.ravel(), y.ravel(), np.full(n * n, z)]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    return Mesh(v, f.astype(np.int64), attrs={"colors": np.full((n * n, 3), 100, np.uint8)})
