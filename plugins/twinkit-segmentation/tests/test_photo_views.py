"""The capture's photos as segmentation views (step photo_views, twinkit_segmentation.photoviews)."""
import json

import numpy as np
import pytest
from PIL import Image

from twinkit import InputError
from twinkit.testing import check_plugin, plugin_from_module, run_step

import twinkit_segmentation.plugin as P
import twinkit_segmentation.steps as S
from twinkit_segmentation.photoviews import (PhotoCamera, camera_parameters, distort, photo_view_image,
                                             projection_from_K, view_matrix_opencv)
from twinkit_segmentation.synthetic import egl_available, street_scene

needs_egl = pytest.mark.skipif(not egl_available(), reason="no headless EGL (Mesa) for moderngl")


def _plugin(kind, name):
    return plugin_from_module(P, kind, name)


def _opencv_pose(position, heading_deg, pitch_deg):
    """World-from-camera rotation (OpenCV: x right, y down, z forward) of a heading / pitch view."""
    h, p = np.radians(heading_deg), np.radians(pitch_deg)
    f = np.array([np.cos(h) * np.cos(p), np.sin(h) * np.cos(p), np.sin(p)])
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return np.column_stack([r, -u, f]), np.asarray(position, float)


def _camera_json(name, R_wc, C, K, w, h, model="PINHOLE", params=None):
    if params is None:
        params = [K[0][0], K[1][1], K[0][2], K[1][2]]
    return {"image": name, "model": model, "width": w, "height": h, "params": list(map(float, params)),
            "K": np.asarray(K).tolist(), "R_world_from_camera": np.asarray(R_wc).tolist(), "center": list(C)}


def test_contract():
    check_plugin(_plugin("step", "photo_views"))


@needs_egl
def test_photo_pose_vertex_map_matches_the_rendered_view():
    """The vertex map from a photo's OpenCV pose and K is the one render_views draws for the same camera, and
    with an off-centre principal point and fx != fy each pixel still maps to the vertex its ray hits."""
    from twinkit_segmentation.render import Renderer
    from twinkit_segmentation.views import Scene, view_matrices

    v, f, n, _ = street_scene(step=1.0)
    w, h = 160, 80
    view = {"position": [-15, 0, 1.5], "heading_deg": 10.0, "pitch_deg": -5.0, "hfov_deg": 75.0, "width": w,
            "height": h}
    fpx = (w / 2) / np.tan(np.radians(75.0) / 2)
    K = np.array([[fpx, 0, w / 2], [0, fpx, h / 2], [0, 0, 1.0]])
    R_wc, C = _opencv_pose(view["position"], view["heading_deg"], view["pitch_deg"])
    r = Renderer(v, f, None, None, w, h)
    try:
        _, vid_view = r.render(*view_matrices(view))
        _, vid_photo = r.render(view_matrix_opencv(R_wc, C), projection_from_K(K, w, h))
        assert 0.05 < (vid_view < 0).mean() < 0.8
        assert (vid_photo == vid_view).mean() > 0.995
        # a camera with another principal point and aspect: check against ray casting through pixel centres
        K2 = np.array([[fpx * 1.1, 0, w * 0.42], [0, fpx * 0.9, h * 0.6], [0, 0, 1.0]])
        _, vid2 = r.render(view_matrix_opencv(R_wc, C), projection_from_K(K2, w, h))
    finally:
        r.release()
    ys, xs = np.mgrid[0:h, 0:w]
    d_cam = np.column_stack([((xs + 0.5 - K2[0, 2]) / K2[0, 0]).ravel(), ((ys + 0.5 - K2[1, 2]) / K2[1, 1]).ravel(),
                             np.ones(w * h)])
    d = d_cam @ R_wc.T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, _ = Scene(v, f, n).cast(np.tile(C, (len(d), 1)), d)
    hit = np.isfinite(t) & (vid2.reshape(-1) >= 0)
    assert np.mean(np.isfinite(t) == (vid2.reshape(-1) >= 0)) > 0.98
    dist = np.linalg.norm(v[vid2.reshape(-1)[hit]] - (C + d[hit] * t[hit, None]), axis=1)
    assert np.median(dist) < 0.5 and np.mean(dist < 1.0) > 0.97  # nearest corner of 1 m triangles


def _pattern(w, h):
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    img = np.stack([127 + 100 * np.sin(xs / 7.0), 127 + 100 * np.sin(ys / 5.0), 127 + 100 * np.sin((xs + ys) / 11.0)],
                   -1)
    return img.round().astype(np.uint8)


def test_distorted_photo_is_resampled_onto_its_pinhole(tmp_path):
    """A photo taken through SIMPLE_RADIAL distortion comes back as the pinhole image the vertex map assumes."""
    from scipy.ndimage import map_coordinates

    w, h = 240, 180
    p = camera_parameters("SIMPLE_RADIAL", [200.0, 118.0, 92.0, -0.15])
    pin = _pattern(w, h)  # what a pinhole camera with K would see
    # the distorted photo: each of its pixels shows the pinhole pixel whose ray distorts onto it
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    xd, yd = (xs + 0.5 - p["cx"]) / p["fx"], (ys + 0.5 - p["cy"]) / p["fy"]
    x, y = xd.copy(), yd.copy()
    for _ in range(30):  # invert the distortion by fixed-point iteration
        dx, dy = distort(p, x, y)
        x, y = x + (xd - dx), y + (yd - dy)
    src_u, src_v = x * p["fx"] + p["cx"] - 0.5, y * p["fy"] + p["cy"] - 0.5
    photo = np.stack([map_coordinates(pin[..., c].astype(float), [src_v, src_u], order=1, mode="nearest")
                      for c in range(3)], -1).round().astype(np.uint8)
    Image.fromarray(photo).save(tmp_path / "d.png")
    cam = PhotoCamera.from_json(_camera_json("d.png", np.eye(3), [0, 0, 0], [[200, 0, 118], [0, 200, 92], [0, 0, 1]],
                                             w, h, model="SIMPLE_RADIAL", params=[200.0, 118.0, 92.0, -0.15]))
    img, K, valid, undist = photo_view_image(tmp_path / "d.png", cam, 0)
    assert undist and valid is not None and img.shape == (h, w, 3)
    inner = np.zeros((h, w), bool)
    inner[20:-20, 20:-20] = True
    err = np.abs(img.astype(float) - pin)[inner & valid].mean()
    raw = np.abs(photo.astype(float) - pin)[inner].mean()
    assert err < 4.0 and raw > 4 * err, (err, raw)
    assert not valid.all() or valid.mean() > 0.9  # barrel distortion: the corners may fall outside the photo
    # downscaled to a long side of 120 px: the same image at half size
    img2, K2, valid2, _ = photo_view_image(tmp_path / "d.png", cam, 120)
    assert img2.shape == (90, 120, 3) and np.allclose(K2[0, 0], 100.0)
    half = np.asarray(Image.fromarray(pin).resize((120, 90), Image.LANCZOS)).astype(float)
    assert np.abs(img2.astype(float) - half)[10:-10, 10:-10].mean() < 8.0
    # a distortion that moves no pixel by a quarter pixel (what SfM refines for an undistorted camera) is
    # not resampled: the view is the plain downscaled photo
    Image.fromarray(pin).save(tmp_path / "p.png")
    cam0 = PhotoCamera.from_json(_camera_json("p.png", np.eye(3), [0, 0, 0], [[200, 0, 118], [0, 200, 92], [0, 0, 1]],
                                              w, h, model="SIMPLE_RADIAL", params=[200.0, 118.0, 92.0, -0.0002]))
    img0, _, valid0, undist0 = photo_view_image(tmp_path / "p.png", cam0, 0)
    assert not undist0 and valid0 is None and (img0 == pin).all()
    with pytest.raises(ValueError, match="not supported"):
        camera_parameters("OPENCV_FISHEYE", [1, 1, 0, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="takes 4 parameters"):
        camera_parameters("SIMPLE_RADIAL", [1, 2, 3])


def _photo_site(tmp_path, mesh_ply, cams):
    """Photos rendered from the textured scene at the given poses + cameras_site.json."""
    from twinkit.mesh import read_mesh
    from twinkit_segmentation.render import Renderer, load_texture

    mesh = read_mesh(mesh_ply)
    tex = load_texture(mesh.texture)
    photos = tmp_path / "photos"
    photos.mkdir()
    rows = []
    w, h = 320, 240
    fpx = 200.0
    K = np.array([[fpx, 0, w / 2], [0, fpx, h / 2], [0, 0, 1.0]])
    r = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, w, h)
    try:
        for name, (pos, heading, pitch) in cams.items():
            R_wc, C = _opencv_pose(pos, heading, pitch)
            rgb, _ = r.render(view_matrix_opencv(R_wc, C), projection_from_K(K, w, h))
            Image.fromarray(rgb).save(photos / name)
            rows.append(_camera_json(name, R_wc, C, K, w, h))
    finally:
        r.release()
    cj = tmp_path / "cameras_site.json"
    cj.write_text(json.dumps({"cameras": rows}))
    return photos, cj


@needs_egl
def test_photo_views_step_drops_photos_that_miss_the_mesh(scene_files, tmp_path):
    mesh_ply, gt_ply, vlab = scene_files
    cams = {"a.png": ([-15, 0, 1.6], 0.0, -5.0), "b.png": ([15, 2, 1.6], 180.0, -8.0),
            "away.png": ([0, 0, 30.0], 0.0, 80.0),  # 30 m up, looking at the sky
            "out.png": ([-60, 0, 1.6], 180.0, 0.0)}  # outside the street, looking away from it
    photos, cj = _photo_site(tmp_path, mesh_ply, cams)
    res = run_step(_plugin("step", "photo_views"), tmp_path / "pv",
                   {"in_textured_mesh_ply": mesh_ply, "in_cameras_site_json": cj, "in_photos_dir": photos},
                   params=S.PhotoViewsParams(long_side_px=160))
    index = json.loads((res["renders"] / "index.json").read_text())
    assert [v["image"] for v in index["kept"]] == ["a.png", "b.png"]
    assert sorted(d["image"] for d in index["dropped"]) == ["away.png", "out.png"]
    assert all(d["reason"] == "off_mesh" for d in index["dropped"])
    v0 = index["kept"][0]
    assert (v0["width"], v0["height"]) == (160, 120) and v0["sampler"] == "photo"
    img = np.asarray(Image.open(res["renders"] / f"{v0['id']}.png"))
    vm = np.load(res["renders"] / f"{v0['id']}_vertex.npz")["vertex"]
    assert img.shape == (120, 160, 3) and vm.shape == (120, 160)
    # the image is the photo (downscaled), not a rendering: sky where the photo shows sky
    photo = np.asarray(Image.open(photos / "a.png").resize((160, 120), Image.LANCZOS)).astype(float)
    assert np.abs(img.astype(float) - photo).mean() < 1.0
    # the oracle through the photo views: the whole chain labels what the photos see
    gt = tmp_path / "gt_labels.npy"
    np.save(gt, vlab)
    pred = run_step(_plugin("step", "predict_views"), tmp_path / "pred",
                    {"in_renders_dir": res["renders"], "in_gt_labels_npy": gt}, config={"image_model": {"plugin": "oracle"}})
    votes = np.load(pred["vertex_votes.npy"])
    seen = votes.sum(axis=1) > 0
    assert seen.mean() > 0.1
    assert (votes[seen].argmax(axis=1) == vlab[seen]).mean() > 0.99


@needs_egl
def test_photo_views_both_sources_share_one_folder_and_predict_in_size_batches(scene_files, tmp_path):
    """source=both: the photos and the sampled views (another image size) in one renders/; predict_views
    batches them by size."""
    mesh_ply, gt_ply, vlab = scene_files
    photos, cj = _photo_site(tmp_path, mesh_ply, {"a.png": ([-15, 0, 1.6], 0.0, -5.0)})
    cfg = {"view_sampler": {"plugin": "auto_street", "width_px": 128, "height_px": 64, "hfov_deg": 75.0,
                            "spacing_m": 12.0, "heights_m": [1.5], "headings": 4},
           "image_model": {"plugin": "oracle"}}
    views = run_step(_plugin("step", "sample_views"), tmp_path / "views", {"in_textured_mesh_ply": mesh_ply}, config=cfg)
    res = run_step(_plugin("step", "photo_views"), tmp_path / "pv",
                   {"in_textured_mesh_ply": mesh_ply, "in_cameras_site_json": cj, "in_photos_dir": photos,
                    "in_views_json": views["views.json"]}, params=S.PhotoViewsParams(source="both", long_side_px=160))
    index = json.loads((res["renders"] / "index.json").read_text())
    samplers = {v["sampler"] for v in index["kept"]}
    assert samplers == {"photo", "auto_street"}
    gt = tmp_path / "gt_labels.npy"
    np.save(gt, vlab)
    pred = run_step(_plugin("step", "predict_views"), tmp_path / "pred",
                    {"in_renders_dir": res["renders"], "in_gt_labels_npy": gt}, config=cfg,
                    params=S.PredictParams(batch_views=8))
    assert json.loads((pred["predictions"] / "index.json").read_text())["views"] == [v["id"] for v in index["kept"]]
    # rendered only needs no photos, and samples its own views when no views.json is wired: the same views
    res2 = run_step(_plugin("step", "photo_views"), tmp_path / "pv2", {"in_textured_mesh_ply": mesh_ply},
                    params=S.PhotoViewsParams(source="rendered"), config=cfg)
    idx2 = json.loads((res2["renders"] / "index.json").read_text())
    assert [v["id"] for v in idx2["kept"]] == [v["id"] for v in index["kept"] if v["sampler"] == "auto_street"]
    assert (res2["renders"] / "views.json").is_file()
    with pytest.raises(InputError, match="cameras_site.json"):
        run_step(_plugin("step", "photo_views"), tmp_path / "pv3", {"in_textured_mesh_ply": mesh_ply})
    # every photo misses the mesh: a clear error naming the best photo's coverage, not an empty folder
    with pytest.raises(InputError, match="the best photo, a.png, sees it in"):
        run_step(_plugin("step", "photo_views"), tmp_path / "pv5",
                 {"in_textured_mesh_ply": mesh_ply, "in_cameras_site_json": cj, "in_photos_dir": photos},
                 params=S.PhotoViewsParams(min_coverage=0.99))
    # a photo the cameras file names but the folder lacks: the error names the file
    (photos / "a.png").unlink()
    with pytest.raises(InputError, match="a.png"):
        run_step(_plugin("step", "photo_views"), tmp_path / "pv4",
                 {"in_textured_mesh_ply": mesh_ply, "in_cameras_site_json": cj, "in_photos_dir": photos})
