"""Felzenszwalb over-segmentation on meshes made by code."""
import numpy as np
import pytest

from twinkit_segmentation.synthetic import grid, street_scene
from twinkit.mesh import edges as mesh_edges
from twinkit.surface.compiled import compiled
from twinkit_segmentation.oversegment import edge_weights, felzenszwalb_mesh


def _fold(angle_deg, step=0.1):
    """Two 2 m x 2 m sheets sharing the edge x=0: flat (0), concave valley (>0) or convex ridge (<0)."""
    v, f, _ = grid(-2, 2, 0, 2, 0.0, step)
    a = np.radians(angle_deg)
    z = np.abs(v[:, 0]) * np.tan(a)
    v = np.column_stack([v[:, 0], v[:, 1], z])
    n = np.where(v[:, [0]] < 0, [np.sin(a), 0, np.cos(a)], [-np.sin(a), 0, np.cos(a)])
    n[np.isclose(v[:, 0], 0)] = [0, 0, 1]
    return v, f, n / np.linalg.norm(n, axis=1, keepdims=True)


def test_concave_edges_weigh_more_than_convex():
    v, f, n = _fold(30)
    e = mesh_edges(f, len(v))
    w_concave = edge_weights(v, n, None, e).max()
    v2, f2, n2 = _fold(-30)
    w_convex = edge_weights(v2, n2, None, mesh_edges(f2, len(v2))).max()
    assert w_concave > 0.1
    assert w_convex < w_concave * 0.5  # squared: (1 - cos 30)^2 vs (1 - cos 30)


def test_fold_splits_at_the_crease_and_flat_stays_whole():
    v, f, n = _fold(45)
    seg = felzenszwalb_mesh(v, f, n, None, k_threshold=0.05)
    left, right = v[:, 0] < -1e-6, v[:, 0] > 1e-6
    assert len(set(seg[left])) == 1 and len(set(seg[right])) == 1
    assert seg[left][0] != seg[right][0]
    v, f, n = _fold(0)
    assert len(np.unique(felzenszwalb_mesh(v, f, n, None, k_threshold=0.05))) == 1


def test_colour_boundary_splits_a_flat_plane():
    v, f, n = grid(0, 4, 0, 4, 0.0, 0.1)
    col = np.where(v[:, [0]] < 2, [200, 200, 200], [60, 60, 60]).astype(np.uint8)
    seg = felzenszwalb_mesh(v, f, n, col, k_threshold=0.05, colour_weight=1.0)
    assert len(np.unique(seg)) == 2
    assert len(np.unique(felzenszwalb_mesh(v, f, n, col, k_threshold=0.05, colour_weight=0.0))) == 1


def test_max_and_min_sizes():
    v, f, n = grid(0, 10, 0, 10, 0.0, 0.1)  # 10201 vertices
    seg = felzenszwalb_mesh(v, f, n, None, k_threshold=10.0, max_vertices=500)
    assert np.bincount(seg).max() <= 500
    rng = np.random.default_rng(0)
    noisy = n + rng.normal(0, 0.3, n.shape)
    noisy /= np.linalg.norm(noisy, axis=1, keepdims=True)
    raw = felzenszwalb_mesh(v, f, noisy, None, k_threshold=0.01)
    merged = felzenszwalb_mesh(v, f, noisy, None, k_threshold=0.01, min_vertices=30)
    assert np.bincount(raw).min() < 30
    assert len(np.unique(merged)) < len(np.unique(raw))
    assert np.bincount(merged).min() >= 30
    assert merged.min() == 0 and merged.max() == len(np.unique(merged)) - 1  # renumbered


def test_segments_never_join_disconnected_objects():
    v, f, n, flab = street_scene(step=1.0)
    seg = felzenszwalb_mesh(v, f, n, None, k_threshold=100.0)
    vlab = np.zeros(len(v), np.uint8)
    vlab[f.reshape(-1)] = np.repeat(flab, 3)
    for s in np.unique(seg):
        assert len(np.unique(vlab[seg == s])) == 1


@pytest.mark.parametrize("k, min_v, max_v", [(0.3, 10, 5000), (0.02, 0, 0), (3.0, 50, 300)])
def test_union_find_methods_give_the_same_segments(k, min_v, max_v):
    """The compiled loop, the vectorised rounds and the plain Python loop are the same algorithm."""
    from twinkit_segmentation import oversegment

    v, f, n = grid(0, 20, 0, 12, 0.0, 0.1)  # 24k vertices, 72k edges
    rng = np.random.default_rng(3)
    n = n + rng.normal(0, 0.1, n.shape)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    col = (rng.integers(0, 4, (len(v), 1)) * 60).repeat(3, 1).astype(np.uint8)  # many equal weights (ties)
    ref = felzenszwalb_mesh(v, f, n, col, k, min_v, max_v, 1.0, 1.0, method="python")
    assert 10 < ref.max() < len(v) - 10
    assert np.array_equal(felzenszwalb_mesh(v, f, n, col, k, min_v, max_v, 1.0, 1.0, method="rounds"), ref)
    if compiled(oversegment._union_sequential) is not None:
        assert np.array_equal(felzenszwalb_mesh(v, f, n, col, k, min_v, max_v, 1.0, 1.0, method="numba"), ref)


def test_mesh_edges_are_unique_sorted_and_complete():
    v, f, _ = grid(0, 3, 0, 2, 0.0, 1.0)  # 4 x 3 vertices, 12 faces
    f = np.vstack([f, [[0, 0, 1]]])  # a degenerate face adds no self-edge
    e = mesh_edges(f, len(v))
    assert (e[:, 0] < e[:, 1]).all()
    assert len(np.unique(e, axis=0)) == len(e) == 3 * 3 + 2 * 4 + 6  # horizontal + vertical + diagonals
    assert np.array_equal(e, e[np.lexsort((e[:, 1], e[:, 0]))])
