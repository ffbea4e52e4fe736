"""The steps of view-based segmentation. Each writes files one can open:

    oversegment           segments.npy (int32 per vertex), segments.ply (random colour per segment)
    sample_views          views.json
    render_views          renders/ (<view>.png, <view>_vertex.npz, index.json)
    photo_views           renders/ as render_views, the capture's photos as the images (+ rendered views)
    predict_views         predictions/ (<view>.png, palette PNG whose pixel values are trainIds),
                          vertex_votes.npy (float32, vertices x 19)
    backproject           labels.npy (uint8 per vertex, 255 = none), confidence.npy, labels.ply, confidence.png
    transfer_gt_labels    gt_labels.npy, gt_labels.ply (ground truth on the reconstructed vertices)
    evaluate_segmentation seg_metrics.json, seg_metrics.md
    import_labels         labels.npy from a repainted labels.ply, label_changes.json

Splitting them this way makes the cache pay: changing the over-segmentation re-runs only
oversegment, backproject and evaluate (votes are stored per vertex, not per segment);
changing the 2D model re-uses the renders.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from twinkit import InputError, StepContext
from twinkit import artefacts as A

from .backproject_parts import (_cue_gates, _fuse, _fuse_sources, _geometry_votes, capture_two_way_share,
                                 geometry_floor, vote_distribution)
from .params import (BackprojectParams, EvaluateParams, FelzenszwalbParams, ImportLabelsParams, NoSegmentsParams,
                     PhotoViewsParams, PredictParams, RenderParams, SampleViewsParams, TransferGtParams)


# ----------------------------------------------------------------------------- over-segmentation

def oversegment(params: FelzenszwalbParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                out_segments_npy: Path, out_segments_ply: Path) -> dict:
    """Felzenszwalb over-segmentation of the mesh graph (normals + colours); segments.npy per vertex."""
    import numpy as np

    from twinkit.mesh import write_colored_ply
    from twinkit_segmentation.segmesh import random_colors, unit_normals
    from twinkit_segmentation.oversegment import felzenszwalb_mesh

    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    t0, c0 = time.perf_counter(), time.process_time()
    seg = felzenszwalb_mesh(mesh.vertices, mesh.faces, unit_normals(mesh), mesh.colors,
                            params.k_threshold, params.min_vertices, params.max_vertices,
                            params.normal_weight, params.colour_weight)
    secs, cpu = time.perf_counter() - t0, time.process_time() - c0
    np.save(out_segments_npy, seg)
    n = int(seg.max()) + 1
    write_colored_ply(out_segments_ply, mesh.vertices, mesh.faces, random_colors(n)[seg],
                      extra={"segment": seg.astype(np.int32)}, comment="twinkit-segmentation segments")
    sizes = np.bincount(seg)
    ctx.log.info("%d segments (mean %.1f vertices) in %.2f s", n, sizes.mean(), secs)
    return {"segments": n, "mean_segment_vertices": float(sizes.mean()), "max_segment_vertices": int(sizes.max()),
            "seconds": round(secs, 3), "cpu_seconds": round(cpu, 3), "vertices": int(len(seg))}


def no_oversegment(params: NoSegmentsParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                   out_segments_npy: Path, out_segments_ply: Path) -> dict:
    """No over-segmentation: every vertex is its own segment (the thesis's ablation)."""
    import numpy as np

    from twinkit.mesh import write_colored_ply

    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    seg = np.arange(len(mesh.vertices), dtype=np.int32)
    np.save(out_segments_npy, seg)
    cols = mesh.colors if mesh.colors is not None else np.full((len(seg), 3), 128, np.uint8)
    write_colored_ply(out_segments_ply, mesh.vertices, mesh.faces, cols, comment="twinkit-segmentation: no segments")
    return {"segments": int(len(seg)), "mean_segment_vertices": 1.0}


# ----------------------------------------------------------------------------- view sampling

def sample_views(params: SampleViewsParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                 in_roads_osm: Path | None = None, in_street_points_txt: Path | None = None,
                 in_points_ply: Path | None = None, out_views_json: Path) -> dict:
    """Camera views from the selected view sampler (view_sampler=auto_street|street_points|uniform|random|combined)."""
    from twinkit_segmentation.render import per_sampler

    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    t0 = time.perf_counter()
    budget = params.auto_max_views if params.max_views < 0 else params.max_views
    capture, colourless = _capture(in_points_ply, ctx)
    if colourless and not params.colourless_views:
        why = (f"{Path(in_points_ply).name} has no colours: no views (the 3D classifier labels a colourless capture; "
               f"steps.sample_views.colourless_views=true renders its grey views too)")
        ctx.log.info("sample_views: %s", why)
        out_views_json.write_text(json.dumps({"sampler": None, "counts": {}, "views": [], "sampled": 0,
                                              "max_views": budget, "skipped": why}, indent=1))
        return {"views": 0, "sampled_views": 0, "max_views": budget, "capture": capture, "skipped": why,
                "seconds": round(time.perf_counter() - t0, 3)}
    roads_osm = A.read_osm(in_roads_osm) if in_roads_osm is not None else None
    views, sampled = _sample_views(mesh, ctx, roads_osm, in_street_points_txt, budget, with_total=True,
                                   capture=capture)
    if not views:
        raise InputError(f"{in_textured_mesh_ply}: the view sampler produced no views; try another view_sampler")
    if len(views) < sampled:
        ctx.log.warning("sample_views: %d views sampled, %d kept (max_views %d%s): whole camera positions, "
                        "spread over the site", sampled, len(views), budget, " auto" if params.max_views < 0 else "")
    counts = per_sampler(views)
    sampler_name = (ctx.config.get("view_sampler") or {}).get("plugin", "?") if ctx.config else "?"
    out_views_json.write_text(json.dumps({"sampler": sampler_name, "counts": counts, "views": views,
                                          "sampled": sampled, "max_views": budget}, indent=1))
    return {"views": len(views), "sampled_views": sampled, "max_views": budget, "capture": capture,
            "per_sampler": counts,
            "seconds": round(time.perf_counter() - t0, 3)}


def _capture(points_ply: Path | None, ctx) -> tuple[str | None, bool]:
    """(the capture type of the cloud (twinkit.surface.density), whether it is colourless
    (:func:`fusion.capture_kind`)), when the run has one; (None, False) without."""
    if points_ply is None or not Path(points_ply).is_file():
        return None, False
    from twinkit.surface import density
    from twinkit_segmentation.fusion import capture_kind

    cloud = A.read_points(points_ply)
    m = density.measure(cloud.vertices)
    ctx.log.info("sample_views: %s", density.describe(m))
    return m["capture"], capture_kind(cloud.colors) == "colourless"


def _sample_views(mesh, ctx, roads_osm, street_points, max_views: int, with_total: bool = False,
                  capture: str | None = None):
    """The selected view sampler's views, cut to ``max_views`` (> 0) by :func:`cap_views`
    (with ``with_total``: (views, how many were sampled))."""
    from twinkit_segmentation.segmesh import unit_normals
    from twinkit_segmentation.views import Scene, cap_views

    scene = Scene(mesh.vertices, mesh.faces, unit_normals(mesh), site=ctx.site,
                  roads_osm=roads_osm, street_points=street_points)
    scene.capture = capture
    views = ctx.component("view_sampler").sample(scene, ctx)
    total = len(views)
    if max_views and len(views) > max_views:
        views = cap_views(views, max_views)
    return (views, total) if with_total else views


# ----------------------------------------------------------------------------- rendering

def render_views(params: RenderParams, ctx: StepContext, *, in_textured_mesh_ply: Path, in_views_json: Path,
                 out_renders_dir: Path) -> dict:
    """Render every view unlit with a sky background; per pixel the nearest vertex (<view>_vertex.npz)."""
    from twinkit_segmentation.render import load_texture, per_sampler, render_view_set, view_signal

    with ctx.substep("read"):
        try:
            vj = json.loads(Path(in_views_json).read_text())
            views = vj["views"]
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{in_views_json}: not a views file ({exc}); re-run sample_views") from None
        mesh = A.read_textured_mesh(in_textured_mesh_ply)
        if not views and vj.get("skipped"):
            out_renders_dir.mkdir(parents=True, exist_ok=True)
            (out_renders_dir / "index.json").write_text(json.dumps(
                {"n_vertices": int(len(mesh.vertices)), "kept": [], "dropped": [], "skipped": vj["skipped"]}, indent=1))
            return {"views": 0, "kept": 0, "skipped": vj["skipped"]}
        tex = load_texture(mesh.texture) if mesh.texture is not None else None
        if tex is None:
            ctx.log.warning("%s has no texture; rendering flat grey", in_textured_mesh_ply.name)
    out_renders_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with ctx.substep("render"):
        kept, dropped, t_render, hole_px = render_view_set(mesh, tex, views, out_renders_dir, params.max_empty_fraction,
                                                            ctx, params.fill_holes, params.max_hole_px)
    index = {"n_vertices": int(len(mesh.vertices)), "kept": kept, "dropped": dropped,
             "max_empty_fraction": params.max_empty_fraction, "fill_holes": params.fill_holes}
    (out_renders_dir / "index.json").write_text(json.dumps(index, indent=1))
    hole_share = hole_px / max(sum(int(v["width"]) * int(v["height"]) for v in kept), 1)
    ctx.log.info("rendered %d views, kept %d, dropped %d (> %.0f %% empty); %.1f %% of the kept pixels were holes "
                 "below the horizon%s", len(views), len(kept), len(dropped), 100 * params.max_empty_fraction,
                 100 * hole_share, " (filled from the nearest surface)" if params.fill_holes else "")
    if not kept:
        raise InputError(f"{in_views_json}: every view is more than {100 * params.max_empty_fraction:.0f} % empty; "
                         f"check the sampler's positions (views.json) against the mesh")
    with ctx.substep("signal"):
        signal = view_signal(kept, params.min_signal_std, params.max_blank_share, ctx)
    return {"views": len(views), "kept": len(kept), **signal, "dropped_empty": len(dropped), "kept_per_sampler": per_sampler(kept),
            "hole_fraction": round(hole_share, 4), "seconds": round(time.perf_counter() - t0, 3), "render_seconds": round(t_render, 3),
            "seconds_per_view": round(t_render / max(len(views), 1), 4)}


# ----------------------------------------------------------------------------- the capture's photos as views

def photo_views(params: PhotoViewsParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                in_cameras_site_json: Path | None = None, in_photos_dir: Path | None = None,
                in_views_json: Path | None = None, in_roads_osm: Path | None = None,
                in_street_points_txt: Path | None = None, out_renders_dir: Path) -> dict:
    """The registered photos as views (renders/ as render_views writes it): each photo, undistorted and
    downscaled, with the vertex map rendered from its pose; optionally plus rendered views (views.json where
    a sample_views step wrote one, else the view_sampler's views, sampled here only when they are used)."""
    import numpy as np

    from twinkit_segmentation.photoviews import photo_summary, photo_view_set
    from twinkit_segmentation.render import per_sampler

    if params.source not in ("photos", "rendered", "both"):
        raise InputError(f"photo_views: source='{params.source}' must be photos, rendered or both")
    use_photos, use_rendered = params.source in ("photos", "both"), params.source in ("rendered", "both")
    if use_photos and (in_cameras_site_json is None or in_photos_dir is None):
        raise InputError("photo_views: source=photos needs cameras_site.json and the photos folder (the photo "
                         "branch's georeference step and site.inputs.photos); use source=rendered without photos")
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    out_renders_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    kept: list = []
    dropped: list = []
    out: dict = {"source": params.source}
    if use_photos:
        cams = A.read_cameras_site(in_cameras_site_json).cameras
        if params.max_photos and len(cams) > params.max_photos:
            cams = [cams[i] for i in np.linspace(0, len(cams) - 1, params.max_photos).round().astype(int)]
        kept, dropped, stats = photo_view_set(mesh, cams, in_photos_dir, in_cameras_site_json, params.long_side_px,
                                              params.min_coverage, out_renders_dir, ctx.progress)
        out.update(photo_summary(kept, dropped, cams, stats, params.min_coverage, ctx.log))
    if use_rendered:
        views = _views_to_render(mesh, ctx, in_textured_mesh_ply, in_views_json, in_roads_osm, in_street_points_txt,
                                 params.max_views, out_renders_dir)
        k2, d2, rendered = _rendered_view_set(mesh, views, in_textured_mesh_ply, params.max_empty_fraction,
                                              out_renders_dir, ctx)
        kept += k2
        dropped += d2
        out.update(rendered)
    index = {"n_vertices": int(len(mesh.vertices)), "kept": kept, "dropped": dropped, "source": params.source,
             "max_empty_fraction": params.max_empty_fraction, "min_coverage": params.min_coverage,
             "long_side_px": params.long_side_px}
    (out_renders_dir / "index.json").write_text(json.dumps(index, indent=1))
    if not kept:
        raise _no_view_kept(dropped, params.min_coverage, in_textured_mesh_ply.name)
    out.update({"kept": len(kept), "kept_per_sampler": per_sampler(kept),
                "seconds": round(time.perf_counter() - t0, 3)})
    return out


def _views_to_render(mesh, ctx, mesh_ply: Path, views_json: Path | None, roads_osm: Path | None,
                     street_points: Path | None, max_views: int, out_dir: Path) -> list:
    """The rendered views: views.json's where a sample_views step wrote one, else sampled here (and written
    to ``out_dir``/views.json); InputError when there are none."""
    if views_json is not None:
        try:
            views = json.loads(Path(views_json).read_text())["views"]
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{views_json}: not a views file ({exc}); re-run sample_views") from None
    else:
        osm = A.read_osm(roads_osm) if roads_osm is not None else None
        views = _sample_views(mesh, ctx, osm, street_points, max_views)
        (out_dir / "views.json").write_text(json.dumps({"views": views}, indent=1))
    if not views:
        raise InputError(f"{mesh_ply}: the view sampler produced no views; try another "
                         f"view_sampler or steps.photo_views.source=photos")
    return views


def _rendered_view_set(mesh, views: list, mesh_ply: Path, max_empty_fraction: float, out_dir: Path,
                       ctx) -> tuple[list, list, dict]:
    """The views rendered into ``out_dir`` (as render_views): (kept, dropped (reason "empty"), metrics)."""
    from twinkit_segmentation.render import load_texture, render_view_set

    tex = load_texture(mesh.texture) if mesh.texture is not None else None
    if tex is None:
        ctx.log.warning("%s has no texture; rendering flat grey", mesh_ply.name)
    k2, d2, t_r, _ = render_view_set(mesh, tex, views, out_dir, max_empty_fraction, ctx)
    ctx.log.info("rendered views: %d of %d kept", len(k2), len(views))
    return k2, [dict(d, reason="empty") for d in d2], {"rendered_views": len(views), "rendered_kept": len(k2),
                                                       "dropped_empty": len(d2), "render_seconds": round(t_r, 3)}


def _no_view_kept(dropped: list, min_coverage: float, mesh_name: str) -> InputError:
    """The error when no view is kept: how many photos missed the mesh (the best one's coverage), how many
    rendered views were mostly empty, and what to check."""
    off = sorted((d for d in dropped if d["reason"] == "off_mesh"), key=lambda d: -d["coverage"])
    best = f"; the best photo, {off[0]['image']}, sees it in {100 * off[0]['coverage']:.1f} %" if off else ""
    return InputError(f"photo_views: no view kept: {len(off)} photos see the mesh in fewer than "
                      f"{100 * min_coverage:.0f} % of their pixels{best}, {len(dropped) - len(off)} rendered "
                      f"views are mostly empty. Check {mesh_name} (a mesh that small or that far "
                      f"from the cameras: see the dense step's point count) and cameras_site.json, or lower "
                      f"steps.photo_views.min_coverage")


# ----------------------------------------------------------------------------- 2D prediction

#: zlib level of predictions/<view>.png: 1.8 ms and 11 KiB per 1024x512 demo view (level 6: 4.0 ms, 7.7 KiB)
PNG_LEVEL = 3


def predict_views(params: PredictParams, ctx: StepContext, *, in_renders_dir: Path,
                  in_gt_labels_npy: Path | None = None, out_predictions_dir: Path,
                  out_vertex_votes_npy: Path) -> dict:
    """Segment every rendering with the selected image_model and sum its votes per vertex."""
    import numpy as np
    from PIL import Image

    from twinkit.cityscapes import N_CLASSES, PALETTE
    from twinkit_segmentation.viewvotes import view_votes

    index_path = Path(in_renders_dir) / "index.json"
    try:
        index = json.loads(index_path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{index_path}: missing or unreadable ({exc}); re-run render_views") from None
    n = int(index["n_vertices"])
    if not index["kept"] and index.get("skipped"):
        out_predictions_dir.mkdir(parents=True, exist_ok=True)
        np.save(out_vertex_votes_npy, np.zeros((n, N_CLASSES), np.float32))
        (out_predictions_dir / "index.json").write_text(json.dumps({"views": [], "skipped": index["skipped"]}, indent=1))
        return {"views": 0, "skipped": index["skipped"], "vertices_seen": 0.0}
    with ctx.substep("load_model"):
        model = ctx.component("image_model")
    if getattr(model, "needs_ground_truth", False):
        if in_gt_labels_npy is None:
            raise InputError("image_model=oracle needs gt_labels.npy: add the transfer_gt_labels step before predict_views")
        model.set_ground_truth(A.read_labels(in_gt_labels_npy))
    out_predictions_dir.mkdir(parents=True, exist_ok=True)
    votes = np.zeros((n, N_CLASSES), dtype=np.float64)
    pal = np.zeros(768, dtype=np.uint8)
    pal[: 3 * N_CLASSES] = PALETTE.reshape(-1)
    kept = index["kept"]
    t_model = cpu_model = 0.0
    t0 = time.perf_counter()
    batches = _size_batches(kept, max(1, int(params.batch_views)), Path(in_renders_dir))
    for batch in ctx.progress(batches, total=len(batches), desc="predict"):
        with ctx.substep("io"):
            images = np.stack([np.asarray(Image.open(Path(in_renders_dir) / f"{v['id']}.png").convert("RGB")) for v in batch])
            vmaps = np.stack([np.load(Path(in_renders_dir) / f"{v['id']}_vertex.npz")["vertex"] for v in batch])
        t1, c1 = time.perf_counter(), time.process_time()
        with ctx.substep("model"):
            kw = {"vertex_maps": vmaps} if getattr(model, "needs_vertex_map", False) else {}
            if params.soft_votes:
                proba = np.asarray(model.predict_proba(images, **kw), dtype=np.float32)
                labels = proba.argmax(axis=1).astype(np.uint8)
            else:
                labels = np.asarray(model.predict(images, **kw), dtype=np.uint8)
        t_model += time.perf_counter() - t1
        cpu_model += time.process_time() - c1
        with ctx.substep("votes"):
            for j, v in enumerate(batch):
                ids, vv = view_votes(vmaps[j], n, labels=labels[j], proba=proba[j] if params.soft_votes else None,
                                     per_view=params.vote_per_view)
                votes[ids] += vv
                if params.save_pngs:
                    im = Image.fromarray(labels[j], mode="P")
                    im.putpalette(pal.tolist())
                    im.save(out_predictions_dir / f"{v['id']}.png", compress_level=PNG_LEVEL)
    with ctx.substep("write"):
        np.save(out_vertex_votes_npy, votes.astype(np.float32))
        (out_predictions_dir / "index.json").write_text(json.dumps(
            {"model": (ctx.config.get("image_model") or {}).get("plugin", "?") if ctx.config else "?",
             "views": [v["id"] for v in kept], "soft_votes": params.soft_votes,
             "vote_per_view": params.vote_per_view}, indent=1))
    seen = float((votes.sum(axis=1) > 0).mean())
    return {"views": len(kept), "model_seconds": round(t_model, 3), "seconds": round(time.perf_counter() - t0, 3),
            "seconds_per_view": round(t_model / max(len(kept), 1), 4),
            "cpu_seconds_per_view": round(cpu_model / max(len(kept), 1), 4),
            **({"runtime": model.runtime} if hasattr(model, "runtime") else {}), "vertices_seen": round(seen, 4)}


def _size_batches(kept: list, step: int, folder: Path) -> list:
    """Consecutive views in batches of at most ``step`` that share one image size (photos and renders of
    several sizes can share a renders/ folder; a batch is one array)."""
    from PIL import Image

    batches: list = []
    last = None
    for v in kept:
        if "width" in v and "height" in v:
            size = (int(v["width"]), int(v["height"]))
        else:
            with Image.open(folder / f"{v['id']}.png") as im:
                size = im.size
        if batches and size == last and len(batches[-1]) < step:
            batches[-1].append(v)
        else:
            batches.append([v])
        last = size
    return batches


# ----------------------------------------------------------------------------- back-projection

def backproject(params: BackprojectParams, ctx: StepContext, *, in_textured_mesh_ply: Path, in_segments_npy: Path,
                in_vertex_votes_npy: Path, out_labels_npy: Path, out_confidence_npy: Path,
                out_labels_ply: Path, out_confidence_png: Path, in_points_ply: Path | None = None,
                in_geometry_votes_npy: Path | None = None, in_points_meta_json: Path | None = None) -> dict:
    """Votes per segment and class, fused with the geometry's class probabilities where a 3D classifier
    wrote them (geometry_votes.npy, weights per capture kind: :mod:`twinkit_segmentation.fusion`), the
    cloud's own classes (points.ply ``classification``) and the gated geometric cues as priors; argmax ->
    labels.npy (per vertex), confidence.npy (the fused winner's probability), labels.ply (palette),
    confidence.png (a top view of the low-confidence vertices)."""
    import numpy as np

    from twinkit.cityscapes import IGNORE
    from twinkit.mesh import edges as mesh_edges
    from twinkit_segmentation.context import CUES
    from twinkit_segmentation.fileclasses import vertex_file_classes
    from twinkit_segmentation.fusion import confidence_picture, confidence_summary, disagreement
    from twinkit_segmentation.metrics import decide_distribution, propagate
    from twinkit_segmentation.segmesh import write_labels_ply

    t0 = time.perf_counter()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    seg = np.load(in_segments_npy)
    votes = np.load(in_vertex_votes_npy).astype(np.float64)
    if len(seg) != len(mesh.vertices) or len(votes) != len(mesh.vertices):
        raise InputError(f"{in_segments_npy.name} ({len(seg)}), {in_vertex_votes_npy.name} ({len(votes)}) and "
                         f"{in_textured_mesh_ply.name} ({len(mesh.vertices)}) disagree on the vertex count; re-run them")
    bad = [c for c in list(params.context_cues) + list(params.cues_with_geometry) if c not in CUES]
    if bad:
        raise InputError(f"backproject: unknown context_cues {bad}; choose from {list(CUES)}")
    p_views, s_total = vote_distribution(params, seg, votes)
    cloud = A.read_points(in_points_ply) if in_points_ply is not None and Path(in_points_ply).is_file() else None
    geom = _geometry_votes(in_geometry_votes_npy, len(mesh.vertices))
    if geom is None and not votes.any():
        raise InputError(f"{in_vertex_votes_npy}: no view voted (a colourless capture gets no views unless "
                         f"steps.sample_views.colourless_views=true) and there is no geometry_votes.npy: add the "
                         f"classify_geometry step before backproject, or render the views")
    p, fsum = _fuse_sources(params, ctx, p_views, votes, geom, cloud)
    unseen = (s_total < params.min_votes) if geom is None else (s_total < params.min_votes) & (geom.sum(axis=1) <= 0)
    fprior, fvoting, fcodes, finfo = vertex_file_classes(params, ctx, in_points_ply, mesh.vertices)
    labels, conf = decide_distribution(p, unseen)
    base_labels = labels.copy()  # the sources alone
    two_way = capture_two_way_share(in_points_meta_json, cloud)
    gates, ginfo = _cue_gates(params, ctx, mesh, cloud, geom, two_way)
    floor = geometry_floor(params, ctx, geom, fsum.get("kind"), two_way)
    # the views' near-unanimous floor holds where they lead: not where a colourless capture has geometry
    unshield = None if geom is None or fsum.get("kind") == "coloured" else geom.sum(axis=1) > 0
    cues = list(params.context_cues) if geom is None else [c for c in params.context_cues
                                                           if c in params.cues_with_geometry]
    labels, conf, edges, cmet, t_ctx = _fuse(params, ctx, mesh, p, votes, labels, conf, fprior, gates,
                                            unshield=unshield, cues=cues, floor=floor)
    unlabelled_before = int((labels == IGNORE).sum())
    if params.fill_unlabelled and unlabelled_before and unlabelled_before < len(labels):
        labels = propagate(labels, edges if edges is not None else mesh_edges(mesh.faces, len(mesh.vertices)))
    if fprior is not None:
        from twinkit_segmentation.fileclasses import summary

        finfo.update(summary(fcodes, fvoting, fprior, base_labels, labels))
        ctx.log.info("file classes: %d of %d vertices carry a class the fusion uses; the views' plain vote gave "
                     "%.1f %% of them a class the file rules out, the fused labels %.1f %% (prior factor %g)",
                     finfo["vertices_with_class"], finfo["vertices"], 100 * finfo["against_file_before"],
                     100 * finfo["against_file_after"], params.file_class_factor)
    disagree = disagreement(p_views, geom)
    csum = confidence_summary(labels, conf, disagree, params.low_confidence)
    ctx.log.info("confidence: %d vertices (%.1f %%) under %.2f; the views and the geometry disagree on %d",
                 csum["low_confidence"], 100 * csum["low_confidence_share"], params.low_confidence,
                 csum["sources_disagree"])
    A.write_labels(out_labels_npy, labels.astype(np.uint8))
    np.save(out_confidence_npy, conf.astype(np.float32))
    write_labels_ply(out_labels_ply, mesh, labels)
    confidence_picture(out_confidence_png, mesh.vertices, conf, labels, disagree, params.low_confidence)
    return {"unlabelled_before_fill": unlabelled_before, "unlabelled": int((labels == IGNORE).sum()),
            "mean_confidence": float(conf[conf > 0].mean()) if (conf > 0).any() else 0.0,
            "context": cmet, "context_seconds": round(t_ctx, 3), "file_classes": finfo, "fusion": fsum,
            "confidence": csum, "cue_gates": ginfo,
            "geometry_floor": None if floor is None else round(float(floor.mean()), 4),
            "seconds": round(time.perf_counter() - t0, 3)}


# ----------------------------------------------------------------------------- ground truth and evaluation

#: per-vertex label properties a site's ground-truth mesh may carry, first found wins (the demo writes ``label``)
GT_VERTEX_LABEL_KEYS = ("label", "labels", "class", "class_id", "scalar_label")


def transfer_gt_labels(params: TransferGtParams, ctx: StepContext, *, in_gt_mesh_ply: Path,
                       in_textured_mesh_ply: Path, out_gt_labels_npy: Path, out_gt_labels_ply: Path) -> dict:
    """Ground truth on the reconstructed vertices (``params.rule``): the nearest ground-truth face's label, or
    (``vertex``) its corner's nearest the closest point. A recipe may rename the outputs (export_demo:
    ``labels.npy``, ``labels.ply``)."""
    import numpy as np

    from twinkit.cityscapes import IGNORE
    from twinkit.street.truth import transfer_labels
    from twinkit_segmentation.segmesh import face_labels, write_labels_ply

    gt = A.read_gt_mesh(in_gt_mesh_ply)
    key = next((k for k in GT_VERTEX_LABEL_KEYS if k in gt.attrs), None)
    vlab = None if key is None else np.asarray(gt.attrs[key]).astype(np.uint8)
    flab = face_labels(gt) if params.rule == "face" else None
    if flab is None and vlab is None:
        raise InputError(f"{in_gt_mesh_ply}: no label property on " + ("faces or vertices" if params.rule == "face"
                         else f"vertices (looked for {', '.join(GT_VERTEX_LABEL_KEYS)}); or use rule=face"))
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    if (params.rule == "vertex" and len(gt.vertices) == len(mesh.vertices)
            and np.abs(gt.vertices - mesh.vertices).max() < 1e-4):
        # the mesh *is* the ground-truth mesh (same vertices): copy, do not guess at coincident vertices
        labels, dist = vlab.copy(), np.zeros(len(vlab), np.float32)
    else:
        labels, dist = transfer_labels(gt.vertices, gt.faces, mesh.vertices, face_labels=flab, vertex_labels=vlab)
    labels[dist > params.max_distance_m] = IGNORE
    A.write_labels(out_gt_labels_npy, labels)
    how = "nearest gt face" if params.rule == "face" else "nearest corner of the nearest gt face"
    write_labels_ply(out_gt_labels_ply, mesh, labels, comment=f"ground truth transferred from the {how}")
    return {"vertices": int(len(labels)), "rule": params.rule, "mean_distance_m": float(dist.mean()),
            "unlabelled": int((labels == IGNORE).sum()),
            "classes": sorted(int(c) for c in np.unique(labels) if c != IGNORE)}


def evaluate_segmentation(params: EvaluateParams, ctx: StepContext, *, in_labels_npy: Path, in_gt_labels_npy: Path,
                          in_segments_npy: Path | None = None, out_seg_metrics_json: Path,
                          out_seg_metrics_md: Path) -> dict:
    """Per-class IoU, F1, precision, recall; mIoU, mF1; confusion; the over-segmentation's upper bound."""
    import numpy as np

    from twinkit_segmentation.metrics import majority_labels, markdown_table, scores

    pred, gt = A.read_labels(in_labels_npy), A.read_labels(in_gt_labels_npy)
    if len(pred) != len(gt):
        raise InputError(f"{in_labels_npy.name} has {len(pred)} vertices but {in_gt_labels_npy.name} has {len(gt)}")
    res = scores(pred, gt, list(params.classes) or None)
    upper = None
    if in_segments_npy is not None:
        upper = scores(majority_labels(np.load(in_segments_npy), gt), gt, res["classes"])
    out_seg_metrics_json.write_text(json.dumps({"scores": res, "upper_bound": upper}, indent=1))
    md = ["# Segmentation vs ground truth\n", f"mIoU **{res['miou']:.1f}**, mF1 **{res['mf1']:.1f}**, "
          f"accuracy {res['accuracy']:.1f} %, labelled {100 * res['labelled_fraction']:.1f} % of vertices"]
    if upper:
        md.append(f"; over-segmentation upper bound mIoU {upper['miou']:.1f}")
    md.append("\n\n" + markdown_table(res, upper))
    out_seg_metrics_md.write_text("".join(md))
    ctx.log.info("mIoU %.1f  mF1 %.1f%s", res["miou"], res["mf1"],
                 f"  (upper bound {upper['miou']:.1f})" if upper else "")
    out = {"miou": round(res["miou"], 2), "mf1": round(res["mf1"], 2), "accuracy": round(res["accuracy"], 2),
           "iou": {k: round(v["iou"], 2) for k, v in res["per_class"].items()}}
    if upper:
        out["upper_bound_miou"] = round(upper["miou"], 2)
    return out


# ----------------------------------------------------------------------------- manual correction

def import_labels(params: ImportLabelsParams, ctx: StepContext, *, in_labels_ply: Path, in_labels_npy: Path,
                  in_textured_mesh_ply: Path | None = None, out_labels_npy: Path,
                  out_label_changes_json: Path) -> dict:
    """Read a repainted labels.ply back (nearest palette colour -> class); labels.npy for later steps."""
    before = A.read_labels(in_labels_npy)
    after = read_repainted(in_labels_ply, len(before), reference_ply=in_textured_mesh_ply)
    changed = before != after
    per = {}
    from twinkit.cityscapes import NAMES as CLASSES

    name = lambda c: CLASSES[c] if c < len(CLASSES) else "unlabelled"  # noqa: E731
    for a, b in zip(before[changed].tolist(), after[changed].tolist()):
        key = f"{name(a)} -> {name(b)}"
        per[key] = per.get(key, 0) + 1
    A.write_labels(out_labels_npy, after)
    out_label_changes_json.write_text(json.dumps({"changed": int(changed.sum()), "transitions": per}, indent=1))
    ctx.log.info("%d vertices changed by hand", int(changed.sum()))
    return {"changed": int(changed.sum())}


def read_repainted(path: Path, n_vertices: int, reference_ply: Path | None = None, vertices=None):
    """Labels from a repainted palette PLY; refuses a PLY whose vertex count or order changed."""
    import numpy as np

    from twinkit.mesh import read_mesh
    from twinkit_segmentation.metrics import palette_to_labels

    m = read_mesh(path)
    if len(m.vertices) != n_vertices:
        raise InputError(f"{path}: has {len(m.vertices)} vertices, the labels have {n_vertices}; the editor changed "
                         f"the mesh. Repaint vertex colours only (MeshLab: keep 'Save vertex order'; Blender: "
                         f"no merge/split), or export again")
    ref = vertices
    if ref is None and reference_ply is not None:
        ref = A.read_textured_mesh(reference_ply).vertices
    if ref is not None:
        moved = np.linalg.norm(m.vertices - ref, axis=1)
        if np.percentile(moved, 99) > 1e-3:
            raise InputError(f"{path}: the vertices are no longer in the original order (or moved); repaint colours "
                             f"only and save without reordering")
    if m.colors is None:
        raise InputError(f"{path}: no vertex colours to read labels from")
    return palette_to_labels(m.colors)
