"""Scoring per-vertex labels against ground truth; back-projection of votes; label propagation.

Command line (score any labelled mesh)::

    python -m twinkit_segmentation.metrics LABELS(.npy|.ply) GT(.npy|.ply) [--segments segments.npy] [--json out.json]

A PLY is read through its ``label`` vertex property, or (a repainted export) through its
vertex colours mapped to the nearest CityScapes palette colour.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from twinkit.cityscapes import COARSE_NAMES, IGNORE, N_CLASSES, NAMES, coarse_of


def confusion(pred: np.ndarray, gt: np.ndarray, n: int = N_CLASSES) -> np.ndarray:
    """``(n, n+1)`` counts: rows = ground truth class, columns = predicted class (last = unlabelled)."""
    pred = np.asarray(pred).astype(np.int64)
    gt = np.asarray(gt).astype(np.int64)
    valid = gt < n
    p = np.where(pred < n, pred, n)[valid]
    return np.bincount(gt[valid] * (n + 1) + p, minlength=n * (n + 1)).reshape(n, n + 1)


def scores(pred: np.ndarray, gt: np.ndarray, classes: list[int] | None = None) -> dict:
    """Per-class IoU / F1 / precision / recall (percent) and their means over ``classes``
    (default: the classes present in the ground truth). Unlabelled predictions count as misses."""
    cm = confusion(pred, gt)
    tp = np.diag(cm[:, :N_CLASSES]).astype(np.float64)
    gt_n = cm.sum(axis=1).astype(np.float64)
    pred_n = cm[:, :N_CLASSES].sum(axis=0).astype(np.float64)
    fp, fn = pred_n - tp, gt_n - tp
    if classes is None:
        classes = [int(c) for c in np.nonzero(gt_n)[0]]
    per = {}
    for c in classes:
        iou = tp[c] / max(tp[c] + fp[c] + fn[c], 1)
        prec = tp[c] / pred_n[c] if pred_n[c] else 0.0
        rec = tp[c] / gt_n[c] if gt_n[c] else 0.0
        f1 = 2 * prec * rec / (prec + rec) if prec + rec else 0.0
        per[NAMES[c]] = {"id": c, "iou": 100 * iou, "f1": 100 * f1, "precision": 100 * prec,
                           "recall": 100 * rec, "gt_vertices": int(gt_n[c]), "pred_vertices": int(pred_n[c])}
    valid = np.asarray(gt) < N_CLASSES
    out = {
        "miou": float(np.mean([v["iou"] for v in per.values()])) if per else 0.0,
        "mf1": float(np.mean([v["f1"] for v in per.values()])) if per else 0.0,
        "accuracy": 100.0 * float(tp.sum() / max(valid.sum(), 1)),
        "labelled_fraction": float((np.asarray(pred)[valid] < N_CLASSES).mean()) if valid.any() else 0.0,
        "classes": classes,
        "per_class": per,
        "confusion": {"rows_gt_cols_pred": list(NAMES) + ["unlabelled"], "matrix": cm.tolist()},
    }
    return out


def coarse_accuracy(pred: np.ndarray, gt: np.ndarray) -> dict:
    """Accuracy (percent) over the five coarse classes (:data:`twinkit.cityscapes.COARSE`) on the items whose
    truth is in one of them (person, rider, sky and 255 are left out); a prediction in no coarse class
    counts as a miss. Also the recall per coarse class. ``pred``, ``gt``: trainIds of the same shape."""
    cg, cp = coarse_of(gt), coarse_of(pred)
    keep = cg >= 0
    hit = (cp == cg) & keep
    per = {name: (100.0 * float(hit[cg == i].sum() / max((cg == i).sum(), 1)) if (cg == i).any() else None)
           for i, name in enumerate(COARSE_NAMES)}
    return {"coarse_accuracy": 100.0 * float(hit.sum() / max(keep.sum(), 1)), "coarse_recall": per,
            "coarse_points": int(keep.sum())}


def score_points(vertices: np.ndarray, vertex_labels: np.ndarray, points: np.ndarray, truth: np.ndarray, *,
                 faces: np.ndarray | None = None, far_m: tuple[float, ...] = (0.2, 0.5),
                 upper_bound: bool = True) -> dict:
    """Score a labelled mesh against hand-labelled points (a real scan's truth), in one frame.

    Each point takes the label of its nearest mesh vertex; counted on the points whose truth is a class
    (``truth != 255``): per-class IoU/F1 and mean IoU over the classes present in the truth, accuracy
    (:func:`scores`), accuracy over the five coarse classes (:func:`coarse_accuracy`), and the share of
    those points farther than each of ``far_m`` from the mesh (from its surface when ``faces`` is given,
    else from the nearest vertex, an upper bound). ``upper_bound``: also the scores if every vertex took
    the class of its nearest labelled point (what the nearest-vertex transfer alone allows).

    vertices (n, 3) float, metres; vertex_labels (n,) trainIds (255 = unlabelled, a miss); points (p, 3)
    float in the vertices' frame; truth (p,) trainIds (255 = ignore); faces (m, 3) int or None.
    Returns a JSON-ready dict: ``miou``, ``accuracy``, ``coarse_accuracy`` (percent), ``per_class``
    ({name: {"iou", ...}}), ``confusion`` (as :func:`scores`), ``far_share`` ({"0.5": fraction
    0-1, ...}), ``n_points`` (labelled points scored) and ``upper_bound`` (the same scores) if asked."""
    vertices = np.asarray(vertices, np.float64)
    points = np.asarray(points, np.float64)
    truth = np.asarray(truth).astype(np.int64)
    keep = truth != IGNORE
    pts, gt = points[keep], truth[keep]
    nearest_vertex, dist = transfer_nearest(vertices, np.arange(len(vertices)), pts)
    pred = np.asarray(vertex_labels)[nearest_vertex]
    with_faces = faces is not None and len(faces) > 0
    if with_faces and len(pts):
        from twinkit.surface.closest import Surface

        dist = Surface(vertices, np.asarray(faces)).distance(pts).astype(np.float64)
    out = _point_scores(pred, gt)
    out["n_points"] = int(keep.sum())
    out["far_share"] = {f"{m:g}": float((dist > m).mean()) if len(dist) else 0.0 for m in far_m}
    out["distance_to"] = "surface" if with_faces else "nearest vertex"
    if upper_bound and len(pts):
        best, _ = transfer_nearest(pts, gt, vertices)     # each vertex: the class of its nearest labelled point
        out["upper_bound"] = _point_scores(best[nearest_vertex], gt)
    return out


def transfer_nearest(source_xyz: np.ndarray, source_values: np.ndarray,
                     query_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each query point takes the value of its nearest source point: ((q,) values, (q,) float distance, m).
    source_xyz (n, 3), source_values (n,), query_xyz (q, 3), one frame."""
    from scipy.spatial import cKDTree

    d, idx = cKDTree(np.asarray(source_xyz, np.float64)).query(np.asarray(query_xyz, np.float64), workers=-1)
    return np.asarray(source_values)[idx], d


def _point_scores(pred: np.ndarray, gt: np.ndarray) -> dict:
    res = scores(pred, gt)
    res.update(coarse_accuracy(pred, gt))
    return res


def majority_labels(segments: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Each segment takes its most frequent ground-truth class (the over-segmentation's upper bound)."""
    segments = np.asarray(segments, dtype=np.int64)
    s = int(segments.max()) + 1 if len(segments) else 0
    g = np.asarray(gt).astype(np.int64)
    valid = g < N_CLASSES
    votes = np.bincount(segments[valid] * N_CLASSES + g[valid], minlength=s * N_CLASSES).reshape(s, N_CLASSES)
    lab = votes.argmax(axis=1).astype(np.uint8)
    lab[votes.sum(axis=1) == 0] = IGNORE
    return lab[segments]


def segment_votes(segments: np.ndarray, vertex_votes: np.ndarray) -> np.ndarray:
    """Sum per-vertex class votes ``(n, 19)`` into per-segment votes ``(s, 19)`` (bincount per class)."""
    segments = np.asarray(segments, dtype=np.int64)
    s = int(segments.max()) + 1
    return np.stack([np.bincount(segments, weights=vertex_votes[:, c], minlength=s)
                     for c in range(vertex_votes.shape[1])], axis=1)


def _weighted_votes(votes, ignore_classes=(10,), class_weights=None) -> np.ndarray:
    """Votes as float64 with the ignored classes zeroed and the class weights applied."""
    v = np.asarray(votes, dtype=np.float64).copy()
    for c in ignore_classes or ():
        if 0 <= int(c) < v.shape[1]:
            v[:, int(c)] = 0.0
    if class_weights is not None and len(class_weights):
        w = np.asarray(class_weights, dtype=np.float64)
        if len(w) != v.shape[1]:
            raise ValueError(f"class_weights needs {v.shape[1]} values (one per trainId), got {len(w)}")
        v *= w[None, :]
    return v


def decide(votes: np.ndarray, ignore_classes=(10,), class_weights=None, min_votes: float = 0.0):
    """(labels uint8 with 255 where nothing voted, confidence = winner's share of the votes)."""
    v = _weighted_votes(votes, ignore_classes, class_weights)
    total = v.sum(axis=1)
    lab = v.argmax(axis=1).astype(np.uint8)
    conf = np.where(total > 0, v.max(axis=1) / np.maximum(total, 1e-12), 0.0).astype(np.float32)
    lab[(total <= 0) | (total < min_votes)] = IGNORE
    return lab, conf


def blend_decide(segments: np.ndarray, vertex_votes: np.ndarray, segment_weight: float = 1.0, ignore_classes=(10,),
                 class_weights=None, min_votes: float = 0.0):
    """Segment vote blended with each vertex's own vote: per vertex the class distribution
    ``segment_weight * p(segment) + (1 - segment_weight) * p(vertex)`` (each normalised to
    sum 1; a vertex no view saw uses its segment's alone), argmax. ``segment_weight`` 1 is
    the plain per-segment vote, 0 the plain per-vertex vote. In between, a vertex keeps the
    segment's label unless its own votes clearly disagree, which repairs segments that
    straddle a class boundary (the over-segmentation's upper bound stops being a cap) while
    noisy, split vertex votes still follow the segment. Returns (labels, confidence)."""
    p, s_total = blend_distribution(segments, vertex_votes, segment_weight, ignore_classes, class_weights)
    return decide_distribution(p, s_total < min_votes)


def decide_distribution(p: np.ndarray, unlabelled=None):
    """Argmax of a per-vertex class distribution (n, 19): (labels with 255 where it is empty or
    ``unlabelled`` is set, confidence = the winner's share)."""
    total = p.sum(axis=1)
    lab = p.argmax(axis=1).astype(np.uint8)
    conf = np.where(total > 0, p.max(axis=1) / np.maximum(total, 1e-12), 0.0).astype(np.float32)
    bad = total <= 0
    if unlabelled is not None:
        bad |= unlabelled
    lab[bad] = IGNORE
    return lab, conf


def blend_distribution(segments: np.ndarray, vertex_votes: np.ndarray, segment_weight: float = 1.0,
                       ignore_classes=(10,), class_weights=None):
    """The class distribution :func:`blend_decide` takes the argmax of: ``(p (n, 19), the segment's
    total votes per vertex (n,))``."""
    v = _weighted_votes(vertex_votes, ignore_classes, class_weights)
    segments = np.asarray(segments, dtype=np.int64)
    sv = segment_votes(segments, v)
    s_total = sv.sum(axis=1)
    p = sv / np.maximum(s_total, 1e-12)[:, None]
    p = p[segments]
    a = float(np.clip(segment_weight, 0.0, 1.0))
    if a < 1.0:
        v_total = v.sum(axis=1)
        seen = v_total > 0
        p[seen] = a * p[seen] + (1.0 - a) * v[seen] / v_total[seen, None]
    return p, s_total[segments]


def propagate(labels: np.ndarray, edges: np.ndarray, max_iter: int = 200) -> np.ndarray:
    """Give unlabelled vertices the most common label of their labelled neighbours, repeatedly
    (occluded parts take the label of what surrounds them)."""
    from scipy import sparse

    lab = labels.copy()
    n = len(lab)
    a = np.concatenate([edges[:, 0], edges[:, 1]])
    b = np.concatenate([edges[:, 1], edges[:, 0]])
    adj = sparse.csr_matrix((np.ones(len(a), np.float32), (a, b)), shape=(n, n))
    for _ in range(max_iter):
        miss = lab == IGNORE
        if not miss.any():
            break
        known = ~miss
        onehot = sparse.csr_matrix((np.ones(known.sum(), np.float32), (np.nonzero(known)[0], lab[known].astype(np.int64))),
                                   shape=(n, N_CLASSES))
        counts = (adj[miss] @ onehot).toarray()
        got = counts.sum(axis=1) > 0
        if not got.any():
            break
        idx = np.nonzero(miss)[0][got]
        lab[idx] = counts[got].argmax(axis=1).astype(np.uint8)
    return lab


def palette_to_labels(colors: np.ndarray) -> np.ndarray:
    """Nearest CityScapes palette colour -> trainId (black = 255, unlabelled)."""
    from twinkit import cityscapes

    return cityscapes.nearest_class(np.asarray(colors).reshape(-1, 3))


def load_labels(path: Path, prefer_colors: bool = False) -> np.ndarray:
    path = Path(path)
    if path.suffix == ".npy":
        return np.load(path).astype(np.uint8)
    from twinkit.mesh import read_mesh

    from twinkit_segmentation.segmesh import vertex_labels

    m = read_mesh(path)
    if vertex_labels(m) is not None and not prefer_colors:
        return vertex_labels(m)
    if m.colors is None:
        raise ValueError(f"{path}: no 'label' property and no vertex colours")
    return palette_to_labels(m.colors)


def markdown_table(res: dict, upper: dict | None = None) -> str:
    lines = ["| class | IoU | F1 | precision | recall |" + (" upper bound IoU |" if upper else ""),
             "|---|---:|---:|---:|---:|" + ("---:|" if upper else "")]
    for name, v in res["per_class"].items():
        ub = f" {upper['per_class'].get(name, {}).get('iou', 0):.1f} |" if upper else ""
        lines.append(f"| {name} | {v['iou']:.1f} | {v['f1']:.1f} | {v['precision']:.1f} | {v['recall']:.1f} |{ub}")
    ub = f" {upper['miou']:.1f} |" if upper else ""
    lines.append(f"| **mean** | **{res['miou']:.1f}** | **{res['mf1']:.1f}** | | |{ub}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Score per-vertex labels against ground truth (mIoU, mF1, per class).")
    ap.add_argument("labels", help="labels.npy, or a labelled / repainted PLY (same vertices as the ground truth)")
    ap.add_argument("gt", help="ground-truth labels (gt_labels.npy or a PLY with a 'label' property)")
    ap.add_argument("--segments", help="segments.npy: also report the over-segmentation's upper bound")
    ap.add_argument("--colors", action="store_true", help="read the labels PLY by its palette colours, not 'label'")
    ap.add_argument("--json", help="write the full result here")
    a = ap.parse_args(argv)
    pred, gt = load_labels(Path(a.labels), a.colors), load_labels(Path(a.gt))
    if len(pred) != len(gt):
        print(f"error: {a.labels} has {len(pred)} vertices, {a.gt} has {len(gt)}", file=sys.stderr)
        return 2
    res = scores(pred, gt)
    upper = scores(majority_labels(np.load(a.segments), gt), gt, res["classes"]) if a.segments else None
    print(markdown_table(res, upper))
    print(f"mIoU {res['miou']:.1f}  mF1 {res['mf1']:.1f}  accuracy {res['accuracy']:.1f}")
    if a.json:
        Path(a.json).write_text(json.dumps({"scores": res, "upper_bound": upper}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
