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
