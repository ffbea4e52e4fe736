"""The backproject step's parts: the views' distribution, the geometry votes, the cue gates and the fusion with
the 3D context, each reading what the step read and returning arrays and metrics (docs/segmentation.md
"Fusion", "Cue gates"). :func:`steps.backproject` reads the files, calls these, writes the labels."""
from __future__ import annotations

import time
from pathlib import Path

from twinkit import StepContext
from twinkit import artefacts as A

from .params import BackprojectParams

def context_options(params: BackprojectParams):
    """The :class:`ContextOptions` of ``backproject``'s params (the bench fuses with the same)."""
    from twinkit_segmentation.context import ContextOptions

    return ContextOptions(ground_window_m=params.ground_window_m, max_curb_m=params.max_curb_m,
                          min_object_m=params.min_object_m, max_vehicle_m=params.max_vehicle_m,
                          min_curb_m=params.min_curb_m, band_width_m=params.band_width_m,
                          ground_factor=params.context_factor, raised_factor=params.context_factor,
                          high_factor=params.context_factor, curb_factor=params.curb_factor,
                          curb_face=params.curb_face, band_default=params.band_default,
                          shape_factor=params.context_factor)


def _geometry_votes(path: Path | None, n: int):
    """geometry_votes.npy as (n, 19) float64, or None without one; ArtefactError on a wrong shape."""
    import numpy as np

    if path is None:
        return None
    g = A.read_class_votes(path, n, "textured_mesh.ply")
    return np.nan_to_num(g.astype(np.float64), nan=0.0).clip(0, None)


def _fuse_sources(params: BackprojectParams, ctx: StepContext, p_views, votes, geom, cloud):
    """The views' distribution fused with the geometry's (:func:`fusion.fuse_sources`) with the weights of
    the capture's kind: (p (n, 19), the fusion's metrics)."""
    from twinkit_segmentation.fusion import capture_kind, fuse_sources, load_weights
    from twinkit_segmentation.metrics import _weighted_votes

    if geom is None:
        return p_views, {"geometry": False}
    kind = capture_kind(None if cloud is None else cloud.colors)
    weights = load_weights(params.fusion_weights or None)
    w = weights.for_kind(kind)
    n_views = _weighted_votes(votes, params.ignore_classes).sum(axis=1)
    p, info = fuse_sources(p_views, n_views, geom, w)
    at10 = float(w.views_at(10.0))
    info.update({"kind": kind, "weights": vars(w), "views_weight_at_10_views": round(at10, 4),
                 "weights_recipe": weights.recipe.get(kind, weights.recipe)})
    ctx.log.info("fusion (%s capture): views x %.2f at 10 views (x %.2f, coverage %.1f views), geometry x %.2f; %d "
                 "vertices both, %d views only, %d geometry only", kind, at10, w.views, w.coverage_views, w.geometry,
                 info["both"], info["views_only"], info["geometry_only"])
    return p, info


def capture_two_way_share(in_points_meta_json: Path | None, cloud=None) -> float | None:
    """The share of the capture's ground sampled in patches rather than single scan lines (points_meta.json's
    density block, :func:`twinkit.surface.density.measure`; an older file's is measured from ``cloud``'s
    vertices when given); None without points_meta.json or ground."""
    if in_points_meta_json is None or not Path(in_points_meta_json).is_file():
        return None
    return A.read_points_meta(in_points_meta_json, points=None if cloud is None else cloud.vertices).ground_two_way_share


def _cue_gates(params: BackprojectParams, ctx: StepContext, mesh, cloud, geom=None, two_way_share=None):
    """(cue -> (n,) bool gate, or None; the gates' metrics). ``geom`` (n, 19) or None: the 3D classifier's
    votes, which gate the furniture cues (``furniture_geometry_share``); ``two_way_share``: the share of the
    capture's ground sampled in patches (points_meta.json), under ``furniture_min_two_way_share`` the
    furniture cues are off everywhere, under ``curb_min_two_way_share`` the curb cue where ``geom`` is given
    (None: unknown, no such gate)."""
    if not params.cue_gates or cloud is None or not params.context:
        return None, {"used": False}
    import numpy as np

    from twinkit_segmentation.gates import FURNITURE_CUES, capture_quality, cue_gates, geometry_gate
    from twinkit_segmentation.segmesh import unit_normals

    t = time.perf_counter()
    opt = context_options(params)
    q = capture_quality(cloud.vertices, mesh.vertices, unit_normals(mesh)[:, 2] >= opt.up_normal_z,
                        threads=max(1, int(getattr(ctx, "threads", 1) or 1)))
    gates = cue_gates(q, opt)
    info = {"used": True, "ground_two_way_share": two_way_share}
    if two_way_share is not None and two_way_share < params.furniture_min_two_way_share:
        ctx.log.info("cue gates: %.0f %% of the capture's ground is sampled in patches (under "
                     "furniture_min_two_way_share=%g: single scan lines, a spinning sweep): the furniture cues (%s) "
                     "stay off, a ring fragment of a crown floats free as a sign would", 100 * two_way_share,
                     params.furniture_min_two_way_share, "/".join(FURNITURE_CUES))
        for c in FURNITURE_CUES:
            gates[c] = np.zeros(len(mesh.vertices), bool)
    if geom is not None and two_way_share is not None and two_way_share < params.curb_min_two_way_share:
        ctx.log.info("cue gates: %.0f %% of the capture's ground is sampled in patches (under "
                     "curb_min_two_way_share=%g): the curb cue stays off beside the 3D classifier, a sweep's near "
                     "rings stand off each other as kerbs would", 100 * two_way_share, params.curb_min_two_way_share)
        gates["curb"] = np.zeros(len(mesh.vertices), bool)
    if geom is not None and params.furniture_geometry_share > 0:
        said = geometry_gate(geom, params.furniture_geometry_share)
        info["furniture_by_geometry_share"] = round(float(said.mean()), 4)
        for c in FURNITURE_CUES:
            gates[c] = gates[c] & said
    info.update({"seconds": round(time.perf_counter() - t, 3),
                 "support_m_p50": round(float(np.median(q["support_m"])), 4),
                 "noise_m_p50": round(float(np.median(q["noise_m"])), 4) if np.isfinite(q["noise_m"]).any() else None,
                 "passed_share": {c: round(float(g.mean()), 4) for c, g in gates.items()}})
    off = {c: 1 - v for c, v in info["passed_share"].items() if c in ("curb", "column", "low") and v < 0.9}
    if off:
        ctx.log.warning("cue gates: the capture is too sparse or noisy for %s on %s of the mesh (median support "
                        "%.3f m, noise %s); those cues stay off there, the views and the geometry decide",
                        "/".join(off), "/".join(f"{100 * v:.0f} %" for v in off.values()), info["support_m_p50"],
                        f"{info['noise_m_p50']:.4f} m" if info["noise_m_p50"] is not None else "unmeasured")
    else:
        ctx.log.info("cue gates: the capture resolves the cues on %s", info["passed_share"])
    return gates, info


def geometry_floor(params: BackprojectParams, ctx: StepContext, geom, kind: str | None, two_way_share):
    """(n,) bool, or None where it does not act: the vertices whose 3D-classifier votes (``geom`` (n, 19) or
    None) give one class at least ``geometry_floor_share`` of their total, on a colourless capture (``kind``) whose
    ground is sampled in rings (``two_way_share`` under ``geometry_floor_max_two_way_share``; None: unknown, no
    floor). There the classifier leads, and the mesh's shape cues read the rings' fragments: a sure vertex keeps
    its class as near-unanimous views keep theirs where they lead."""
    if (geom is None or kind != "colourless" or params.geometry_floor_share <= 0 or two_way_share is None
            or two_way_share >= params.geometry_floor_max_two_way_share):
        return None
    tot = geom.sum(axis=1)
    sure = (tot > 0) & (geom.max(axis=1) >= params.geometry_floor_share * tot)
    ctx.log.info("geometry floor: %.0f %% of the capture's ground is sampled in patches (a capture in rings): %d "
                 "vertices (%.1f %%) whose 3D classifier gives one class %.0f %% or more keep it against the cues",
                 100 * two_way_share, int(sure.sum()), 100 * float(sure.mean()), 100 * params.geometry_floor_share)
    return sure


def vote_distribution(params: BackprojectParams, seg, votes):
    """(p (n, 19) float64 class distribution per vertex, its total votes (n,)): the vertex's own weighted
    votes, blended with its segment's (``seg`` (n,) int) when ``params.use_segments``. ``votes``: (n, 19)
    float64 votes per vertex and trainId."""
    from twinkit_segmentation.metrics import _weighted_votes, blend_distribution

    if params.use_segments:
        return blend_distribution(seg, votes, params.segment_weight, params.ignore_classes,
                                  params.class_weights or None)
    p = _weighted_votes(votes, params.ignore_classes, params.class_weights or None)
    return p, p.sum(axis=1)


def _fuse(params: BackprojectParams, ctx: StepContext, mesh, p, votes, labels, conf, fprior, gates=None,
          unshield=None, cues=None, floor=None):
    """The vote scaled by the mesh's geometric cues and the file's classes (``fprior`` (n, 19) or None), or
    Potts smoothing alone: (labels, confidence, mesh edges or None, the fusion's metrics, seconds). ``unshield``
    (n,) bool: vertices the views' near-unanimous floor does not hold; ``floor`` (n,) bool: vertices held
    against the cues whatever the views (:func:`geometry_floor`)."""
    from twinkit.cityscapes import IGNORE
    from twinkit.mesh import edges as mesh_edges
    from twinkit_segmentation.context import fuse_with_context, near_unanimous, potts_smooth
    from twinkit_segmentation.metrics import _weighted_votes
    from twinkit_segmentation.segmesh import unit_normals

    edges = None
    cmet: dict = {}
    t_ctx = 0.0
    cues = list(params.context_cues) if cues is None else list(cues)
    if (params.context and cues) or fprior is not None:
        # the file's classes go through the same fusion as the cues (with no cue when context is off)
        cues = cues if params.context else []
        t1 = time.perf_counter()
        edges = mesh_edges(mesh.faces, len(mesh.vertices))
        keep = labels == IGNORE
        sure = near_unanimous(_weighted_votes(votes, params.ignore_classes, params.class_weights or None), None,
                              params.keep_share, params.keep_votes)
        if unshield is not None:
            sure &= ~unshield
        if floor is not None:
            sure |= floor
        labels, conf, cmet = fuse_with_context(p, mesh.vertices, unit_normals(mesh), edges, context_options(params),
                                               cues, min_retained=params.min_retained,
                                               smooth_beta=params.smooth_beta, smooth_iters=params.smooth_iters,
                                               keep=sure, extra_prior=fprior, gates=gates)
        labels[keep] = IGNORE  # too few votes stays too few votes
        t_ctx = time.perf_counter() - t1
        ctx.log.info("3D context (%s): %d vertices changed (%s), %d votes explained away, %d smoothed, "
                     "%d objects above the ground, %d near-unanimous vertices kept against a cue, %.2f s",
                     "+".join(cmet["cues"]), cmet["changed"],
                     ", ".join(f"{c} {cmet[c + '_changed']}" for c in cmet["cues"]), cmet["explained_away"],
                     cmet["smoothed"], cmet["objects"], cmet["kept_unanimous"], t_ctx)
    elif params.smooth_beta > 0:
        t1 = time.perf_counter()
        edges = mesh_edges(mesh.faces, len(mesh.vertices))
        labels, n_s = potts_smooth(labels, p, edges, params.smooth_beta, params.smooth_iters)
        cmet = {"smoothed": n_s}
        t_ctx = time.perf_counter() - t1
        ctx.log.info("Potts smoothing: %d vertices changed, %.2f s", n_s, t_ctx)
    return labels, conf, edges, cmet, t_ctx
