"""The georeference, roi and dense steps on a synthetic SfM model; bad input gives clear errors."""
from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from twinkit import InputError
from twinkit.testing import plugin_from_module, run_step

import twinkit_photo.plugin as photo
from twinkit_photo.georef import Transform

SITE = {"name": "t", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
K = [[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]]


def _step(name):
    return plugin_from_module(photo, "step", name)


def _truth(n=8):
    """Cameras walking along +x at 1.6 m, looking +y (OpenCV: y down), site frame."""
    R_wc = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)
    C = np.c_[np.linspace(-7, 7, n), np.zeros(n), np.full(n, 1.6)]
    return R_wc, C


def _model_dir(tmp_path, T_model_from_site: Transform, gps=None):
    """An sfm/ folder as the sfm step writes it, for a scene of ground + a facade."""
    R_wc, C = _truth()
    rng = np.random.default_rng(0)
    ground = np.c_[rng.uniform(-12, 12, 600), rng.uniform(0, 10, 600), np.zeros(600)]
    facade = np.c_[rng.uniform(-12, 12, 300), np.full(300, 10.0), rng.uniform(0, 8, 300)]
    pts = np.vstack([ground, facade])
    d = tmp_path / "sfm"
    d.mkdir()
    cams = []
    for k, c in enumerate(C):
        cams.append({"image": f"{k:02d}.jpg", "model": "PINHOLE", "width": 640, "height": 480,
                     "params": [800, 800, 320, 240], "K": K,
                     "R_world_from_camera": (T_model_from_site.R @ R_wc).tolist(),
                     "center": T_model_from_site.apply(c)[0].tolist()})
    doc = {"cameras": cams, "exif_gps": gps or {}}
    (d / "cameras_model.json").write_text(json.dumps(doc))
    np.savez_compressed(d / "sparse.npz", xyz=T_model_from_site.apply(pts), rgb=np.zeros((len(pts), 3), np.uint8),
                        error=np.zeros(len(pts)), vis_image=np.array([], str), vis_point=np.array([], np.int64))
    truth = {"cameras": [{"image": f"{k:02d}.jpg", "center": c.tolist()} for k, c in enumerate(C)]}
    (tmp_path / "cameras.json").write_text(json.dumps(truth))
    return d, pts, C


def _arbitrary():
    a = 0.7
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    b = -1.1
    Rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return Transform(0.37, Rz @ Rx, np.array([3.0, -2.0, 5.0]))


def test_gcp_georeference_recovers_the_site_frame(tmp_path):
    T = _arbitrary()
    sfm_dir, pts, C = _model_dir(tmp_path, T)
    R_wc, _ = _truth()
    # five GCPs on the facade and ground, observed in pixels by the photos that see them
    gcp_pts = [[-3, 10, 2], [0, 10, 4], [4, 10, 1], [-2, 9, 0], [3, 9.5, 0]]
    points = []
    for g, X in enumerate(gcp_pts):
        obs = []
        for k, c in enumerate(C):
            xc = R_wc.T @ (np.array(X, float) - c)
            if xc[2] <= 0:
                continue
            p = np.asarray(K) @ xc
            u, v = p[0] / p[2], p[1] / p[2]
            if 0 <= u < 640 and 0 <= v < 480:
                obs.append({"image": f"{k:02d}.jpg", "pixel": [u, v]})
        points.append({"id": f"g{g}", "site_xyz": X, "observations": obs})
    (tmp_path / "gcp.json").write_text(json.dumps({"points": points}))
    out = run_step(_step("georeference"), tmp_path / "run",
                   {"in_sfm_dir": sfm_dir, "in_gcp_json": tmp_path / "gcp.json", "in_cameras_json": tmp_path / "cameras.json"},
                   photo.GeorefParams(), site=SITE)
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "gcp" and rep["gcp"]["used"] == 5
    assert rep["camera_centre_error_m"]["max"] < 1e-4
    cams = json.loads(out["cameras_site.json"].read_text())["cameras"]
    np.testing.assert_allclose(np.asarray(cams[0]["R_world_from_camera"]), R_wc, atol=1e-6)
    assert "gcp_unused" not in rep
    # a file with one usable point (as ../shared/data/photos/berlin_gcp): auto says why and what it used instead
    (tmp_path / "gcp1.json").write_text(json.dumps({"points": points[:1]}))
    one = run_step(_step("georeference"), tmp_path / "run1", {"in_sfm_dir": sfm_dir, "in_gcp_json": tmp_path / "gcp1.json"},
                   photo.GeorefParams(), site=SITE)
    rep1 = json.loads(one["georef.json"].read_text())
    assert rep1["method"] == "none" and rep1["gcp_unused"]["usable"] == 1
    assert "3 needed" in rep1["gcp_unused"]["why"] and "levelled" in rep1["gcp_unused"]["used_instead"]


def test_gps_georeference_levels_and_scales(tmp_path):
    from twinkit.geo import SiteFrame

    T = _arbitrary()
    _, C = _truth()
    frame = SiteFrame.from_site(SITE)
    rng = np.random.default_rng(5)
    noisy = C[:, :2] + rng.normal(0, 0.3, (len(C), 2))
    ll = frame.local_to_lonlat(noisy)
    gps = {f"{k:02d}.jpg": [float(ll[k, 1]), float(ll[k, 0]), 12.0 + 1.6] for k in range(len(C))}
    sfm_dir, _, _ = _model_dir(tmp_path, T, gps)
    out = run_step(_step("georeference"), tmp_path / "run", {"in_sfm_dir": sfm_dir, "in_cameras_json": tmp_path / "cameras.json"},
                   photo.GeorefParams(), site=SITE)
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "gps" and rep["level"]["up_from"] == "ground_plane"
    assert rep["camera_centre_error_m"]["mean"] < 0.5  # 0.3 m GPS noise, 8 photos
    assert rep["transform"]["scale"] == pytest.approx(1 / 0.37, rel=0.05)


def test_no_gps_falls_back_or_fails_clearly(tmp_path):
    sfm_dir, _, _ = _model_dir(tmp_path, _arbitrary())
    with pytest.raises(InputError, match="EXIF GPS"):
        run_step(_step("georeference"), tmp_path / "a", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(method="gps"),
                 site=SITE)
    out = run_step(_step("georeference"), tmp_path / "b", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(), site=SITE)
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "none"
    cams = json.loads(out["cameras_site.json"].read_text())["cameras"]
    R = np.asarray(cams[0]["R_world_from_camera"])
    assert R[2, 1] == pytest.approx(-1.0, abs=0.02)  # levelled: the camera's y (down) points to -z


def test_roi_and_a_hand_edited_roi(tmp_path):
    sfm_dir, _, _ = _model_dir(tmp_path, Transform(1.0, np.eye(3), np.zeros(3)))
    g = run_step(_step("georeference"), tmp_path / "g", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(method="none"),
                 site=SITE)
    r = run_step(_step("roi"), tmp_path / "r", {"in_cameras_site_json": g["cameras_site.json"],
                                               "in_sparse_site_ply": g["sparse_site.ply"]}, photo.RoiParams())
    doc = json.loads(r["roi.json"].read_text())
    assert doc["ground"]["source"].startswith("RANSAC")
    assert doc["ground"]["z_m"] == pytest.approx(-1.6, abs=0.05)  # centred on the cameras at 1.6 m
    doc["box"]["max"][2] = doc["box"]["min"][2] - 1  # a broken hand edit
    bad = tmp_path / "roi.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="roi.json"):
        run_step(_step("dense"), tmp_path / "d", {"in_photos_dir": tmp_path, "in_cameras_site_json": g["cameras_site.json"],
                                                  "in_sparse_site_ply": g["sparse_site.ply"], "in_roi_json": bad})


def test_sfm_rejects_a_corrupt_photo_by_name(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        Image.fromarray(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)).save(folder / f"{k}.jpg")
    data = (folder / "2.jpg").read_bytes()
    (folder / "2.jpg").write_bytes(data[:200])
    with pytest.raises(InputError, match="2.jpg"):
        run_step(_step("sfm"), tmp_path / "run", {"in_photos_dir": folder})


def test_sfm_unrelated_photos_fail_clearly(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    for k in range(3):
        rng = np.random.default_rng(k)
        Image.fromarray(rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)).save(folder / f"{k}.jpg")
    with pytest.raises(InputError, match="photos"):
        run_step(_step("sfm"), tmp_path / "run", {"in_photos_dir": folder}, photo.SfmParams(max_features=512))


def test_an_outlier_camera_is_flagged_and_left_out(tmp_path):
    """One photo misregistered 70 m off the walk, with its GPS fix on the walk: flagged with both reasons in
    georef.json and absent from cameras_site.json (so from the ROI, dense and photo steps)."""
    from twinkit.geo import SiteFrame

    T = _arbitrary()
    _, C = _truth()
    C = C * [5.0, 1.0, 1.0]  # a 70 m walk, photos 10 m apart (phone GPS errors of metres stay small beside it)
    frame = SiteFrame.from_site(SITE)
    ll = frame.local_to_lonlat(C[:, :2])
    gps = {f"{k:02d}.jpg": [float(ll[k, 1]), float(ll[k, 0]), 12.0 + 1.6] for k in range(len(C))}
    sfm_dir, _, _ = _model_dir(tmp_path, T, gps)
    doc = json.loads((sfm_dir / "cameras_model.json").read_text())
    for k, cam in enumerate(doc["cameras"]):
        cam["center"] = T.apply(C[k])[0].tolist()
    doc["cameras"][5]["center"] = T.apply(C[5] + [0.0, 70.0, 0.0])[0].tolist()  # photo 05 registered 70 m off
    (sfm_dir / "cameras_model.json").write_text(json.dumps(doc))
    out = run_step(_step("georeference"), tmp_path / "run", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(), site=SITE)
    rep = json.loads(out["georef.json"].read_text())
    assert list(rep["outlier_cameras"]) == ["05.jpg"], rep["outlier_cameras"]
    assert "from its own GPS fix" in rep["outlier_cameras"]["05.jpg"]
    assert rep["gps"]["residual_m"]["05.jpg"] > 60 and max(v for k, v in rep["gps"]["residual_m"].items()
                                                          if k != "05.jpg") < 1.0
    names = [c["image"] for c in json.loads(out["cameras_site.json"].read_text())["cameras"]]
    assert "05.jpg" not in names and len(names) == 7
    # the same camera kept when the check is off
    out2 = run_step(_step("georeference"), tmp_path / "run2", {"in_sfm_dir": sfm_dir},
                    photo.GeorefParams(outlier_factor=0), site=SITE)
    assert len(json.loads(out2["cameras_site.json"].read_text())["cameras"]) == 8


def _rot(axis, deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _no_gps_walk(tmp_path, slope_deg=25.0):
    """A hand-held walk along +x (site frame, z up): 20 photos, each turned by a few degrees of roll and pitch
    (as people hold phones), looking at a facade; the sparse cloud is the facade and clutter, plus a sloped bank
    (``slope_deg`` about the walk direction) holding 21 % of the points: the biggest plane within 30 degrees of the
    cameras' up, which the old rule (any plane over 5 % within 30 degrees) took for the ground. Written in an
    arbitrary model frame."""
    rng = np.random.default_rng(11)
    n = 20
    base = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)  # looking +y, level
    R_wc = np.array([base @ _rot("z", rng.normal(0, 3)) @ _rot("x", rng.normal(0, 3)) @ _rot("y", rng.normal(0, 5))
                     for _ in range(n)])
    C = np.c_[np.linspace(-10, 10, n), rng.normal(0, 0.2, n), 1.6 + rng.normal(0, 0.05, n)]
    facade = np.c_[rng.uniform(-15, 15, 500), 8 + rng.normal(0, 0.3, 500), rng.uniform(0, 10, 500)]
    clutter = np.c_[rng.uniform(-15, 15, 420), rng.uniform(1, 8, 420), rng.uniform(-1, 6, 420)]
    u, v = rng.uniform(-15, 15, 250), rng.uniform(0, 6, 250)
    t = np.radians(slope_deg)
    bank = np.c_[u, 1 + v * np.cos(t), -0.5 + v * np.sin(t)]  # rises towards the facade
    pts = np.vstack([facade, clutter, bank])
    Tm = _arbitrary()
    d = tmp_path / "sfm"
    d.mkdir()
    cams = [{"image": f"{k:02d}.jpg", "model": "PINHOLE", "width": 640, "height": 480, "params": [800, 800, 320, 240],
             "K": K, "R_world_from_camera": (Tm.R @ R_wc[k]).tolist(), "center": Tm.apply(C[k])[0].tolist()}
            for k in range(n)]
    (d / "cameras_model.json").write_text(json.dumps({"cameras": cams, "exif_gps": {}}))
    np.savez_compressed(d / "sparse.npz", xyz=Tm.apply(pts), rgb=np.zeros((len(pts), 3), np.uint8),
                        error=np.zeros(len(pts)), vis_image=np.array([], str), vis_point=np.array([], np.int64))
    return d, Tm


def test_a_no_gps_set_is_levelled_by_the_horizon_within_2_degrees(tmp_path):
    """No GPS: the photos' own horizon (robust mean of the cameras' up axes) levels the model; a sloped bank, the
    biggest plane in the cloud, is not taken for the ground (the old rule did and tilted the model by the bank's
    25 degrees). The frame is marked unscaled, and the roi step says so."""
    sfm_dir, Tm = _no_gps_walk(tmp_path)
    out = run_step(_step("georeference"), tmp_path / "run", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(), site={})
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "none"
    R = np.asarray(rep["transform"]["R"])
    up = R @ (Tm.R @ np.array([0, 0, 1.0]))  # the true vertical, in the levelled frame
    tilt = np.degrees(np.arccos(np.clip(up[2], -1, 1)))
    assert tilt < 2.0, (tilt, rep["level"])
    assert rep["level"]["up_from"] == "camera_horizon"
    assert rep["level"]["ground_plane"]["used"] is False
    assert rep["level_vs_camera_horizon_deg"] < 0.01
    # unscaled: stated in georef.json, cameras_site.json and the metrics; the roi step ends degraded
    assert rep["scaled"] is False and "unscaled" in rep["units"]
    cams = json.loads(out["cameras_site.json"].read_text())
    assert cams["scaled"] is False and "unscaled" in cams["frame"]
    from twinkit.testing import make_context

    ctx = make_context(tmp_path / "r", step_id="roi")
    metrics = photo.roi(photo.RoiParams(), ctx, in_cameras_site_json=out["cameras_site.json"],
                        in_sparse_site_ply=out["sparse_site.ply"], out_roi_json=tmp_path / "roi.json")
    assert metrics["scaled"] is False and json.loads((tmp_path / "roi.json").read_text())["scaled"] is False
    (entry,) = ctx.degraded_reasons
    assert "unscaled" in entry["reason"] and "distance_m" in entry["hint"]


def test_the_user_can_give_up_a_known_distance_or_a_transform(tmp_path):
    sfm_dir, Tm = _no_gps_walk(tmp_path)
    up_true = Tm.R @ np.array([0, 0, 1.0])
    # a wrong up from the user wins (they said so), and is reported as theirs
    tilted = _rot("x", 10) @ up_true
    out = run_step(_step("georeference"), tmp_path / "a", {"in_sfm_dir": sfm_dir},
                   photo.GeorefParams(up_model=tilted.tolist()), site={})
    rep = json.loads(out["georef.json"].read_text())
    assert rep["level"]["up_from"] == "user"
    assert rep["level_vs_camera_horizon_deg"] > 5
    # a known distance sets the scale: two camera centres 20 m apart (the truth: model units are 0.37 m... x1/0.37)
    doc = json.loads((sfm_dir / "cameras_model.json").read_text())
    a, b = doc["cameras"][0]["center"], doc["cameras"][-1]["center"]
    d_true = float(np.linalg.norm(np.subtract(a, b)) / 0.37)
    out = run_step(_step("georeference"), tmp_path / "b", {"in_sfm_dir": sfm_dir},
                   photo.GeorefParams(distance_points_model=[*a, *b], distance_m=d_true), site={})
    rep = json.loads(out["georef.json"].read_text())
    assert rep["scaled"] is True and rep["transform"]["scale"] == pytest.approx(1 / 0.37, rel=1e-6)
    assert abs(rep["known_distance"]["error_m"]) < 1e-6
    # a 4x4 transform replaces levelling and fit
    inv = np.eye(4)
    inv[:3, :3] = Tm.R.T / Tm.scale
    inv[:3, 3] = -Tm.R.T @ Tm.t / Tm.scale
    out = run_step(_step("georeference"), tmp_path / "c", {"in_sfm_dir": sfm_dir},
                   photo.GeorefParams(transform_model_to_site=inv.ravel().tolist()), site={})
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "transform" and rep["scaled"] is True
    cams = json.loads(out["cameras_site.json"].read_text())["cameras"]
    assert cams[0]["center"][2] == pytest.approx(1.6, abs=0.2)
    with pytest.raises(InputError, match="16"):
        run_step(_step("georeference"), tmp_path / "d", {"in_sfm_dir": sfm_dir},
                 photo.GeorefParams(transform_model_to_site=[1.0, 0, 0]), site={})
    with pytest.raises(InputError, match="distance_m"):
        run_step(_step("georeference"), tmp_path / "e", {"in_sfm_dir": sfm_dir},
                 photo.GeorefParams(distance_points_model=[0, 0, 0, 1, 1, 1]), site={})


def test_exif_gps_without_a_site_crs_suggests_the_utm_zone(tmp_path):
    from twinkit.geo import SiteFrame

    _, C = _truth()
    ll = SiteFrame.from_site(SITE).local_to_lonlat(C[:, :2])
    gps = {f"{k:02d}.jpg": [float(ll[k, 1]), float(ll[k, 0]), 13.6] for k in range(len(C))}
    sfm_dir, _, _ = _model_dir(tmp_path, _arbitrary(), gps)
    out = run_step(_step("georeference"), tmp_path / "run", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(),
                   site={"name": "nocrs"})
    rep = json.loads(out["georef.json"].read_text())
    assert rep["method"] == "none"
    assert "EPSG:32635" in rep["gps_unused"]["suggestion"]  # Helsinki, 24.9 E: UTM zone 35N
    assert "lat: 60.169" in rep["gps_unused"]["suggestion"]
    with pytest.raises(InputError, match="EPSG:32635"):
        run_step(_step("georeference"), tmp_path / "b", {"in_sfm_dir": sfm_dir}, photo.GeorefParams(method="gps"),
                 site={"name": "nocrs"})
