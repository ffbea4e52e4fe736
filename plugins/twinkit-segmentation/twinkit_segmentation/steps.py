"""The steps of view-based segmentation. Each writes files one can open:

    oversegment           segments.npy (int32 per vertex), segments.ply (random colour per segment)
    sample_views          views.json
    render_views          renders/ (<view>.png, <view>_vertex.npz, index.json)
    photo_views           renders/ as render_views, the capture's photos as the images (+ rendered views)
    predict_views         predictions/ (<view>.png, palette PNG whose pixel values are trainIds),
                          vertex_votes.npy (float32, vertices x 19)
    backproject           labels.npy (uint8 per vertex, 255 = none), confidence.npy, labels.ply
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
from dataclasses import dataclass
from pathlib import Path
from typing import List

from twinkit import InputError, StepContext
from twinkit import artefacts as A
from twinkit.ranges import param


# ----------------------------------------------------------------------------- over-segmentation
@dataclass
class FelzenszwalbParams:
    k_threshold: float = param(0.3, ge=0, help="Felzenszwalb's k: larger = larger segments.")
    min_vertices: int = param(10, ge=0,
                              help="Merge segments smaller than this into a neighbour along the lightest edge; 0 = "
                                   "off.")
    max_vertices: int = param(5000, ge=0, help="Never grow a segment beyond this many vertices; 0 = unlimited.")
    normal_weight: float = param(1.0, ge=0,
                                 help="Weight of the normal difference (1 - n1.n2, squared on convex edges) in an "
                                      "edge's cost.")
    colour_weight: float = param(1.0, ge=0,
                                 help="Weight of the RGB distance (0..1) in an edge's cost; 0 = geometry only.")


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


@dataclass
class NoSegmentsParams:
    pass


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
@dataclass
class SampleViewsParams:
    max_views: int = param(-1, ge=0, also=(-1,),
                           help="Keep at most this many views, as whole camera positions (all their heights and "
                                "headings) spread over the site in farthest-point order. 0 = all; -1 = auto "
                                "(auto_max_views).")
    auto_max_views: int = param(480, ge=1,
                                help="The view budget of max_views=-1 (rendering and the 2D model take about 0.25 s "
                                     "a view on 2 cores: 480 views are about 2 minutes).")


def sample_views(params: SampleViewsParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                 in_roads_osm: Path | None = None, in_street_points_txt: Path | None = None,
                 in_points_ply: Path | None = None, out_views_json: Path) -> dict:
    """Camera views from the selected view sampler (view_sampler=auto_street|street_points|uniform|random|combined)."""

    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    t0 = time.perf_counter()
    budget = params.auto_max_views if params.max_views < 0 else params.max_views
    capture = _capture(in_points_ply, ctx)
    roads_osm = A.read_osm(in_roads_osm) if in_roads_osm is not None else None
    views, sampled = _sample_views(mesh, ctx, roads_osm, in_street_points_txt, budget, with_total=True,
                                   capture=capture)
    if not views:
        raise InputError(f"{in_textured_mesh_ply}: the view sampler produced no views; try another view_sampler")
    if len(views) < sampled:
        ctx.log.warning("sample_views: %d views sampled, %d kept (max_views %d%s): whole camera positions, "
                        "spread over the site", sampled, len(views), budget, " auto" if params.max_views < 0 else "")
    counts = _per_sampler(views)
    sampler_name = (ctx.config.get("view_sampler") or {}).get("plugin", "?") if ctx.config else "?"
    out_views_json.write_text(json.dumps({"sampler": sampler_name, "counts": counts, "views": views,
                                          "sampled": sampled, "max_views": budget}, indent=1))
    return {"views": len(views), "sampled_views": sampled, "max_views": budget, "capture": capture,
            "per_sampler": counts,
            "seconds": round(time.perf_counter() - t0, 3)}


def _capture(points_ply: Path | None, ctx) -> str | None:
    """The capture type of the cloud (twinkit.surface.density), when the run has one."""
    if points_ply is None or not Path(points_ply).is_file():
        return None
    from twinkit.surface import density

    m = density.measure(A.read_points(points_ply).vertices)
    ctx.log.info("sample_views: %s", density.describe(m))
    return m["capture"]


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
@dataclass
class RenderParams:
    max_empty_fraction: float = param(0.6, ge=0, le=1,
                                      help="Drop views whose image is more than this share background.")
    fill_holes: bool = param(True,
                             help="Paint background below the horizon (a hole in the mesh or the capture's edge, "
                                  "never sky) with the nearest surface's colour, so the 2D model does not read "
                                  "sky-blue patches in the street; false = plain sky-blue background everywhere.")
    max_hole_px: float = param(16.0, ge=0,
                               help="fill_holes: a background gap at most 2x this wide (px) is a hole; wider = past "
                                    "the capture's edge, left as background.")
    min_signal_std: float = param(4.0, ge=0,
                                  help="A view whose mesh pixels vary less than this (standard deviation of the "
                                       "grey level, 0..255) is blank: the 2D model reads nothing from a flat grey "
                                       "silhouette.")
    max_blank_share: float = param(0.5, ge=0, le=1,
                                   help="The run is marked degraded when more than this share of the views is "
                                        "blank.")


def render_views(params: RenderParams, ctx: StepContext, *, in_textured_mesh_ply: Path, in_views_json: Path,
                 out_renders_dir: Path) -> dict:
    """Render every view unlit with a sky background; per pixel the nearest vertex (<view>_vertex.npz)."""
    from twinkit_segmentation.render import load_texture

    try:
        views = json.loads(Path(in_views_json).read_text())["views"]
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{in_views_json}: not a views file ({exc}); re-run sample_views") from None
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    tex = load_texture(mesh.texture) if mesh.texture is not None else None
    if tex is None:
        ctx.log.warning("%s has no texture; rendering flat grey", in_textured_mesh_ply.name)
    out_renders_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    kept, dropped, t_render, hole_px = _render_view_set(mesh, tex, views, out_renders_dir, params.max_empty_fraction,
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
    signal = view_signal(kept, params.min_signal_std, params.max_blank_share, ctx)
    return {"views": len(views), "kept": len(kept), **signal, "dropped_empty": len(dropped), "kept_per_sampler": _per_sampler(kept),
            "hole_fraction": round(hole_share, 4), "seconds": round(time.perf_counter() - t0, 3), "render_seconds": round(t_render, 3),
            "seconds_per_view": round(t_render / max(len(views), 1), 4)}


def view_signal(kept: list, min_std: float, max_blank_share: float, ctx) -> dict:
    """How much the kept views show (their ``signal_std``); too many blank views: degraded, with a hint."""
    import numpy as np

    stds = np.array([float(v.get("signal_std", 0.0)) for v in kept])
    if not len(stds):
        return {}
    blank = float((stds < min_std).mean())
    out = {"signal_std_median": round(float(np.median(stds)), 2), "blank_views": int((stds < min_std).sum()),
           "blank_share": round(blank, 4)}
    if blank > max_blank_share:
        ctx.degraded(f"{100 * blank:.0f} % of the {len(stds)} views are blank (grey level varies by less than "
                     f"{min_std:g} over the mesh; median {out['signal_std_median']:g}): the 2D labels cannot be trusted",
                     "a cloud without colours: keep bake_texture colourless at auto (intensity or shaded), "
                     "not grey; else check the texture (docs/pointcloud.md 'Clouds without colour')")
    elif blank > 0.2:
        ctx.log.warning("%.0f %% of the %d views are nearly blank (grey level std < %g)", 100 * blank, len(stds),
                        min_std)
    return out


def _per_sampler(kept: list) -> dict:
    per: dict = {}
    for v in kept:
        per[v["sampler"]] = per.get(v["sampler"], 0) + 1
    return per


def _render_view_set(mesh, tex, views: list, out_dir: Path, max_empty_fraction: float, ctx,
                     fill_holes: bool = True, max_hole_px: float = 16.0):
    """Render sampled views (views.json records) into ``out_dir``, holes in the ground filled (see
    :class:`RenderParams`); (kept, dropped, render seconds, hole pixels of the kept views)."""
    import numpy as np
    from PIL import Image

    from twinkit_segmentation.render import Renderer, below_horizon, fill_from_nearest, ground_holes
    from twinkit_segmentation.views import view_matrices

    renderers: dict = {}
    kept, dropped = [], []
    t_render = 0.0
    hole_px = 0
    try:
        for v in ctx.progress(views, total=len(views), desc="render"):
            size = (int(v["width"]), int(v["height"]))
            if size not in renderers:
                renderers[size] = Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, *size)
            r = renderers[size]
            vm, pm = view_matrices(v)
            t1 = time.perf_counter()
            rgb, vertex = r.render(vm, pm)
            t_render += time.perf_counter() - t1
            empty = float((vertex < 0).mean())
            if empty > max_empty_fraction:
                dropped.append({"id": v["id"], "empty_fraction": round(empty, 4)})
                continue
            hole_mask = ground_holes(vertex >= 0, below_horizon(vm, pm, *size), max_hole_px)
            holes = int(hole_mask.sum())
            hole_px += holes
            if fill_holes:
                fill_from_nearest(rgb, hole_mask, vertex >= 0)
            Image.fromarray(rgb).save(out_dir / f"{v['id']}.png", compress_level=1)
            np.savez_compressed(out_dir / f"{v['id']}_vertex.npz", vertex=vertex)
            on = vertex >= 0
            signal = float(rgb[on].astype(np.float32).mean(axis=1).std()) if on.any() else 0.0
            kept.append(dict(v, empty_fraction=round(empty, 4), hole_fraction=round(holes / vertex.size, 4),
                             signal_std=round(signal, 2)))
    finally:
        for r in renderers.values():
            r.release()
    return kept, dropped, t_render, hole_px


# ----------------------------------------------------------------------------- the capture's photos as views
@dataclass
class PhotoViewsParams:
    source: str = param("photos", choices=("photos", "rendered", "both"),
                        help="Which views to label: photos (the registered photos), rendered (views.json, as "
                             "render_views), or both.")
    long_side_px: int = param(1024, ge=0,
                              help="Downscale photos to this long side (px), the scale the CityScapes 2D models "
                                   "expect; 0 = full size.")
    min_coverage: float = param(0.1, ge=0, le=1,
                                help="Drop a photo whose pose sees the mesh in fewer than this share of its pixels "
                                     "(it missed the mesh).")
    max_empty_fraction: float = param(0.6, ge=0, le=1,
                                      help="Rendered views: drop those with more than this share background (as "
                                           "render_views).")
    max_photos: int = param(0, ge=0, help="Use at most this many photos, evenly spread in file order; 0 = all.")
    max_views: int = param(0, ge=0,
                           help="Rendered views sampled here (when no views.json is wired): at most this many; 0 = "
                                "all.")


def photo_views(params: PhotoViewsParams, ctx: StepContext, *, in_textured_mesh_ply: Path,
                in_cameras_site_json: Path | None = None, in_photos_dir: Path | None = None,
                in_views_json: Path | None = None, in_roads_osm: Path | None = None,
                in_street_points_txt: Path | None = None, out_renders_dir: Path) -> dict:
    """The registered photos as views (renders/ as render_views writes it): each photo, undistorted and
    downscaled, with the vertex map rendered from its pose; optionally plus rendered views (views.json where
    a sample_views step wrote one, else the view_sampler's views, sampled here only when they are used)."""
    import numpy as np
    from PIL import Image

    from twinkit_segmentation.photoviews import (PhotoCamera, max_distortion_px, photo_view_image, projection_from_K,
                                                 view_matrix_opencv)
    from twinkit_segmentation.render import Renderer, load_texture

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
        renderers: dict = {}
        t_load = t_render = 0.0
        n_undistorted = 0
        shift = 0.0
        used_ids: set = set()
        try:
            for c in ctx.progress(cams, total=len(cams), desc="photo views"):
                try:
                    cam = PhotoCamera.from_json(c)
                except (KeyError, ValueError) as exc:
                    raise InputError(f"{in_cameras_site_json}: camera of {c.get('image', '?')}: {exc}") from None
                path = Path(in_photos_dir) / cam.image
                t1 = time.perf_counter()
                try:
                    img, K, valid, undist = photo_view_image(path, cam, params.long_side_px)
                except OSError as exc:
                    raise InputError(f"{path}: cannot read the photo ({exc}); put the photos georeference used "
                                     f"in {in_photos_dir}, or re-run sfm") from None
                except ValueError as exc:
                    raise InputError(f"{path}: {exc}; use the photos the SfM registered") from None
                t_load += time.perf_counter() - t1
                h, w = img.shape[:2]
                dist_px = max_distortion_px(cam.params, cam.width, cam.height, w / cam.width)
                shift = max(shift, dist_px)
                if (w, h) not in renderers:  # the vertex map only: no texture needed
                    renderers[(w, h)] = Renderer(mesh.vertices, mesh.faces, None, None, w, h)
                t1 = time.perf_counter()
                _, vertex = renderers[(w, h)].render(view_matrix_opencv(cam.R_wc, cam.center),
                                                     projection_from_K(K, w, h))
                t_render += time.perf_counter() - t1
                if valid is not None:
                    vertex[~valid] = -1  # no photo pixel there after undistortion
                coverage = float((vertex >= 0).mean())
                vid = _photo_view_id(cam.image, used_ids)
                if coverage < params.min_coverage:
                    dropped.append({"id": vid, "image": cam.image, "reason": "off_mesh", "coverage": round(coverage, 4)})
                    continue
                n_undistorted += int(undist)
                Image.fromarray(img).save(out_renders_dir / f"{vid}.png", compress_level=1)
                np.savez_compressed(out_renders_dir / f"{vid}_vertex.npz", vertex=vertex)
                kept.append({"id": vid, "sampler": "photo", "image": cam.image, "width": w, "height": h,
                             "K": K.round(4).tolist(), "R_world_from_camera": cam.R_wc.tolist(),
                             "center": cam.center.tolist(), "undistorted": bool(undist),
                             "max_distortion_px": round(dist_px, 3),
                             "empty_fraction": round(1 - coverage, 4)})
        finally:
            for r in renderers.values():
                r.release()
        n_photo = len(kept)
        off = [d for d in dropped if d["reason"] == "off_mesh"]
        sizes = sorted({(v["width"], v["height"]) for v in kept})
        ctx.log.info("photo views: %d of %d registered photos kept at %s px (%d of them undistorted; largest "
                     "distortion %.2f px, resampled from 0.25 px), %d dropped (the pose sees the mesh in < %.0f %% of the "
                     "pixels)", n_photo, len(cams), ", ".join(f"{a}x{b}" for a, b in sizes) or "-", n_undistorted,
                     shift, len(off), 100 * params.min_coverage)
        if cams and len(off) > len(cams) / 2:
            ctx.log.warning("photo views: %d of %d photos miss the mesh; check the georeference (cameras_site.json) "
                            "against the mesh", len(off), len(cams))
        out.update({"photos": len(cams), "photo_views": n_photo, "dropped_off_mesh": len(off),
                    "undistorted": n_undistorted, "max_distortion_px": round(shift, 3),
                    "photo_sizes": [list(s) for s in sizes],
                    "photo_load_seconds": round(t_load, 3), "photo_render_seconds": round(t_render, 3)})
    if use_rendered:
        if in_views_json is not None:
            try:
                views = json.loads(Path(in_views_json).read_text())["views"]
            except (OSError, ValueError, KeyError) as exc:
                raise InputError(f"{in_views_json}: not a views file ({exc}); re-run sample_views") from None
        else:
            roads_osm = A.read_osm(in_roads_osm) if in_roads_osm is not None else None
            views = _sample_views(mesh, ctx, roads_osm, in_street_points_txt, params.max_views)
            (out_renders_dir / "views.json").write_text(json.dumps({"views": views}, indent=1))
        if not views:
            raise InputError(f"{in_textured_mesh_ply}: the view sampler produced no views; try another "
                             f"view_sampler or steps.photo_views.source=photos")
        tex = load_texture(mesh.texture) if mesh.texture is not None else None
        if tex is None:
            ctx.log.warning("%s has no texture; rendering flat grey", in_textured_mesh_ply.name)
        k2, d2, t_r, _ = _render_view_set(mesh, tex, views, out_renders_dir, params.max_empty_fraction, ctx)
        kept += k2
        dropped += [dict(d, reason="empty") for d in d2]
        ctx.log.info("rendered views: %d of %d kept", len(k2), len(views))
        out.update({"rendered_views": len(views), "rendered_kept": len(k2), "dropped_empty": len(d2),
                    "render_seconds": round(t_r, 3)})
    index = {"n_vertices": int(len(mesh.vertices)), "kept": kept, "dropped": dropped, "source": params.source,
             "max_empty_fraction": params.max_empty_fraction, "min_coverage": params.min_coverage,
             "long_side_px": params.long_side_px}
    (out_renders_dir / "index.json").write_text(json.dumps(index, indent=1))
    if not kept:
        off = sorted((d for d in dropped if d["reason"] == "off_mesh"), key=lambda d: -d["coverage"])
        best = f"; the best photo, {off[0]['image']}, sees it in {100 * off[0]['coverage']:.1f} %" if off else ""
        raise InputError(f"photo_views: no view kept: {len(off)} photos see the mesh in fewer than "
                         f"{100 * params.min_coverage:.0f} % of their pixels{best}, {len(dropped) - len(off)} rendered "
                         f"views are mostly empty. Check {in_textured_mesh_ply.name} (a mesh that small or that far "
                         f"from the cameras: see the dense step's point count) and cameras_site.json, or lower "
                         f"steps.photo_views.min_coverage")
    out.update({"kept": len(kept), "kept_per_sampler": _per_sampler(kept),
                "seconds": round(time.perf_counter() - t0, 3)})
    return out


def _photo_view_id(image: str, used: set) -> str:
    """A file-name-safe, unique view id for a photo ("photo_<stem>")."""
    import re

    base = "photo_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(image).with_suffix("").as_posix())
    vid, k = base, 1
    while vid in used:
        vid, k = f"{base}_{k}", k + 1
    used.add(vid)
    return vid


# ----------------------------------------------------------------------------- 2D prediction
@dataclass
class PredictParams:
    soft_votes: bool = param(False, help="Vote with the softmax probabilities instead of one vote per pixel.")
    vote_per_view: bool = param(True,
                                help="Each view gives each vertex it sees one vote in total, shared by its pixels' "
                                     "classes (false: one vote per pixel).")
    batch_views: int = param(4, ge=1, le=1024,
                             help="Views sent to the 2D model at once; lower it when the model runs out of memory.")
    save_pngs: bool = param(True,
                            help="Write predictions/<view>.png (a palette PNG whose pixel value is the trainId).")


def predict_views(params: PredictParams, ctx: StepContext, *, in_renders_dir: Path,
                  in_gt_labels_npy: Path | None = None, out_predictions_dir: Path,
                  out_vertex_votes_npy: Path) -> dict:
    """Segment every rendering with the selected image_model and sum its votes per vertex."""
    import numpy as np
    from PIL import Image

    from twinkit.cityscapes import N_CLASSES, PALETTE

    index_path = Path(in_renders_dir) / "index.json"
    try:
        index = json.loads(index_path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{index_path}: missing or unreadable ({exc}); re-run render_views") from None
    n = int(index["n_vertices"])
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
    t_model = 0.0
    t0 = time.perf_counter()
    batches = _size_batches(kept, max(1, int(params.batch_views)), Path(in_renders_dir))
    for batch in ctx.progress(batches, total=len(batches), desc="predict"):
        images = np.stack([np.asarray(Image.open(Path(in_renders_dir) / f"{v['id']}.png").convert("RGB")) for v in batch])
        vmaps = np.stack([np.load(Path(in_renders_dir) / f"{v['id']}_vertex.npz")["vertex"] for v in batch])
        t1 = time.perf_counter()
        kw = {"vertex_maps": vmaps} if getattr(model, "needs_vertex_map", False) else {}
        if params.soft_votes:
            proba = np.asarray(model.predict_proba(images, **kw), dtype=np.float32)
            labels = proba.argmax(axis=1).astype(np.uint8)
        else:
            labels = np.asarray(model.predict(images, **kw), dtype=np.uint8)
        t_model += time.perf_counter() - t1
        for j, v in enumerate(batch):
            vm = vmaps[j].reshape(-1)
            hit = vm >= 0
            if params.soft_votes:
                p = proba[j].reshape(N_CLASSES, -1)[:, hit]
                vv = np.stack([np.bincount(vm[hit], weights=p[c], minlength=n) for c in range(N_CLASSES)], axis=1)
            else:
                lab = labels[j].reshape(-1)[hit].astype(np.int64)
                ok = lab < N_CLASSES
                vv = np.bincount(vm[hit][ok].astype(np.int64) * N_CLASSES + lab[ok],
                                 minlength=n * N_CLASSES).reshape(n, N_CLASSES).astype(np.float64)
            if params.vote_per_view:  # a close-up covers a vertex with hundreds of pixels, a far view with one
                tot = vv.sum(axis=1, keepdims=True)
                vv = np.divide(vv, tot, out=np.zeros_like(vv), where=tot > 0)
            votes += vv
            if params.save_pngs:
                im = Image.fromarray(labels[j], mode="P")
                im.putpalette(pal.tolist())
                im.save(out_predictions_dir / f"{v['id']}.png")
    np.save(out_vertex_votes_npy, votes.astype(np.float32))
    (out_predictions_dir / "index.json").write_text(json.dumps(
        {"model": (ctx.config.get("image_model") or {}).get("plugin", "?") if ctx.config else "?",
         "views": [v["id"] for v in kept], "soft_votes": params.soft_votes,
         "vote_per_view": params.vote_per_view}, indent=1))
    seen = float((votes.sum(axis=1) > 0).mean())
    return {"views": len(kept), "model_seconds": round(t_model, 3), "seconds": round(time.perf_counter() - t0, 3),
            "seconds_per_view": round(t_model / max(len(kept), 1), 4), "vertices_seen": round(seen, 4)}


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
@dataclass
class BackprojectParams:
    use_segments: bool = param(True,
                               help="Vote per segment of the over-segmentation, blended with the vertex's own votes "
                                    "(false: per vertex only).")
    segment_weight: float = param(0.5, ge=0, le=1,
                                  help="Share of the segment's vote against the vertex's own (1 = the segment "
                                       "only).")
    ignore_classes: List[int] = param(default_factory=lambda: [10], ge=0, le=255,
                                      help="trainIds outside the target set, whose votes are ignored (10 = sky).")
    class_weights: List[float] = param(default_factory=list, ge=0,
                                       help="One weight per class (19, in trainId order) multiplying its votes; "
                                            "empty = all 1.")
    min_votes: float = param(0.0, ge=0, help="Vertices with fewer votes than this stay unlabelled.")
    fill_unlabelled: bool = param(True, help="Vertices no view saw take their neighbours' label.")
    context: bool = param(True,
                          help='Scale the blended vote by geometric cues of the mesh (docs/segmentation.md "3D '
                               'context in the vote"); false = no cues (with smooth_beta 0 too: the plain blended '
                               "vote).")
    context_cues: List[str] = param(default_factory=lambda: ["ground", "raised", "high", "curb", "column", "mounted",
                                                             "low", "narrow"], free=True,
                                    help="Which geometric cues act (of ground, raised, high, curb, column, mounted, "
                                         "low, narrow, slender). slender is off by default: it helps only where the "
                                         'model votes fence at all (docs/segmentation.md "Shape cues").')
    ground_window_m: float = param(3.0, gt=0, help="metres: the local ground's window (street.ground.LocalGround, opening); wider than the widest vehicle (2.55 m)")
    max_curb_m: float = param(0.30, ge=0,
                              help="An up-facing vertex at most this high (m) above the local ground is ground (the "
                                   "highest curb).")
    min_object_m: float = param(0.50, ge=0,
                                help="A vertex more than this (m) above the local ground is not road, sidewalk or "
                                     "terrain.")
    max_vehicle_m: float = param(4.70, ge=0,
                                 help="A vertex more than this (m) above the local ground is no vehicle or person "
                                      "(above the tallest bus or truck).")
    min_curb_m: float = param(0.05, ge=0, help="The lowest curb step (m).")
    band_width_m: float = param(4.0, ge=0, help="A sidewalk lies at most this far (m) from its curb.")
    context_factor: float = param(0.1, ge=0, le=1,
                                  help="Prior (vote factor) of a class the geometry rules out (ground, raised, high "
                                       "cues).")
    curb_factor: float = param(0.2, ge=0, le=1,
                               help="Prior (vote factor) of road on a raised band beside the carriageway.")
    curb_face: bool = param(True,
                            help="The curb's own face and rounded edge count as the band (CityScapes labels them "
                                 "sidewalk).")
    band_default: bool = param(True, help="Band vertices whose votes the cues explained away become sidewalk.")
    min_retained: float = param(0.2, ge=0, le=1,
                                help="A vertex whose cues leave less than this share of its votes is decided by its "
                                     "neighbours; 0 = off.")
    keep_share: float = param(1.0, ge=0, le=1,
                              help="The floor: a vertex whose own votes give one class at least this share (from at "
                                   "least keep_votes votes) keeps the plain vote's label, no cue acts; 0 = off.")
    keep_votes: float = param(32.0, ge=0, help="The floor (keep_share) needs at least this many votes (views).")
    smooth_beta: float = param(1.0, ge=0,
                               help="Potts smoothing on the vertex graph: the weight of the neighbours' labels; 0 = "
                                    "off.")
    smooth_iters: int = param(5, ge=0, help="Iterations of the Potts smoothing.")
    file_classes: bool = param(True,
                               help="Use the scan file's own classes (ASPRS codes in points.ply's classification) "
                                    'as a prior beside the views (docs/segmentation.md "File classes").')
    file_class_factor: float = param(0.1, ge=0, le=1,
                                     help="A class the file's classification rules out (a car on ASPRS ground) "
                                          "keeps this factor of its votes; the same strength as context_factor.")
    file_class_spacings: float = param(3.0, gt=0,
                                       help="A vertex takes the class of its nearest point within this many point "
                                            "spacings.")


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


def backproject(params: BackprojectParams, ctx: StepContext, *, in_textured_mesh_ply: Path, in_segments_npy: Path,
                in_vertex_votes_npy: Path, out_labels_npy: Path, out_confidence_npy: Path,
                out_labels_ply: Path, in_points_ply: Path | None = None) -> dict:
    """Votes per segment and class, argmax -> labels.npy (per vertex), confidence.npy, labels.ply (palette).
    The cloud's own classes (points.ply ``classification``), where it has them, are a prior beside the votes."""
    import numpy as np

    from twinkit.cityscapes import IGNORE
    from twinkit.mesh import edges as mesh_edges
    from twinkit_segmentation.segmesh import write_labels_ply
    from twinkit_segmentation.context import CUES, fuse_with_context, near_unanimous, potts_smooth
    from twinkit_segmentation.metrics import _weighted_votes, blend_distribution, decide_distribution, propagate
    from twinkit_segmentation.segmesh import unit_normals

    t0 = time.perf_counter()
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    seg = np.load(in_segments_npy)
    votes = np.load(in_vertex_votes_npy).astype(np.float64)
    if len(seg) != len(mesh.vertices) or len(votes) != len(mesh.vertices):
        raise InputError(f"{in_segments_npy.name} ({len(seg)}), {in_vertex_votes_npy.name} ({len(votes)}) and "
                         f"{in_textured_mesh_ply.name} ({len(mesh.vertices)}) disagree on the vertex count; re-run them")
    if params.use_segments:
        p, s_total = blend_distribution(seg, votes, params.segment_weight, params.ignore_classes,
                                        params.class_weights or None)
    else:
        p = _weighted_votes(votes, params.ignore_classes, params.class_weights or None)
        s_total = p.sum(axis=1)
    fprior, fvoting, fcodes, finfo = _file_classes(params, ctx, in_points_ply, mesh.vertices)
    labels, conf = decide_distribution(p, s_total < params.min_votes)
    base_labels = labels.copy()  # the views alone
    edges = None
    cmet: dict = {}
    t_ctx = 0.0
    bad = [c for c in params.context_cues if c not in CUES]
    if bad:
        raise InputError(f"backproject: unknown context_cues {bad}; choose from {list(CUES)}")
    if (params.context and params.context_cues) or fprior is not None:
        # the file's classes go through the same fusion as the cues (with no cue when context is off)
        cues = list(params.context_cues) if params.context else []
        t1 = time.perf_counter()
        edges = mesh_edges(mesh.faces, len(mesh.vertices))
        opt = context_options(params)
        keep = labels == IGNORE
        sure = near_unanimous(_weighted_votes(votes, params.ignore_classes, params.class_weights or None), None,
                              params.keep_share, params.keep_votes)
        labels, conf, cmet = fuse_with_context(p, mesh.vertices, unit_normals(mesh), edges, opt,
                                               cues, min_retained=params.min_retained,
                                               smooth_beta=params.smooth_beta, smooth_iters=params.smooth_iters,
                                               keep=sure, extra_prior=fprior)
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
    A.write_labels(out_labels_npy, labels.astype(np.uint8))
    np.save(out_confidence_npy, conf.astype(np.float32))
    write_labels_ply(out_labels_ply, mesh, labels)
    return {"unlabelled_before_fill": unlabelled_before, "unlabelled": int((labels == IGNORE).sum()),
            "mean_confidence": float(conf[conf > 0].mean()) if (conf > 0).any() else 0.0,
            "context": cmet, "context_seconds": round(t_ctx, 3), "file_classes": finfo,
            "seconds": round(time.perf_counter() - t0, 3)}


def _file_classes(params: BackprojectParams, ctx: StepContext, points_ply: Path | None, vertices):
    """(prior (n, 19) or None, voting (n,), per-vertex codes, info) from the cloud's own classes."""
    import numpy as np

    from twinkit_segmentation.fileclasses import classes_on_vertices, file_class_prior, read_point_classes

    if not params.file_classes:
        return None, None, None, {"used": False, "why": "file_classes: false"}
    if points_ply is None:
        return None, None, None, {"used": False, "why": "no points.ply"}
    got = read_point_classes(Path(points_ply))
    if got is None:
        return None, None, None, {"used": False, "why": "the cloud has no classification field"}
    pts, codes = got
    vcodes, spacing, reach = classes_on_vertices(pts, codes, vertices, params.file_class_spacings,
                                                 max(1, int(getattr(ctx, "threads", 1) or 1)))
    prior, voting = file_class_prior(vcodes, params.file_class_factor)
    info = {"used": bool(voting.any()), "point_spacing_m": round(spacing, 4), "reach_m": round(reach, 4),
            "factor": params.file_class_factor}
    if not voting.any():
        ctx.log.info("file classes: none of the cloud's classes (%s) says anything the labels use; not used",
                     ", ".join(str(int(c)) for c in np.unique(codes)[:12]))
        return None, None, None, dict(info, why="only silent codes (0 never classified, 1 unclassified, ...)")
    return prior, voting, vcodes, info


# ----------------------------------------------------------------------------- ground truth and evaluation
@dataclass
class TransferGtParams:
    max_distance_m: float = param(0.5, gt=0,
                                  help="Vertices farther than this (m) from any ground-truth face stay unlabelled "
                                       "(255).")


def transfer_gt_labels(params: TransferGtParams, ctx: StepContext, *, in_gt_mesh_ply: Path,
                       in_textured_mesh_ply: Path, out_gt_labels_npy: Path, out_gt_labels_ply: Path) -> dict:
    """Ground truth on the reconstructed vertices: the label of the nearest ground-truth face."""
    import numpy as np

    from twinkit.cityscapes import IGNORE
    from twinkit.street.truth import transfer_labels
    from twinkit_segmentation.segmesh import face_labels, vertex_labels, write_labels_ply

    gt = A.read_gt_mesh(in_gt_mesh_ply)
    if face_labels(gt) is None and vertex_labels(gt) is None:
        raise InputError(f"{in_gt_mesh_ply}: no 'label' property on faces or vertices")
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels, dist = transfer_labels(gt.vertices, gt.faces, mesh.vertices, face_labels=face_labels(gt),
                                   vertex_labels=vertex_labels(gt))
    labels[dist > params.max_distance_m] = IGNORE
    A.write_labels(out_gt_labels_npy, labels)
    write_labels_ply(out_gt_labels_ply, mesh, labels, comment="ground truth transferred from the nearest gt face")
    return {"vertices": int(len(labels)), "mean_distance_m": float(dist.mean()),
            "unlabelled": int((labels == IGNORE).sum()),
            "classes": sorted(int(c) for c in np.unique(labels) if c != IGNORE)}


@dataclass
class EvaluateParams:
    classes: List[int] = param(default_factory=list, ge=0, le=255,
                               help="trainIds to average the scores over; empty = those present in the ground "
                                    "truth.")


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
@dataclass
class ImportLabelsParams:
    pass


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
