"""3D context in the vote: geometric cues from the mesh alone, turned into a per-vertex class prior.

The 2D model sees pixels; the mesh knows where the ground is. Each cue is a physical statement
about a vertex's neighbourhood (site frame, metres, z up), and each becomes a soft factor on the
class distribution of the blended vote (``p(class) * prior(class)``, then argmax), so strong,
unanimous evidence can still win over a cue and nothing is decided by the cue alone:

- ``ground``: an up-facing vertex (normal z >= ``up_normal_z``) at most ``max_curb_m`` above the
  local ground is ground. Its classes other than road, sidewalk and terrain are scaled by
  ``ground_factor`` (a flat surface at ground level is not a car, a bush, a wall). The local
  ground is :class:`twinkit.surface.localground.LocalGround` with a window of ``ground_window_m``,
  wider than any vehicle is wide, so a car roof never counts as ground.
- ``raised``: a vertex more than ``min_object_m`` above the local ground (above any curb) is not
  road, sidewalk or terrain: those are scaled by ``raised_factor``.
- ``high``: a vertex more than ``max_vehicle_m`` above the local ground (taller than a bus or a
  truck) is no vehicle, rider or person: those are scaled by ``high_factor``.
- ``curb``: an up-facing ground vertex within ``band_width_m`` of a curb step (a cell whose
  surface stands ``min_curb_m``..``max_curb_m`` above the lowest surface within
  ``step_radius_m``), level with the step's top (within ``level_tol_m``) and ``min_curb_m``..
  ``max_curb_m`` above the step's foot, lies on a raised band beside a lower surface: a
  sidewalk (or a verge), not the carriageway. Road is scaled by ``curb_factor``.

The curb's own face and rounded edge (not up-facing) join the band with ``curb_face``. Votes the
cues explain away are replaced by the neighbours' allowed labels (:func:`fill_allowed`), on a band
by sidewalk (``band_default``); :func:`potts_smooth` smooths the result on the vertex graph.
:func:`segment_smooth` (``fuse_with_context(segment_weight=...)``, not used by the step, not
measured) would average the prior over each over-segmentation segment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.cityscapes import N_CLASSES

ROAD, SIDEWALK, TERRAIN = 0, 1, 9
GROUND_CLASSES = (ROAD, SIDEWALK, TERRAIN)
#: people and vehicles (person, rider, car, truck, bus, train, motorcycle, bicycle)
MOVABLE_CLASSES = (11, 12, 13, 14, 15, 16, 17, 18)
CUES = ("ground", "raised", "high", "curb")


@dataclass
class ContextOptions:
    ground_window_m: float = 3.0  # wider than the widest vehicle (a bus is 2.55 m wide)
    cell_m: float = 0.25
    up_normal_z: float = 0.85  # up-facing: at most ~32 degrees from level (ramps are under 15 %)
    max_curb_m: float = 0.30  # the highest curb; up-facing vertices up to this above the ground are ground
    min_object_m: float = 0.50  # above any curb and step: an object, not the ground
    max_vehicle_m: float = 4.70  # above the tallest road vehicle (buses and trucks: 4.0-4.6 m)
    min_curb_m: float = 0.05  # the lowest curb step
    step_radius_m: float = 0.5  # a curb rises within this distance (a road's slope or camber does not)
    band_width_m: float = 4.0  # a sidewalk band: at most this far from its curb
    level_tol_m: float = 0.06  # the band is level with the curb's top (cross slope)
    ground_factor: float = 0.1
    raised_factor: float = 0.1
    high_factor: float = 0.1
    curb_factor: float = 0.2
    curb_face: bool = True  # the curb's own face and edge count as the band (and as ground)
    band_default: bool = True  # band vertices whose votes are explained away become sidewalk


def geometric_context(vertices: np.ndarray, normals: np.ndarray, opt: ContextOptions | None = None) -> dict:
    """Per-vertex cue masks and the heights they come from: ``{"height": h, "ground": bool(n), ...}``."""
    from twinkit.surface.localground import LocalGround

    opt = opt or ContextOptions()
    v = np.asarray(vertices, np.float64)
    nz = np.asarray(normals, np.float64)[:, 2]
    g = LocalGround(v, normals, window_m=opt.ground_window_m, cell_m=opt.cell_m, up_normal_z=opt.up_normal_z)
    h = g.height(v)
    up = nz >= opt.up_normal_z
    ground = up & (h <= opt.max_curb_m)
    out = {"height": h, "ground": ground, "raised": h > opt.min_object_m, "high": h > opt.max_vehicle_m}
    # curb: step cells (surface min_curb..max_curb above the lowest surface nearby), then vertices on
    # their top level, beside them
    from scipy.ndimage import distance_transform_edt

    low = g.foot(opt.step_radius_m)
    step = g.steps(opt.min_curb_m, opt.step_radius_m, opt.max_curb_m)
    curb = np.zeros(len(v), bool)
    if step.any():
        d, (iy, ix) = distance_transform_edt(~step, return_indices=True)
        j, i = g._cells(v[:, :2])
        sj, si = iy[j, i], ix[j, i]
        top, foot = g.surface[sj, si], low[sj, si]
        above_foot = v[:, 2] - foot
        curb = (ground & (d[j, i] * g.cell <= opt.band_width_m) & (np.abs(v[:, 2] - top) <= opt.level_tol_m)
                & (above_foot >= opt.min_curb_m) & (above_foot <= opt.max_curb_m))
        if opt.curb_face:
            # the curb itself (its face and rounded edge, not up-facing): within the step's reach, above
            # the foot by at least half the lowest curb, not above the top; CityScapes counts it as sidewalk
            face = (~up & (d[j, i] * g.cell <= opt.step_radius_m) & (h <= opt.max_curb_m)
                    & (above_foot >= opt.min_curb_m / 2) & (v[:, 2] - top <= opt.level_tol_m))
            curb |= face
            out["ground"] = ground | face
    out["curb"] = curb
    out["step_cells"] = int(step.sum())
    return out


def context_prior(ctx: dict, opt: ContextOptions | None = None, cues=CUES) -> np.ndarray:
    """(n, 19) multiplicative class prior from the cue masks of :func:`geometric_context`; only the
    cues named in ``cues`` act."""
    opt = opt or ContextOptions()
    n = len(ctx["height"])
    prior = np.ones((n, N_CLASSES))
    other = [c for c in range(N_CLASSES) if c not in GROUND_CLASSES]
    if "ground" in cues:
        prior[np.ix_(ctx["ground"], other)] *= opt.ground_factor
    if "raised" in cues:
        prior[np.ix_(ctx["raised"], list(GROUND_CLASSES))] *= opt.raised_factor
    if "high" in cues:
        prior[np.ix_(ctx["high"], list(MOVABLE_CLASSES))] *= opt.high_factor
    if "curb" in cues:
        prior[ctx["curb"], ROAD] *= opt.curb_factor
    return prior


def segment_smooth(prior: np.ndarray, segments: np.ndarray, weight: float) -> np.ndarray:
    """Geometric mean of the prior over each segment, blended with the vertex's own (in log space)."""
    if weight <= 0:
        return prior
    seg = np.asarray(segments, np.int64)
    lp = np.log(np.maximum(prior, 1e-12))
    cnt = np.bincount(seg)
    mean = np.stack([np.bincount(seg, weights=lp[:, c], minlength=len(cnt)) for c in range(lp.shape[1])], axis=1)
    mean /= np.maximum(cnt, 1)[:, None]
    w = float(np.clip(weight, 0.0, 1.0))
    return np.exp(w * mean[seg] + (1 - w) * lp)


def explained_away(p: np.ndarray, prior: np.ndarray, min_retained: float) -> np.ndarray:
    """(n,) bool: seen vertices whose votes went almost all (all but ``min_retained`` of their mass) to
    classes their geometry rules out. Those votes describe something else the views saw there (the
    car in front of the pavement, the road beyond the curb) and say nothing about the vertex's class."""
    total = p.sum(axis=1)
    kept = (p * prior).sum(axis=1)
    return (total > 0) & (kept < min_retained * total)


def fill_allowed(labels: np.ndarray, missing: np.ndarray, allowed: np.ndarray, edges: np.ndarray,
                 max_iter: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Give each ``missing`` vertex the most common label among its labelled neighbours that its
    ``allowed`` (n, 19) mask permits, repeatedly (a band of pavement grows along itself, never from
    the road across the curb). Returns (labels, still missing)."""
    from scipy import sparse

    from twinkit.cityscapes import IGNORE

    lab = labels.copy()
    miss = missing.copy()
    lab[miss] = IGNORE
    n = len(lab)
    a = np.concatenate([edges[:, 0], edges[:, 1]])
    b = np.concatenate([edges[:, 1], edges[:, 0]])
    adj = sparse.csr_matrix((np.ones(len(a), np.float32), (a, b)), shape=(n, n))
    for _ in range(max_iter):
        if not miss.any():
            break
        known = (~miss) & (lab < N_CLASSES)
        onehot = sparse.csr_matrix((np.ones(int(known.sum()), np.float32),
                                    (np.nonzero(known)[0], lab[known].astype(np.int64))), shape=(n, N_CLASSES))
        idx = np.nonzero(miss)[0]
        counts = (adj[idx] @ onehot).toarray() * allowed[idx]
        got = counts.sum(axis=1) > 0
        if not got.any():
            break
        lab[idx[got]] = counts[got].argmax(axis=1).astype(np.uint8)
        miss[idx[got]] = False
    return lab, miss


def fuse_with_context(p: np.ndarray, vertices: np.ndarray, normals: np.ndarray, edges: np.ndarray,
                      opt: ContextOptions | None = None, cues=CUES, segments: np.ndarray | None = None,
                      segment_weight: float = 0.0, min_retained: float = 0.2,
                      smooth_beta: float = 0.0, smooth_iters: int = 5) -> tuple[np.ndarray, np.ndarray, dict]:
    """The blended vote ``p`` (n, 19) with the geometric prior: (labels (n,) uint8, 255 where nothing
    voted; confidence; metrics with the vertices each cue touched and changed).

    1. ``q = p * prior``; argmax.
    2. Vertices whose votes the cues explained away (less than ``min_retained`` of their vote mass
       survives the prior) take the most common label of their neighbours that their context
       allows (:func:`fill_allowed`); on a curb band (``band_default``) they are sidewalk, the band's
       own meaning (else a grass verge behind the pavement grows into it); where no allowed neighbour
       is reached, the allowed class with the most votes, else sidewalk on a band, else the argmax of ``q``.
    3. With ``smooth_beta`` > 0, :func:`potts_smooth` with ``q`` as the unaries (uniform over the
       allowed classes where the votes were explained away).
    """
    from twinkit_segmentation.metrics import decide_distribution

    opt = opt or ContextOptions()
    cues = tuple(c for c in cues if c in CUES)
    ctx = geometric_context(vertices, normals, opt)
    base, _ = decide_distribution(p)
    prior = context_prior(ctx, opt, cues)
    if segments is not None and segment_weight > 0:
        prior = segment_smooth(prior, segments, segment_weight)
    q = p * prior
    lab, conf = decide_distribution(q)
    allowed = prior >= 0.5
    ea = explained_away(p, prior, min_retained) if (cues and min_retained > 0) else np.zeros(len(p), bool)
    if ea.any():
        if "curb" in cues and opt.band_default:
            # a raised band beside the carriageway whose views saw something else (the car parked in
            # front of it, the road beyond): the band's own meaning, sidewalk
            band = ea & ctx["curb"]
            lab[band] = SIDEWALK
            ea_fill = ea & ~band
        else:
            ea_fill = ea
        lab, still = fill_allowed(lab, ea_fill, allowed, edges)
        qa = p * allowed
        if "curb" in cues:
            qa[ctx["curb"], SIDEWALK] += 1e-9  # a raised band beside the carriageway with no usable vote
        fallback = np.where(qa.sum(axis=1) > 0, qa.argmax(axis=1), q.argmax(axis=1)).astype(np.uint8)
        lab[still] = fallback[still]
        conf = conf.copy()
        conf[ea] = 0.0  # decided by the neighbours, not by the votes
    smoothed = 0
    if smooth_beta > 0:
        unary = q.copy()
        unary[ea] = allowed[ea]
        lab, smoothed = potts_smooth(lab, unary, edges, smooth_beta, smooth_iters)
    metrics = {"cues": list(cues), "explained_away": int(ea.sum()), "changed": int((lab != base).sum()),
               "smoothed": smoothed,
               "step_cells": ctx["step_cells"]}
    for c in CUES:
        m = ctx[c]
        metrics[f"{c}_vertices"] = int(m.sum())
        metrics[f"{c}_changed"] = int((m & (lab != base)).sum()) if c in cues else 0
    return lab, conf, metrics


def potts_smooth(labels: np.ndarray, unary: np.ndarray, edges: np.ndarray, beta: float = 1.0,
                 iters: int = 5) -> tuple[np.ndarray, int]:
    """Label smoothing on the vertex graph (a Potts model solved by iterated conditional modes):
    each vertex takes ``argmax_c log unary(c) + beta * share of its neighbours labelled c``, a few
    sweeps (all vertices at once). ``unary`` (n, 19) is a class distribution per vertex (rows of
    zeros: no evidence, the vertex keeps its label and only votes for its neighbours). Unlabelled
    vertices (255) neither vote nor change. Returns (labels, vertices changed)."""
    from scipy import sparse

    lab = np.asarray(labels).copy()
    n = len(lab)
    if beta <= 0 or iters <= 0 or n == 0:
        return lab, 0
    a = np.concatenate([edges[:, 0], edges[:, 1]])
    b = np.concatenate([edges[:, 1], edges[:, 0]])
    adj = sparse.csr_matrix((np.ones(len(a), np.float32), (a, b)), shape=(n, n))
    deg = np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)
    tot = unary.sum(axis=1)
    act = (tot > 0) & (lab < N_CLASSES)
    lu = np.log(np.maximum(unary[act] / tot[act, None], 1e-4))
    start = lab.copy()
    for _ in range(iters):
        known = lab < N_CLASSES
        oh = sparse.csr_matrix((np.ones(int(known.sum()), np.float32), (np.nonzero(known)[0], lab[known].astype(np.int64))),
                               shape=(n, N_CLASSES))
        share = (adj[act] @ oh).toarray() / deg[act, None]
        new = (lu + beta * share).argmax(axis=1).astype(lab.dtype)
        if (new == lab[act]).all():
            break
        lab[act] = new
    return lab, int((lab != start).sum())
