"""3D context in the vote: geometric cues from the mesh alone, turned into a per-vertex class prior.

The 2D model sees pixels; the mesh knows where the ground is. Each cue is a physical statement
about a vertex's neighbourhood (site frame, metres, z up), and each becomes a soft factor on the
class distribution of the blended vote (``p(class) * prior(class)``, then argmax), so strong,
unanimous evidence can still win over a cue and nothing is decided by the cue alone:

- ``ground``: an up-facing vertex (normal z >= ``up_normal_z``) at most ``max_curb_m`` above the
  local ground is ground. Its classes other than road, sidewalk and terrain are scaled by
  ``ground_factor`` (a flat surface at ground level is not a car, a bush, a wall). The local
  ground is :class:`twinkit.street.ground.LocalGround` (its opening) with a window of ``ground_window_m``,
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

Objects above the ground (:func:`objects.objects_above_ground`): the vertices above the highest curb
(``max_curb_m``) that are not ground, split into the connected parts of the mesh they form (a
pole, a sign plate, a car, a hedge, a building's facade). Each object has a top, a bottom, a
footprint (its horizontal extent along its principal axes) and a horizontal *slice* per
``slice_m`` of height, with the slice's own extent. Five shape cues read them (``SHAPE_CUES``;
all but ``slender`` on by default, ``DEFAULT_CUES``):

- ``column``: a vertex in a slice at most ``column_width_m`` across, of an object whose thin
  slices span at least ``column_span_m``, whose top stands at least ``column_top_m`` up and that
  carries no crown (no slice ``crown_m`` wide both ways, and no such object above it): a post, not
  building, vegetation, a vehicle. Everything but pole, traffic light and sign is scaled by
  ``shape_factor``.
- ``mounted``: a compact item ``mount_min_m``..``mount_max_m`` up, either the wider slices of a
  column or an object that floats (its bottom ``float_m`` above the ground, at most ``compact_m``
  in any direction: carried by a post too thin for the scan) free, at least ``clear_m`` from any
  larger object (else it is a fragment of a facade or a crown the mesh split off): everything but
  pole, light and sign x ``shape_factor``; a thin plate (thinner than ``plate_m`` with its post) is a sign (light x
  ``mount_factor``), a bulkier box a signal head (sign x ``mount_factor``).
- ``low``: an object whose top stands less than ``low_top_m`` above the ground is no building and
  carries no signal head (those hang with their lower edge 2 m up or more): building and traffic
  light x ``shape_factor``.
- ``narrow``: an object whose footprint is narrower than ``narrow_m`` is no car, truck, bus or train.
- ``slender``: a low object (top under ``low_top_m``) thinner than ``hedge_min_m`` is no vegetation
  (a fence, a wall, a bicycle, a bollard; even a trimmed hedge is thicker).

The floor for near-unanimous evidence (``fuse_with_context(keep=...)``, from
:func:`near_unanimous`): a vertex whose own votes (or, if asked, its segment's) give one class a
share of at least ``keep_share`` from at least ``keep_votes`` views (``backproject``'s params) gets
no prior and keeps the plain vote's label through the fill and the smoothing.

The curb's own face and rounded edge (not up-facing) join the band with ``curb_face``. Votes the
cues explain away are replaced by the neighbours' allowed labels (:func:`fill_allowed`), on a band
by sidewalk (``band_default``); :func:`potts_smooth` smooths the result on the vertex graph.
:func:`segment_smooth` (``fuse_with_context(segment_weight=...)``, not used by the step, not
measured) would average the prior over each over-segmentation segment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twinkit.cityscapes import (BUILDING, GROUND, MOVABLE, N_CLASSES, ROAD, SIDEWALK, STREET_FURNITURE,
                                TRAFFIC_LIGHT, TRAFFIC_SIGN, VEGETATION, WIDE_VEHICLES)
from twinkit.ranges import param

SHAPE_CUES = ("column", "mounted", "low", "narrow", "slender")
CUES = ("ground", "raised", "high", "curb") + SHAPE_CUES
#: on by default: every cue that helped on each measured seed (slender helps only where the 2D model
#: votes fence at all; docs/segmentation.md "Shape cues")
DEFAULT_CUES = tuple(c for c in CUES if c != "slender")


@dataclass
class ContextOptions:
    ground_window_m: float = param(3.0,
                                   help="Window (m) of the local ground model, wider than the widest vehicle (a bus "
                                        "is 2.55 m wide), so a car roof never counts as ground.")
    cell_m: float = param(0.25,
                          help="Cell size (m) of the local ground grid and of the grid on which curb steps are "
                               "found.")
    up_normal_z: float = param(0.85,
                               help="A vertex is up-facing when its normal's z is at least this (about 32 degrees "
                                    "from level; ramps are under 15 %).")
    max_curb_m: float = param(0.30,
                              help="The highest curb (m): up-facing vertices up to this above the local ground are "
                                   "ground.")
    min_object_m: float = param(0.50,
                                help="Above any curb and step (m): a vertex higher than this above the local ground "
                                     "is an object, not the ground.")
    max_vehicle_m: float = param(4.70,
                                 help="Above the tallest road vehicle (m; buses and trucks are 4.0-4.6 m): nothing "
                                      "higher is a vehicle or a person.")
    min_curb_m: float = param(0.05, help="The lowest curb step (m).")
    step_radius_m: float = param(0.5,
                                 help="A curb rises within this distance (m); a road's slope or camber does not.")
    band_width_m: float = param(4.0, help="A sidewalk band lies at most this far (m) from its curb.")
    level_tol_m: float = param(0.06,
                               help="The band is level with the curb's top within this (m), allowing for the cross "
                                    "slope.")
    ground_factor: float = param(0.1,
                                 help="Prior of the classes other than road, sidewalk and terrain on a ground "
                                      "vertex (the ground cue).")
    raised_factor: float = param(0.1,
                                 help="Prior of road, sidewalk and terrain on a vertex above min_object_m (the "
                                      "raised cue).")
    high_factor: float = param(0.1, help="Prior of vehicles, riders and persons above max_vehicle_m (the high cue).")
    curb_factor: float = param(0.2, help="Prior of road on a raised band beside a curb (the curb cue).")
    curb_face: bool = param(True, help="The curb's own face and edge count as the band (and as ground).")
    band_default: bool = param(True, help="Band vertices whose votes the cues explained away become sidewalk.")
    # objects above the ground and their shape (lengths: physical sizes, see docs/segmentation.md)
    slice_m: float = param(0.25,
                           help="Height (m) of one horizontal slice of an object above the ground: finer than any "
                                "signal head (>= 0.3 m) or sign plate (>= 0.4 m).")
    column_width_m: float = param(0.40,
                                  help="A post's slice is at most this wide (m): posts are at most ~0.3 m across "
                                       "(lamp posts 0.1-0.3 m), plus the reconstruction's blur.")
    column_span_m: float = param(1.5,
                                 help="A post's bare shaft spans at least this height (m), from the curb to its "
                                      "load above head height.")
    column_top_m: float = param(2.2,
                                help="A post's top stands at least this high (m): signs and signal heads hang above "
                                     "head clearance (>= 2.2 m over a footway).")
    crown_m: float = param(1.5,
                           help="A tree crown is wider than this (m) both ways; a plate, a signal head or a lamp "
                                "arm is not.")
    float_m: float = param(1.0,
                           help="An object whose lowest point is this far up (m) stands on nothing the scan saw (it "
                                "floats).")
    compact_m: float = param(1.5, help="A sign plate or a signal head is at most this large (m) in any direction.")
    clear_m: float = param(0.5,
                           help="A free-standing sign or signal head stands at least this far (m) clear of facades "
                                "and crowns (sidewalk clearance).")
    mount_min_m: float = param(1.5,
                               help="Mounted items hang between mount_min_m and mount_max_m (m) above the ground.")
    mount_max_m: float = param(8.0,
                               help="Upper height (m) of mounted items (overhead signals reach ~6-7 m, lamps 8-10 "
                                    "m).")
    plate_m: float = param(0.30,
                           help="A sign plate with its post is thinner than this (m; a plate is centimetres, a post "
                                "<= 0.2 m); a signal head (>= 0.25 m deep) beside its post is thicker.")
    low_top_m: float = param(2.5,
                             help="An object whose top is lower than this (m) is no building (a storey is >= 2.5 m) "
                                  "and carries no signal head (heads hang >= 2 m up); walls, fences, hedges and "
                                  "cars are lower.")
    narrow_m: float = param(1.2,
                            help="An object narrower than this (m) is no car, truck, bus or train (the narrowest "
                                 "cars, quadricycles, are 1.24 m wide).")
    hedge_min_m: float = param(0.4,
                               help="Even a trimmed hedge is thicker than this (m); a fence, a wall, a bicycle or a "
                                    "post is thinner.")
    shape_factor: float = param(0.1, help="Prior of the classes a shape cue rules out.")
    mount_factor: float = param(0.2,
                                help="Prior of the less likely reading of a mounted item (a light on a plate, a "
                                     "sign on a box): unlikely, not ruled out.")


def near_unanimous(vertex_votes: np.ndarray, segments: np.ndarray | None, share: float,
                   min_votes: float = 0.0) -> np.ndarray:
    """(n,) bool: vertices whose own votes, or whose segment's, give one class at least ``share`` of
    the mass, from at least ``min_votes`` votes (one per view with ``vote_per_view``): the floor
    below which no cue goes, near-unanimous evidence is left as it is."""
    v = np.asarray(vertex_votes, np.float64)
    if share <= 0 or share > 1:
        return np.zeros(len(v), bool)
    tot = v.sum(axis=1)
    sure = (tot > 0) & (tot >= min_votes) & (v.max(axis=1) >= share * tot)
    if segments is not None:
        seg = np.asarray(segments, np.int64)
        sv = np.zeros((int(seg.max()) + 1, v.shape[1]))
        np.add.at(sv, seg, v)
        st = sv.sum(axis=1)
        s_sure = (st > 0) & (st >= min_votes) & (sv.max(axis=1) >= share * st)
        sure |= s_sure[seg]
    return sure


def geometric_context(vertices: np.ndarray, normals: np.ndarray, opt: ContextOptions | None = None,
                      edges: np.ndarray | None = None, step_gate: np.ndarray | None = None) -> dict:
    """Per-vertex cue masks and the heights they come from: ``{"height": h, "ground": bool(n), ...}``.
    The shape cues need the mesh's ``edges`` (vertex pairs); without them their masks are empty.
    ``step_gate`` (n,) bool: the capture resolves a curb step at the vertex (:func:`gates.cue_gates`);
    a step cell counts only where most of its vertices say so (a step the scan lines or the noise
    made is no curb)."""
    from twinkit.street.ground import LocalGround

    opt = opt or ContextOptions()
    v = np.asarray(vertices, np.float64)
    nz = np.asarray(normals, np.float64)[:, 2]
    up = nz >= opt.up_normal_z
    g = LocalGround(v, up, window="opening", window_m=opt.ground_window_m, cell_m=opt.cell_m)
    h = g.height()
    ground = up & (h <= opt.max_curb_m)
    out = {"height": h, "ground": ground, "raised": h > opt.min_object_m, "high": h > opt.max_vehicle_m}
    # curb: step cells (surface min_curb..max_curb above the lowest surface nearby), then vertices on
    # their top level, beside them
    from scipy.ndimage import distance_transform_edt

    low = g.foot(opt.step_radius_m)
    step = g.steps(opt.min_curb_m, opt.step_radius_m, opt.max_curb_m)
    out["step_cells_ungated"] = int(step.sum())
    if step_gate is not None:
        gj, gi = g.cells(v[:, :2])
        n_in = np.zeros(step.shape)
        n_ok = np.zeros(step.shape)
        np.add.at(n_in, (gj, gi), 1.0)
        np.add.at(n_ok, (gj, gi), np.asarray(step_gate, np.float64))
        step &= n_ok >= 0.5 * np.maximum(n_in, 1.0)
    curb = np.zeros(len(v), bool)
    if step.any():
        d, (iy, ix) = distance_transform_edt(~step, return_indices=True)
        j, i = g.cells(v[:, :2])
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
    # objects: above the highest curb and not ground
    above = (h > opt.max_curb_m) & ~out["ground"]
    if edges is not None and len(edges):
        from .objects import shape_cues

        out.update(shape_cues(v, h, above, edges, opt))
    else:
        out.update({c: np.zeros(len(v), bool) for c in SHAPE_CUES + ("plate", "box")}, objects=0)
    return out


def context_prior(ctx: dict, opt: ContextOptions | None = None, cues=CUES) -> np.ndarray:
    """(n, 19) multiplicative class prior from the cue masks of :func:`geometric_context`; only the
    cues named in ``cues`` act."""
    opt = opt or ContextOptions()
    n = len(ctx["height"])
    prior = np.ones((n, N_CLASSES))
    other = [c for c in range(N_CLASSES) if c not in GROUND]
    if "ground" in cues:
        prior[np.ix_(ctx["ground"], other)] *= opt.ground_factor
    if "raised" in cues:
        prior[np.ix_(ctx["raised"], list(GROUND))] *= opt.raised_factor
    if "high" in cues:
        prior[np.ix_(ctx["high"], list(MOVABLE))] *= opt.high_factor
    if "curb" in cues:
        prior[ctx["curb"], ROAD] *= opt.curb_factor
    furniture_out = [c for c in range(N_CLASSES) if c not in STREET_FURNITURE]
    if "column" in cues:
        prior[np.ix_(ctx["column"], furniture_out)] *= opt.shape_factor
    if "mounted" in cues:
        prior[np.ix_(ctx["mounted"], furniture_out)] *= opt.shape_factor
        prior[ctx["plate"], TRAFFIC_LIGHT] *= opt.mount_factor
        prior[ctx["box"], TRAFFIC_SIGN] *= opt.mount_factor
    if "low" in cues:
        prior[np.ix_(ctx["low"], [BUILDING, TRAFFIC_LIGHT])] *= opt.shape_factor
    if "narrow" in cues:
        prior[np.ix_(ctx["narrow"], list(WIDE_VEHICLES))] *= opt.shape_factor
    if "slender" in cues:
        prior[ctx["slender"], VEGETATION] *= opt.shape_factor
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


def gated_context(vertices: np.ndarray, normals: np.ndarray, edges: np.ndarray, opt: ContextOptions,
                  gates: dict | None) -> tuple[dict, dict, np.ndarray | None]:
    """:func:`geometric_context` with each cue kept only where its gate (cue -> (n,) bool) is set; the curb's
    gate acts on the curb steps, ``low``'s also needs the scan's reach. Returns (context, the cues' vertex
    counts before gating, the curb step gate or None)."""
    gates = dict(gates or {})
    step_gate = gates.pop("curb", None)
    ctx = geometric_context(vertices, normals, opt, edges, step_gate=step_gate)
    if "low" in gates:
        from .gates import reach_gate

        gates["low"] = np.asarray(gates["low"], bool) & reach_gate(vertices, ctx["height"], opt)
    ungated = {c: int(ctx[c].sum()) for c in gates if c in ctx}
    for c, g in gates.items():
        if c in ctx:
            ctx[c] = ctx[c] & np.asarray(g, bool)
    for part in ("plate", "box"):  # the mounted item's reading as a sign or a signal head goes with it
        if part in ctx:
            ctx[part] = ctx[part] & ctx["mounted"]
    return ctx, ungated, step_gate


def fuse_with_context(p: np.ndarray, vertices: np.ndarray, normals: np.ndarray, edges: np.ndarray,
                      opt: ContextOptions | None = None, cues=DEFAULT_CUES, segments: np.ndarray | None = None,
                      segment_weight: float = 0.0, min_retained: float = 0.2,
                      smooth_beta: float = 0.0, smooth_iters: int = 5,
                      keep: np.ndarray | None = None,
                      extra_prior: np.ndarray | None = None,
                      gates: dict | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The blended vote ``p`` (n, 19) with the geometric prior: (labels (n,) uint8, 255 where nothing
    voted; confidence; metrics with the vertices each cue touched and changed).

    0. Vertices in ``keep`` (near-unanimous evidence, :func:`near_unanimous`) get no prior at all and
       keep the plain vote's label through the fill and the smoothing.
    1. ``q = p * prior``; argmax.
    2. Vertices whose votes the cues explained away (less than ``min_retained`` of their vote mass
       survives the prior) take the most common label of their neighbours that their context
       allows (:func:`fill_allowed`); on a curb band (``band_default``) they are sidewalk, the band's
       own meaning (else a grass verge behind the pavement grows into it); where no allowed neighbour
       is reached, the allowed class with the most votes, else sidewalk on a band, else the argmax of ``q``.
    3. With ``smooth_beta`` > 0, :func:`potts_smooth` with ``q`` as the unaries (uniform over the
       allowed classes where the votes were explained away).

    ``extra_prior`` (n, 19), e.g. the scan file's own classes (:mod:`twinkit_segmentation.fileclasses`),
    multiplies the geometric prior after step 0: near-unanimous views do not shield a vertex from it.
    ``gates`` (cue -> (n,) bool, :func:`twinkit_segmentation.gates.cue_gates`): a gated cue acts only
    where its gate is set (the capture resolves what it reads).
    """
    from twinkit_segmentation.metrics import decide_distribution

    opt = opt or ContextOptions()
    cues = tuple(c for c in cues if c in CUES)
    ctx, ungated, step_gate = gated_context(vertices, normals, edges, opt, gates)
    base, _ = decide_distribution(p)
    prior = context_prior(ctx, opt, cues)
    if segments is not None and segment_weight > 0:
        prior = segment_smooth(prior, segments, segment_weight)
    kept = np.zeros(len(p), bool) if keep is None else np.asarray(keep, bool)
    shielded = kept & (prior[np.arange(len(p)), p.argmax(axis=1)] < 1.0)  # a cue was against their class
    prior[kept] = 1.0  # the floor: no cue overrules near-unanimous evidence
    if extra_prior is not None:  # the file's classes: evidence from the capture itself, not a cue
        combined = prior * extra_prior
        file_ok = extra_prior >= 1.0
        speaks = ~file_ok.all(axis=1)
        # where the geometry rules out every class the file allows (ASPRS ground on a steep street reads
        # as "raised"), the file wins: it was classified on the full scan, the cues read the mesh
        clash = speaks & ~((combined >= 0.5) & file_ok).any(axis=1)
        combined[clash] = extra_prior[clash]
        prior = combined
    q = p * prior
    lab, conf = decide_distribution(q)
    allowed = prior >= 0.5
    ea = explained_away(p, prior, min_retained) if ((cues or extra_prior is not None) and min_retained > 0) else np.zeros(len(p), bool)
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
        lab, smoothed = potts_smooth(lab, unary, edges, smooth_beta, smooth_iters, fixed=kept)
    metrics = {"cues": list(cues), "explained_away": int(ea.sum()), "changed": int((lab != base).sum()),
               "smoothed": smoothed, "kept_unanimous": int(shielded.sum())}
    return lab, conf, {**metrics, **_cue_metrics(ctx, cues, lab != base, ungated, step_gate is not None)}


def _cue_metrics(ctx: dict, cues, changed: np.ndarray, ungated: dict, step_gated: bool) -> dict:
    """Per cue: the vertices it marks and those whose label the fusion changed there; what the gates took off."""
    out = {"step_cells": ctx["step_cells"], "objects": ctx["objects"],
           "gated_off": {c: n - int(ctx[c].sum()) for c, n in ungated.items()},
           "step_cells_gated_off": ctx["step_cells_ungated"] - ctx["step_cells"] if step_gated else 0}
    for c in CUES:
        m = ctx[c]
        out[f"{c}_vertices"] = int(m.sum())
        out[f"{c}_changed"] = int((m & changed).sum()) if c in cues else 0
    return out


def potts_smooth(labels: np.ndarray, unary: np.ndarray, edges: np.ndarray, beta: float = 1.0,
                 iters: int = 5, fixed: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Label smoothing on the vertex graph (a Potts model solved by iterated conditional modes):
    each vertex takes ``argmax_c log unary(c) + beta * share of its neighbours labelled c``, a few
    sweeps (all vertices at once). ``unary`` (n, 19) is a class distribution per vertex (rows of
    zeros: no evidence, the vertex keeps its label and only votes for its neighbours). Unlabelled
    vertices (255) neither vote nor change, nor do ``fixed`` ones (they still vote). Returns (labels,
    vertices changed)."""
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
    if fixed is not None:
        act &= ~np.asarray(fixed, bool)
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
