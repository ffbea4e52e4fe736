"""The street a scan network should cover (bench_scan_roads.py --coverage): the middle of the road-labelled
ground, which of it a network's roads cover, and the roads each check kept (scan_roads.json stages)."""
from __future__ import annotations

import numpy as np
from scan_fixtures import cross_mesh

from twinkit_roads.scan import Arm, Network, covered, record_stage, street_axis


def test_street_axis_measures_the_road_labelled_streets_length():
    v, f, lab, _ = cross_mesh(half_m=30.0)
    pts, dirs = street_axis(v, f, lab)
    # main road 60 m along x; side street 2 x (30 - 8.7) m along y; a skeleton stops about half the road's
    # width short of the capture's edge (and forks to its corners there)
    length = 0.25 * len(pts)
    assert 0.85 * (60 + 42.6) < length < 1.05 * (60 + 42.6)
    on_main = np.abs(pts[:, 1]) < 1.0
    assert 60 - 17.4 <= 0.25 * on_main.sum() <= 60
    assert not (np.abs(pts[:, 1]) > 9).any() or (np.abs(pts[np.abs(pts[:, 1]) > 9, 0]) < 1.0).all()  # side street


def test_covered_counts_the_street_within_half_the_carriageway_of_an_axis():
    v, f, lab, _ = cross_mesh(half_m=30.0)
    pts, dirs = street_axis(v, f, lab)
    main = [{"axis": [[-30.0, 0.0], [30.0, 0.0]], "width_m": 17.4}]
    share = covered(pts, dirs, main, tol_m=1.0).mean()
    assert 0.4 < share < 0.6  # the main road (not its forks to the corners), not the side street
    both = main + [{"axis": [[0.0, -30.0], [0.0, 30.0]], "width_m": 6.5}]
    assert covered(pts, dirs, both, tol_m=1.0).mean() > 0.97
    # a road across the street, however wide, does not cover it
    across = [{"axis": [[0.0, -30.0], [0.0, 30.0]], "width_m": 60.0}]
    assert covered(pts, dirs, across, tol_m=1.0)[np.abs(pts[:, 1]) < 1.0].mean() < 0.1


def test_a_wide_roads_end_does_not_cover_the_street_beyond_it():
    """A road that stops short covers the street up to its end (plus the tolerance), not half its width on."""
    x = np.arange(0.0, 40.0, 0.25)
    pts, dirs = np.c_[x, np.zeros_like(x)], np.tile([1.0, 0.0], (len(x), 1))
    stub = [{"axis": [[10.0, 0.5], [20.0, 0.5]], "width_m": 12.0}]
    cov = covered(pts, dirs, stub, tol_m=1.0)
    assert cov[(x >= 10.0) & (x <= 20.0)].all()
    assert not cov[(x < 8.9) | (x > 21.1)].any()  # within 7 m of the axis's ends, yet past them
    assert 0.25 * cov.sum() <= 10.0 + 2 * 1.0 + 0.5


def test_record_stage_keeps_each_checks_roads():
    net = Network({0: {"xy": (0, 0), "kind": "end"}, 1: {"xy": (20, 0), "kind": "end"}},
                  [Arm(0, 1, np.array([[0.0, 0.0], [20.0, 0.0]]), 7.0)], np.zeros((1, 1), bool), None, None, {})
    record_stage(net, "derived")
    net.arms[0].xy = np.array([[5.0, 0.0], [20.0, 0.0]])
    record_stage(net, "trim_unsupported")
    st = net.stats["stages"]
    assert [s["stage"] for s in st] == ["derived", "trim_unsupported"]
    assert [s["length_m"] for s in st] == [20.0, 15.0]
    assert st[1]["arms"][0]["width_m"] == 7.0


def _bench():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "bench" / "bench_scan_roads.py"
    spec = importlib.util.spec_from_file_location("bench_scan_roads", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_hand_labels_reach_the_mesh_in_the_runs_frame_and_only_near_a_labelled_point(tmp_path):
    """bench_scan_roads --truth-cloud / --labelled: each vertex takes the class of its nearest labelled point of the
    hand-labelled cloud, moved by read_cloud's shift, within the distance; unlabelled points (255) give nothing;
    and the street drawn from those labels is the labelled road's, not the predicted one's."""
    import json

    from plyfile import PlyData, PlyElement

    v, f, lab, _ = cross_mesh(half_m=30.0)
    shift = np.array([1000.0, -500.0, 20.0])
    pts = np.asarray(v, np.float64) + shift  # the cloud in its own frame: the run's frame plus the shift
    cls = np.where(lab == 0, 0, 1).astype(np.uint8)  # road / sidewalk
    cls[::7] = 255  # unlabelled points: never the truth
    rec = np.empty(len(pts), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("cs_trainid", "u1")])
    rec["x"], rec["y"], rec["z"], rec["cs_trainid"] = pts[:, 0], pts[:, 1], pts[:, 2], cls
    ply = tmp_path / "scan.ply"
    PlyData([PlyElement.describe(rec, "vertex")]).write(str(ply))
    meta = tmp_path / "points_meta.json"
    meta.write_text(json.dumps({"frame": {"shift_m": shift.tolist()}}))
    B = _bench()
    got = B.truth_vertex_labels(v, ply, meta, 0.5)
    labelled = cls != 255
    assert (got[labelled] == cls[labelled]).mean() > 0.99
    assert set(np.unique(got)) <= {0, 1}  # an unlabelled point is never a vertex's truth
    # without the shift every vertex is kilometres from the cloud: nothing is labelled
    meta.write_text(json.dumps({"frame": {}}))
    assert (B.truth_vertex_labels(v, ply, meta, 0.5) == 255).all()
    # the street from the hand labels is the road's length, whatever a prediction says
    pred = np.full(len(v), 1, np.uint8)  # a prediction with no road at all
    assert len(street_axis(v, f, pred)[0]) == 0
    meta.write_text(json.dumps({"frame": {"shift_m": shift.tolist()}}))
    assert 0.25 * len(street_axis(v, f, B.truth_vertex_labels(v, ply, meta, 0.5))[0]) > 0.85 * (60 + 42.6)


def test_in_junctions_finds_the_street_on_the_junctions_connecting_lanes(tmp_path):
    """A street point in the middle of a four-way crossing lies on the junction's connecting lanes, whichever way
    the street's reference runs there; points along the arms, away from it, do not."""
    from test_scan_source import derive_xodr

    from twinkit_roads.scan import in_junctions

    v, f, lab, _ = cross_mesh(step_m=1.0)
    _, text = derive_xodr(tmp_path, v, f, lab)
    pts = np.array([[0.0, 0.0], [2.0, 1.0], [-25.0, 0.0], [0.0, 30.0], [60.0, 60.0]])
    assert in_junctions(pts, text).tolist() == [True, True, False, False, False]
    assert not in_junctions(np.zeros((0, 2)), text).any()
