"""Poisson -> clean -> simplify -> bake -> evaluate on a synthetic scene with known geometry,
and the textured OBJ round trip."""
from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from twinkit.testing import make_context

from twinkit_pointcloud import plugin as P
from twinkit.mesh import Mesh, read_obj, read_ply, write_ply

from conftest import box_scene, checker_colour


def box_distance(p: np.ndarray) -> np.ndarray:
    """Distance from points to the true surface: ground z = 0 outside the box, box [-1, 1]^2 x [0, 2]."""
    q = np.abs(p - [0.0, 0.0, 1.0]) - 1.0
    outside = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
    d_box = np.abs(outside)
    d_ground = np.where((np.abs(p[:, 0]) > 1) | (np.abs(p[:, 1]) > 1), np.abs(p[:, 2]), np.inf)
    return np.minimum(d_box, d_ground)


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("pipe")
    pts, col, _ = box_scene()
    src = tmp / "scene.ply"
    write_ply(src, Mesh(pts, attrs={"colors": col}))
    ctx = make_context(tmp / "work", site={"name": "synthetic", "bounds_m": [[-5, -5, 0], [5, 5, 2]]})
    w = ctx.workdir
    res = {}
    # a 10 x 10 m box scene for the meshing steps, not a street: the street-size check is off here
    res["read"] = P.read_cloud(P.ReadCloudParams(min_street_extent_m=0), ctx, in_cloud=src, out_points_ply=w / "points.ply",
                               out_points_meta_json=w / "points_meta.json")
    res["poisson"] = P.poisson(P.PoissonParams(depth=8), ctx, in_points_ply=w / "points.ply",
                               out_dense_mesh_ply=w / "dense_mesh.ply")
    res["clean"] = P.clean_mesh(P.CleanParams(max_dist_m=0.08), ctx, in_dense_mesh_ply=w / "dense_mesh.ply",
                                in_points_ply=w / "points.ply", out_clean_mesh_ply=w / "clean_mesh.ply",
                                out_clean_report_json=w / "clean_report.json")
    res["simplify"] = P.simplify(P.SimplifyParams(target_faces=6000), ctx, in_clean_mesh_ply=w / "clean_mesh.ply",
                                 out_mesh_ply=w / "mesh.ply")
    res["bake"] = P.bake_texture(P.BakeParams(texture_px=1024), ctx, in_mesh_ply=w / "mesh.ply",
                                 in_clean_mesh_ply=w / "clean_mesh.ply", out_textured_mesh_obj=w / "textured_mesh.obj",
                                 out_textured_mesh_ply=w / "textured_mesh.ply")
    res["eval"] = P.evaluate(P.EvalParams(), ctx, in_textured_mesh_ply=w / "textured_mesh.ply",
                             in_points_ply=w / "points.ply", out_recon_metrics_json=w / "recon_metrics.json")
    return w, res


def test_all_outputs_exist(pipeline):
    w, res = pipeline
    for f in ("points.ply", "points_meta.json", "dense_mesh.ply", "clean_mesh.ply", "clean_report.json",
              "clean_report.png", "mesh.ply", "textured_mesh.obj", "textured_mesh.mtl", "textured_mesh.png",
              "textured_mesh.ply", "recon_metrics.json", "recon_metrics.png"):
        assert (w / f).exists(), f
    for step in res.values():
        assert step["seconds"] > 0 and step["peak_rss_mb"] > 0


def test_normals_estimated_and_oriented(pipeline):
    w, _ = pipeline
    m = read_ply(w / "points.ply")
    pts, _, true_n = box_scene()
    assert np.allclose(m.vertices, pts, atol=1e-5)
    agree = np.einsum("ij,ij->i", m.normals, true_n)
    assert (agree > 0.9).mean() > 0.97  # oriented outward/up (box corners excepted)


def test_dense_mesh_geometry(pipeline):
    w, res = pipeline
    clean = read_ply(w / "clean_mesh.ply")
    assert "dist_to_cloud_m" in clean.attrs and clean.attrs["dist_to_cloud_m"].max() <= 0.2
    d = box_distance(clean.vertices)
    assert np.mean(d) < 0.01 and np.quantile(d, 0.95) < 0.03
    rep = json.loads((w / "clean_report.json").read_text())
    assert rep["output"]["faces"] == clean.n_faces
    # the trimmed mesh stays inside the scene (Poisson's closing surface was cut away)
    assert clean.vertices[:, 2].max() < 2.1 and clean.vertices[:, 2].min() > -0.1


def test_simplified_mesh(pipeline):
    w, res = pipeline
    m = read_ply(w / "mesh.ply")
    assert 5000 <= m.n_faces <= 6060  # the target, plus the fans that close the pin-holes collapses leave
    d = box_distance(m.vertices)
    assert np.mean(d) < 0.01 and d.max() < 0.1
    # borders preserved: the extent of the ground is kept
    clean = read_ply(w / "clean_mesh.ply")
    assert np.allclose(m.vertices[:, :2].min(axis=0), clean.vertices[:, :2].min(axis=0), atol=0.02)
    assert np.allclose(m.vertices[:, :2].max(axis=0), clean.vertices[:, :2].max(axis=0), atol=0.02)


def test_evaluation_distances(pipeline):
    w, res = pipeline
    met = json.loads((w / "recon_metrics.json").read_text())
    assert met["cloud_to_mesh_m"]["mean"] < 0.005
    assert met["cloud_to_mesh_m"]["p95"] < 0.015
    assert met["counts"]["faces"] == res["simplify"]["faces"]


def test_textured_obj_round_trip(pipeline):
    from PIL import Image

    w, res = pipeline
    obj = read_obj(w / "textured_mesh.obj")
    assert "mtllib textured_mesh.mtl" in (w / "textured_mesh.obj").read_text()
    mtl = (w / "textured_mesh.mtl").read_text()
    assert "map_Kd textured_mesh.png" in mtl
    assert obj.texture == w / "textured_mesh.png"
    img = np.asarray(Image.open(w / "textured_mesh.png").convert("RGB"))
    assert img.shape == (1024, 1024, 3)
    ply = read_ply(w / "textured_mesh.ply")
    assert obj.n_faces == ply.n_faces and np.array_equal(obj.faces, ply.faces)
    assert np.allclose(obj.vertices, ply.vertices, atol=1e-5)
    tuv = obj.corner_uv  # (m, 3, 2)
    assert tuv.min() >= 0 and tuv.max() <= 1
    assert np.allclose(ply.face_attrs["texcoord"].reshape(-1, 3, 2), tuv, atol=1e-5)
    # colours: at points inside ground faces, away from checker edges, the texture shows the checker
    rng = np.random.default_rng(3)
    V, F = obj.vertices, obj.faces
    b = rng.dirichlet([4, 4, 4], size=len(F))
    p3 = np.einsum("ij,ijk->ik", b, V[F])
    puv = np.einsum("ij,ijk->ik", b, tuv)
    frac = np.abs(p3[:, :2] - np.round(p3[:, :2]))
    on_ground = (np.abs(p3[:, 2]) < 0.01) & ((np.abs(p3[:, 0]) > 1.2) | (np.abs(p3[:, 1]) > 1.2))
    sel = on_ground & (frac.min(axis=1) > 0.12) & (np.abs(p3[:, :2]).max(axis=1) < 4.8)
    assert sel.sum() > 200
    col = (puv[sel, 0] * 1024).astype(int).clip(0, 1023)
    row = ((1 - puv[sel, 1]) * 1024).astype(int).clip(0, 1023)
    got = img[row, col].astype(int)
    want = checker_colour(p3[sel]).astype(int)
    ok = np.abs(got - want).max(axis=1) < 40
    assert ok.mean() > 0.95
    # vertex colours of the PLY are the checker too (same filter on vertices)
    vv = ply.vertices
    fv = np.abs(vv[:, :2] - np.round(vv[:, :2])).min(axis=1)
    vs = (np.abs(vv[:, 2]) < 0.01) & (fv > 0.12) & ((np.abs(vv[:, 0]) > 1.2) | (np.abs(vv[:, 1]) > 1.2))
    assert (np.abs(ply.colors[vs].astype(int) - checker_colour(vv[vs]).astype(int)).max(axis=1) < 40).mean() > 0.9


def test_no_colours_gives_shaded_or_neutral_texture(tmp_path, caplog):
    """A cloud without colours: by default a shaded grey (issue 28); colourless=grey: the flat grey of before."""
    from PIL import Image

    pts, _, nrm = box_scene(8000, 1500)
    ctx = make_context(tmp_path / "w")
    w = ctx.workdir
    write_ply(w / "points.ply", Mesh(pts, attrs={"normals": nrm.astype(np.float32)}))
    P.poisson(P.PoissonParams(depth=6), ctx, in_points_ply=w / "points.ply", out_dense_mesh_ply=w / "dense.ply")
    P.clean_mesh(P.CleanParams(max_dist_m=0.3), ctx, in_dense_mesh_ply=w / "dense.ply", in_points_ply=w / "points.ply",
                 out_clean_mesh_ply=w / "clean_mesh.ply", out_clean_report_json=w / "clean_report.json")
    P.simplify(P.SimplifyParams(target_faces=1000), ctx, in_clean_mesh_ply=w / "clean_mesh.ply", out_mesh_ply=w / "mesh.ply")
    with caplog.at_level(logging.WARNING):
        r = P.bake_texture(P.BakeParams(texture_px=256), ctx, in_mesh_ply=w / "mesh.ply",
                           in_clean_mesh_ply=w / "clean_mesh.ply", out_textured_mesh_obj=w / "s.obj",
                           out_textured_mesh_ply=w / "s.ply")
    assert not r["neutral_texture"] and r["colourless"] == "shaded" and "shaded" in caplog.text
    img = np.asarray(Image.open(w / "s.png"))
    assert img[..., 0].std() > 10 and (img[..., 0] == img[..., 1]).all()  # grey levels, not one grey
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        r = P.bake_texture(P.BakeParams(texture_px=256, colourless="grey"), ctx, in_mesh_ply=w / "mesh.ply",
                           in_clean_mesh_ply=w / "clean_mesh.ply", out_textured_mesh_obj=w / "t.obj",
                           out_textured_mesh_ply=w / "t.ply")
    assert r["neutral_texture"] and "neutral grey" in caplog.text
    img = np.asarray(Image.open(w / "t.png"))
    assert (img == 128).all()


def test_bad_texture_size_no_outputs(tmp_path):
    from twinkit import InputError

    ctx = make_context(tmp_path / "w")
    with pytest.raises(InputError, match="texture_px"):
        P.bake_texture(P.BakeParams(texture_px=5000), ctx, in_mesh_ply=tmp_path / "a.ply",
                       in_clean_mesh_ply=tmp_path / "b.ply", out_textured_mesh_obj=ctx.workdir / "t.obj",
                       out_textured_mesh_ply=ctx.workdir / "t.ply")
    assert not list(ctx.workdir.iterdir())


def test_voxel_size_sets_depth(tmp_path):
    from twinkit.surface.poisson import depth_for_voxel

    pts = np.array([[0, 0, 0], [50, 10, 5]], float)
    assert depth_for_voxel(pts, 0.012, scale=1.1) == 13  # 55 m / 2^13 = 6.7 mm; 2^12 -> 13.4 mm
    assert depth_for_voxel(pts, 0.05, scale=1.1) == 11


def test_evaluate_against_ground_truth_mesh(pipeline, tmp_path):
    import open3d as o3d

    w, _ = pipeline
    box = o3d.geometry.TriangleMesh.create_box(2, 2, 2).translate((-1, -1, 0))
    bv, bf = np.asarray(box.vertices), np.asarray(box.triangles)
    keep = ~(bv[bf][:, :, 2] == 0).all(axis=1)  # no bottom
    gv = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], float)
    gf = np.array([[0, 1, 2], [0, 2, 3]])
    gt = Mesh(np.vstack([gv, bv]), np.vstack([gf, bf[keep] + 4]))
    gt.face_attrs["label"] = np.r_[np.zeros(len(gf)), np.full(int(keep.sum()), 2)].astype(np.uint8)  # road, building
    write_ply(tmp_path / "gt_mesh.ply", gt)
    ctx = make_context(tmp_path / "w")
    P.evaluate(P.EvalParams(gt_samples=50_000), ctx, in_textured_mesh_ply=w / "textured_mesh.ply",
               in_points_ply=w / "points.ply", out_recon_metrics_json=ctx.workdir / "recon_metrics.json",
               in_gt_mesh_ply=tmp_path / "gt_mesh.ply")
    met = json.loads((ctx.workdir / "recon_metrics.json").read_text())
    assert met["gt"]["accuracy_mesh_to_gt_m"]["mean"] < 0.01
    assert met["gt"]["gt_covered_within_5cm"] > 0.9
    pc = met["gt"]["per_class"]
    assert set(pc) == {"road", "building"}
    assert abs(pc["road"]["area_m2"] - 100.0) < 1e-6 and abs(pc["building"]["area_m2"] - 20.0) < 1e-6
    assert pc["road"]["covered"] > 0.9 and pc["building"]["covered"] > 0.9 and pc["road"]["observed"] > 0.9
    assert met["gt"]["accuracy_by_class_mean_m"]["road"] < 0.01
    assert (ctx.workdir / "recon_metrics.png").exists()
