"""Unit tests of the algorithm modules on small meshes made by code."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.mesh import Mesh


def grid_mesh(n=30, size=1.0, z=0.0):
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    v = np.c_[x.ravel(), y.ravel(), np.full(n * n, z)]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]])
    return Mesh(v, f.astype(np.int64), attrs={"colors": np.full((n * n, 3), 100, np.uint8)})


def test_chart_uv_no_overlap_and_in_range():
    from twinkit.surface.texture import rasterize
    from twinkit_pointcloud.uv import chart_uv

    # a closed box: six charts
    import open3d as o3d

    b = o3d.geometry.TriangleMesh.create_box(2, 1, 1).subdivide_midpoint(3)
    v, f = np.asarray(b.vertices), np.asarray(b.triangles)
    uv, info = chart_uv(v, f, 512)
    assert info["charts"] >= 6  # six faces, long ones cut on a grid
    assert uv.min() >= 0 and uv.max() <= 1
    owner = np.full((512, 512), -1)
    hits = 0
    for fid, bary, row, col in rasterize(uv, 512):
        inner = (bary > 0.02).all(axis=1)  # texel centres strictly inside
        prev = owner[row[inner], col[inner]]
        assert ((prev == -1) | (prev == fid[inner])).all()  # no two triangles share a texel
        owner[row[inner], col[inner]] = fid[inner]
        hits += inner.sum()
    assert hits > 0.3 * 512 * 512


def test_orient_normals_methods():
    from twinkit_pointcloud.normals import estimate_normals, orient_normals

    rng = np.random.default_rng(0)
    # a sphere: the propagation turns it outward; as a street capture, its underside (at the local ground)
    # faces up
    from twinkit_pointcloud.normals import _orient_mst

    p = rng.normal(size=(4000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    n = estimate_normals(p, k=16)
    assert (np.einsum("ij,ij->i", _orient_mst(p, n, 16), p) > 0).mean() > 0.99
    o, used = orient_normals(p, n, "mst")
    out = np.einsum("ij,ij->i", o, p) > 0
    assert used == "mst" and out[p[:, 2] > -0.5].mean() > 0.99 and (o[p[:, 2] < -0.95, 2] > 0).all()
    # towards a scanner
    q = np.c_[rng.uniform(-3, 3, 3000), rng.uniform(-3, 3, 3000), np.zeros(3000)]
    nq = -np.tile([0, 0, 1.0], (3000, 1)).astype(np.float32)
    o2, used2 = orient_normals(q, nq, "auto", scanner_index=np.zeros(3000, int),
                               scanner_positions=np.array([[0, 0, 1.5]]))
    assert used2 == "scanner" and (o2[:, 2] > 0).all()
    o3, _ = orient_normals(q, nq, "up")
    assert (o3[:, 2] > 0).all()


def test_plugin_registers(monkeypatch):
    from twinkit.plugins import load_registry

    monkeypatch.setenv("TWINKIT_PLUGINS", "pointcloud")  # only this package's entry point
    reg = load_registry()
    assert "poisson" in reg.plugins["reconstructor"]
    for name in ("read_cloud", "clean_mesh", "simplify", "bake_texture", "evaluate_reconstruction"):
        assert name in reg.plugins["step"], name
        p = reg.plugins["step"][name]
        assert p.distribution == "twinkit-pointcloud"
        p.default_params()
    try:
        from twinkit.testing import check_plugin
        import twinkit.signature  # noqa: F401
    except ImportError:
        pytest.skip("twinkit.signature not available yet: contract check skipped")
    own = [p for p in reg.all() if p.distribution == "twinkit-pointcloud"]
    assert own, "the plugin's steps were not registered"
    for p in own:
        check_plugin(p)


def test_import_is_light():
    import subprocess
    import sys

    code = "import sys, twinkit_pointcloud.plugin; print(any(m in sys.modules for m in ('open3d', 'pymeshlab', 'laspy', 'pye57', 'scipy')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"


def test_coverage_by_label():
    from twinkit_pointcloud.metrics import coverage_by_label, sample_surface_by_label

    a, b = grid_mesh(11, size=1.0), grid_mesh(11, size=0.1)  # areas 1 and 0.01 m^2
    v = np.vstack([a.vertices, b.vertices + [5, 0, 0]])
    f = np.vstack([a.faces, b.faces + a.n_vertices])
    lab = np.r_[np.zeros(a.n_faces, np.int32), np.full(b.n_faces, 5, np.int32)]
    S, L, areas = sample_surface_by_label(v, f, lab, 1000, min_per_label=500)
    assert (L == 5).sum() == 500 and (L == 0).sum() == 990 and abs(areas[0] - 1.0) < 1e-9
    dist = np.where(L == 0, 0.0, np.where(S[:, 0] < 5.05, 0.01, 0.5))  # half of the small one covered
    seen = np.where(L == 0, 0.0, 1.0)  # the small one was never seen
    cov = coverage_by_label(dist, L, areas, dist_to_cloud=seen, observed_m=0.1)
    assert cov["road"]["covered"] == 1.0 and cov["road"]["observed"] == 1.0
    assert 0.4 < cov["pole"]["covered"] < 0.6 and cov["pole"]["covered_observed"] is None


def test_distance_near_exact():
    from twinkit_pointcloud.metrics import distance_near_exact
    from twinkit.surface.closest import Surface

    m = grid_mesh(11, size=1.0)  # 10 cm edges
    s = Surface(m.vertices, m.faces)
    q = np.array([[0.55, 0.55, 0.03], [0.5, 0.5, 3.0], [5.0, 0.5, 0.0]])
    d = distance_near_exact(s, m.vertices, q, near_m=0.5)
    exact = s.distance(q)
    assert abs(d[0] - 0.03) < 1e-5  # near: exact
    assert (d >= exact - 1e-6).all() and (d - exact < 0.08).all()  # far: nearest vertex, within an edge
