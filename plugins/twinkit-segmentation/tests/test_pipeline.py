"""Rendering, samplers, and the whole chain with the oracle model on a small street made by code."""
import json

import numpy as np
import pytest

from twinkit import InputError
from twinkit.testing import check_plugin, plugin_from_module, run_step

import twinkit_segmentation.plugin as P
from twinkit.mesh import read_mesh
from twinkit_segmentation.segmesh import vertex_labels
from twinkit_segmentation.synthetic import egl_available, street_scene

needs_egl = pytest.mark.skipif(not egl_available(), reason="no headless EGL (Mesa) for moderngl")

CAM = {"width_px": 256, "height_px": 128, "hfov_deg": 75.0}


def _plugin(kind, name):
    return plugin_from_module(P, kind, name)


def test_contracts():
    for kind, name in [("segmenter", "felzenszwalb"), ("segmenter", "vertices"), ("view_sampler", "auto_street"),
                       ("view_sampler", "uniform"), ("view_sampler", "random"), ("view_sampler", "street_points"),
                       ("view_sampler", "combined"), ("image_model", "oracle"), ("step", "sample_views"),
                       ("step", "render_views"), ("step", "photo_views"), ("step", "predict_views"), ("step", "backproject"),
                       ("step", "transfer_gt_labels"), ("step", "evaluate_segmentation"), ("step", "import_labels")]:
        check_plugin(_plugin(kind, name))


@needs_egl
def test_render_vertex_map_matches_ray_casting():
    from twinkit_segmentation.render import Renderer
    from twinkit_segmentation.views import Scene, view_matrices

    v, f, n, _ = street_scene(step=1.0)
    r = Renderer(v, f, None, None, 160, 80)
    view = {"position": [-15, 0, 1.5], "heading_deg": 0.0, "pitch_deg": -5.0, "hfov_deg": 75.0, "width": 160, "height": 80}
    rgb, vid = r.render(*view_matrices(view))
    r.release()
    assert rgb.shape == (80, 160, 3) and vid.shape == (80, 160)
    assert (rgb[vid < 0] == [135, 206, 235]).all()  # sky-blue background
    assert 0.05 < (vid < 0).mean() < 0.8
    # cast the ray through each pixel centre and compare the hit point with the mapped vertex
    scene = Scene(v, f, n)
    vm, pm = view_matrices(view)
    ys, xs = np.mgrid[0:80, 0:160]
    ndc = np.stack([(xs + 0.5) / 160 * 2 - 1, 1 - (ys + 0.5) / 80 * 2], -1).reshape(-1, 2)
    d_cam = np.column_stack([ndc[:, 0] / pm[0, 0], ndc[:, 1] / pm[1, 1], -np.ones(len(ndc))])
    d = d_cam @ vm[:3, :3]  # camera -> world (rotation transpose)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, _ = scene.cast(np.tile(view["position"], (len(d), 1)), d)
    hit = np.isfinite(t) & (vid.reshape(-1) >= 0)
    assert np.mean(np.isfinite(t) == (vid.reshape(-1) >= 0)) > 0.98
    p = np.asarray(view["position"]) + d[hit] * t[hit, None]
    dist = np.linalg.norm(v[vid.reshape(-1)[hit]] - p, axis=1)
    assert np.median(dist) < 0.5 and np.mean(dist < 1.0) > 0.97  # nearest corner of 1 m triangles


def test_samplers(tmp_path):
    from twinkit_segmentation import views as V

    v, f, n, _ = street_scene(step=1.0)
    scene = V.Scene(v, f, n)
    uni = V.build("uniform")(V.UniformParams(spacing_m=10, headings=4))
    uv = uni.sample(scene)
    assert len(uv) == 4 * 2 * 4 and all(abs(x["position"][2] - 2.0) < 1e-6 for x in uv)
    rnd = V.build("random")(V.RandomParams(n_views=7, seed=3)).sample(scene)
    assert len(rnd) == 7 and rnd == V.build("random")(V.RandomParams(n_views=7, seed=3)).sample(scene)
    pts = tmp_path / "street_points.txt"
    pts.write_text("# picked in CloudCompare\n0 0 0\n5.5,1.0,0.0\n\n")
    st = V.build("street_points")(V.StreetPointsParams(points_file=str(pts))).sample(scene)
    assert len(st) == 2 * 3 * 8
    assert sorted({x["position"][2] for x in st}) == [1.5, 3.0, 4.5]
    assert sorted({x["heading_deg"] for x in st})[:3] == [0.0, 45.0, 90.0]
    (tmp_path / "bad.txt").write_text("1 2\n")
    with pytest.raises(InputError, match="bad.txt"):
        V.build("street_points")(V.StreetPointsParams(points_file=str(tmp_path / "bad.txt"))).sample(scene)
    auto = V.build("auto_street")(V.AutoStreetParams(spacing_m=5.0))
    cand, source = auto.candidates(scene)
    assert source == "ground" and len(cand) > 5
    assert (np.abs(cand[:, 2]) < 1e-3).all()  # on the ground, never on a roof or a car
    assert (np.abs(cand[:, 1]) < 9.0).all()  # in the street between the buildings
    comb = V.build("combined")(V.CombinedParams(use=["uniform", "random"], uniform=V.UniformParams(spacing_m=10, headings=4),
                                                random=V.RandomParams(n_views=5)))
    assert len(comb.sample(scene)) == 32 + 5


def test_auto_street_from_osm_roads(tmp_path):
    from pyproj import Transformer

    from twinkit_segmentation import views as V

    site = {"crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365}}
    tr = Transformer.from_crs("EPSG:3067", "EPSG:4326", always_xy=True)
    bx, by = Transformer.from_crs("EPSG:4326", "EPSG:3067", always_xy=True).transform(24.93365, 60.16945)
    (lon1, lat1), (lon2, lat2) = tr.transform(bx - 18, by + 1), tr.transform(bx + 18, by + 1)
    osm = tmp_path / "roads.osm"
    osm.write_text(f"""<osm version="0.6"><node id="1" lat="{lat1}" lon="{lon1}"/><node id="2" lat="{lat2}" lon="{lon2}"/>
<way id="3"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/></way></osm>""")
    v, f, n, _ = street_scene(step=1.0)
    scene = V.Scene(v, f, n, site=site, roads_osm=osm)
    cand, source = V.build("auto_street")(V.AutoStreetParams(spacing_m=6.0)).candidates(scene)
    assert source == "roads" and len(cand) >= 4
    assert np.allclose(cand[:, 1], 1.0, atol=0.05)  # on the road's centre line


def _labelled_ply(path, v, f, vlab=None, flab=None):
    from plyfile import PlyData, PlyElement

    vert = np.empty(len(v), [("x", "f4"), ("y", "f4"), ("z", "f4")] + ([("label", "u1")] if vlab is not None else []))
    vert["x"], vert["y"], vert["z"] = np.asarray(v).T
    if vlab is not None:
        vert["label"] = vlab
    face = np.empty(len(f), [("vertex_indices", "i4", (3,))] + ([("label", "u1")] if flab is not None else []))
    face["vertex_indices"] = f
    if flab is not None:
        face["label"] = flab
    PlyData([PlyElement.describe(vert, "vertex"), PlyElement.describe(face, "face")]).write(str(path))
    return path


def test_transfer_gt_labels_rules(tmp_path):
    """face: the nearest face's label; vertex: its corner's nearest the closest point; the mesh itself under
    the vertex rule returns its own labels; farther than max_distance_m: 255."""
    from twinkit_segmentation.params import TransferGtParams

    xs, ys = np.meshgrid(np.arange(5.0), np.arange(5.0))
    v = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(25)])
    q = [(i * 5 + j, i * 5 + j + 1, i * 5 + j + 5, i * 5 + j + 6) for i in range(4) for j in range(4)]
    f = np.array([t for a, b, c, d in q for t in ((a, b, d), (a, d, c))])
    rng = np.random.default_rng(0)
    vlab = rng.choice([0, 1, 2, 8], len(v)).astype(np.uint8)
    flab = np.full(len(f), 13, np.uint8)
    gt = _labelled_ply(tmp_path / "gt_mesh.ply", v, f, vlab, flab)
    step = _plugin("step", "transfer_gt_labels")

    def run(mesh, rule, name, truth=gt):
        out = run_step(step, tmp_path / name, {"in_gt_mesh_ply": truth, "in_textured_mesh_ply": mesh},
                       TransferGtParams(rule=rule))
        return np.load(out["gt_labels.npy"])

    same = run(gt, "vertex", "same")
    assert same.dtype == np.uint8 and same.tolist() == vlab.tolist()
    assert (run(gt, "face", "same_face") == 13).all()
    moved = v + [0.1, 0.2, 0.3]
    moved[0, 2] = 2.0  # farther than max_distance_m (0.5)
    mesh = _labelled_ply(tmp_path / "textured_mesh.ply", moved, f)
    got = run(mesh, "vertex", "moved")
    assert got[0] == 255 and got[1:].tolist() == vlab[1:].tolist()  # nearest corner: the vertex it moved from
    got = run(mesh, "face", "moved_face")
    assert got[0] == 255 and (got[1:] == 13).all()
    with pytest.raises(InputError, match="rule=face"):
        run(gt, "vertex", "nolab", truth=_labelled_ply(tmp_path / "face_only.ply", v, f, None, flab))


@needs_egl
def test_oracle_chain_end_to_end(scene_files, tmp_path):
    mesh_ply, gt_ply, vlab = scene_files
    out = {}
    gt = run_step(_plugin("step", "transfer_gt_labels"), tmp_path / "gt",
                  {"in_gt_mesh_ply": gt_ply, "in_textured_mesh_ply": mesh_ply})
    assert (np.load(gt["gt_labels.npy"]) == vlab).mean() > 0.9  # ties where parts touch (box bottoms on the ground)
    gt = {"gt_labels.npy": tmp_path / "gt_labels.npy"}  # score against the exact per-vertex labels
    np.save(gt["gt_labels.npy"], vlab)
    seg = run_step(_plugin("segmenter", "felzenszwalb"), tmp_path / "seg", {"in_textured_mesh_ply": mesh_ply})
    assert np.load(seg["segments.npy"]).shape == (len(vlab),)
    cfg = {"view_sampler": dict(CAM, plugin="auto_street", spacing_m=6.0, heights_m=[1.5, 4.5], headings=8),
           "image_model": {"plugin": "oracle"}}
    views = run_step(_plugin("step", "sample_views"), tmp_path / "views", {"in_textured_mesh_ply": mesh_ply}, config=cfg)
    vj = json.loads(views["views.json"].read_text())
    assert len(vj["views"]) >= 32 and vj["counts"] == {"auto_street": len(vj["views"])}
    ren = run_step(_plugin("step", "render_views"), tmp_path / "ren",
                   {"in_textured_mesh_ply": mesh_ply, "in_views_json": views["views.json"]})
    index = json.loads((ren["renders"] / "index.json").read_text())
    assert index["kept"] and len(index["kept"]) + len(index["dropped"]) == len(vj["views"])
    first = index["kept"][0]["id"]
    assert (ren["renders"] / f"{first}.png").is_file() and (ren["renders"] / f"{first}_vertex.npz").is_file()
    pred = run_step(_plugin("step", "predict_views"), tmp_path / "pred",
                    {"in_renders_dir": ren["renders"], "in_gt_labels_npy": gt["gt_labels.npy"]}, config=cfg)
    from PIL import Image

    im = Image.open(pred["predictions"] / f"{first}.png")
    assert im.mode == "P" and im.size == (256, 128)
    votes = np.load(pred["vertex_votes.npy"])
    seen_by = np.zeros(len(vlab))
    for v in index["kept"]:
        u = np.unique(np.load(ren["renders"] / f"{v['id']}_vertex.npz")["vertex"])
        seen_by[u[u >= 0]] += 1
    known = vlab < 19
    assert np.allclose(votes.sum(axis=1)[known], seen_by[known], atol=1e-3)  # one vote per view that sees the vertex
    assert seen_by.max() > 1
    bp = run_step(_plugin("step", "backproject"), tmp_path / "bp",
                  {"in_textured_mesh_ply": mesh_ply, "in_segments_npy": seg["segments.npy"],
                   "in_vertex_votes_npy": pred["vertex_votes.npy"]})
    labels = np.load(bp["labels.npy"])
    assert labels.dtype == np.uint8 and labels.shape == vlab.shape
    assert vertex_labels(read_mesh(bp["labels.ply"])).tolist() == labels.tolist()
    ev = run_step(_plugin("step", "evaluate_segmentation"), tmp_path / "ev",
                  {"in_labels_npy": bp["labels.npy"], "in_gt_labels_npy": gt["gt_labels.npy"],
                   "in_segments_npy": seg["segments.npy"]})
    res = json.loads(ev["seg_metrics.json"].read_text())
    assert res["upper_bound"]["miou"] > 99.0
    assert res["scores"]["miou"] >= 95.0, ev["seg_metrics.md"].read_text()
    out["labels"] = bp
    # without ground truth the oracle refuses, naming the fix
    with pytest.raises(InputError, match="gt_labels"):
        run_step(_plugin("step", "predict_views"), tmp_path / "pred2", {"in_renders_dir": ren["renders"]}, config=cfg)


def test_manual_correction_round_trip(scene_files, tmp_path):
    from plyfile import PlyData

    mesh_ply, _, vlab = scene_files
    mesh = read_mesh(mesh_ply)
    from twinkit.cityscapes import PALETTE
    from twinkit_segmentation.segmesh import write_labels_ply

    labels_npy = tmp_path / "labels.npy"
    np.save(labels_npy, vlab)
    painted = tmp_path / "painted" / "labels.ply"
    painted.parent.mkdir()
    write_labels_ply(painted, mesh, vlab)
    ply = PlyData.read(str(painted), mmap=False)
    vert = ply["vertex"].data
    idx = np.nonzero(vlab == 0)[0][:25]  # repaint 25 road vertices as sidewalk (slightly off-palette)
    vert["red"][idx], vert["green"][idx], vert["blue"][idx] = PALETTE[1] - [3, 0, 2]
    ply.write(str(painted))
    out = run_step(_plugin("step", "import_labels"), tmp_path / "imp",
                   {"in_labels_ply": painted, "in_labels_npy": labels_npy, "in_textured_mesh_ply": mesh_ply})
    new = np.load(out["labels.npy"])
    assert (new != vlab).sum() == 25 and (new[idx] == 1).all()
    changes = json.loads(out["label_changes.json"].read_text())
    assert changes == {"changed": 25, "transitions": {"road -> sidewalk": 25}}
    # a PLY with a vertex removed, or reordered, is refused
    from twinkit.cityscapes import colorize
    from twinkit.mesh import write_colored_ply

    bad = tmp_path / "bad" / "labels.ply"
    bad.parent.mkdir()
    write_colored_ply(bad, mesh.vertices[:-1], mesh.faces[:10], colorize(vlab[:-1]))
    with pytest.raises(InputError, match="vertices"):
        run_step(_plugin("step", "import_labels"), tmp_path / "imp2",
                 {"in_labels_ply": bad, "in_labels_npy": labels_npy, "in_textured_mesh_ply": mesh_ply})
    perm = np.random.default_rng(0).permutation(len(vlab))
    write_colored_ply(bad, mesh.vertices[perm], mesh.faces[:10], colorize(vlab[perm]))
    with pytest.raises(InputError, match="order"):
        run_step(_plugin("step", "import_labels"), tmp_path / "imp3",
                 {"in_labels_ply": bad, "in_labels_npy": labels_npy, "in_textured_mesh_ply": mesh_ply})


def test_below_horizon_follows_the_camera_pitch():
    from twinkit_segmentation.render import below_horizon
    from twinkit_segmentation.views import view_matrices

    level = {"position": [0, 0, 1.5], "heading_deg": 30.0, "pitch_deg": 0.0, "hfov_deg": 75.0, "width": 64, "height": 32}
    b = below_horizon(*view_matrices(level), 64, 32)
    assert not b[:16].any() and b[16:].all()  # a level camera: the horizon is the middle row
    down = dict(level, pitch_deg=-10.0)
    b = below_horizon(*view_matrices(down), 64, 32)
    assert 0 < np.argmax(b[:, 32]) < 16  # pitched down: the horizon moves up
    assert b[:, 0].sum() == b[:, 63].sum()  # no roll


def _ground_with_hole(hole: float, extent: float = 30.0, step: float = 0.5):
    """A flat, 1 m-grid street floor from -extent/2..extent/2 with a square hole of side ``hole`` at (6, 0)."""
    xs = np.arange(-extent / 2, extent / 2 + step / 2, step)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    v = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    n = len(xs)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            cx, cy = xs[i] + step / 2, xs[j] + step / 2
            if abs(cx - 6.0) < hole / 2 and abs(cy) < hole / 2:
                continue
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [[a, b, c], [a, c, d]]
    return v, np.asarray(faces)


@needs_egl
def test_holes_in_the_ground_are_filled_but_cast_no_vote():
    from twinkit_segmentation.render import Renderer, below_horizon, fill_from_nearest, ground_holes
    from twinkit_segmentation.views import view_matrices

    v, f = _ground_with_hole(1.0)
    r = Renderer(v, f, None, None, 160, 80)
    view = {"position": [0, 0, 1.5], "heading_deg": 0.0, "pitch_deg": -12.0, "hfov_deg": 75.0, "width": 160, "height": 80}
    vm, pm = view_matrices(view)
    rgb, vid = r.render(vm, pm)
    r.release()
    sky = np.all(rgb == [135, 206, 235], axis=2)
    below = below_horizon(vm, pm, 160, 80)
    holes = ground_holes(vid >= 0, below, 8)
    floor_rows = np.arange(80)[:, None] >= np.argmax((vid >= 0).any(axis=1))  # the floor's far edge and nearer
    assert (sky & below & floor_rows).sum() > 10  # the hole shows the sky colour below the horizon
    assert holes[sky & below & floor_rows].all()
    n = fill_from_nearest(rgb, holes, vid >= 0)
    assert n == holes.sum()
    assert not np.all(rgb == [135, 206, 235], axis=2)[holes].any()  # painted with the floor's grey
    assert (vid[holes] < 0).all()  # and still no vertex: no vote comes from a filled pixel
    # the world past the floor's far edge is a wide gap: left as background, not smeared
    far = sky & below & ~floor_rows
    assert far.sum() > 100 and not holes[far].any()


@needs_egl
def test_render_views_step_fills_holes_by_default(tmp_path):
    from PIL import Image

    from twinkit.mesh import Mesh, write_ply
    from twinkit_segmentation.steps import RenderParams

    v, f = _ground_with_hole(1.0)
    mesh_path = tmp_path / "m.ply"
    write_ply(mesh_path, Mesh(v, f))
    view = {"id": "v0", "sampler": "test", "position": [0, 0, 1.5], "heading_deg": 0.0, "pitch_deg": -12.0,
            "hfov_deg": 75.0, "width": 160, "height": 80}
    (tmp_path / "views.json").write_text(json.dumps({"views": [view]}))
    sky_low = {}
    for fill in (True, False):
        out = run_step(_plugin("step", "render_views"), tmp_path / f"r{fill}",
                       {"in_textured_mesh_ply": mesh_path, "in_views_json": tmp_path / "views.json"},
                       params=RenderParams(fill_holes=fill, max_empty_fraction=0.9))
        index = json.loads((out["renders"] / "index.json").read_text())
        assert index["kept"][0]["hole_fraction"] > 0  # counted either way
        rgb = np.asarray(Image.open(out["renders"] / "v0.png").convert("RGB"))
        sky_low[fill] = int(np.all(rgb[32:] == [135, 206, 235], axis=2).sum())  # the hole (the floor: rows 32-79)
    assert sky_low[False] > 10 and sky_low[True] == 0
