"""score_points: labels of a mesh moved onto hand-labelled points by nearest vertex, scored per class,
over the five coarse classes, with the far share and the transfer's upper bound."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit import cityscapes as cs
from twinkit_segmentation.metrics import coarse_accuracy, score_points


def test_coarse_groups_hold_the_classes_the_benchmark_names():
    ids = np.arange(256)
    c = cs.coarse_of(ids)
    name = {i: (cs.COARSE_NAMES[c[i]] if c[i] >= 0 else None) for i in range(cs.N_CLASSES)}
    assert {i for i, n in name.items() if n == "ground"} == {cs.ROAD, cs.SIDEWALK, cs.TERRAIN}
    assert {i for i, n in name.items() if n == "facade"} == {cs.BUILDING, cs.WALL, cs.FENCE}
    assert {i for i, n in name.items() if n == "vegetation"} == {cs.VEGETATION}
    assert {i for i, n in name.items() if n == "pole-like"} == {cs.POLE, cs.TRAFFIC_LIGHT, cs.TRAFFIC_SIGN}
    assert {i for i, n in name.items() if n == "vehicle"} == {cs.CAR, cs.TRUCK, cs.BUS, cs.TRAIN,
                                                               cs.MOTORCYCLE, cs.BICYCLE}
    assert {i for i, n in name.items() if n is None} == {cs.PERSON, cs.RIDER, cs.SKY}
    assert (c[cs.N_CLASSES:] == -1).all()


def test_coarse_accuracy_counts_a_sibling_class_as_right_and_leaves_people_out():
    gt = np.array([cs.ROAD, cs.BUILDING, cs.VEGETATION, cs.POLE, cs.PERSON, cs.CAR])
    pred = np.array([cs.SIDEWALK, cs.WALL, cs.POLE, cs.TRAFFIC_SIGN, cs.ROAD, cs.IGNORE])
    res = coarse_accuracy(pred, gt)
    # road~sidewalk, building~wall, pole~sign right; vegetation->pole and car->unlabelled wrong; person out
    assert res["coarse_points"] == 5
    assert res["coarse_accuracy"] == pytest.approx(60.0)
    assert res["coarse_recall"]["vegetation"] == 0.0 and res["coarse_recall"]["facade"] == 100.0


def _scene():
    """Vertices on a line 10 m apart with one class each; points scattered near them in another order."""
    rng = np.random.default_rng(3)
    vclass = np.array([cs.ROAD, cs.BUILDING, cs.VEGETATION, cs.CAR, cs.SIDEWALK], np.uint8)
    verts = np.stack([np.arange(5) * 10.0, np.zeros(5), np.zeros(5)], axis=1)
    owner = rng.integers(0, 5, 200)                                  # which vertex each point lies near
    pts = verts[owner] + rng.uniform(-0.1, 0.1, (200, 3))
    pts[:20, 0] += 4.0                     # 4 m off: still nearer its own vertex than the next (10 m away)
    return verts, vclass, pts, owner


def test_each_point_takes_its_nearest_vertex_label():
    verts, vclass, pts, owner = _scene()
    truth = vclass[owner]
    res = score_points(verts, vclass, pts, truth)
    assert res["accuracy"] == pytest.approx(100.0) and res["miou"] == pytest.approx(100.0)
    assert res["coarse_accuracy"] == pytest.approx(100.0)
    assert res["n_points"] == 200
    assert res["far_share"]["0.5"] == pytest.approx(0.1)         # the 20 points moved 4 m away
    # the same labels read by index (point i <- vertex i) or by the wrong vertex would not score 100
    shifted = np.roll(vclass, 1)
    assert score_points(verts, shifted, pts, truth)["accuracy"] == pytest.approx(0.0)


def test_ignored_points_do_not_count_and_the_upper_bound_sees_past_wrong_labels():
    verts, vclass, pts, owner = _scene()
    truth = vclass[owner].copy()
    truth[owner == 0] = cs.IGNORE                                    # the road points are unlabelled
    wrong = np.full(5, cs.TERRAIN, np.uint8)
    res = score_points(verts, wrong, pts, truth)
    assert res["n_points"] == int((owner != 0).sum())
    assert "road" not in res["per_class"] and res["accuracy"] == 0.0
    # terrain (ground) is right coarse-wise only for the sidewalk points
    assert res["coarse_accuracy"] == pytest.approx(100.0 * (owner == 4).sum() / (owner != 0).sum())
    assert res["upper_bound"]["miou"] == pytest.approx(100.0)


def test_distance_to_the_surface_when_faces_are_given():
    verts = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]], float)
    faces = np.array([[0, 1, 2]])
    pts = np.array([[3.0, 3.0, 0.3], [3.0, 3.0, 0.1]])               # over the triangle, 4 m from any vertex
    truth = np.array([cs.ROAD, cs.ROAD])
    res = score_points(verts, np.full(3, cs.ROAD), pts, truth, faces=faces)
    assert res["far_share"] == {"0.2": pytest.approx(0.5), "0.5": pytest.approx(0.0)}
    assert score_points(verts, np.full(3, cs.ROAD), pts, truth)["far_share"]["0.5"] == 1.0
