"""The mesh covers what was scanned (issue 44): thin and far objects seen by a few points keep their surface
through the clean-up, stray points do not, and evaluate reports the share of points the mesh lost."""
from __future__ import annotations

import logging

import numpy as np
import pytest
from twinkit.mesh import Mesh, write_ply
from twinkit.surface import cleanup as C
from twinkit.testing import make_context

from twinkit_pointcloud import plugin as P


def sweep_scene(seed: int = 0):
    """A single-sweep-like street: ground sampled on rings around the sensor (spacing growing with the range,
    dense near, ~0.3 m apart at 20 m), and a sign board at 18 m seen by 36 points: its surface is a small
    component of its own. Returns (points (n, 3), normals (n, 3), sign mask (n,))."""
    rng = np.random.default_rng(seed)
    parts, norms = [], []
    for r in np.geomspace(3.0, 25.0, 40):  # rings, farther apart with the range
        n = int(2 * np.pi * r / (0.01 * r + 0.02))  # in-ring spacing grows with the range
        a = rng.uniform(0, 2 * np.pi, n)
        parts.append(np.c_[r * np.cos(a), r * np.sin(a), np.zeros(n)])
        norms.append(np.tile([0.0, 0.0, 1.0], (n, 1)))
    ground = np.vstack(parts)
    # the sign at (18, 0): a 0.6 x 0.6 m board facing the sensor, 1.5-2.1 m up, seen by 6 scan lines of 6 points
    zz, yy = np.meshgrid(np.linspace(1.5, 2.1, 6), np.linspace(-0.3, 0.3, 6))
    post = np.c_[np.full(zz.size, 18.0), yy.ravel(), zz.ravel()]
    post_n = np.tile([-1.0, 0.0, 0.0], (zz.size, 1))
    pts = np.vstack([ground, post])
    nrm = np.vstack(norms + [post_n])
    mask = np.r_[np.zeros(len(ground), bool), np.ones(len(post), bool)]
    return pts, nrm, mask


@pytest.fixture(scope="module")
def dense_sweep(tmp_path_factory):
    """The sweep's points file and its Poisson mesh (depth 9)."""
    tmp = tmp_path_factory.mktemp("sweep")
    pts, nrm, mask = sweep_scene()
    ctx = make_context(tmp / "work", site={"name": "sweep"})
    w = ctx.workdir
    write_ply(w / "points.ply", Mesh(pts, attrs={"normals": nrm.astype(np.float32)}))
    P.poisson(P.PoissonParams(depth=9), ctx, in_points_ply=w / "points.ply", out_dense_mesh_ply=w / "dense_mesh.ply")
    return ctx, pts, mask


def _clean_far(ctx, pts, params: P.CleanParams, name: str) -> np.ndarray:
    from twinkit.mesh import read_ply
    from twinkit.surface.metrics import cloud_to_mesh

    w = ctx.workdir
    P.clean_mesh(params, ctx, in_dense_mesh_ply=w / "dense_mesh.ply", in_points_ply=w / "points.ply",
                 out_clean_mesh_ply=w / f"{name}.ply", out_clean_report_json=w / f"{name}.json")
    m = read_ply(w / f"{name}.ply")
    return cloud_to_mesh(pts, m.vertices, m.faces)


def test_a_small_far_object_keeps_its_surface(dense_sweep):
    ctx, pts, post = dense_sweep
    d = _clean_far(ctx, pts, P.CleanParams(fill_ground_cell_m=0), "clean_default")
    assert (d[post] <= 0.5).mean() >= 0.9


def test_the_size_rule_alone_loses_it(dense_sweep):
    """Without the support rule (the setting before issue 44) the sign goes."""
    ctx, pts, post = dense_sweep
    d = _clean_far(ctx, pts, P.CleanParams(fill_ground_cell_m=0, min_component_points=0), "clean_old")
    assert (d[post] > 0.5).mean() >= 0.5


def _patch(centre, size: float, n: int = 4) -> Mesh:
    """A flat n x n grid of 2 (n-1)^2 faces, ``size`` m wide, at ``centre``."""
    g = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(g, g)
    v = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)] + centre
    f = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            f += [[a, a + 1, a + n], [a + 1, a + n + 1, a + n]]
    return Mesh(v, np.asarray(f))


def _join(*meshes: Mesh) -> Mesh:
    vs, fs, o = [], [], 0
    for m in meshes:
        vs.append(m.vertices)
        fs.append(m.faces + o)
        o += m.n_vertices
    return Mesh(np.vstack(vs), np.vstack(fs))


def test_small_components_stay_when_points_stand_on_them():
    big = _patch([0, 0, 0], 10.0, 30)                 # 1682 faces
    real = _patch([20, 0, 0], 0.6, 4)                 # 18 faces, 5 points on it
    stray = _patch([0, 20, 0], 0.6, 4)                # 18 faces, 1 point on it
    mesh = _join(big, real, stray)
    pts = np.vstack([big.vertices, real.vertices[:5] + [0, 0, 0.01], stray.vertices[:1]])
    out, n, kept = C.keep_large_components(mesh, 200, points=pts, min_points=3, within_m=0.1)
    assert (n, kept) == (3, 2)
    assert np.isclose(out.vertices[:, 0].max(), 20.3) and out.vertices[:, 1].max() < 10
    _, _, kept_old = C.keep_large_components(mesh, 200)
    assert kept_old == 1


def test_local_trim_keeps_the_surface_between_sparse_samples():
    """A plane sampled every 0.4 m: its mesh vertices between samples lie up to 0.28 m from them. The global
    trim (0.1 m) cuts them; the local one (2 x the local spacing) keeps them."""
    mesh = _patch([0, 0, 0], 8.0, 81)                 # vertices every 0.1 m
    g = np.arange(-4.0, 4.01, 0.4)
    x, y = np.meshgrid(g, g)
    pts = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    opt = dict(max_dist_m=0.1, min_component_faces=0, max_hole_edges=0, repair_non_manifold=False)
    old, _ = C.clean_mesh(mesh, pts, C.CleanOptions(**opt))
    new, _ = C.clean_mesh(mesh, pts, C.CleanOptions(local_trim_factor=2.0, **opt))
    assert new.n_faces >= 0.95 * mesh.n_faces
    assert old.n_faces < 0.5 * mesh.n_faces
    # a dense sampling keeps the global trim: a bubble 0.3 m off the plane still goes
    dense = np.c_[np.random.default_rng(0).uniform(-4, 4, (20000, 2)), np.zeros(20000)]
    lifted = Mesh(mesh.vertices + [0, 0, 0.3], mesh.faces)
    out, _ = C.clean_mesh(_join(mesh, lifted), dense, C.CleanOptions(local_trim_factor=2.0, **opt))
    assert out.vertices[:, 2].max() < 0.1


def test_evaluate_reports_the_far_share_and_degrades(tmp_path, caplog):
    from twinkit_pointcloud.metrics import far_from_mesh

    d = np.r_[np.zeros(70), np.full(30, 2.0)]
    cls = np.r_[np.full(50, 2), np.full(20, 5), np.full(30, 5)]
    far = far_from_mesh(d, cls)
    assert far["share"] == pytest.approx(0.3)
    assert far["per_class"]["ground"]["share"] == 0.0
    assert far["per_class"]["high vegetation"]["share"] == pytest.approx(0.6)
    # through the step: a mesh that covers only part of the cloud
    ctx = make_context(tmp_path / "work", site={"name": "t"})
    w = ctx.workdir
    mesh = _patch([0, 0, 0], 4.0, 9)
    pts = np.c_[np.random.default_rng(1).uniform(-2, 6, (2000, 2)), np.zeros(2000)]  # 3/4 off the mesh
    write_ply(w / "points.ply", Mesh(pts))
    write_ply(w / "textured.ply", mesh)
    with caplog.at_level(logging.INFO):
        r = P.evaluate(P.EvalParams(image_px=64), ctx, in_textured_mesh_ply=w / "textured.ply",
                       in_points_ply=w / "points.ply", out_recon_metrics_json=w / "recon_metrics.json")
    assert r["far_share"] > 0.5
    assert any("farther than 0.5 m" in x["reason"] for x in ctx.degraded_reasons)


def test_the_report_shows_the_far_share(tmp_path):
    import json

    from twinkit_pointcloud.report import sec_recon_metrics

    f = tmp_path / "recon_metrics.json"
    f.write_text(json.dumps({"cloud_far": {"far_m": 0.5, "share": 0.3, "points": 30,
                                           "per_class": {"high vegetation": {"points": 50, "share": 0.6}}}}))

    class Ctx:
        def first(self, pattern):
            return ({"folder": "07_evaluate"}, f)

        def read_json(self, p):
            return json.loads(p.read_text())

        def esc(self, x):
            return str(x)

        def length_unit(self):
            return "m"

        def table(self, headers, rows):
            return "|".join(map(str, headers)) + "\n" + "\n".join("|".join(map(str, r)) for r in rows)

    html = sec_recon_metrics(Ctx())
    assert "farther than 0.5 m" in html and "30.00 %" in html and "high vegetation|50|60.00 %" in html
