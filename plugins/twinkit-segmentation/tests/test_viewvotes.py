"""One view's votes, counted for its seen vertices only, equal the full-size count bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.cityscapes import N_CLASSES
from twinkit_segmentation.viewvotes import view_votes


def _full_size(vm, n, labels=None, proba=None, per_view=True):
    """The (vertices x 19) count predict_views made before view_votes."""
    vm = vm.reshape(-1)
    hit = vm >= 0
    if proba is not None:
        p = proba.reshape(N_CLASSES, -1)[:, hit]
        vv = np.stack([np.bincount(vm[hit], weights=p[c], minlength=n) for c in range(N_CLASSES)], axis=1)
    else:
        lab = labels.reshape(-1)[hit].astype(np.int64)
        ok = lab < N_CLASSES
        vv = np.bincount(vm[hit][ok].astype(np.int64) * N_CLASSES + lab[ok],
                         minlength=n * N_CLASSES).reshape(n, N_CLASSES).astype(np.float64)
    if per_view:
        tot = vv.sum(axis=1, keepdims=True)
        vv = np.divide(vv, tot, out=np.zeros_like(vv), where=tot > 0)
    return vv


@pytest.mark.parametrize("per_view", [True, False])
@pytest.mark.parametrize("soft", [False, True])
def test_view_votes_equal_the_full_count(per_view, soft):
    rng = np.random.default_rng(7)
    n, h, w = 500, 24, 32
    votes_new, votes_old = np.zeros((n, N_CLASSES)), np.zeros((n, N_CLASSES))
    for _ in range(4):  # several views summed, as predict_views does
        vm = rng.integers(-1, 120, (h, w)).astype(np.int32) * 3  # a few vertices, many pixels each; -3 = sky
        vm[vm < 0] = -1
        labels = rng.integers(0, N_CLASSES, (h, w)).astype(np.uint8)
        labels[0] = 255  # no CityScapes counterpart: no vote
        proba = rng.random((N_CLASSES, h, w)).astype(np.float32) if soft else None
        ids, vv = view_votes(vm, n, labels=labels, proba=proba, per_view=per_view)
        assert np.all(np.diff(ids) > 0) and vv.shape == (len(ids), N_CLASSES)
        assert set(ids) <= set(np.unique(vm[vm >= 0]))
        votes_new[ids] += vv
        votes_old += _full_size(vm, n, labels=labels, proba=proba, per_view=per_view)
    assert np.array_equal(votes_new, votes_old)
    if per_view:  # one vote per view and vertex: at most 4 in all
        assert votes_new.sum(axis=1).max() <= 4 + 1e-9


def test_view_votes_needs_labels_or_proba():
    with pytest.raises(ValueError, match="labels or proba"):
        view_votes(np.zeros((2, 2), np.int32), 1)
