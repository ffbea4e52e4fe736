"""A sparse capture says so (issue 46, item 5): a mesh mostly made of ground fill is degraded with the figures;
a dense capture of the same street is not."""
from __future__ import annotations

import json

import numpy as np
from twinkit.mesh import Mesh, write_ply
from twinkit.testing import make_context

from twinkit_pointcloud import plugin as P


def street(sparse: bool, seed: int = 0):
    """A 16 x 16 m flat street with a 2 m wall on one side. Dense: ground every 6 cm. Sparse: a single sweep's
    rings around a sensor at the centre, farther apart with the range (the ground between them has no point)."""
    rng = np.random.default_rng(seed)
    if sparse:
        parts = []
        for r in np.geomspace(1.5, 11.0, 9):
            n = int(2 * np.pi * r / 0.05)
            a = rng.uniform(0, 2 * np.pi, n)
            parts.append(np.c_[r * np.cos(a), r * np.sin(a), np.zeros(n)])
        ground = np.vstack(parts)
        ground = ground[(np.abs(ground[:, :2]) <= 8).all(axis=1)]
    else:
        g = np.arange(-8, 8, 0.06)
        x, y = np.meshgrid(g, g)
        ground = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)] + rng.normal(0, 0.003, (x.size, 3))
    zz, yy = np.meshgrid(np.arange(0.1, 2.0, 0.08), np.arange(-8, 8, 0.08))
    wall = np.c_[np.full(zz.size, 8.0), yy.ravel(), zz.ravel()]
    pts = np.vstack([ground, wall])
    nrm = np.vstack([np.tile([0.0, 0.0, 1.0], (len(ground), 1)), np.tile([-1.0, 0.0, 0.0], (len(wall), 1))])
    return pts, nrm.astype(np.float32)


def _clean(tmp_path, sparse: bool):
    ctx = make_context(tmp_path / "work", site={"name": "street"}, step_id="clean")
    w = ctx.workdir
    pts, nrm = street(sparse)
    write_ply(w / "points.ply", Mesh(pts, attrs={"normals": nrm}))
    P.poisson(P.PoissonParams(), ctx, in_points_ply=w / "points.ply", out_dense_mesh_ply=w / "dense_mesh.ply")
    out = P.clean_mesh(P.CleanParams(), ctx, in_dense_mesh_ply=w / "dense_mesh.ply", in_points_ply=w / "points.ply",
                       out_clean_mesh_ply=w / "clean_mesh.ply", out_clean_report_json=w / "clean_report.json")
    return ctx, out, json.loads((w / "clean_report.json").read_text())


def test_a_sparse_sweep_is_degraded_with_the_figures(tmp_path):
    ctx, out, rep = _clean(tmp_path, sparse=True)
    share = rep["ground_fill"]["area_share"]
    assert out["fill_share"] == share and share > P.CleanParams().max_fill_share
    (reason,) = [d["reason"] for d in ctx.degraded_reasons]
    assert f"{100 * share:.0f} % of the mesh's surface" in reason and "too sparse" in reason


def test_a_dense_capture_is_not(tmp_path):
    ctx, out, rep = _clean(tmp_path, sparse=False)
    assert out["fill_share"] is None or out["fill_share"] < P.CleanParams().max_fill_share
    assert ctx.degraded_reasons == [], ctx.degraded_reasons


def test_the_shadows_heights_are_smoothed_where_the_ground_is_rings_only():
    """The clean step's auto setting: the ground fill's median over the shadows' heights (the streaks of the
    row and column interpolation between rings) is on for a sweep's rings and off for ground sampled in
    patches, whose fill the demo's kerb alignment reads (docs/pointcloud.md "The fill without streaks")."""
    import logging

    class Cloud:
        def __init__(self, pts):
            self.vertices = pts

    log = logging.getLogger("test")
    rings = P._clean_auto(P.CleanParams(), Cloud(street(sparse=True)[0]), log)
    patches = P._clean_auto(P.CleanParams(), Cloud(street(sparse=False)[0]), log)
    assert rings["ground_two_way_share"] < 0.5 < patches["ground_two_way_share"]
    assert rings["fill_ground_smooth_cells"] == 5 and patches["fill_ground_smooth_cells"] == 0
    fixed = P._clean_auto(P.CleanParams(fill_ground_smooth_cells=3), Cloud(street(sparse=False)[0]), log)
    assert fixed["fill_ground_smooth_cells"] == 3
