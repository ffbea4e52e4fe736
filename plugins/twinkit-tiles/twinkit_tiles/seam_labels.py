"""Do the semantic labels agree across the tile seams?

Segmentation runs on the merged mesh (one mesh, views that see across the borders), so nothing about
a seam should show in its labels. This module measures it: along every mesh edge that crosses a seam
plane, do the labels of its two ends differ more often than along edges crossing *control planes*
(parallel planes through the tiles' interiors, where there is no seam)? With ground truth, only label
changes the ground truth does not have count (a curb under a seam is a legitimate change).
"""
from __future__ import annotations

import numpy as np

IGNORE = 255


def control_planes(planes: list[tuple[int, float]], lo: np.ndarray, hi: np.ndarray,
                   min_gap_m: float = 2.0) -> list[tuple[int, float]]:
    """Planes half-way between neighbouring seams (and between the outer seams and the data's edge),
    at least ``min_gap_m`` from every seam: lines through tile interiors."""
    out = []
    for axis in (0, 1):
        vals = sorted(v for a, v in planes if a == axis)
        if not vals:
            continue
        stops = [float(lo[axis])] + vals + [float(hi[axis])]
        for a, b in zip(stops[:-1], stops[1:]):
            c = 0.5 * (a + b)
            if all(abs(c - v) >= min_gap_m for v in vals) and lo[axis] < c < hi[axis]:
                out.append((axis, c))
    return out


def _edges(faces: np.ndarray) -> np.ndarray:
    e = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def _crossing(X: np.ndarray, e: np.ndarray, axis: int, val: float) -> np.ndarray:
    sa, sb = X[e[:, 0], axis] - val, X[e[:, 1], axis] - val
    return ((sa <= 0) & (sb > 0)) | ((sa > 0) & (sb <= 0))


def _plane_stats(X, e, labels, gt, axis, val) -> dict:
    cross = _crossing(X, e, axis, val)
    a, b = e[cross, 0], e[cross, 1]
    ok = (labels[a] != IGNORE) & (labels[b] != IGNORE)
    change = labels[a] != labels[b]
    row = {"plane": ["xyz"[axis], round(float(val), 3)], "edges": int(ok.sum()),
           "label_changes": int((change & ok).sum())}
    if gt is not None:
        okg = ok & (gt[a] != IGNORE) & (gt[b] != IGNORE)
        row["edges_with_gt"] = int(okg.sum())
        row["changes_not_in_gt"] = int((change & okg & (gt[a] == gt[b])).sum())
    return row


def _rate(rows: list[dict], num: str, den: str) -> float | None:
    n = sum(r[den] for r in rows)
    return round(100.0 * sum(r[num] for r in rows) / n, 3) if n else None


def seam_label_stats(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, planes: list[tuple[int, float]],
                     gt: np.ndarray | None = None, band_m: float = 1.0) -> dict:
    """Label changes along edges crossing the seams vs. control planes, in % of the crossing edges;
    with ground truth, also the changes the ground truth does not have, and the per-vertex accuracy
    within ``band_m`` of a seam vs. farther away."""
    X = np.asarray(vertices, np.float64)
    labels = np.asarray(labels)
    if len(labels) != len(X):
        raise ValueError(f"{len(labels)} labels for {len(X)} vertices")
    if gt is not None and len(gt) != len(X):
        raise ValueError(f"{len(gt)} ground-truth labels for {len(X)} vertices")
    e = _edges(np.asarray(faces, np.int64))
    ctrl = control_planes(planes, X.min(axis=0), X.max(axis=0))
    seam_rows = [_plane_stats(X, e, labels, gt, a, v) for a, v in planes]
    ctrl_rows = [_plane_stats(X, e, labels, gt, a, v) for a, v in ctrl]
    out = {"seams": seam_rows, "controls": ctrl_rows,
           "seam_change_pct": _rate(seam_rows, "label_changes", "edges"),
           "control_change_pct": _rate(ctrl_rows, "label_changes", "edges")}
    if gt is not None:
        out["seam_changes_not_in_gt_pct"] = _rate(seam_rows, "changes_not_in_gt", "edges_with_gt")
        out["control_changes_not_in_gt_pct"] = _rate(ctrl_rows, "changes_not_in_gt", "edges_with_gt")
        from .edges import near_planes

        near = near_planes(X, planes, band_m)
        ok = (labels != IGNORE) & (gt != IGNORE)

        def acc(m):
            return round(100.0 * float((labels[m & ok] == gt[m & ok]).mean()), 2) if (m & ok).any() else None

        out.update(band_m=band_m, accuracy_near_seams_pct=acc(near), accuracy_elsewhere_pct=acc(~near),
                   vertices_near_seams=int((near & ok).sum()))
    return out
