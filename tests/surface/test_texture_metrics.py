"""Atlas rasterising, texel filling, closest points and cloud-to-mesh distances (twinkit.surface)."""
from __future__ import annotations

import numpy as np
import pytest

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


def _numpy_only(monkeypatch):
    import twinkit.surface.compiled as C

    monkeypatch.setattr(C, "ENABLED", False)


def test_compiled_and_numpy_atlas_code_agree(monkeypatch):
    """The compiled loops give the numpy code's numbers bit for bit (rasterize, barycentric mix, closest, texel
    writes), for float64 and float32 UVs."""
    from twinkit.surface.closest import Surface, barycentric_mix
    from twinkit.surface.texture import put_texels, rasterize

    rng = np.random.default_rng(0)
    uv = rng.random((300, 3, 2))
    m = grid_mesh(21)
    s = Surface(m.vertices, m.faces)
    q = rng.random((5000, 3)) * [1, 1, 0.2]
    cols = rng.integers(0, 256, (m.n_vertices, 3)).astype(np.uint8)

    def run():
        out = [np.concatenate(parts) for parts in zip(*rasterize(uv, 64, max_candidates=500))]
        out += [np.concatenate(parts) for parts in zip(*rasterize(uv.astype(np.float32), 64))]
        fid, bary, dist = s.closest(q)
        out += [fid, bary, dist, barycentric_mix(m.vertices, m.faces, fid, bary, np.float64)]
        colv = s.interpolate(cols, fid, bary) * 1.01 - 1  # some values outside 0..255
        img, filled = np.zeros((70, 70, 3), np.uint8), np.zeros((70, 70), bool)
        put_texels(img, filled, rng.integers(0, 70, len(q)), rng.integers(0, 70, len(q)), colv)
        return out + [colv, img, filled]

    rng = np.random.default_rng(1)
    fast = run()
    _numpy_only(monkeypatch)
    rng = np.random.default_rng(1)
    slow = run()
    assert len(fast[0]) > 1000
    for a, b in zip(fast, slow):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_fill_in_threads_same_as_one():
    from twinkit.surface.texture import fill_empty_texels

    rng = np.random.default_rng(2)
    img = rng.integers(0, 256, (50, 50, 3)).astype(np.uint8)
    filled = rng.random((50, 50)) < 0.05
    filled[:20, :20] = False  # a tile (with its halo) without any filled texel: grey
    a, b = img.copy(), img.copy()
    fill_empty_texels(a, filled, tile=16, halo=3)
    fill_empty_texels(b, filled, tile=16, halo=3, threads=3)
    assert np.array_equal(a, b) and np.array_equal(a[filled], img[filled])
    assert (a[2, 2] == 128).all()


@pytest.mark.parametrize("deflate", ["isal", "zlib"])
def test_write_png_reads_back(tmp_path, monkeypatch, deflate):
    from PIL import Image

    from twinkit import deflate as D
    from twinkit.surface.texture import write_png

    if deflate == "isal":
        pytest.importorskip("isal")
    monkeypatch.setenv("TWINKIT_DEFLATE", deflate)
    assert D.backend() == deflate
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (37, 53, 3)).astype(np.uint8)
    for threads in (1, 4):
        for row_filter in ("up", "sub"):  # an atlas's filter, a rendered view's
            for rle in (False, True):
                write_png(tmp_path / "a.png", img, threads=threads, row_filter=row_filter, rle=rle)
                assert np.array_equal(np.asarray(Image.open(tmp_path / "a.png")), img)
    rows = np.repeat(rng.integers(0, 256, (1, 256, 3)), 64, axis=0).astype(np.uint8)
    write_png(tmp_path / "d.png", rows, row_filter="sub")
    write_png(tmp_path / "r.png", rows, row_filter="sub", rle=True)
    assert np.array_equal(np.asarray(Image.open(tmp_path / "r.png")), rows)
    if deflate == "zlib":
        # one random row repeated: deflate finds each row a row back, run-length matches (distance 1) cannot
        assert (tmp_path / "r.png").stat().st_size > 5 * (tmp_path / "d.png").stat().st_size
    else:  # ISA-L has no run-length strategy: the same stream either way, and it finds the rows a row back
        assert (tmp_path / "r.png").read_bytes() == (tmp_path / "d.png").read_bytes()
        assert (tmp_path / "d.png").stat().st_size < 0.1 * rows.nbytes
    with pytest.raises(ValueError, match="row_filter"):
        write_png(tmp_path / "b.png", img, row_filter="paeth")
    grey = img[..., 0]
    write_png(tmp_path / "g.png", grey)  # not RGB: through Pillow
    assert np.array_equal(np.asarray(Image.open(tmp_path / "g.png")), grey)
