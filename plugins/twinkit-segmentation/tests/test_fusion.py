"""The fusion of views and geometry by capture kind, the confidence it reports, and the cue gates
(docs/segmentation.md "Fusion", "Cue gates")."""
import json

import numpy as np
import pytest

from twinkit.cityscapes import BUILDING, ROAD, SIDEWALK, VEGETATION
from twinkit.mesh import Mesh, read_mesh, write_ply
from twinkit.testing import plugin_from_module, run_step

import twinkit_segmentation.plugin as P
from twinkit_segmentation.fusion import (SourceWeights, confidence_summary, disagreement, fuse_sources,
                                         load_weights)
from twinkit_segmentation.synthetic import grid

#: a weights file of the two regimes the calibration finds (views lead on coloured captures, geometry on
#: colourless ones); the tests check that backproject picks the regime from the capture
WEIGHTS = {"kinds": {"coloured": {"views": 1.0, "geometry": 0.3, "coverage_views": 2.0},
                     "colourless": {"views": 0.2, "geometry": 1.0, "coverage_views": 2.0}}, "recipe": {"test": True}}


def _backproject(tmp_path, name, inputs, **params):
    from twinkit_segmentation.steps import BackprojectParams

    return run_step(plugin_from_module(P, "step", "backproject"), tmp_path / name, inputs,
                    params=BackprojectParams(**params))


@pytest.fixture(scope="module")
def facade_case(scene_files, tmp_path_factory):
    """The small street; 5 views per vertex voting the truth, except on the buildings, where all say
    vegetation (a grey facade read as a hedge); the geometry says the truth with 0.7. points.ply twice:
    with the scene's colours and without any."""
    tmp = tmp_path_factory.mktemp("fusion")
    mesh_ply, _, vlab = scene_files
    m = read_mesh(mesh_ply)
    v = m.vertices
    votes = np.zeros((len(v), 19), np.float32)
    votes[np.arange(len(v)), np.minimum(vlab, 18)] = 5.0
    facade = vlab == BUILDING
    votes[facade] = 0.0
    votes[facade, VEGETATION] = 5.0
    geom = np.full((len(v), 19), 0.3 / 18, np.float32)
    geom[np.arange(len(v)), np.minimum(vlab, 18)] = 0.7
    np.save(tmp / "votes.npy", votes)
    np.save(tmp / "geometry.npy", geom)
    np.save(tmp / "segments.npy", np.arange(len(v), dtype=np.int32))
    pts = v + np.random.default_rng(0).normal(0, 0.01, v.shape)
    rgb = np.random.default_rng(1).integers(0, 255, (len(v), 3)).astype(np.uint8)
    write_ply(tmp / "coloured.ply", Mesh(vertices=pts, attrs={"colors": rgb}))
    write_ply(tmp / "grey.ply", Mesh(vertices=pts))
    (tmp / "weights.json").write_text(json.dumps(WEIGHTS))
    inputs = {"in_textured_mesh_ply": mesh_ply, "in_segments_npy": tmp / "segments.npy",
              "in_vertex_votes_npy": tmp / "votes.npy"}
    return tmp, inputs, vlab, facade


def test_colourless_capture_takes_the_geometry_on_a_facade(facade_case, tmp_path):
    tmp, inputs, vlab, facade = facade_case
    w = str(tmp / "weights.json")
    grey = dict(inputs, in_points_ply=tmp / "grey.ply")
    alone = np.load(_backproject(tmp_path, "views", grey, fusion_weights=w)["labels.npy"])
    assert (alone[facade] == VEGETATION).mean() > 0.9  # the views alone: the facade is a hedge
    out = _backproject(tmp_path, "grey", dict(grey, in_geometry_votes_npy=tmp / "geometry.npy"), fusion_weights=w)
    labels = np.load(out["labels.npy"])
    assert (labels[facade] == BUILDING).mean() > 0.9
    assert (labels[~facade] == vlab[~facade]).mean() > 0.9  # where both agree nothing moves
    m = json.loads((out["labels.npy"].parent / "step.json").read_text())["metrics"]
    assert m["fusion"]["kind"] == "colourless" and m["fusion"]["weights"]["views"] == 0.2
    assert m["confidence"]["sources_disagree"] == int(facade.sum())
    assert (out["labels.npy"].parent / "confidence.png").stat().st_size > 0


def test_coloured_capture_keeps_unanimous_views(facade_case, tmp_path):
    tmp, inputs, _, facade = facade_case
    out = _backproject(tmp_path, "col", dict(inputs, in_points_ply=tmp / "coloured.ply",
                                             in_geometry_votes_npy=tmp / "geometry.npy"),
                       fusion_weights=str(tmp / "weights.json"))
    labels = np.load(out["labels.npy"])
    assert (labels[facade] == VEGETATION).mean() > 0.9  # five unanimous views on a coloured capture lead
    m = json.loads((out["labels.npy"].parent / "step.json").read_text())["metrics"]
    assert m["fusion"]["kind"] == "coloured"


def test_missing_geometry_rows_fall_back_to_the_views(facade_case, tmp_path):
    tmp, inputs, vlab, facade = facade_case
    grey = dict(inputs, in_points_ply=tmp / "grey.ply")
    w = str(tmp / "weights.json")
    plain = np.load(_backproject(tmp_path, "plain", grey, fusion_weights=w)["labels.npy"])
    np.save(tmp / "geometry_zero.npy", np.zeros((len(vlab), 19), np.float32))
    zero = _backproject(tmp_path, "zero", dict(grey, in_geometry_votes_npy=tmp / "geometry_zero.npy"),
                        fusion_weights=w)
    assert np.array_equal(np.load(zero["labels.npy"]), plain)
    # rows present on half the vertices: the other half keep the views' distribution exactly
    geom = np.load(tmp / "geometry.npy")
    gone = np.arange(len(vlab)) % 2 == 0
    geom[gone] = 0.0
    pv = np.load(tmp / "votes.npy").astype(np.float64)
    q, info = fuse_sources(pv, pv.sum(axis=1), geom, SourceWeights(0.2, 1.0, 2.0))
    assert np.allclose(q[gone], pv[gone] / pv[gone].sum(axis=1, keepdims=True))
    assert info["views_only"] == int(gone.sum()) and info["both"] == int((~gone).sum())
    # and where no view saw a vertex, the geometry decides
    pv[:10] = 0.0
    q, info = fuse_sources(pv, pv.sum(axis=1), np.load(tmp / "geometry.npy"), SourceWeights(1.0, 0.1, 2.0))
    assert (q[:10].argmax(axis=1) == np.minimum(vlab[:10], 18)).all() and info["geometry_only"] == 10


def test_confidence_and_disagreement_on_a_tiny_case():
    pv = np.array([[4, 0, 0], [0, 4, 0], [2, 2, 0], [0, 0, 0], [0, 0, 0]], float)
    pg = np.array([[0.9, 0.1, 0], [0.9, 0.1, 0], [0.5, 0.5, 0], [0, 0.2, 0.8], [0, 0, 0]], float)
    pad = lambda a: np.pad(a, ((0, 0), (0, 16)))  # noqa: E731
    q, info = fuse_sources(pad(pv), pv.sum(axis=1), pad(pg), SourceWeights(1.0, 1.0, 2.0))
    assert info == {"geometry": True, "views_only": 0, "geometry_only": 1, "both": 3, "neither": 1}
    assert np.allclose(q[:4].sum(axis=1), 1.0) and not q[4].any()
    assert q[0].argmax() == 0 and q[0].max() > 0.95  # both say class 0: sure
    assert abs(q[2, 0] - q[2, 1]) < 1e-9  # a tie stays a tie: 0.5
    d = disagreement(pad(pv), pad(pg))
    assert d.tolist() == [False, True, False, False, False]  # (row 2: a tie, argmax 0 both)
    labels = np.array([0, 1, 0, 2, 255], np.uint8)
    conf = q.max(axis=1)
    s = confidence_summary(labels, conf, d, 0.6)
    assert s["sources_disagree"] == 1 and s["low_confidence"] == int(((conf < 0.6) & (labels < 19)).sum()) >= 1


def _ring_road(tmp, noise_m=0.01, ring_offset_m=0.06):
    """A flat road seen by a spinning sensor 1.7 m up: rings every ~0.5-1.5 m (dense along each ring,
    2 cm), each ring offset in height by up to ``ring_offset_m`` (the beams' calibration), range noise
    ``noise_m``; the mesh follows the rings (a step at each ring). Views: road, one in three sidewalk."""
    rng = np.random.default_rng(3)
    radii = 4.0 * 1.07 ** np.arange(24)
    radii = radii[radii < 18]
    off = rng.uniform(-ring_offset_m, ring_offset_m, len(radii))
    pts = []
    for r, o in zip(radii, off):
        a = np.arange(0, 2 * np.pi, 0.02 / r)
        pts.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.full(len(a), o)]))
    pts = np.concatenate(pts)
    pts += rng.normal(0, noise_m, pts.shape)
    v, f, _ = grid(-12, 12, -12, 12, 0.0, 0.25)
    rr = np.linalg.norm(v[:, :2], axis=1)
    v[:, 2] = off[np.abs(rr[:, None] - radii[None]).argmin(axis=1)]
    write_ply(tmp / "mesh.ply", Mesh(vertices=v, faces=f))
    write_ply(tmp / "points.ply", Mesh(vertices=pts))
    votes = np.zeros((len(v), 19), np.float32)
    votes[:, ROAD] = 2.0
    votes[:, SIDEWALK] = 1.0
    np.save(tmp / "votes.npy", votes)
    np.save(tmp / "segments.npy", np.arange(len(v), dtype=np.int32))
    return {"in_textured_mesh_ply": tmp / "mesh.ply", "in_segments_npy": tmp / "segments.npy",
            "in_vertex_votes_npy": tmp / "votes.npy", "in_points_ply": tmp / "points.ply"}


def test_a_noisy_flat_road_stays_road_with_the_curb_gated(tmp_path):
    inputs = _ring_road(tmp_path)
    ungated = np.load(_backproject(tmp_path, "ungated", inputs, cue_gates=False)["labels.npy"])
    assert (ungated == SIDEWALK).mean() > 0.05  # the curb cue reads the rings' steps as curbs
    out = _backproject(tmp_path, "gated", inputs)
    labels = np.load(out["labels.npy"])
    assert (labels == SIDEWALK).mean() < 0.01
    m = json.loads((out["labels.npy"].parent / "step.json").read_text())["metrics"]
    assert m["context"]["step_cells_gated_off"] > 0 and m["cue_gates"]["used"]


def test_shipped_weights_load_and_say_how_they_were_made():
    w = load_weights()
    for kind in ("coloured", "colourless"):
        k = w.for_kind(kind)
        assert k.views > 0 and k.geometry >= 0 and k.coverage_views > 0
    assert set(w.recipe) >= {"coloured", "colourless"}, "fusion_weights.json carries the recipe of each kind"
    # the calibration's finding: a coloured capture's views are taken at their word; a colourless one's
    # grey renders are read through what they were worth on generated truth: their road mostly is road,
    # their building and vegetation (a sparse crown and a facade look alike in grey) far from always
    assert w.for_kind("coloured").view_reliability is None
    R = np.asarray(w.for_kind("colourless").view_reliability)
    assert R.shape == (19, 19) and np.allclose(R.sum(axis=1), 1.0, atol=1e-3)
    assert R[ROAD, ROAD] > 0.7 and R[BUILDING, BUILDING] < 0.8 and R[VEGETATION, VEGETATION] < 0.8
    assert R[BUILDING, VEGETATION] > 0.05 and R[VEGETATION, BUILDING] > 0.1


def test_the_views_reliability_lets_the_geometry_name_what_the_views_confuse():
    from twinkit_segmentation.fusion import calibrate, view_reliability

    rng = np.random.default_rng(0)
    n = 4000
    gt = np.where(np.arange(n) < n // 2, BUILDING, VEGETATION).astype(np.uint8)
    # the views call every facade building, and 80 % of the crowns building too (grey renders)
    said = np.where((gt == VEGETATION) & (rng.random(n) > 0.8), VEGETATION, BUILDING)
    pv = np.zeros((n, 19))
    pv[np.arange(n), said] = 1.0
    right = rng.random(n) > 0.2  # the geometry: the truth on 80 %, not sure of it
    pg = np.full((n, 19), 0.35 / 18)
    pg[np.arange(n), np.where(right, gt, BUILDING + VEGETATION - gt)] = 0.65
    R = view_reliability(pv, gt.astype(np.int64), prior=5.0)
    assert abs(R[BUILDING, VEGETATION] - 0.8 * 2000 / (2000 + 1600 + 5)) < 0.01
    assert R[VEGETATION, VEGETATION] > 0.98 and np.allclose(R.sum(axis=1), 1.0)
    crowns_called_building = (gt == VEGETATION) & (said == BUILDING) & right
    plain = SourceWeights(views=1.0, geometry=1.0, coverage_views=1e-3)
    q, _ = fuse_sources(pv, np.full(n, 10.0), pg, plain)
    assert (q[crowns_called_building].argmax(axis=1) == BUILDING).all()  # taken at their word, the views win
    read = SourceWeights(views=1.0, geometry=1.0, coverage_views=1e-3, view_reliability=R.tolist())
    q, _ = fuse_sources(pv, np.full(n, 10.0), pg, read)
    assert (q[crowns_called_building].argmax(axis=1) == VEGETATION).all()
    assert (q[(gt == BUILDING) & right].argmax(axis=1) == BUILDING).all()
    # the calibration counts the matrix and fits the weights with it: a lower loss than without
    sample = {"p_views": pv, "n_views": np.full(n, 10.0), "p_geom": pg, "gt": gt}
    w0, info0 = calibrate([sample])
    w1, info1 = calibrate([sample], reliability_prior=5.0)
    assert w0.view_reliability is None and w1.view_reliability is not None
    assert info1["logloss"] < info0["logloss"]


def test_the_balanced_calibration_weighs_the_views_by_what_they_do_for_every_class():
    """mIoU counts every class alike; the plain log-loss lets the frequent class decide. Views that help
    only on the frequent class get their weight from the plain loss, and lose it when the rare
    classes they blur count as much."""
    from twinkit.cityscapes import POLE, ROAD
    from twinkit_segmentation.fusion import calibrate, class_balance

    rng = np.random.default_rng(1)
    n = 6000
    gt = np.where(np.arange(n) < int(0.9 * n), ROAD, np.where(np.arange(n) % 2, POLE, VEGETATION)).astype(np.uint8)
    # the views: right about the road, and call every pole and crown road too (grey renders of thin things)
    pv = np.full((n, 19), 0.02 / 18)
    pv[:, ROAD] = 0.98
    # the geometry: right on 70 % of every class, unsure (0.6)
    right = rng.random(n) < 0.7
    other = np.where(gt == ROAD, VEGETATION, ROAD)
    pg = np.full((n, 19), 0.4 / 18)
    pg[np.arange(n), np.where(right, gt, other)] = 0.6
    sample = {"p_views": pv, "n_views": np.full(n, 20.0), "p_geom": pg, "gt": gt}
    w_plain, info_plain = calibrate([sample], loss="plain")
    w_bal, info_bal = calibrate([sample])
    assert info_bal["loss"] == "balanced" and info_plain["loss"] == "plain"
    assert info_plain["views_weight_at_10_views"] > 0.3            # road is 90 % of the vertices
    assert info_bal["views_weight_at_10_views"] < 0.25 * info_plain["views_weight_at_10_views"]
    cb = class_balance(gt.astype(np.int64))
    assert np.isclose(cb.sum(), 1.0) and np.isclose(cb[gt == POLE].sum(), cb[gt == ROAD].sum())
    with pytest.raises(ValueError, match="balanced"):
        calibrate([sample], loss="mean")


def test_the_furniture_cues_need_the_classifier_to_leave_furniture_open(tmp_path):
    from twinkit.cityscapes import POLE, TRAFFIC_SIGN
    from twinkit_segmentation.backproject_parts import _cue_gates
    from twinkit_segmentation.gates import FURNITURE_CUES, geometry_gate
    from twinkit_segmentation.params import BackprojectParams

    g = np.zeros((4, 19))
    g[1, VEGETATION], g[1, POLE] = 0.95, 0.05  # foliage to the classifier
    g[2, VEGETATION], g[2, TRAFFIC_SIGN] = 0.7, 0.3
    g[3, POLE] = 2.0  # votes, not normalised
    assert geometry_gate(g, 0.1).tolist() == [True, False, True, True]  # row 0: no support, the cue's own call
    # in backproject's gates: a dense capture resolves every shape cue; a classifier that says foliage
    # everywhere closes column and mounted, and only those
    v, f, _ = grid(0, 4, 0, 4, 0.0, 0.1)
    mesh = Mesh(vertices=v, faces=f)
    cloud = Mesh(vertices=v + np.random.default_rng(0).normal(0, 0.002, v.shape))

    class Ctx:
        threads = 1
        log = __import__("logging").getLogger("test")

    foliage = np.zeros((len(v), 19))
    foliage[:, VEGETATION] = 1.0
    open_, _ = _cue_gates(BackprojectParams(), Ctx(), mesh, cloud)
    shut, info = _cue_gates(BackprojectParams(), Ctx(), mesh, cloud, foliage)
    assert all(open_[c].all() for c in FURNITURE_CUES)
    assert not any(shut[c].any() for c in FURNITURE_CUES) and info["furniture_by_geometry_share"] == 0.0
    assert all(np.array_equal(open_[c], shut[c]) for c in open_ if c not in FURNITURE_CUES)
    off, _ = _cue_gates(BackprojectParams(furniture_geometry_share=0.0), Ctx(), mesh, cloud, foliage)
    assert all(off[c].all() for c in FURNITURE_CUES)


def _flat_capture():
    """(a step context class, vertices, mesh, cloud): a 4 m square of flat ground and its scan, 2 mm noise."""
    class Ctx:
        threads = 1
        log = __import__("logging").getLogger("test")

    v, f, _ = grid(0, 4, 0, 4, 0.0, 0.1)
    return Ctx, v, Mesh(vertices=v, faces=f), Mesh(vertices=v + np.random.default_rng(0).normal(0, 0.002, v.shape))


def test_the_furniture_cues_stay_off_on_a_capture_whose_ground_is_single_scan_lines(tmp_path):
    from twinkit import artefacts as A
    from twinkit_segmentation.backproject_parts import _cue_gates, capture_two_way_share
    from twinkit_segmentation.gates import FURNITURE_CUES
    from twinkit_segmentation.params import BackprojectParams

    Ctx, v, mesh, cloud = _flat_capture()
    dense, info = _cue_gates(BackprojectParams(), Ctx(), mesh, cloud, two_way_share=0.99)
    rings, rinfo = _cue_gates(BackprojectParams(), Ctx(), mesh, cloud, two_way_share=0.3)  # a spinning sweep
    assert all(dense[c].all() for c in FURNITURE_CUES) and not any(rings[c].any() for c in FURNITURE_CUES)
    assert all(np.array_equal(dense[c], rings[c]) for c in dense if c not in FURNITURE_CUES)
    assert rinfo["ground_two_way_share"] == 0.3
    unknown, _ = _cue_gates(BackprojectParams(), Ctx(), mesh, cloud, two_way_share=None)
    off, _ = _cue_gates(BackprojectParams(furniture_min_two_way_share=0.0), Ctx(), mesh, cloud, two_way_share=0.3)
    assert all(unknown[c].all() and off[c].all() for c in FURNITURE_CUES)
    # the share comes from points_meta.json; a file written before the key gets it measured from the cloud
    meta = tmp_path / "points_meta.json"
    A.write_points_meta(meta, {"source": {"reader": "test"}, "counts": {}, "fields": {}, "frame": {}, "bounds_m": [],
                               "density": {"points": len(v), "spacing_m": 0.1, "capture": "mobile"}})
    grid_share = capture_two_way_share(meta, cloud)
    assert grid_share is not None and grid_share > 0.9  # a grid spreads both ways
    assert capture_two_way_share(None, cloud) is None and capture_two_way_share(tmp_path / "missing.json") is None


def test_the_curb_cue_stays_off_beside_the_classifier_on_a_capture_whose_ground_is_single_scan_lines():
    from twinkit.surface.density import RING_CAPTURE_SHARE
    from twinkit_segmentation.backproject_parts import _cue_gates
    from twinkit_segmentation.params import BackprojectParams

    Ctx, v, mesh, cloud = _flat_capture()
    geom = np.zeros((len(v), 19), np.float32)
    geom[:, 0] = 1.0
    gate = BackprojectParams()  # the default gate: a capture in rings, the ground model reads the surfaces
    assert gate.curb_min_two_way_share == RING_CAPTURE_SHARE
    dense, _ = _cue_gates(gate, Ctx(), mesh, cloud, geom, two_way_share=0.99)
    rings, _ = _cue_gates(gate, Ctx(), mesh, cloud, geom, two_way_share=0.3)  # a spinning sweep
    views_only, _ = _cue_gates(gate, Ctx(), mesh, cloud, None, two_way_share=0.3)
    on, _ = _cue_gates(BackprojectParams(curb_min_two_way_share=0.0), Ctx(), mesh, cloud, geom, two_way_share=0.3)
    assert dense["curb"].mean() > 0.9 and not rings["curb"].any()
    # without the classifier the curb is the views' only help on the ground; 0 turns the gate off
    assert np.array_equal(views_only["curb"], dense["curb"]) and np.array_equal(on["curb"], dense["curb"])
    assert all(np.array_equal(dense[c], rings[c]) for c in dense if c not in ("curb", "column", "mounted"))


def test_the_low_cue_needs_a_capture_that_sees_higher():
    from twinkit_segmentation.context import ContextOptions
    from twinkit_segmentation.gates import reach_gate

    # a facade cut 2 m up by the sensor's field of view, nothing higher around: its top is the scan's edge
    x, z = np.meshgrid(np.linspace(0, 40, 161), np.linspace(0, 2.0, 9))
    wall = np.column_stack([x.ravel(), np.full(x.size, 5.0), z.ravel()])
    opt = ContextOptions()
    assert not reach_gate(wall, wall[:, 2], opt).any()
    # the same wall beside a 6 m lamp post the scan saw whole: a low top there is the object's own
    post = np.column_stack([np.full(25, 8.0), np.full(25, 3.0), np.linspace(0, 6.0, 25)])
    both = np.vstack([wall, post])
    ok = reach_gate(both, both[:, 2], opt)
    d = np.hypot(both[:, 0] - 8.0, both[:, 1] - 3.0)
    assert ok[d < 8.0].all() and (d > 13.0).sum() > 100 and not ok[d > 13.0].any()  # (10 m on a 2 m grid)


def test_on_a_capture_in_rings_a_sure_classifier_holds_against_the_ground_cue(tmp_path):
    """Low plants the classifier is sure of stay vegetation on a sweep; on a dense capture the ground cue
    still makes ground-level vertices ground (docs/segmentation.md "The classifier's floor on a sweep")."""
    from twinkit import artefacts as A

    v, f, _ = grid(0, 8, 0, 8, 0.0, 0.25)
    write_ply(tmp_path / "mesh.ply", Mesh(vertices=v, faces=f))
    write_ply(tmp_path / "points.ply", Mesh(vertices=v + np.random.default_rng(0).normal(0, 0.003, v.shape)))
    np.save(tmp_path / "votes.npy", np.zeros((len(v), 19), np.float32))  # a colourless capture: no views
    np.save(tmp_path / "segments.npy", np.arange(len(v), dtype=np.int32))
    plants = (np.abs(v[:, 0] - 4) < 1.0) & (np.abs(v[:, 1] - 4) < 1.0)
    geom = np.zeros((len(v), 19), np.float32)
    geom[:, SIDEWALK] = 1.0
    geom[plants, SIDEWALK], geom[plants, VEGETATION] = 0.1, 0.9
    np.save(tmp_path / "geometry.npy", geom)
    inputs = {"in_textured_mesh_ply": tmp_path / "mesh.ply", "in_segments_npy": tmp_path / "segments.npy",
              "in_vertex_votes_npy": tmp_path / "votes.npy", "in_points_ply": tmp_path / "points.ply",
              "in_geometry_votes_npy": tmp_path / "geometry.npy"}

    def run(name, share, **params):
        meta = tmp_path / f"{name}_meta" / "points_meta.json"
        meta.parent.mkdir()
        density = {"points": len(v), "spacing_m": 0.25, "capture": "spinning", "ground_two_way_share": share}
        A.write_points_meta(meta, {"source": {"reader": "test"}, "counts": {}, "fields": {}, "frame": {},
                                   "bounds_m": [], "density": density})
        out = _backproject(tmp_path, name, {**inputs, "in_points_meta_json": meta}, **params)
        metrics = json.loads((out["labels.npy"].parent / "step.json").read_text())["metrics"]
        return np.load(out["labels.npy"]), metrics

    rings, m_rings = run("rings", 0.3)
    dense, m_dense = run("dense", 0.99)
    off, m_off = run("off", 0.3, geometry_floor_share=0.0)
    assert (rings[plants] == VEGETATION).mean() > 0.9
    assert (dense[plants] == VEGETATION).mean() < 0.1 and (off[plants] == VEGETATION).mean() < 0.1
    assert (rings[~plants] == SIDEWALK).all() and (dense[~plants] == SIDEWALK).all()
    assert m_rings["geometry_floor"] == 1.0  # every vertex: the classifier gives one class 0.7 or more
    assert m_dense["geometry_floor"] is None and m_off["geometry_floor"] is None
