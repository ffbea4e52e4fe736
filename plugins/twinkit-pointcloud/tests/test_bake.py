"""The colour bake on a mesh whose colours are known everywhere: a plane coloured by a linear ramp."""
from __future__ import annotations

import numpy as np

from twinkit.surface.texture import NEUTRAL_GREY


def _ramp_scene(n=41):
    """A dense 1 m plane (n x n vertices) coloured R = 20 + 200 x, G = 20 + 200 y, B = 90; two triangles of the
    same plane 1 mm above it, UV-mapped onto [0.1, 0.9]^2 of the atlas."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    dv = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    df = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    dc = np.c_[20 + 200 * dv[:, 0], 20 + 200 * dv[:, 1], np.full(n * n, 90)].round().astype(np.uint8)
    sv = np.array([[0, 0, 1e-3], [1, 0, 1e-3], [1, 1, 1e-3], [0, 1, 1e-3]])
    sf = np.array([[0, 1, 2], [0, 2, 3]])
    uv = 0.1 + 0.8 * sv[sf][..., :2]
    return sv, sf, uv, dv, df, dc


def test_ramp_baked_texel_by_texel(monkeypatch):
    from twinkit_pointcloud.texture import bake_colors

    import twinkit.surface.compiled as C

    size = 64
    sv, sf, uv, dv, df, dc = _ramp_scene()
    img, info = bake_colors(sv, sf, uv, size, dv, df, dc, threads=2)
    # texel (row, col) has its centre at u = (col + 0.5) / size, v = 1 - (row + 0.5) / size
    u = (np.arange(size) + 0.5) / size
    v = 1 - (np.arange(size) + 0.5) / size
    X = (u[None, :] - 0.1) / 0.8 + 0 * v[:, None]
    Y = (v[:, None] - 0.1) / 0.8 + 0 * u[None, :]
    inside = (X >= 0) & (X <= 1) & (Y >= 0) & (Y <= 1)
    want = np.stack([20 + 200 * X, 20 + 200 * Y, np.full_like(X, 90)], axis=-1)
    err = np.abs(img.astype(float) - want)[inside]
    assert inside.sum() > 0.6 * size * size and err.max() <= 1.0  # the dense colours' own rounding
    assert info["texels_baked"] >= inside.sum() and abs(info["mean_transfer_distance_m"] - 1e-3) < 1e-5
    # outside the square every texel takes its nearest baked texel's colour: the corner texel's
    assert (img[0, 0] == img[inside][np.argmin(X[inside] + (1 - Y[inside]))]).all()
    assert not (img == NEUTRAL_GREY).all(axis=-1).any()
    # the numpy code (no numba) bakes the same atlas
    monkeypatch.setattr(C, "ENABLED", False)
    img2, info2 = bake_colors(sv, sf, uv, size, dv, df, dc, threads=1)
    assert np.array_equal(img, img2) and info == info2


def test_colourless_bake_is_grey():
    from twinkit_pointcloud.texture import bake_colors

    sv, sf, uv, *_ = _ramp_scene(3)
    img, info = bake_colors(sv, sf, uv, 32, None, None, None)
    assert (img == NEUTRAL_GREY).all() and info["texels_baked"] > 0
