"""Photo folders, EXIF, georeferencing maths and the plane-sweep stereo on synthetic data."""
from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from twinkit import InputError
from twinkit_photo import dense as D
from twinkit.geo.similarity import closed_form_similarity
from twinkit_photo.georef import Transform, level, robust_umeyama, rotation_between, triangulate
from twinkit_photo.images import list_images, read_info


def _rat(x, den=10000):
    return (int(round(x * den)), den)


def _dms(deg):
    d = int(deg)
    m = int((deg - d) * 60)
    s = ((deg - d) * 60 - m) * 60
    return ((d, 1), (m, 1), _rat(s))


def _jpeg(path, lat=None, lon=None, alt=None, size=(64, 48)):
    import piexif

    exif = {"0th": {}, "Exif": {piexif.ExifIFD.FocalLengthIn35mmFilm: 28}, "GPS": {}}
    if lat is not None:
        exif["GPS"] = {1: b"S" if lat < 0 else b"N", 2: _dms(abs(lat)), 3: b"W" if lon < 0 else b"E",
                       4: _dms(abs(lon)), 5: 0, 6: _rat(alt or 0.0, 100)}
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(
        path, exif=piexif.dump(exif))


def test_exif_gps_and_focal(tmp_path):
    _jpeg(tmp_path / "a.jpg", 60.16945, -24.93365, 12.5)
    info = read_info(tmp_path / "a.jpg")
    assert info.has_gps
    assert info.lat == pytest.approx(60.16945, abs=1e-7)
    assert info.lon == pytest.approx(-24.93365, abs=1e-7)  # west is negative
    assert info.alt == pytest.approx(12.5)
    assert info.focal_35mm == 28


def test_no_gps_is_a_note_not_an_error(tmp_path):
    _jpeg(tmp_path / "b.jpg")
    info = read_info(tmp_path / "b.jpg")
    assert not info.has_gps and info.width == 64


def test_corrupt_jpeg_names_the_file(tmp_path):
    _jpeg(tmp_path / "good.jpg")
    data = (tmp_path / "good.jpg").read_bytes()
    (tmp_path / "broken.jpg").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="broken.jpg"):
        read_info(tmp_path / "broken.jpg")


def test_empty_or_missing_folder(tmp_path):
    with pytest.raises(InputError, match="no photos"):
        list_images(tmp_path)
    with pytest.raises(InputError, match="not a folder"):
        list_images(tmp_path / "nope")
    from twinkit import artefacts as A

    A.write_no_photos(tmp_path / "none", "No photo walk: add site.photos=true.")
    with pytest.raises(InputError, match="no photos .*add site.photos=true"):
        list_images(tmp_path / "none")


def _rand_rot(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_umeyama_recovers_similarity():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    T = Transform(2.5, _rand_rot(rng), np.array([10.0, -3.0, 1.0]))
    est = closed_form_similarity(src, T.apply(src))
    assert est.scale == pytest.approx(2.5, rel=1e-9)
    np.testing.assert_allclose(est.R, T.R, atol=1e-9)
    np.testing.assert_allclose(est.apply(src), T.apply(src), atol=1e-9)


def test_robust_umeyama_leaves_out_a_misclicked_gcp():
    rng = np.random.default_rng(3)
    T = Transform(1.7, rotation_between([0, 0, 1.0], [0.3, -0.2, 0.9]), np.array([4.0, -1.0, 2.0]))
    src = rng.uniform(-10, 10, (10, 3))
    dst = T.apply(src) + rng.normal(0, 0.005, (10, 3))
    dst[4] += [0.4, 0.0, 0.0]  # one point clicked on the wrong corner
    plain = closed_form_similarity(src, dst)
    est, keep = robust_umeyama(src, dst, outlier_m=0.05)
    assert keep.sum() == 9 and not keep[4]
    err_plain = np.abs(plain.apply(src[keep]) - dst[keep]).max()
    err_robust = np.abs(est.apply(src[keep]) - dst[keep]).max()
    assert err_robust < 0.02 < err_plain
    # clean data: nothing is left out
    _, keep2 = robust_umeyama(src, T.apply(src), outlier_m=0.05)
    assert keep2.all()


def test_level_finds_up_from_ground_and_cameras():
    rng = np.random.default_rng(2)
    ground = np.c_[rng.uniform(-10, 10, 400), rng.uniform(-10, 10, 400), rng.normal(0, 0.005, 400)]
    walls = np.c_[rng.uniform(-10, 10, 200), np.full(200, 6.0), rng.uniform(0, 8, 200)]
    C = np.c_[np.linspace(-5, 5, 8), np.zeros(8), np.full(8, 1.6)]
    # cameras look along +y, level: camera y (down) = world -z
    R_wc = np.array([[[1, 0, 0], [0, 0, 1], [0, -1, 0]]] * 8, float)
    Rm = _rand_rot(rng)  # an arbitrary model frame
    pts_m = np.vstack([ground, walls]) @ Rm.T
    R_lvl, info = level(C @ Rm.T, Rm @ R_wc, pts_m)
    assert info["up_from"] == "ground_plane"
    up = R_lvl @ (Rm @ np.array([0, 0, 1.0]))
    assert up[2] > math.cos(math.radians(0.5))


def test_rotation_between_handles_opposite():
    R = rotation_between([0, 0, -1.0], [0, 0, 1.0])
    np.testing.assert_allclose(R @ [0, 0, -1.0], [0, 0, 1.0], atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_triangulate_gcp_from_pixels():
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    X = np.array([1.0, 2.0, 10.0])
    rows, obs = {}, []
    for k, cx in enumerate((-1.0, 0.0, 1.5)):
        C = np.array([cx, 0.0, 0.0])
        R_wc = np.eye(3)
        p = K @ (R_wc.T @ (X - C))
        rows[f"{k}.jpg"] = {"K": K.tolist(), "width": 640, "height": 480, "R_world_from_camera": R_wc.tolist(),
                            "center": C.tolist()}
        obs.append({"image": f"{k}.jpg", "pixel": [p[0] / p[2], p[1] / p[2]]})
    est, n = triangulate(rows, obs)
    assert n == 3
    np.testing.assert_allclose(est, X, atol=1e-6)
    est2, n2 = triangulate(rows, obs[:1] + [{"image": "unregistered.jpg", "pixel": [0, 0]}])
    assert est2 is None and n2 == 1


def _render_plane_views(tex, K, centres, depth):
    """Images of a textured fronto-parallel plane at z = depth seen from cameras at ``centres`` looking +z."""
    import cv2

    h, w = 240, 320
    views = []
    # texture covers x, y in [-s, s] at z = depth
    s = 6.0
    T = np.array([[tex.shape[1] / (2 * s), 0, tex.shape[1] / 2], [0, tex.shape[0] / (2 * s), tex.shape[0] / 2],
                  [0, 0, 1]])
    for C in centres:
        # pixel -> plane point: X = C + depth * K^-1 x  (cameras axis-aligned)
        A = np.linalg.inv(K)
        M = T @ np.array([[depth * A[0, 0], 0, depth * A[0, 2] + C[0]], [0, depth * A[1, 1], depth * A[1, 2] + C[1]],
                          [0, 0, 1]])
        img = cv2.warpPerspective(tex, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        views.append(D.View(name=f"{len(views)}", K=K.copy(), R_wc=np.eye(3), C=np.asarray(C, float),
                            gray=img.astype(np.float32) / 255.0, rgb=np.dstack([img] * 3)))
    return views


def test_plane_sweep_recovers_a_textured_plane():
    import cv2

    rng = np.random.default_rng(3)
    tex = cv2.GaussianBlur(rng.integers(0, 255, (600, 600)).astype(np.uint8), (0, 0), 1.5)
    tex = cv2.normalize(tex, None, 0, 255, cv2.NORM_MINMAX)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    depth = 8.0
    views = _render_plane_views(tex, K, [(0, 0, 0), (0.6, 0, 0), (-0.5, 0.2, 0)], depth)
    for v in views:
        v.dmin, v.dmax = 3.0, 30.0
    opt = D.DenseOptions(coarse_scale=0.5, planes=128, up=(0.0, -1.0, 0.0), min_consistent=1)
    for i, v in enumerate(views):
        v.depth, score = D.plane_sweep(v, [w for j, w in enumerate(views) if j != i], opt)
    d = views[0].depth
    inner = d[40:-40, 60:-60]
    assert (inner > 0).mean() > 0.5
    assert np.median(np.abs(inner[inner > 0] - depth)) / depth < 0.01
    xyz, rgb, nrm, src = D.fuse(views, opt)
    assert len(xyz) > 1000
    assert np.median(np.abs(xyz[:, 2] - depth)) < 0.05
    # normals of a plane facing the cameras point back at them (-z)
    assert np.median(nrm[:, 2]) < -0.9


def test_reads_opensfm_gcp_file_of_berlin():
    from conftest import shared_photos
    from twinkit.geo import SiteFrame

    from twinkit_photo.georef import read_gcp_file

    folder = shared_photos("berlin_gcp")
    frame = SiteFrame.from_site({"name": "berlin", "crs": "EPSG:25833",
                                 "base_point": {"lat": 52.5192, "lon": 13.4007, "alt": 0.0}})
    gcps = read_gcp_file(folder / "ground_control_points.json", frame)
    assert len(gcps) >= 2  # points without a position are skipped
    for g in gcps:
        assert np.linalg.norm(g["site_xyz"][:2]) < 100  # metres from the base point, not degrees
        assert all("normalized" in o and o["image"].endswith(".jpg") for o in g["observations"])


def test_bad_gcp_file_names_the_file(tmp_path):
    from twinkit_photo.georef import read_gcp_file

    (tmp_path / "gcp.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="gcp.json"):
        read_gcp_file(tmp_path / "gcp.json", None)


def test_a_thin_dense_cloud_makes_the_run_degraded(tmp_path):
    """Lund's CPU sweep: 4,280 points from 29 photos (a 5 m² mesh) is degraded; the demo's 397,798 from 40 is not."""
    from twinkit.testing import make_context

    import twinkit_photo.plugin as photo
    from twinkit_photo.dense_cloud import dense_gate

    thin = make_context(tmp_path / "thin", step_id="dense")
    dense_gate(thin.degraded, 4280, 29, photo.DenseParams(), "cpu")
    (entry,) = thin.degraded_reasons
    assert "4,280 points from 29 photos (148 per photo" in entry["reason"] and "patchmatch" in entry["hint"]
    fine = make_context(tmp_path / "fine", step_id="dense")
    dense_gate(fine.degraded, 397_798, 40, photo.DenseParams(), "cpu")
    assert fine.degraded_reasons == []


def test_vertical_lines_correct_photos_that_all_look_up():
    """A facade photographed from the street, every photo pitched up 10 degrees (and rolled a little): the mean
    of the cameras' up axes is 10 degrees off, the vertical edges in the photos give the vertical within
    0.5 degree; horizontal edges (window sills) and a few slanted ones do not pull it."""
    import cv2

    from twinkit_photo.georef import camera_horizon, vertical_from_lines

    def rot(axis, deg):
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
        return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
                "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]

    import tempfile
    from pathlib import Path

    rng = np.random.default_rng(4)
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    base = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)
    edges = [((x, 10.0, 0.0), (x, 10.0, 9.0)) for x in np.arange(-12, 12.1, 1.5)]            # vertical
    edges += [((-12, 10.0, z), (12, 10.0, z)) for z in (2.0, 4.5, 7.0)]                       # sills
    edges += [((-8, 10.0, 0.0), (-5, 10.0, 6.0)), ((6, 10.0, 1.0), (7.5, 10.0, 8.0))]         # slanted
    cams = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, cx in enumerate(np.linspace(-6, 6, 6)):
            R = base @ rot("x", 10.0) @ rot("z", rng.normal(0, 1.5))
            C = np.array([cx, 0.0, 1.6])
            img = np.zeros((480, 640), np.uint8)
            for a, b in edges:
                pa, pb = (K @ (R.T @ (np.asarray(p, float) - C)) for p in (a, b))
                cv2.line(img, tuple(int(round(v)) for v in pa[:2] / pa[2]), tuple(int(round(v)) for v in pb[:2] / pb[2]),
                         255, 2, cv2.LINE_AA)
            name = f"{k}.png"
            cv2.imwrite(str(Path(tmp) / name), img)
            cams.append({"image": name, "width": 640, "height": 480, "K": K.tolist(), "model": "PINHOLE",
                         "params": [800, 800, 320, 240], "R_world_from_camera": R.tolist(), "center": C.tolist()})
        up_cam, _ = camera_horizon(np.array([c["R_world_from_camera"] for c in cams]))
        v, info = vertical_from_lines(Path(tmp), cams, up_cam, min_lines=10)
    assert math.degrees(math.acos(up_cam[2])) > 9.0  # the photos' horizon: off by the pitch
    assert v is not None, info
    assert math.degrees(math.acos(min(1.0, v[2]))) < 0.5, info
    assert info["photos_with_lines"] == 6


def test_level_takes_the_vertical_lines_over_the_photos_horizon_within_30_degrees():
    C = np.c_[np.linspace(-5, 5, 8), np.zeros(8), np.full(8, 1.6)]
    a = math.radians(11.0)  # every photo pitched up 11 degrees (Sceaux)
    R_up = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    R_wc = np.array([np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float) @ R_up] * 8)
    info_lines = {"lines": 300, "photos_with_lines": 8, "std_error_deg": 0.1}
    R_lvl, info = level(C, R_wc, np.zeros((0, 3)), vertical=(np.array([0, 0, 1.0]), info_lines))
    assert info["up_from"] == "vertical_lines" and (R_lvl @ [0, 0, 1.0])[2] > math.cos(math.radians(0.01))
    assert info["final_vs_camera_horizon"]["total_deg"] == pytest.approx(11.0, abs=0.01)
    # lines 40 degrees from the photos' horizon are not trusted
    far = np.array([0, math.sin(math.radians(51)), math.cos(math.radians(51))])
    _, info = level(C, R_wc, np.zeros((0, 3)), vertical=(far, info_lines))
    assert info["up_from"] == "camera_horizon"


def test_fusion_tolerance_follows_the_sfm_reprojection_error(tmp_path):
    from twinkit_photo.dense_cloud import fusion_tolerance

    rep = tmp_path / "sfm_report.json"
    assert fusion_tolerance(0.02, rep) == (0.02, "given")  # a given tolerance is used as it is
    assert fusion_tolerance(-1, None)[0] == pytest.approx(0.003)  # nothing known: the demo's tolerance
    rep.write_text('{"mean_reprojection_error_px": 0.30}')
    assert fusion_tolerance(-1, rep)[0] == pytest.approx(0.003)  # never tighter than 0.3 %
    rep.write_text('{"mean_reprojection_error_px": 0.70}')
    tol, why = fusion_tolerance(-1, rep)
    assert tol == pytest.approx(0.006) and "0.70 px" in why  # twice the pose error: twice the tolerance
    rep.write_text('{"mean_reprojection_error_px": 3.5}')
    assert fusion_tolerance(-1, rep)[0] == pytest.approx(0.01)  # capped
    rep.write_text("{not json")
    assert fusion_tolerance(-1, rep)[0] == pytest.approx(0.003)
