"""Atlas rasterising, texel filling, closest points and cloud-to-mesh distances (twinkit.surface)."""
from __future__ import annotations

import numpy as np

from tests.mesh.meshes import grid_mesh


def test_rasterize_covers_each_texel_once():
    from twinkit.surface.texture import rasterize

    # two triangles covering the unit square
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    hits = np.zeros((16, 16), int)
    for fid, bary, row, col in rasterize(uv, 16, max_candidates=100):
        assert np.allclose(bary.sum(axis=1), 1, atol=1e-5)
        np.add.at(hits, (row, col), 1)
    assert (hits >= 1).all() and hits.sum() <= 16 * 16 + 16  # the shared diagonal may count twice


def test_fill_empty_texels_takes_nearest():
    from twinkit.surface.texture import NEUTRAL_GREY, fill_empty_texels

    img = np.zeros((8, 8, 3), np.uint8)
    filled = np.zeros((8, 8), bool)
    img[0, 0], filled[0, 0] = 200, True
    img[7, 7], filled[7, 7] = 50, True
    fill_empty_texels(img, filled, tile=4, halo=8)
    assert (img[1, 1] == 200).all() and (img[6, 6] == 50).all()
    none = np.zeros((4, 4, 3), np.uint8)
    fill_empty_texels(none, np.zeros((4, 4), bool))
    assert (none == NEUTRAL_GREY).all()


def test_cloud_to_mesh_and_closest_points():
    from twinkit.surface.closest import Surface
    from twinkit.surface.metrics import cloud_to_mesh

    m = grid_mesh(11)
    q = np.array([[0.5, 0.5, 0.2], [0.25, 0.75, -0.1], [2.0, 0.5, 0.0]])
    d = cloud_to_mesh(q, m.vertices, m.faces)
    np.testing.assert_allclose(d, [0.2, 0.1, 1.0], atol=1e-5)
    s = Surface(m.vertices, m.faces)
    fid, bary, dist = s.closest(q)
    np.testing.assert_allclose(dist, d, atol=1e-6)
    col = s.interpolate(m.colors.astype(np.float32), fid, bary)
    np.testing.assert_allclose(col, 100, atol=1e-4)


def test_poisson_depth_and_voxel():
    from twinkit.surface.poisson import depth_for_voxel, voxel_for_depth

    p = np.array([[0, 0, 0], [10, 1, 1]], float)
    d = depth_for_voxel(p, 0.05)
    assert voxel_for_depth(p, d) <= 0.05 < voxel_for_depth(p, d - 1)
