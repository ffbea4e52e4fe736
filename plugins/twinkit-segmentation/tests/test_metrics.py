"""Scores, upper bound, vote decisions, palette round trip, propagation."""
import numpy as np
import pytest

from twinkit.cityscapes import IGNORE, PALETTE, colorize
from twinkit_segmentation.metrics import (
    blend_decide, confusion, decide, majority_labels, palette_to_labels, propagate, scores, segment_votes,
)


def test_scores_by_hand():
    gt = np.array([0, 0, 0, 1, 1, 2, IGNORE], np.uint8)
    pred = np.array([0, 0, 1, 1, IGNORE, 2, 0], np.uint8)
    r = scores(pred, gt)
    assert r["classes"] == [0, 1, 2]
    road, side, bld = r["per_class"]["road"], r["per_class"]["sidewalk"], r["per_class"]["building"]
    assert road["iou"] == pytest.approx(100 * 2 / 3)  # tp 2, fn 1, fp 0
    assert side["iou"] == pytest.approx(100 * 1 / 3)  # tp 1, fp 1, fn 1 (unlabelled counts as a miss)
    assert side["precision"] == pytest.approx(50.0) and side["recall"] == pytest.approx(50.0)
    assert bld["iou"] == 100.0 and bld["f1"] == 100.0
    assert r["miou"] == pytest.approx((200 / 3 + 100 / 3 + 100) / 3)
    cm = np.array(r["confusion"]["matrix"])
    assert cm.sum() == 6 and cm[1, 19] == 1  # gt sidewalk predicted unlabelled
    assert confusion(pred, gt).shape == (19, 20)


def test_upper_bound_is_majority_per_segment():
    gt = np.array([0, 0, 1, 1, 1, 2], np.uint8)
    seg = np.array([0, 0, 0, 1, 1, 1])
    ub = majority_labels(seg, gt)
    assert ub.tolist() == [0, 0, 0, 1, 1, 1]
    assert scores(majority_labels(np.arange(6), gt), gt)["miou"] == 100.0


def test_decide_ignores_weights_and_min_votes():
    votes = np.array([[5, 0, 0, 0, 0, 0, 0, 0, 0, 0, 9] + [0] * 8,
                      [2, 3] + [0] * 17,
                      [0] * 19], float)
    lab, conf = decide(votes, ignore_classes=[10])
    assert lab.tolist() == [0, 1, IGNORE]
    assert conf[0] == 1.0 and conf[1] == pytest.approx(0.6)
    w = np.ones(19)
    w[0] = 2.0
    lab, _ = decide(votes, ignore_classes=[10], class_weights=w)
    assert lab[1] == 0
    lab, _ = decide(votes, ignore_classes=[10], min_votes=5.5)
    assert lab.tolist() == [IGNORE, IGNORE, IGNORE] or lab[1] == IGNORE


def test_segment_votes_sum():
    votes = np.zeros((4, 19))
    votes[0, 1] = 1
    votes[1, 2] = 3
    votes[2, 1] = 2
    sv = segment_votes(np.array([0, 0, 0, 1]), votes)
    assert sv.shape == (2, 19) and sv[0, 1] == 3 and sv[0, 2] == 3 and sv[1].sum() == 0


def test_palette_round_trip_with_noise():
    labels = np.array(list(range(19)) + [IGNORE], np.uint8)
    cols = colorize(labels).astype(int)
    assert (palette_to_labels(cols) == labels).all()
    jitter = np.clip(cols + np.random.default_rng(0).integers(-6, 7, cols.shape), 0, 255)
    assert (palette_to_labels(jitter) == labels).all()
    assert (colorize(np.array([0])) == PALETTE[0]).all()


def test_propagate_fills_holes():
    # a path 0-1-2-3-4, labels known at the ends
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    lab = np.array([0, IGNORE, IGNORE, IGNORE, 2], np.uint8)
    out = propagate(lab, edges)
    assert (out != IGNORE).all() and out[0] == 0 and out[4] == 2 and out[1] == 0 and out[3] == 2


def test_blend_keeps_confident_segments_and_repairs_straddling_ones():
    # segment 0: vertices 0-3; three vertices voted road, vertex 3 clearly sidewalk (a segment
    # straddling a boundary). segment 1: vertices 4-5; vertex 5 has a noisy, split vote.
    votes = np.zeros((7, 19))
    votes[0:3, 0] = 4
    votes[3, 1] = 4
    votes[4, 2] = 6
    votes[5, 2], votes[5, 8] = 2, 3  # leans vegetation, but only 60/40
    # vertex 6 (segment 1) was seen by no view: it takes its segment's vote
    seg = np.array([0, 0, 0, 0, 1, 1, 1])
    only_seg, _ = blend_decide(seg, votes, 1.0)
    assert only_seg.tolist() == [0, 0, 0, 0, 2, 2, 2]  # the plain per-segment vote
    assert np.array_equal(only_seg, decide(segment_votes(seg, votes))[0][seg])
    half, conf = blend_decide(seg, votes, 0.5)
    assert half.tolist() == [0, 0, 0, 1, 2, 2, 2]  # vertex 3 repaired, vertex 5 follows its segment
    assert conf[6] == pytest.approx(8 / 11)  # unseen vertex: its segment's share (6 + 2 of 6 + 2 + 3)
    assert blend_decide(seg, votes, 0.0)[0].tolist()[:6] == [0, 0, 0, 1, 2, 8]  # per vertex
    lab, _ = blend_decide(seg, votes, 0.5, min_votes=12)  # segment 1 has 11 votes
    assert lab.tolist() == [0, 0, 0, 1, IGNORE, IGNORE, IGNORE]
