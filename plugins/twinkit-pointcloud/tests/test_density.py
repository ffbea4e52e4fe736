"""Density-aware defaults (issue 28): a sparse cloud keeps its walls, and a stage that removes most of its
input says so."""
from __future__ import annotations

import numpy as np
import pytest
from twinkit.mesh import Mesh, face_areas, read_ply, write_ply
from twinkit.surface import density
from twinkit.testing import make_context

from twinkit_pointcloud import plugin as P


def _plane(rng, origin, u, v, nu, nv, step, normal, noise):
    a = np.arange(0.0, nu + 1e-9, step)
    b = np.arange(0.0, nv + 1e-9, step)
    ga, gb = np.meshgrid(a, b)
    ga = ga.ravel() + rng.uniform(-0.25, 0.25, ga.size) * step
    gb = gb.ravel() + rng.uniform(-0.25, 0.25, gb.size) * step
    p = np.asarray(origin) + ga[:, None] * np.asarray(u) + gb[:, None] * np.asarray(v)
    p += rng.normal(0, noise, (len(p), 1)) * np.asarray(normal)
    return p, np.tile(normal, (len(p), 1))


def sparse_block(step=0.3, noise=0.03, seed=0):
    """A 24 m x 24 m ground and an 8 x 8 x 6 m building (walls and roof) sampled every ``step`` metres
    with ``noise`` along the normal, like aerial lidar at ~11 points/m^2."""
    rng = np.random.default_rng(seed)
    parts = [_plane(rng, (-12, -12, 0), (1, 0, 0), (0, 1, 0), 24, 24, step, (0, 0, 1), noise)]
    p, n = parts[0]
    inside = (np.abs(p[:, 0]) < 4) & (np.abs(p[:, 1]) < 4)
    parts[0] = (p[~inside], n[~inside])
    parts += [
        _plane(rng, (-4, -4, 0), (1, 0, 0), (0, 0, 1), 8, 6, step, (0, -1, 0), noise),
        _plane(rng, (-4, 4, 0), (1, 0, 0), (0, 0, 1), 8, 6, step, (0, 1, 0), noise),
        _plane(rng, (-4, -4, 0), (0, 1, 0), (0, 0, 1), 8, 6, step, (-1, 0, 0), noise),
        _plane(rng, (4, -4, 0), (0, 1, 0), (0, 0, 1), 8, 6, step, (1, 0, 0), noise),
        _plane(rng, (-4, -4, 6), (1, 0, 0), (0, 1, 0), 8, 8, step, (0, 0, 1), noise),
    ]
    pts = np.concatenate([q for q, _ in parts])
    nrm = np.concatenate([m for _, m in parts]).astype(np.float32)
    return pts, nrm


def wall_area(mesh) -> float:
    """Area of the mesh's near-vertical faces between 1 and 5 m high within 0.5 m of the building's walls."""
    v, f = mesh.vertices, mesh.faces
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-12)
    c = v[f].mean(axis=1)
    near = np.abs(np.max(np.abs(c[:, :2]), axis=1) - 4.0) < 0.5
    sel = (np.abs(fn[:, 2]) < 0.3) & (c[:, 2] > 1) & (c[:, 2] < 5) & near
    return float(face_areas(v, f[sel]).sum())


@pytest.fixture(scope="module")
def sparse_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sparse")
    pts, nrm = sparse_block()
    src = tmp / "sparse.ply"
    write_ply(src, Mesh(pts, attrs={"normals": nrm}))
    ctx = make_context(tmp / "work", site={"name": "synthetic", "bounds_m": [[-12, -12, 0], [12, 12, 6]]})
    w = ctx.workdir
    read = P.read_cloud(P.ReadCloudParams(), ctx, in_cloud=src, out_points_ply=w / "points.ply",
                        out_points_meta_json=w / "points_meta.json")
    rec = P.poisson(P.PoissonParams(), ctx, in_points_ply=w / "points.ply", out_dense_mesh_ply=w / "dense_mesh.ply")
    return ctx, w, read, rec


def test_measure_spacing_and_capture():
    pts, _ = sparse_block()
    m = density.measure(pts)
    assert 0.15 < m["spacing_m"] < 0.35 and m["spacing_p90_m"] < 0.45
    assert m["capture"] == "mobile"  # a quarter of the points on walls: not an aerial capture
    ground = pts[pts[:, 2] < 0.2]
    g = density.measure(ground)
    assert g["capture"] == "aerial" and g["vertical_share"] < 0.05
    assert density.measure(pts, scanner_positions=[[0, 0, 2]])["capture"] == "terrestrial"
    # a street scanner's spacing (2 cm) leaves the settings of before issue 28
    fine = density.measure(pts * (0.02 / m["spacing_m"]))
    assert density.trim_distance(fine) == 0.10
    assert density.trim_distance(m) > 0.4


def test_settings_follow_the_density():
    assert density.poisson_depth({"spacing_m": 0.03, "extent_m": [70, 70, 10]}) == 11  # the demo's
    assert density.poisson_depth({"spacing_m": 0.3, "extent_m": [24, 24, 6]}) == 7
    assert density.texture_size(3754.0, 0.016) == 4096  # the demo: 64 mm median dense edge / 4 -> 4,944 px
    assert density.texture_size(3754.0, 0.011) == 8192  # 7,191 px: nearer 8192 on a log scale
    assert density.texture_size(300.0, 0.1) == 1024


def test_sparse_cloud_keeps_its_walls(sparse_run):
    ctx, w, read, rec = sparse_run
    assert read["capture"] == "mobile" and 0.15 < read["spacing_m"] < 0.35
    assert rec["depth"] < 11  # the octree follows the spacing
    out = P.clean_mesh(P.CleanParams(), ctx, in_dense_mesh_ply=w / "dense_mesh.ply", in_points_ply=w / "points.ply",
                       out_clean_mesh_ply=w / "clean_mesh.ply", out_clean_report_json=w / "clean_report.json")
    assert out["max_dist_m"] > 0.3
    mesh = read_ply(w / "clean_mesh.ply")
    true_area = 4 * 8 * 4.0  # four walls, 1..5 m
    assert wall_area(mesh) > 0.8 * true_area
    assert out["trim_removed_share"] < 0.5
    assert not ctx.degraded_reasons


def test_fixed_trim_below_the_spacing_is_degraded(sparse_run, caplog):
    ctx, w, _, _ = sparse_run
    ctx2 = make_context(w.parent / "work2", site=ctx.site)
    out = P.clean_mesh(P.CleanParams(max_dist_m=0.06, gap_dist_m=0), ctx2, in_dense_mesh_ply=w / "dense_mesh.ply",
                       in_points_ply=w / "points.ply", out_clean_mesh_ply=ctx2.workdir / "clean_mesh.ply",
                       out_clean_report_json=ctx2.workdir / "clean_report.json")
    assert out["trim_removed_share"] > 0.9
    (reason,) = ctx2.degraded_reasons
    assert "removed" in reason["reason"] and "max_dist_m" in reason["hint"]
    assert wall_area(read_ply(ctx2.workdir / "clean_mesh.ply")) < 0.2 * 4 * 8 * 4.0


def test_simplify_overshoot_is_degraded(tmp_path):
    # 3000 separate triangles: all border, none can collapse with preserve_border
    rng = np.random.default_rng(0)
    base = rng.uniform(0, 50, (3000, 1, 3))
    v = (base + rng.uniform(0, 0.3, (3000, 3, 3))).reshape(-1, 3)
    f = np.arange(len(v)).reshape(-1, 3)
    write_ply(tmp_path / "clean_mesh.ply", Mesh(v, f))
    ctx = make_context(tmp_path / "work", site={"name": "synthetic"})
    out = P.simplify(P.SimplifyParams(target_faces=500), ctx, in_clean_mesh_ply=tmp_path / "clean_mesh.ply",
                     out_mesh_ply=tmp_path / "mesh.ply")
    assert out["faces"] > 600 and out["overshoot"] > 0.2
    (reason,) = ctx.degraded_reasons
    assert "target of 500" in reason["reason"]
