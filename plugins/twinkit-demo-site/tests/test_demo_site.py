"""Tests of the demo site generator (small preset, generated once per session)."""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from twinkit.cityscapes import PERSON
from twinkit.testing import run_plugin

REQUIRED_CLASSES = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 17, 18}


def _all_files(folder: Path) -> dict[str, bytes]:
    """Every file the generator wrote (not the engine's record of the run, step.json, which has its times)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "step.json"}


# ------------------------------------------------------------------ plugin contract
def test_entry_point_registers_site_generator(monkeypatch):
    from twinkit.plugins import load_registry

    monkeypatch.setenv("TWINKIT_PLUGINS", "demo_site")  # only this package's entry point
    reg = load_registry()
    plugin = reg.get("site_generator", "demo_intersection")
    assert plugin.distribution == "twinkit-demo-site"
    from twinkit_demo_site.plugin import DemoSiteParams, generate_demo_site

    assert plugin.run is generate_demo_site and plugin.params is DemoSiteParams
    try:
        from twinkit.testing import check_plugin

        check_plugin(plugin)
    except ImportError as exc:  # the core's signature module may not exist yet
        pytest.skip(f"twinkit.testing.check_plugin not usable yet: {exc}")


def test_unknown_size_is_a_clear_error(tmp_path):
    from twinkit import TwinkitError
    from twinkit.testing import make_context
    from twinkit_demo_site.plugin import DemoSiteParams, generate_demo_site

    from conftest import out_kwargs

    with pytest.raises(TwinkitError, match="unknown size 'huge'"):
        generate_demo_site(DemoSiteParams(size="huge"), make_context(tmp_path), **out_kwargs(tmp_path))


# ------------------------------------------------------------------ determinism
def test_same_seed_gives_byte_identical_files(sparse_twice):
    (da, metrics), (db, _) = sparse_twice
    a, b = _all_files(da), _all_files(db)
    assert sorted(a) == sorted(b)
    assert metrics["photos"] == 3 and len(a) >= 11 + 2 * metrics["photos"]
    differing = [k for k in a if a[k] != b[k]]
    assert not differing, f"files differ between two runs with the same seed: {differing}"


def test_no_photo_walk_leaves_the_scan_and_roads_as_they_were(sparse_twice, tmp_path):
    """photos=false (what the point-cloud recipes ask for): no photo, empty cameras and GCPs, every other
    file byte-identical to the run with photos."""
    from conftest import SITE, SPARSE, _folder_and_metrics

    folder, metrics = _folder_and_metrics(run_plugin("site_generator", "demo_intersection", tmp_path, site=dict(SITE),
                                                     **{**SPARSE, "photos": False}))
    with_photos = _all_files(sparse_twice[0][0])
    without = _all_files(folder)
    assert metrics["photos"] == 0 and [p.name for p in (folder / "photos").iterdir()] == ["NO_PHOTOS.txt"]
    assert json.loads((folder / "cameras.json").read_text())["cameras"] == []
    assert json.loads((folder / "gcp.json").read_text())["points"] == []
    same = [k for k in without if not k.startswith("photos") and k not in ("cameras.json", "gcp.json", "site.json",
                                                                            "step.json")]
    assert len(same) >= 8 and all(without[k] == with_photos[k] for k in same), \
        [k for k in same if without[k] != with_photos[k]]


def test_other_seed_gives_another_site():
    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(0)
    m0 = build_scene(30.0, 0, atlas).mesh
    m1 = build_scene(30.0, 1, atlas).mesh
    assert len(m0.faces) != len(m1.faces) or not np.array_equal(m0.vertices, m1.vertices)


# ------------------------------------------------------------------ mesh
def test_gt_mesh_obj_and_ply_agree(demo, gt):
    folder = demo[0]
    obj = (folder / "gt_mesh.obj").read_text().splitlines()
    assert "mtllib gt_mesh.mtl" in obj
    mtl = (folder / "gt_mesh.mtl").read_text()
    assert "map_Kd gt_mesh.png" in mtl
    from PIL import Image

    assert Image.open(folder / "gt_mesh.png").size == (2048, 2048)
    v = np.array([[float(t) for t in ln.split()[1:4]] for ln in obj if ln.startswith("v ")])
    f = np.array([[int(t.split("/")[0]) - 1 for t in ln.split()[1:4]] for ln in obj if ln.startswith("f ")])
    assert len(v) == len(gt["v"]) and len(f) == len(gt["f"])
    assert np.abs(v - gt["v"]).max() < 1e-4
    assert np.array_equal(f, gt["f"])
    # every group name carries the trainId of its faces
    groups = [ln.split()[1] for ln in obj if ln.startswith("g ")]
    assert {int(g.rsplit("_", 1)[1]) for g in groups} == set(np.unique(gt["face_label"]).tolist())


def test_mesh_has_every_class_and_consistent_labels(gt):
    assert REQUIRED_CLASSES <= set(np.unique(gt["face_label"]).tolist())
    # per-vertex label equals the label of every face using it
    for k in range(3):
        assert np.array_equal(gt["vertex_label"][gt["f"][:, k]], gt["face_label"])


def test_mesh_is_textured_not_flat(gt):
    """Each big class shows texture: vertex colours sampled from the atlas vary within the class."""
    for lab in (0, 1, 2, 8, 9):
        rgb = gt["vertex_rgb"][gt["vertex_label"] == lab].astype(float)
        assert rgb.std(0).mean() > 4.0, f"class {lab} looks flat"


def test_curb_height_between_10_and_15_cm(gt, site):
    road = gt["v"][gt["f"][gt["face_label"] == 0].ravel()]
    walk = gt["v"][gt["f"][gt["face_label"] == 1].ravel()]
    assert abs(np.median(road[:, 2])) < 1e-6
    h = np.median(walk[:, 2])
    assert 0.10 <= h <= 0.15


# ------------------------------------------------------------------ point cloud
def test_every_point_label_is_its_nearest_face_label(cloud, gt):
    import open3d as o3d

    surf = cloud["label"] != PERSON
    ans = gt["scene"].compute_closest_points(o3d.core.Tensor(cloud["xyz"][surf].astype(np.float32)))
    near = gt["face_label"][ans["primitive_ids"].numpy()]
    bad = np.count_nonzero(near != cloud["label"][surf])
    assert bad == 0, f"{bad} points carry a label other than their nearest face's"


def test_intensity_is_the_materials_reflectance_not_the_colour(demo, cloud):
    # a lidar sees asphalt darker than paving and grass brighter than both, whatever their colours (the demo's
    # grass is the darkest of the three in the photos)
    import laspy

    from twinkit.cityscapes import ROAD, SIDEWALK, TERRAIN

    inten = np.asarray(laspy.read(demo[0] / "cloud.las").intensity)  # the LAS has the PLY's points in order
    med = {c: np.median(inten[cloud["label"] == c]) for c in (ROAD, SIDEWALK, TERRAIN)}
    assert med[ROAD] < 0.8 * med[SIDEWALK] < 0.8 * med[TERRAIN], med
    lum = {c: cloud["rgb"][cloud["label"] == c].mean() for c in (SIDEWALK, TERRAIN)}
    assert lum[TERRAIN] < lum[SIDEWALK], lum


def test_range_noise_is_a_few_millimetres(cloud, gt):
    import open3d as o3d

    surf = cloud["label"] != PERSON
    d = gt["scene"].compute_distance(o3d.core.Tensor(cloud["xyz"][surf].astype(np.float32))).numpy()
    assert d.max() < 0.012  # 3 sigma of 3 mm, plus float32 rounding
    rms = float(np.sqrt(np.mean(d ** 2)))
    assert 0.0015 < rms < 0.005, rms


def test_pedestrian_ghost_points_float_in_free_space(cloud, gt, site):
    import open3d as o3d

    ghost = cloud["label"] == PERSON
    assert 20 <= ghost.sum() < 0.01 * len(ghost)
    d = gt["scene"].compute_distance(o3d.core.Tensor(cloud["xyz"][ghost].astype(np.float32))).numpy()
    assert np.median(d) > 0.3
    assert site["counts"]["ghost_points"] == int(ghost.sum())


def test_no_point_inside_solids(cloud, site):
    xyz = cloud["xyz"]
    for s in site["solids"]:
        lo, hi = np.array(s["min"]) + 0.01, np.array(s["max"]) - 0.01
        inside = np.all((xyz > lo) & (xyz < hi), axis=1)
        assert not inside.any(), f"{inside.sum()} points inside solid {s}"


def test_normals_are_unit_and_face_their_scanner(cloud, demo):
    n = cloud["normals"]
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-3)
    sc = json.loads((demo[0] / "scanners.json").read_text())
    pos = np.array(sc["positions"])[cloud["scanner"]]
    to_scanner = pos - cloud["xyz"]
    assert np.all(np.einsum("ij,ij->i", n, to_scanner) > 0)


def test_density_falls_off_with_distance(cloud, demo):
    from scipy.spatial import cKDTree

    sc = json.loads((demo[0] / "scanners.json").read_text())
    pos = np.array(sc["positions"])[cloud["scanner"]]
    ground = (cloud["label"] == 0) | (cloud["label"] == 1)
    xyz = cloud["xyz"][ground]
    r = np.linalg.norm(xyz[:, :2] - pos[ground][:, :2], axis=1)
    d, _ = cKDTree(xyz).query(xyz, k=2)
    spacing = d[:, 1]
    near, far = np.median(spacing[r < 5]), np.median(spacing[(r > 15) & (r < 30)])
    assert far > 1.5 * near, (near, far)


def test_point_count_near_preset_target(demo):
    assert 200_000 <= demo[1]["points"] <= 450_000


def test_e57_las_ply_open_with_same_points(demo, cloud, site):
    import laspy
    import pye57
    from pye57 import libe57

    folder = demo[0]
    n = len(cloud["xyz"])
    e0, n0, z0 = (site["base_point_projected"][k] for k in "xyz")
    # LAS: projected coordinates with CRS, same order and labels as the PLY
    las = laspy.read(folder / "cloud.las")
    assert las.header.point_count == n
    assert las.header.parse_crs().to_epsg() == 3067
    assert np.allclose(las.header.scales, 0.001)
    assert np.abs(np.asarray(las.x) - e0 - cloud["xyz"][:, 0]).max() < 0.002
    assert np.abs(np.asarray(las.y) - n0 - cloud["xyz"][:, 1]).max() < 0.002
    assert np.abs(np.asarray(las.z) - z0 - cloud["xyz"][:, 2]).max() < 0.002
    assert np.array_equal(np.asarray(las.label), cloud["label"])
    assert np.asarray(las.red).max() > 255  # 16-bit colour
    # E57: float64 projected coordinates, colour, normals in the nor: extension
    e57 = pye57.E57(str(folder / "cloud.e57"))
    assert e57.scan_count == 1
    data = e57.read_scan_raw(0, ignore_unsupported_fields=True)
    assert len(data["cartesianX"]) == n
    assert np.abs(data["cartesianX"] - e0 - cloud["xyz"][:, 0]).max() < 1e-4
    assert np.abs(data["cartesianY"] - n0 - cloud["xyz"][:, 1]).max() < 1e-4
    assert np.array_equal(data["colorRed"], cloud["rgb"][:, 0])
    assert "ETRS89 / TM35FIN" in e57.root["coordinateMetadata"].value()
    imf = e57.image_file
    pts = e57.data3d[0]["points"]
    nx = np.empty(n, "f")
    bufs = libe57.VectorSourceDestBuffer()
    bufs.append(libe57.SourceDestBuffer(imf, "nor:normalX", nx, n, True, True))
    reader = pts.reader(bufs)
    assert reader.read() == n
    reader.close()
    assert np.allclose(nx, cloud["normals"][:, 0], atol=1e-6)


# ------------------------------------------------------------------ roads
def _osm(folder):
    root = ET.parse(folder / "roads.osm").getroot()
    nodes = {int(n.get("id")): (float(n.get("lon")), float(n.get("lat")), {t.get("k"): t.get("v") for t in n.findall("tag")})
             for n in root.findall("node")}
    ways = [([int(r.get("ref")) for r in w.findall("nd")], {t.get("k"): t.get("v") for t in w.findall("tag")})
            for w in root.findall("way")]
    return nodes, ways


def _to_local(lonlat, site):
    from pyproj import Transformer

    t = Transformer.from_crs("EPSG:4326", site["crs"], always_xy=True)
    e, n = t.transform(lonlat[:, 0], lonlat[:, 1])
    return np.stack([np.asarray(e) - site["base_point_projected"]["x"], np.asarray(n) - site["base_point_projected"]["y"]], 1)


def _undo(xy, tf):
    a = math.radians(tf["rotation_deg"])
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return (xy - [tf["dx_m"], tf["dy_m"]]) @ R


def _labels_below(gt, xy):
    """Label of the ground-truth face nearest to (x, y, 0) (road level), for (n, 2) site-frame points."""
    import open3d as o3d

    p = np.zeros((len(xy), 3), np.float32)
    p[:, :2] = xy
    ans = gt["scene"].compute_closest_points(o3d.core.Tensor(p))
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    dist = np.linalg.norm(ans["points"].numpy() - p, axis=1)
    lab = gt["face_label"][prim].astype(int)
    lab[dist > 0.01] = 255  # no surface at road level here
    return lab


def _sample_ways(nodes, ways, site, step=0.5):
    out = []
    for refs, _tags in ways:
        ll = np.array([nodes[r][:2] for r in refs])
        xy = _to_local(ll, site)
        for a, b in zip(xy[:-1], xy[1:]):
            k = max(2, int(np.linalg.norm(b - a) / step))
            t = np.linspace(0, 1, k)[:, None]
            out.append(a + (b - a) * t)
    return np.concatenate(out)


def test_osm_tags(demo):
    nodes, ways = _osm(demo[0])
    assert len(ways) >= 3
    for refs, tags in ways:
        assert {"highway", "lanes", "oneway", "sidewalk"} <= set(tags), tags
        assert all(r in nodes for r in refs)
    assert any(t.get("oneway") == "yes" for _, t in ways)
    node_tags = [t for *_, t in nodes.values()]
    assert sum(t.get("highway") == "traffic_signals" for t in node_tags) == 1
    assert sum(t.get("highway") == "crossing" for t in node_tags) == 4


def test_osm_centre_lines_lie_on_road_after_undoing_the_shift(demo, gt, site):
    nodes, ways = _osm(demo[0])
    tf = site["osm_transform"]
    xy = _sample_ways(nodes, ways, site)
    H = site["bounds_local"]["max"][0]
    true = _undo(xy, tf)
    inside = np.all(np.abs(true) < H - 0.5, axis=1)
    lab = _labels_below(gt, true[inside])
    assert inside.sum() > 100
    assert np.all(lab == 0), f"{np.count_nonzero(lab != 0)} centre-line samples off the road"
    # the shift is real: raw OSM is displaced by the recorded amount
    shift = np.linalg.norm(xy - true, axis=1)
    assert np.median(shift) > 1.0
    assert abs(math.hypot(tf["dx_m"], tf["dy_m"]) - 3.5) < 1e-3


def test_roads_truth_lane_lines_on_road(demo, gt, site):
    truth = json.loads((demo[0] / "roads_truth.json").read_text())
    assert len(truth["lanes"]) >= 8
    H = site["bounds_local"]["max"][0]
    pts = []
    for lane in truth["lanes"]:
        p = np.array(lane["points"])[:, :2]
        t = np.linspace(0.01, 0.99, 200)[:, None]
        pts.append(p[0] + (p[1] - p[0]) * t)
    pts = np.concatenate(pts)
    pts = pts[np.all(np.abs(pts) < H - 0.5, axis=1)]
    assert np.all(_labels_below(gt, pts) == 0)


# ------------------------------------------------------------------ photos
def test_photos_exif_gps_reads_back(demo, site):
    import piexif
    from PIL import Image

    folder = demo[0]
    cams = json.loads((folder / "cameras.json").read_text())
    assert "OpenCV" in cams["convention"] and "world-from-camera" in cams["convention"]
    assert len(cams["cameras"]) == demo[1]["photos"] == 40
    errs = []
    for cam in cams["cameras"]:
        img = Image.open(folder / "photos" / cam["image"])
        assert img.size == (cams["intrinsics"]["width"], cams["intrinsics"]["height"])
        ex = piexif.load(img.info["exif"])
        gps = ex["GPS"]

        def deg(v, ref):
            d = sum(a / b / 60 ** i for i, (a, b) in enumerate(v))
            return -d if ref in (b"S", b"W") else d

        lat = deg(gps[piexif.GPSIFD.GPSLatitude], gps[piexif.GPSIFD.GPSLatitudeRef])
        lon = deg(gps[piexif.GPSIFD.GPSLongitude], gps[piexif.GPSIFD.GPSLongitudeRef])
        alt = gps[piexif.GPSIFD.GPSAltitude][0] / gps[piexif.GPSIFD.GPSAltitude][1]
        assert abs(lat - cam["gps"]["lat"]) < 1e-7 and abs(lon - cam["gps"]["lon"]) < 1e-7
        assert abs(alt - cam["gps"]["alt"]) < 1e-2
        fl = ex["Exif"][piexif.ExifIFD.FocalLength]
        assert abs(fl[0] / fl[1] - cams["intrinsics"]["focal_mm"]) < 1e-3
        xy = _to_local(np.array([[lon, lat]]), site)[0]
        errs.append(np.linalg.norm(xy - np.array(cam["center"][:2])))
    errs = np.array(errs)
    assert 0.3 < np.median(errs) < 8.0  # a few metres of noise, not zero, not wild


def test_camera_poses_and_label_renders(demo):
    from PIL import Image

    folder = demo[0]
    cams = json.loads((folder / "cameras.json").read_text())
    centers = []
    for cam in cams["cameras"]:
        R = np.array(cam["R_world_from_camera"])
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0.99
        assert 1.4 < cam["center"][2] < 2.0
        assert R[2, 1] < 0  # image y (down) points down in the world
        centers.append(cam["center"])
        lab = np.array(Image.open(folder / "photos" / cam["label_image"]))
        assert lab.shape == (768, 1024)
        assert (lab == 255).any() and ((lab == 0) | (lab == 1)).mean() > 0.1  # sky and ground in every view
    c = np.array(centers)
    step = np.linalg.norm(np.diff(c[:, :2], axis=0), axis=1)
    assert step.max() < 5.0  # strong overlap: consecutive photos a few metres apart
    # the heading sweeps smoothly (photogrammetric capture): consecutive views turn by less than the 64 degree
    # field of view, except where the walk turns a street corner
    fwd = np.array([np.array(cam["R_world_from_camera"])[:, 2] for cam in cams["cameras"]])
    turn = np.degrees(np.arccos(np.clip((fwd[1:] * fwd[:-1]).sum(1), -1, 1)))
    assert np.median(turn) < 35.0 and (turn < 60.0).mean() > 0.8


def test_weathering_makes_repeated_texture_unique():
    """Two points with the same atlas UV (one facade tile repeated) differ once weathered, and not without."""
    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.raycast import Tracer
    from twinkit_demo_site.textures import build_atlas
    from twinkit_demo_site.weathering import weathering

    atlas = build_atlas(0)
    scene = build_scene(30.0, 0, atlas)
    prim = np.zeros(2000, np.int64)  # the same face, the same barycentrics ...
    bary = np.random.default_rng(1).uniform(0, 0.5, (2000, 2)).astype(np.float32)
    pts_a = np.random.default_rng(2).uniform(-20, 20, (2000, 3)).astype(np.float32)
    pts_b = pts_a + np.float32([3.7, 0.0, 0.0])  # ... seen at two places 3.7 m apart
    plain = Tracer(scene.mesh, atlas, threads=1)
    assert np.array_equal(plain.albedo(prim, bary, pts_a), plain.albedo(prim, bary, pts_b))
    worn = Tracer(scene.mesh, atlas, threads=1, weathering=0.6, seed=0)
    a, b = worn.albedo(prim, bary, pts_a), worn.albedo(prim, bary, pts_b)
    assert np.abs(a - b).mean() > 0.02
    assert np.allclose(a, worn.albedo(prim, bary, pts_a))  # deterministic
    n = weathering(pts_a.astype(np.float64), 0)
    assert 0.1 < n.std() < 0.3 and np.abs(n).max() <= 1.0
    assert not np.allclose(n, weathering(pts_a.astype(np.float64), 1))  # the site seed changes it


def test_blocked_value_noise_equals_the_corner_sum():
    """value_noise (blocked, hash terms shared between corners) is bit-identical to summing the eight weighted
    lattice hashes directly, across block boundaries and negative coordinates, and continuous in space."""
    from twinkit_demo_site import weathering as W

    rng = np.random.default_rng(5)
    pts = rng.uniform(-50.0, 50.0, (W.BLOCK * 2 + 77, 3))
    for wavelength, salt in ((1.6, 0), (0.025, 0xFFFFFFFF), (0.19, 12345)):
        q = pts / wavelength
        base = np.floor(q)
        f = (q - base).astype(np.float32)
        w = f * f * (np.float32(3.0) - np.float32(2.0) * f)
        i = base.astype(np.int64)
        ref = np.zeros(len(pts), np.float32)
        with np.errstate(over="ignore"):
            for dx in (0, 1):
                for dy in (0, 1):
                    for dz in (0, 1):
                        wgt = ((w[:, 0] if dx else 1 - w[:, 0]) * (w[:, 1] if dy else 1 - w[:, 1])
                               * (w[:, 2] if dz else 1 - w[:, 2]))
                        ref += wgt * W._hash01(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, salt)
        assert np.array_equal(W.value_noise(pts, wavelength, salt), ref)
    step = np.linspace(0.0, 3.0, 3001)[:, None] * np.array([[1.0, 0.3, 0.2]])
    trace = W.value_noise(step, 0.55, 7)
    assert np.abs(np.diff(trace)).max() < 0.05 and trace.std() > 0.1  # smooth, not constant


def test_gcp_file_is_consistent_with_photos_and_mesh(demo, gt):
    """gcp.json: zebra corners that exist in the mesh, surveyed to mm, seen where the true cameras project them."""
    folder = demo[0]
    doc = json.loads((folder / "gcp.json").read_text())
    cams = {c["image"]: c for c in json.loads((folder / "cameras.json").read_text())["cameras"]}
    K = np.array(json.loads((folder / "cameras.json").read_text())["intrinsics"]["K"])
    pts = doc["points"]
    assert len(pts) == 16
    xyz = np.array([p["site_xyz"] for p in pts])
    # each GCP is a mesh vertex (a stripe corner) within survey noise
    d = np.linalg.norm(gt["v"][None, :, :] - xyz[:, None, :], axis=2).min(1)
    assert d.max() < 0.03
    seen = [p for p in pts if len(p["observations"]) >= 2]
    assert len(seen) >= 8
    # triangulating each GCP from its pixels with the true poses lands on its surveyed position
    errs = []
    for p in seen:
        A = []
        for o in p["observations"]:
            c = cams[o["image"]]
            R, C = np.array(c["R_world_from_camera"]), np.array(c["center"])
            P = K @ np.hstack([R.T, (-R.T @ C)[:, None]])
            u, v = o["pixel"]
            A += [u * P[2] - P[0], v * P[2] - P[1]]
        X = np.linalg.svd(np.array(A))[2][-1]
        errs.append(np.linalg.norm(X[:3] / X[3] - np.array(p["site_xyz"])))
    assert np.median(errs) < 0.03
    # and the photo shows a painted corner there: the 9x9 pixels around it hold both paint and asphalt
    from PIL import Image

    o = seen[0]["observations"][0]
    img = np.asarray(Image.open(folder / "photos" / o["image"]).convert("L"), float)
    u, v = (int(round(x - 0.5)) for x in o["pixel"])
    patch = img[v - 4:v + 5, u - 4:u + 5]
    assert patch.max() - patch.min() > 40


def test_site_json_georeference(site):
    from pyproj import Transformer

    assert site["crs"] == "EPSG:3067" and site["preset"] == "small" and site["seed"] == 0
    e, n = Transformer.from_crs("EPSG:4326", site["crs"], always_xy=True).transform(
        site["base_point"]["lon"], site["base_point"]["lat"])
    assert abs(e - site["base_point_projected"]["x"]) < 1e-3 and abs(n - site["base_point_projected"]["y"]) < 1e-3
    assert site["bounds_local"]["min"][:2] == [-30.0, -30.0]
    assert REQUIRED_CLASSES <= set(site["labels_present"])
    assert {"dx_m", "dy_m", "rotation_deg"} <= set(site["osm_transform"])


def test_photos_rendered_two_at_a_time_are_the_same_files(tmp_path):
    """render_photos with threads=2 renders photos side by side but writes them, and draws their GPS noise, in
    order: the JPEGs, label PNGs and cameras are those of one thread."""
    import hashlib

    from twinkit_demo_site.layout import build_scene
    from twinkit_demo_site.photos import render_photos, walk_poses
    from twinkit_demo_site.plugin import site_frame
    from twinkit_demo_site.raycast import Tracer
    from twinkit_demo_site.textures import build_atlas

    atlas = build_atlas(0)
    scene = build_scene(30.0, 0, atlas)
    tracer = Tracer(scene.mesh, atlas, threads=2, weathering=0.6, seed=0)
    poses = walk_poses(scene.walk_path, 5, np.random.default_rng(4))
    geo = site_frame({})
    docs, files = [], []
    for threads in (1, 2):
        out = tmp_path / f"t{threads}"
        docs.append(render_photos(tracer, poses, out, geo, np.random.default_rng(6), width=96, height=64,
                                  focal_px=80.0, gps_noise_m=2.0, supersample=2, threads=threads))
        files.append({p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
                      for p in sorted(out.rglob("*")) if p.is_file()})
    assert docs[0] == docs[1]
    assert files[0] == files[1] and len(files[0]) == 10  # 5 JPEGs and 5 label PNGs
