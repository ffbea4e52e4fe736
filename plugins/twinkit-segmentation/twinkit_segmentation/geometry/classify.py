"""Run the 3D classifier on a cloud and carry its class probabilities to mesh vertices."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .features import block_mean, feature_names, point_features
from .model import GeometryModel, load_model


@dataclass
class CloudLabels:
    """The classifier's answer for a cloud: ``base`` (m,) int64 indices of the base points (one per voxel)
    into the cloud, ``inverse`` (n,) int64 each cloud point's base point, ``proba`` (m, 19) float32 class
    probabilities of the base points, ``seconds`` per part."""

    base: np.ndarray
    inverse: np.ndarray
    proba: np.ndarray
    seconds: dict

    def point_labels(self) -> np.ndarray:
        """(n,) uint8 trainId of every cloud point (its base point's most probable class)."""
        return self.proba.argmax(axis=1).astype(np.uint8)[self.inverse]


def classify_cloud(xyz: np.ndarray, intensity: np.ndarray | None = None, model: GeometryModel | None = None,
                   *, base_voxel_m: float = 0.1, ground_window_m: float = 8.0, smooth_m: float = 0.25,
                   prior: bool = True, turns: int = 4) -> CloudLabels:
    """Features (:func:`.features.point_features`) and the MLP's probabilities for ``xyz`` (n, 3) float, site
    frame, z up, metres; ``intensity`` (n,) or None. ``model``: None = the shipped one. ``smooth_m``: each
    base point's probabilities become the normalised geometric mean of those of the base points in the
    3 x 3 x 3 voxels of this side around it (:func:`smooth_proba`); 0 = each point alone. ``prior``: apply the
    model's class-prior correction (:attr:`.model.GeometryModel.logit_shift`). ``turns``: the cloud is
    classified this many times, turned about the vertical by 90 / ``turns`` degrees each time (the voxel
    grids of the features are square to the axes, and how a grid cuts a surface is noise), and each base
    point of the first pass takes the normalised geometric mean of its point's probabilities in every pass."""
    model = model or load_model()
    if list(model.feature_names) != feature_names():
        raise ValueError("the 3D classifier's model was trained on other features than this code computes; "
                         "retrain it (python -m twinkit_segmentation.geometry.train)")
    xyz = np.asarray(xyz, np.float64)
    n_turns = max(1, int(turns))
    first, logp, sec = None, None, {}
    for k in range(n_turns):
        pts = turned(xyz, 90.0 * k / n_turns)
        f = point_features(pts, intensity, base_voxel_m=base_voxel_m, ground_window_m=ground_window_m)
        t = time.perf_counter()
        proba = model.proba(f.values, prior=prior)
        part = dict(f.seconds, model=round(time.perf_counter() - t, 3))
        if smooth_m > 0:
            t = time.perf_counter()
            proba = smooth_proba(pts[f.base], proba, smooth_m)
            part["smooth"] = round(time.perf_counter() - t, 3)
        sec = {key: round(sec.get(key, 0.0) + v, 3) for key, v in part.items()}
        if first is None:  # the first pass's base points carry the answer
            first, first_proba = f, proba
            logp = np.log(np.maximum(proba, 1e-4))
        else:
            logp += np.log(np.maximum(proba[f.inverse[first.base]], 1e-4))
    if n_turns == 1:
        return CloudLabels(base=first.base, inverse=first.inverse, proba=first_proba, seconds=sec)
    logp /= n_turns  # the mean of the logarithms: a geometric mean, as sharp as one pass
    q = np.exp(logp - logp.max(axis=1, keepdims=True)) * (first_proba.max(axis=0) > 0)  # unused classes stay 0
    proba = (q / np.maximum(q.sum(axis=1, keepdims=True), 1e-30)).astype(np.float32)
    return CloudLabels(base=first.base, inverse=first.inverse, proba=proba, seconds=sec)


def turned(xyz: np.ndarray, degrees: float) -> np.ndarray:
    """``xyz`` (n, 3) turned about the vertical through its centroid by ``degrees`` (counter-clockwise);
    ``xyz`` itself for 0."""
    if degrees == 0 or len(xyz) == 0:
        return xyz
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    centre = xyz.mean(axis=0)
    return (xyz - centre) @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) + centre


def smooth_proba(points: np.ndarray, proba: np.ndarray, side_m: float, floor: float = 1e-4) -> np.ndarray:
    """(m, c) float32: per point, the normalised geometric mean of ``proba`` (m, c) over the ``points`` (m, 3)
    in the 3 x 3 x 3 voxels of side ``side_m`` (m) around its own (:func:`.features.block_mean` of the log
    probabilities, each floored at ``floor``). Single points' shape features are noisy on a real scan; their
    neighbours on the same surface mostly share the class. Columns that were all zero stay zero."""
    used = proba.max(axis=0) > 0
    lp = block_mean(points, np.log(np.maximum(proba[:, used], floor)), side_m)
    lp -= lp.max(axis=1, keepdims=True)
    q = np.exp(lp)
    q /= q.sum(axis=1, keepdims=True)
    out = np.zeros_like(proba, dtype=np.float32)
    out[:, used] = q
    return out


def votes_at(points: np.ndarray, proba: np.ndarray, targets: np.ndarray, *, radius_m: float = 0.4,
             neighbours: int = 8, workers: int = 1) -> np.ndarray:
    """(t, c) float32: per target (mesh vertex, (t, 3) float metres) the mean of the probabilities ``proba``
    (m, c) of the up to ``neighbours`` nearest ``points`` (m, 3) within ``radius_m``, each weighted by
    ``1 / (d + 0.05 m)``; a zero row where no point is that near."""
    from scipy.spatial import cKDTree

    out = np.zeros((len(targets), proba.shape[1]), np.float32)
    if len(points) == 0 or len(targets) == 0:
        return out
    k = max(1, min(int(neighbours), len(points)))
    d, idx = cKDTree(np.asarray(points, np.float64)).query(np.asarray(targets, np.float64), k=k,
                                                           distance_upper_bound=radius_m, workers=workers)
    d, idx = d.reshape(len(targets), k), idx.reshape(len(targets), k)
    ok = np.isfinite(d)
    w = np.where(ok, 1.0 / (d + 0.05), 0.0).astype(np.float32)
    safe = np.where(ok, idx, 0)
    for j in range(k):
        out += w[:, j:j + 1] * proba[safe[:, j]]
    tot = w.sum(axis=1, keepdims=True)
    np.divide(out, tot, out=out, where=tot > 0)
    return out
