"""Distances between a point cloud and a triangle surface (reconstruction diagnostics)."""
from __future__ import annotations

import numpy as np


def cloud_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, threads: int = 0) -> np.ndarray:
    """Distance (m) from every point to the mesh surface, (n,) float32."""
    from .closest import Surface

    return Surface(vertices, faces, threads).distance(points)
