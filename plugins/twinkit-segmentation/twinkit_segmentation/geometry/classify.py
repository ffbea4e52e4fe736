"""Run the 3D classifier on a cloud and carry its class probabilities to mesh vertices."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from twinkit.cityscapes import BUILDING, ROAD, SIDEWALK, TERRAIN, WALL

from .features import _columns, block_mean, point_features
from .model import GeometryModel, load_model


@dataclass
class CloudLabels:
    """The classifier's answer for a cloud: ``base`` (m,) int64 indices of the base points (one per voxel)
    into the cloud, ``inverse`` (n,) int64 each cloud point's base point, ``proba`` (m, 19) float32 class
    probabilities of the base points, ``seconds`` per part, ``ground`` what :func:`diffuse_ground` found (None
    when it did not run)."""

    base: np.ndarray
    inverse: np.ndarray
    proba: np.ndarray
    seconds: dict
    ground: dict | None = None

    def point_labels(self) -> np.ndarray:
        """(n,) uint8 trainId of every cloud point (its base point's most probable class)."""
        return self.proba.argmax(axis=1).astype(np.uint8)[self.inverse]


def classify_cloud(xyz: np.ndarray, intensity: np.ndarray | None = None, model: GeometryModel | None = None,
                   *, base_voxel_m: float = 0.1, ground_window_m: float = 8.0, smooth_m: float = 0.25,
                   prior: bool = True, turns: int = 4, ground_alpha: float = 0.0,
                   ground_model: GeometryModel | None = None, ground_weight: float = 1.0) -> CloudLabels:
    """Features (:func:`.features.point_features`) and the MLP's probabilities for ``xyz`` (n, 3) float, site
    frame, z up, metres; ``intensity`` (n,) or None. ``model``: None = the shipped one. ``smooth_m``: each
    base point's probabilities become the normalised geometric mean of those of the base points in the
    3 x 3 x 3 voxels of this side around it (:func:`smooth_proba`); 0 = each point alone. ``prior``: apply the
    model's class-prior correction (:attr:`.model.GeometryModel.logit_shift`). ``turns``: the cloud is
    classified this many times, turned about the vertical by 90 / ``turns`` degrees each time (the voxel
    grids of the features are square to the axes, and how a grid cuts a surface is noise), and each base
    point of the first pass takes the normalised geometric mean of its point's probabilities in every pass.
    ``ground_alpha``: > 0 spreads the ground classes' probabilities along the smooth ground
    (:func:`diffuse_ground` with this ``alpha``); 0 = not. ``ground_model``: a model of the ground classes
    alone that splits each point's ground probability between them (:func:`split_ground`, ``ground_weight``);
    None = ``model``'s own split."""
    model = model or load_model()
    model.columns()  # a model reading a feature this code no longer computes: a clear error before any work
    if ground_model is not None:
        ground_model.columns()
    xyz = np.asarray(xyz, np.float64)
    n_turns = max(1, int(turns))
    first, logp, sec = None, None, {}
    for k in range(n_turns):
        pts = turned(xyz, 90.0 * k / n_turns)
        f = point_features(pts, intensity, base_voxel_m=base_voxel_m, ground_window_m=ground_window_m)
        t = time.perf_counter()
        proba = model.proba(f.values, prior=prior)
        if ground_model is not None:
            proba = split_ground(proba, ground_model.proba(f.values, prior=False), ground_model.classes,
                                 ground_weight)
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
        proba = first_proba
    else:
        logp /= n_turns  # the mean of the logarithms: a geometric mean, as sharp as one pass
        q = np.exp(logp - logp.max(axis=1, keepdims=True)) * (first_proba.max(axis=0) > 0)  # unused classes stay 0
        proba = (q / np.maximum(q.sum(axis=1, keepdims=True), 1e-30)).astype(np.float32)
    if ground_alpha > 0:
        t = time.perf_counter()
        proba, ground = diffuse_ground(xyz[first.base], proba, alpha=ground_alpha)
        sec["ground_diffusion"] = round(time.perf_counter() - t, 3)
    else:
        ground = None
    return CloudLabels(base=first.base, inverse=first.inverse, proba=proba, seconds=sec, ground=ground)


def split_ground(proba: np.ndarray, ground_proba: np.ndarray, classes: np.ndarray, weight: float = 1.0
                 ) -> np.ndarray:
    """(m, c) float32: ``proba`` (m, c) with each point's probability of the ground ``classes`` (trainIds)
    shared out between them as ``ground_proba`` (m, c), a model of those classes alone, says, weighted
    geometrically with ``proba``'s own split (``weight`` 1: the ground model's split alone, 0: unchanged).
    Each point keeps its total ground probability: which points are ground stays the whole model's answer,
    what the ground is made of becomes the specialist's (docs/segmentation.md "A ground model")."""
    cls = np.asarray(classes, np.int64)
    own = np.maximum(proba[:, cls].astype(np.float64), 1e-6)
    mass = proba[:, cls].sum(axis=1, keepdims=True)
    logq = (1.0 - weight) * np.log(own / own.sum(axis=1, keepdims=True)) + \
        weight * np.log(np.maximum(ground_proba[:, cls].astype(np.float64), 1e-6))
    q = np.exp(logq - logq.max(axis=1, keepdims=True))
    out = np.array(proba, np.float32, copy=True)
    out[:, cls] = (mass * q / q.sum(axis=1, keepdims=True)).astype(np.float32)
    return out


def diffuse_ground(points: np.ndarray, proba: np.ndarray, *, radius_m: float = 0.35, noise_k: float = 2.0,
                   slope: float = 0.03, alpha: float = 0.995,
                   groups: tuple[tuple[int, ...], ...] = ((ROAD,), (SIDEWALK, TERRAIN))) -> tuple[np.ndarray, dict]:
    """Spread the carriageway's and the raised ground's probabilities along the smooth ground, not across kerbs.

    ``points`` (m, 3) float metres, z up (base points, one per voxel); ``proba`` (m, c) their class
    probabilities. The points whose most probable class is in ``groups`` are joined to those within
    ``radius_m``; a pair's conductance is ``exp(-e^2 / 2 sigma^2)`` with ``e`` its height difference beyond
    ``slope`` times its horizontal distance and ``sigma`` = ``noise_k`` times the capture's own ground noise
    (the median height difference of pairs under 0.15 m apart), so a 10-15 cm kerb cuts the ground apart on
    a clean scan and a noisy one does not fall into pieces. Per group, the log of its probability ``l``
    becomes the solution of ``(D - alpha W) l = (1 - alpha) D l0`` (W the conductances, D their row sums):
    each point's own evidence mixed with its connected neighbours' out to a few metres (``alpha`` -> 1
    reaches farther). A kerb-bounded stretch of pavement that the single points half call road then mostly
    reads as one. The default groups are the road and the raised ground (pavement and grass together): a kerb
    parts the carriageway from what lies beside it, while pavement and a verge often meet flush, and spreading
    across that edge lets the larger eat the smaller. Each point keeps its total ground probability and, inside
    a group, its own split between the group's classes. Returns the new (m, c) float32 probabilities and
    ``{"points", "pairs", "noise_m"}`` (``noise_m`` None and the input returned when there are too few ground
    pairs to measure)."""
    from scipy.sparse import coo_matrix, diags
    from scipy.sparse.linalg import cg
    from scipy.spatial import cKDTree

    members = [np.asarray(g, np.int64) for g in groups]
    gi = np.flatnonzero(np.isin(proba.argmax(axis=1), np.concatenate(members)))
    info = {"points": int(len(gi)), "pairs": 0, "noise_m": None}
    if len(gi) < 50:
        return proba, info
    p = np.asarray(points, np.float64)[gi]
    pairs = cKDTree(p).query_pairs(radius_m, output_type="ndarray")
    if len(pairs) < 50:
        return proba, info
    dxy = np.linalg.norm(p[pairs[:, 0], :2] - p[pairs[:, 1], :2], axis=1)
    dz = np.abs(p[pairs[:, 0], 2] - p[pairs[:, 1], 2])
    near = dxy < 0.15
    if near.sum() < 50:
        return proba, info
    noise = max(float(np.median(dz[near])), 1e-3)
    w = np.exp(-0.5 * (np.maximum(dz - slope * dxy, 0.0) / (noise_k * noise)) ** 2)
    n = len(gi)
    rows, cols = np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]
    W = coo_matrix((np.r_[w, w], (rows, cols)), shape=(n, n)).tocsr()
    deg = np.asarray(W.sum(axis=1)).ravel() + 1e-6
    A = (diags(deg) - alpha * W).tocsr()
    precond = diags(1.0 / deg)
    pg = proba[gi].astype(np.float64)
    mass = np.stack([pg[:, m].sum(axis=1) for m in members], axis=1)  # (n, groups)
    l0 = np.log(np.maximum(mass, 1e-4))
    l0 -= l0[:, -1:]  # the system is linear and the split depends on differences only: one solve fewer
    lg = np.zeros_like(l0)
    for j in range(len(members) - 1):
        lg[:, j], _ = cg(A, (1 - alpha) * deg * l0[:, j], x0=l0[:, j], rtol=1e-4, M=precond)
    q = np.exp(lg - lg.max(axis=1, keepdims=True))
    q *= mass.sum(axis=1, keepdims=True) / q.sum(axis=1, keepdims=True)  # each point's ground total kept
    out = np.array(proba, np.float32, copy=True)
    for j, m in enumerate(members):
        split = pg[:, m] / np.maximum(mass[:, j:j + 1], 1e-12)
        split[mass[:, j] <= 1e-12] = 1.0 / len(m)
        out[np.ix_(gi, m)] = (q[:, j:j + 1] * split).astype(np.float32)
    info.update(pairs=int(len(pairs)), noise_m=round(noise, 4))
    return out, info


def cut_walls(points: np.ndarray, proba: np.ndarray, sensor: dict, tolerance_m: float,
              cell_m: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """(proba, cut): on a single spinning sweep whose sensor :func:`twinkit.surface.rings.ring_sensor` found,
    the points (m, 3) whose ``cell_m`` column (with its 8 neighbours) reaches within ``tolerance_m`` of the
    top beam's cone were cut by the scan, and their height is not known; the classifier tells a
    free-standing wall from a building by its height, so there its wall probability counts as building
    (docs/segmentation.md "Cut by the top beam"). ``proba`` (m, c) is not changed; ``cut`` (m,) bool."""
    from twinkit.surface.rings import under_ceiling

    pts = np.asarray(points, np.float64)
    if len(pts) == 0 or tolerance_m <= 0:
        return proba, np.zeros(len(pts), bool)
    z0 = float(pts[:, 2].min())
    top, _ = _columns(pts, pts[:, 2] - z0, cell_m)
    tops = np.column_stack([pts[:, :2], top + z0])
    cut = under_ceiling(tops, sensor) < tolerance_m
    out = proba.copy()
    out[cut, BUILDING] += out[cut, WALL]
    out[cut, WALL] = 0.0
    return out, cut


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
