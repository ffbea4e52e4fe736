"""Colourless clouds: the grey levels the bake step gives a mesh without colours (twinkit_pointcloud.shading)."""
from __future__ import annotations

import numpy as np


def test_colourless_modes_shade_the_geometry():
    from twinkit_pointcloud.shading import vertex_colours

    v = np.array([[0, 0, 0], [0, 0, 5], [0, 0, 5.0], [0, 0, 0.0]])
    n = np.array([[0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 0, -1.0]])
    g = vertex_colours("shaded", v, n)[:, 0].astype(int)
    assert g[0] > g[1] and g[0] > g[2] and g[1] != g[2] and g[3] == g.min()  # up light, walls differ, down dark
    i = vertex_colours("intensity", v[:2].repeat(2, 0), n[:1].repeat(4, 0), intensity=np.array([0.1, 0.1, 0.9, 0.9]))
    assert i[2, 0] > i[0, 0] + 60
    assert (vertex_colours("grey", v, n) == 128).all()
