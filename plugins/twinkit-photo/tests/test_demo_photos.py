"""The demo site's photos end to end through sfm and georeference: every photo registers, and the GCP route
puts every camera centre within 5 cm of the truth (issue target). Then the dense step's GPU route
(COLMAP patch-match) with everything real but the CUDA call: a stand-in writes the depth and normal maps
that patch-match would, in COLMAP's format, from the true surface. About four minutes on two cores: make bench
runs it (bench/bench_slow_tests.py), make test skips it. The fast tests of the same steps: the GCP route on a
synthetic model (test_steps.py), the dense step on a walked street (test_patchmatch.py)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from twinkit.testing import bench_check, need_plugin, plugin_from_module, run_step, shared_plugin_run

import twinkit_photo.plugin as photo

SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def _demo_site(folder):
    """The small demo site (the twinkit-demo-site package's generator, through the registry); its folder."""
    need_plugin("site_generator", "demo_intersection")
    out = shared_plugin_run("site_generator", "demo_intersection", folder, site=dict(SITE), size="small", seed=0)
    return out["site.json"].parent


def _patch_match_stand_in(gt_mesh_ply):
    """Does what pycolmap.patch_match_stereo does, for a workspace written by undistort_images: one
    geometric depth map and normal map per image, in COLMAP's binary format; here from the true mesh."""
    import open3d as o3d
    import pycolmap

    from twinkit_photo.mvs import write_colmap_array

    gt = o3d.io.read_triangle_mesh(str(gt_mesh_ply))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(gt))

    def run(workspace_path, options=None, **_):
        ws = Path(workspace_path)
        rec = pycolmap.Reconstruction(str(ws / "sparse"))
        for d in ("depth_maps", "normal_maps"):
            (ws / "stereo" / d).mkdir(parents=True, exist_ok=True)
        for iid in rec.reg_image_ids():
            im = rec.images[iid]
            cam = rec.cameras[im.camera_id]
            cfw = im.cam_from_world() if callable(getattr(im, "cam_from_world", None)) else im.cam_from_world
            R_cw, t_cw = np.asarray(cfw.rotation.matrix()), np.asarray(cfw.translation)
            C = -R_cw.T @ t_cw
            K = np.asarray(cam.calibration_matrix())
            w, h = int(cam.width), int(cam.height)
            u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
            dc = np.c_[(u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1], np.ones(u.size)]
            dw = dc @ R_cw  # R_cw.T @ dc per row
            n = np.linalg.norm(dw, axis=1, keepdims=True)
            rays = np.c_[np.broadcast_to(C, dw.shape), dw / n].astype(np.float32)
            ans = scene.cast_rays(o3d.core.Tensor(rays))
            t = ans["t_hit"].numpy()
            depth = np.where(np.isfinite(t) & (t < 40), t / n[:, 0], 0.0).reshape(h, w)  # z along the optical axis
            nw = ans["primitive_normals"].numpy()
            nc = nw @ R_cw.T
            nc[(nc[:, 2] > 0)] *= -1  # facing the camera
            nc[depth.ravel() == 0] = 0
            write_colmap_array(ws / "stereo" / "depth_maps" / f"{im.name}.geometric.bin", depth)
            write_colmap_array(ws / "stereo" / "normal_maps" / f"{im.name}.geometric.bin", nc.reshape(h, w, 3))

    return run


@bench_check()
def test_demo_photos_register_and_georeference_within_5cm(tmp_path, monkeypatch):
    site = _demo_site(tmp_path / "site")
    s = run_step(plugin_from_module(photo, "step", "sfm"), tmp_path / "sfm",
                 {"in_photos_dir": site / "photos", "in_cameras_json": site / "cameras.json"}, photo.SfmParams())
    rep = json.loads(s["sfm_report.json"].read_text())
    assert rep["registered"] == rep["photos"] == 40
    assert rep["mean_reprojection_error_px"] < 1.0
    g = run_step(plugin_from_module(photo, "step", "georeference"), tmp_path / "geo",
                 {"in_sfm_dir": s["sfm"], "in_gcp_json": site / "gcp.json", "in_cameras_json": site / "cameras.json"},
                 photo.GeorefParams(), site=dict(SITE))
    geo = json.loads(g["georef.json"].read_text())
    assert geo["method"] == "gcp" and geo["gcp"]["used"] >= 8
    err = geo["camera_centre_error_m"]
    assert err["n"] == 40 and err["max"] < 0.05 and err["mean"] < 0.03
    # the cameras file the dense step reads agrees with the truth too (not only the report)
    truth = {c["image"]: np.array(c["center"]) for c in json.loads((site / "cameras.json").read_text())["cameras"]}
    cams = json.loads(g["cameras_site.json"].read_text())["cameras"]
    d = [np.linalg.norm(np.array(c["center"]) - truth[c["image"]]) for c in cams]
    assert max(d) < 0.05

    # ---- dense, GPU route: the real model transform, undistortion and COLMAP fusion around a stand-in
    import pycolmap

    roi = run_step(plugin_from_module(photo, "step", "roi"), tmp_path / "roi",
                   {"in_cameras_site_json": g["cameras_site.json"], "in_sparse_site_ply": g["sparse_site.ply"]},
                   photo.RoiParams())
    monkeypatch.setattr(pycolmap, "has_cuda", True, raising=False)
    monkeypatch.setattr(pycolmap, "patch_match_stereo", _patch_match_stand_in(site / "gt_mesh.ply"))
    dres = run_step(plugin_from_module(photo, "step", "dense"), tmp_path / "dense",
                    {"in_photos_dir": site / "photos", "in_cameras_site_json": g["cameras_site.json"],
                     "in_sparse_site_ply": g["sparse_site.ply"], "in_roi_json": roi["roi.json"],
                     "in_sfm_dir": s["sfm"], "in_georef_json": g["georef.json"]},
                    photo.DenseParams(max_image_px=320, voxel_m=0.05))
    meta = json.loads(dres["points_meta.json"].read_text())
    assert meta["dense"]["backend"] == "patchmatch" and meta["dense"]["depth_maps"] == 40
    import open3d as o3d
    from twinkit.mesh import read_ply

    P = read_ply(dres["points.ply"]).vertices.astype(np.float32)
    assert len(P) > 5000
    gt = o3d.t.geometry.RaycastingScene()
    gt.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(o3d.io.read_triangle_mesh(str(site / "gt_mesh.ply"))))
    dist = gt.compute_distance(o3d.core.Tensor(P)).numpy()
    # exact depth maps: what remains is the georeferenced poses' error (about 1 cm) -- so the model was moved
    # into the site frame correctly, and the fused points came back in it
    assert np.median(dist) < 0.03
