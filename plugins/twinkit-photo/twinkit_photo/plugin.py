"""twinkit steps of the photo branch (entry point ``photo`` in group ``twinkit``).

photos -> sfm -> georeference -> roi -> dense -> (the point-cloud branch: poisson, clean_mesh, simplify,
bake_texture, evaluate_reconstruction) -> photo_texture. Every step body is here and only reads its inputs,
calls the algorithm modules and writes its outputs:

- ``sfm``           :mod:`images` (photos, EXIF), :mod:`sfm` (pycolmap)
- ``georeference``  :mod:`georef_fit` (which route, the fits, outliers), :mod:`georef` (the algorithms)
- ``roi``           :mod:`roi`
- ``dense``         :mod:`dense_cloud` (backend, tolerance, passes, points.ply), :mod:`dense`,
  :mod:`patchmatch`, :mod:`mvs` (COLMAP's patch-match)
- ``photo_texture`` :mod:`projtex`

Parameters are in :mod:`params`; heavy libraries are imported inside the step functions only.
"""
from __future__ import annotations

import time
from pathlib import Path

from twinkit import InputError, hookimpl
from twinkit.jsonio import write_json

from .files import read_json, write_cloud
from .params import DenseParams, GeorefParams, PhotoTextureParams, RoiParams, SfmParams

__all__ = ["DenseParams", "GeorefParams", "PhotoTextureParams", "RoiParams", "SfmParams", "dense", "georeference",
           "photo_texture", "roi", "sfm"]


def _threads(ctx) -> int:
    return max(1, int(getattr(ctx, "threads", 1) or 1))


def _frame(ctx):
    """The site frame (twinkit.geo), or None when the site has no CRS / base point."""
    from twinkit.geo import SiteFrame

    site = dict(ctx.site or {})
    if not site.get("crs") or not site.get("base_point"):
        return None
    return SiteFrame.from_site(site)


def _photo_infos(folder: Path, log):
    from .images import drop_identical, list_images, read_info

    infos = [read_info(p) for p in drop_identical(list_images(folder), log)]
    for i in infos:
        for note in i.notes:
            log.debug("%s: %s", i.name, note)
    if len(infos) < 2:
        raise InputError(f"{folder}: only {len(infos)} photo; structure from motion needs at least 2 "
                         f"overlapping photos (better 10 or more)")
    return infos


# ----------------------------------------------------------------------------- sfm

def sfm(params: SfmParams, ctx, *, in_photos_dir: Path, out_sfm_dir: Path, out_sfm_report_json: Path,
        in_cameras_json: Path | None = None) -> dict:
    """Features, matching and mapping with pycolmap; a COLMAP model folder and a report."""
    from .images import camera_groups
    from .sfm import (check_registration, choose_intrinsics, mean_reprojection_error, run_sfm_in_temp, sfm_options,
                      sfm_report, write_model)

    params = params or SfmParams()
    t_all = time.perf_counter()
    folder = Path(in_photos_dir)
    infos = _photo_infos(folder, ctx.log)
    n_gps = sum(i.has_gps for i in infos)
    K, k_source = choose_intrinsics(params.intrinsics, folder, infos, in_cameras_json)
    ctx.log.info("sfm: %d photos in %s (%d with GPS), intrinsics from %s", len(infos), folder.name, n_gps, k_source)
    groups = camera_groups(infos)
    if len(groups) > 1:
        ctx.log.info("sfm: %d camera groups (size, make/model, focal), each with its own intrinsics: %s", len(groups),
                     "; ".join(f"{g['size'][0]}x{g['size'][1]} {g['make'] or ''} {g['model'] or ''}".strip()
                               + f" ({len(g['photos'])})" for g in groups))
    opt = sfm_options(params, K, groups, _threads(ctx))
    names = [i.name for i in infos]
    res = run_sfm_in_temp(folder, names, opt, has_gps=n_gps >= max(3, len(infos) // 2), log=ctx.log)
    ratio, missing = check_registration(names, res.registered, params.min_registered_ratio,
                                        params.degraded_below_ratio, folder, ctx.degraded)
    rec = res.reconstruction
    n_points = write_model(Path(out_sfm_dir), rec, infos)
    reproj = mean_reprojection_error(rec)
    report = sfm_report(rec, res, infos, groups, ratio, missing, mapper=params.mapper, k_source=k_source,
                        n_gps=n_gps, n_points=n_points, reproj=reproj, total_s=time.perf_counter() - t_all)
    write_json(out_sfm_report_json, report)
    ctx.log.info("sfm: registered %d / %d photos (%.1f %%), mean reprojection error %.3f px, %d sparse points",
                 report["registered"], len(infos), 100 * ratio, reproj, n_points)
    return {k: report[k] for k in ("registered", "photos", "registered_ratio", "mean_reprojection_error_px",
                                   "sparse_points", "timings_s")}


# ----------------------------------------------------------------------------- georeference

def georeference(params: GeorefParams, ctx, *, in_sfm_dir: Path, out_cameras_site_json: Path,
                 out_georef_json: Path, out_sparse_site_ply: Path, in_gcp_json: Path | None = None,
                 in_cameras_json: Path | None = None, in_photos_dir: Path | None = None) -> dict:
    """Level the model, then map it into the site frame from GCPs, EXIF GPS or (without either) as is."""
    import numpy as np
    from twinkit.artefacts import write_cameras_site

    from . import georef_fit as G
    from .georef import read_gcp_file

    params = params or GeorefParams()
    t0 = time.perf_counter()
    sfm_dir = Path(in_sfm_dir)
    m = G.SfmModel(read_json(sfm_dir / "cameras_model.json", "SfM cameras"), np.load(sfm_dir / "sparse.npz"))
    frame = _frame(ctx)
    known = G.known_distance(params)
    gcps = read_gcp_file(in_gcp_json, frame) if in_gcp_json is not None and params.method in ("auto", "gcp") else []
    if params.method == "gcp" and in_gcp_json is None:
        raise InputError("steps.georeference.method=gcp needs a ground-control-point file: set site.inputs.gcp=<file.json>")
    gcp_rows = G.usable_gcps(m.rows, gcps, params.min_gcp_views)
    info: dict = {}
    method = G.choose_method(params, m, gcp_rows, len(gcps), in_gcp_json, frame, ctx.log, info)
    T, gps_site = G.fit(method, params, m, gcp_rows=gcp_rows, gcp_json=in_gcp_json, known=known, frame=frame,
                        sfm_dir=sfm_dir, photos_dir=in_photos_dir, log=ctx.log, info=info)
    scaled = G.describe_scale(method, params, T, known, ctx.log, info, ctx.degraded)
    T, xyz = G.ground_height(params, T, m.sparse["xyz"], info)
    outliers = G.flag_outliers(method, params, m, T, ctx.log, ctx.degraded, info)
    info["photos"] = G.photos_table(m, T, gps_site, outliers, info)
    cams_out = G.site_cameras(m, T, outliers)
    report = {"method": method, "transform": T.to_json(), **info, "cameras": len(cams_out)}
    if in_cameras_json is not None:
        report.update(G.truth_check(m, cams_out, read_json(in_cameras_json, "camera truth"), method, ctx.log))
    write_cameras_site(out_cameras_site_json, G.cameras_site_doc(method, scaled, cams_out, info))
    write_cloud(out_sparse_site_ply, xyz, m.sparse["rgb"], comments=[f"twinkit-photo georeference ({method})"])
    np.savez_compressed(Path(out_sparse_site_ply).with_suffix(".npz"), vis_image=m.sparse["vis_image"],
                        vis_point=m.sparse["vis_point"])
    report["time_s"] = round(time.perf_counter() - t0, 3)
    write_json(out_georef_json, report)
    return G.step_summary(report, T, len(outliers))


# ----------------------------------------------------------------------------- roi

def roi(params: RoiParams, ctx, *, in_cameras_site_json: Path, in_sparse_site_ply: Path, out_roi_json: Path) -> dict:
    """Region of interest: a box around the camera positions, standing on a RANSAC ground plane."""
    import numpy as np
    from twinkit.artefacts import read_cameras_site
    from twinkit.mesh import read_ply

    from .roi import ground_plane, roi_box, roi_doc, subject_depth

    params = params or RoiParams()
    cdoc = read_cameras_site(in_cameras_site_json)
    cams = cdoc.cameras
    scaled = bool(cdoc.extra.get("scaled", True))
    unit = "m" if scaled else "model units"
    if not scaled:
        # the margins, the ground threshold and max_depth_m below are metres; this frame is not
        ctx.degraded("the site frame is unscaled (no GPS with a site CRS, no GCPs, no known distance): the region "
                     "of interest, the dense step and the mesh apply thresholds in metres to model units",
                     "give steps.georeference.scale=<metres per model unit>, or "
                     "steps.georeference.distance_points_model=[x1,y1,z1,x2,y2,z2] with "
                     "steps.georeference.distance_m=<metres>, or site.crs and site.base_point for the photos' GPS")
    C = np.array([c["center"] for c in cams], float)
    pts = read_ply(in_sparse_site_ply).vertices
    ground = ground_plane(C, pts, params.ground_threshold_m)
    depth, depth_why = subject_depth(C, pts, params.max_depth_m)
    if depth != params.max_depth_m:
        ctx.log.warning("roi: the photos look farther than steps.roi.max_depth_m (%g %s): the depth limit is %.1f "
                        "%s (%s)", params.max_depth_m, unit, depth, unit, depth_why)
    box = roi_box(C, pts, ground["z_m"], params, depth)
    doc = roi_doc(C, pts, box, ground, depth, scaled, depth_why, cdoc.extra.get("units"))
    write_json(out_roi_json, doc)
    ctx.log.info("roi: box %s .. %s, ground z %.2f %s (%s), depth limit %.1f %s", np.round(box["min"], 1),
                 np.round(box["max"], 1), ground["z_m"], unit, ground["source"], depth, unit)
    return {"ground_z_m": ground["z_m"], "sparse_inside_ratio": doc["sparse_inside_ratio"], "scaled": scaled,
            "max_depth": depth}


# ----------------------------------------------------------------------------- dense

def dense(params: DenseParams, ctx, *, in_photos_dir: Path, in_cameras_site_json: Path, in_sparse_site_ply: Path,
          in_roi_json: Path, out_points_ply: Path, out_points_meta_json: Path, in_sfm_dir: Path | None = None,
          in_georef_json: Path | None = None, in_sfm_report_json: Path | None = None) -> dict:
    """Depth map per photo, fused to a coloured cloud with normals (what read_cloud writes): our CPU
    PatchMatch (or plane sweep), or COLMAP's patch-match stereo where pycolmap has CUDA (needs the sfm
    model and georef.json)."""
    import cv2
    from twinkit.artefacts import read_cameras_site

    from .dense_cloud import choose_backend, roi_limits

    params = params or DenseParams()
    backend = choose_backend(params.backend, in_sfm_dir is not None and in_georef_json is not None)
    t0 = time.perf_counter()
    cv2.setNumThreads(_threads(ctx))
    cams = read_cameras_site(in_cameras_site_json).cameras
    roi_doc = read_json(in_roi_json, "region of interest")
    bmin, bmax, max_depth = roi_limits(roi_doc, in_roi_json)
    if backend == "patchmatch":
        return _dense_colmap(params, ctx, in_photos_dir, in_sfm_dir, in_georef_json, bmin, bmax,
                             out_points_ply, out_points_meta_json, t0)
    return _dense_cpu(params, ctx, cams, roi_doc, bmin, bmax, max_depth, in_photos_dir, in_cameras_site_json,
                      in_sparse_site_ply, in_sfm_report_json, out_points_ply, out_points_meta_json, t0)


def _dense_cpu(params: DenseParams, ctx, cams, roi_doc, bmin, bmax, max_depth, in_photos_dir, in_cameras_site_json,
               in_sparse_site_ply, in_sfm_report_json, out_points_ply, out_points_meta_json, t0) -> dict:
    """The CPU route: depth maps (PatchMatch or plane sweep), consistency fusion, the region of interest."""
    from . import dense as D
    from . import dense_cloud as DC

    sp, vis = DC.read_sparse(in_sparse_site_ply)
    rel_tol, rel_why = DC.fusion_tolerance(params.rel_tol, in_sfm_report_json)
    ctx.log.info("dense: fusion tolerance %.2f %% of the depth (%s)", 100 * rel_tol, rel_why)
    opt, pm = DC.cpu_options(params, rel_tol, max_depth, _threads(ctx))
    views = D.load_views(Path(in_photos_dir), cams, opt.max_image_px)
    D.depth_ranges(views, sp, vis, max_depth)
    nb = D.choose_neighbors(views, vis, opt, sp)
    ground = roi_doc.get("ground") or {}
    if params.cpu_method == "patchmatch" and "normal" in ground and "z_m" in ground:
        D.near_limit_from_ground(views, ground["normal"], float(ground["z_m"]))  # after the neighbour choice
    t_sweep = time.perf_counter()
    n_maps, geometric = DC.depth_maps(views, nb, params.cpu_method, params.pm_geometric, opt, pm, ctx.progress,
                                      ctx.log)
    t_sweep = time.perf_counter() - t_sweep
    if n_maps == 0:
        raise InputError(f"{in_cameras_site_json}: no photo has a neighbour with a usable baseline "
                         f"({opt.min_angle_deg}-{opt.max_angle_deg} degrees); take photos a step or two apart")
    t_fuse = time.perf_counter()
    xyz, rgb, nrm, src = D.fuse(views, opt)
    t_fuse = time.perf_counter() - t_fuse
    info = DC.cpu_dense_info(params, views, nb, n_maps, geometric, rel_tol, rel_why, xyz, src, bmin, bmax)
    written, n_fused = DC.write_dense(
        xyz, rgb, nrm, bmin, bmax, params.voxel_m, in_photos_dir, out_points_ply, out_points_meta_json,
        f"{params.cpu_method} + fusion", "depth maps" if params.cpu_method == "sweep" else "patchmatch planes",
        dense_info=info, times={"seconds": round(time.perf_counter() - t0, 3), "depth_maps_s": round(t_sweep, 3),
                                "fusion_s": round(t_fuse, 3)})
    ctx.log.info("dense: %d depth maps, %d fused points, %d after the region of interest and %.3f %s voxels",
                 n_maps, n_fused, written, params.voxel_m, "m" if roi_doc.get("scaled", True) else "model-unit")
    DC.dense_gate(ctx.degraded, written, n_maps, params, "cpu")
    return {"points": written, "points_per_photo": round(written / max(n_maps, 1), 1), "depth_maps": n_maps,
            "fused": n_fused, "depth_maps_s": round(t_sweep, 3), "fusion_s": round(t_fuse, 3)}


def _dense_colmap(params: DenseParams, ctx, in_photos_dir, in_sfm_dir, in_georef_json, bmin, bmax,
                  out_points_ply, out_points_meta_json, t0) -> dict:
    """COLMAP patch-match + fusion in a throw-away workspace, then the same region of interest, voxel
    merge and outputs as the CPU route."""
    import tempfile

    from .dense_cloud import dense_gate, read_transform, write_dense
    from .mvs import colmap_dense

    scale, R, t = read_transform(in_georef_json)
    with tempfile.TemporaryDirectory(prefix="twinkit-mvs-") as tmp:
        xyz, rgb, nrm, info = colmap_dense(Path(in_sfm_dir), scale, R, t, Path(in_photos_dir), Path(tmp),
                                           max_image_px=params.max_image_px, min_consistent=params.min_consistent,
                                           threads=_threads(ctx), log=ctx.log)
    written, n_fused = write_dense(xyz, rgb, nrm, bmin, bmax, params.voxel_m, in_photos_dir, out_points_ply,
                                   out_points_meta_json, "COLMAP patch-match + fusion", "COLMAP patch-match",
                                   dense_info={"backend": "patchmatch", "depth_maps": info["depth_maps"],
                                               "working_px": params.max_image_px},
                                   times={"seconds": round(time.perf_counter() - t0, 3)})
    ctx.log.info("dense (patch-match): %d depth maps, %d fused points, %d after the region of interest and "
                 "%.3f m voxels", info["depth_maps"], n_fused, written, params.voxel_m)
    dense_gate(ctx.degraded, written, info["depth_maps"], params, "patchmatch")
    return {"backend": "patchmatch", "points": written, "depth_maps": info["depth_maps"], "fused": n_fused}


# ----------------------------------------------------------------------------- texture from the photos

def photo_texture(params: PhotoTextureParams, ctx, *, in_textured_mesh_ply: Path, in_photos_dir: Path,
                  in_cameras_site_json: Path, out_textured_mesh_obj: Path, out_textured_mesh_ply: Path,
                  in_roi_json: Path | None = None) -> dict:
    """Replace the baked texture (colours from the dense cloud) by the photos, projected and blended per texel.
    Photos reach as far as ``max_dist_m`` or the region of interest's depth limit, whichever is farther."""
    from twinkit.artefacts import read_cameras_site, write_textured_mesh, write_textured_obj
    from twinkit.surface.texture import write_png

    from .projtex import photo_views, project_texture, read_textured_mesh

    params = params or PhotoTextureParams()
    t0 = time.perf_counter()
    mesh, uv, base = read_textured_mesh(in_textured_mesh_ply)
    views = photo_views(read_cameras_site(in_cameras_site_json).cameras, in_photos_dir)
    if not views:
        raise InputError(f"{in_cameras_site_json}: no cameras")
    max_dist = params.max_dist_m
    if in_roi_json is not None:  # the depth the dense step kept (raised where the photos' subject is far)
        max_dist = max(max_dist, float(read_json(in_roi_json, "region of interest").get("max_depth_m") or 0.0))
    img, info = project_texture(mesh.vertices, mesh.faces, uv, base, views, max_views=params.max_views,
                                min_cos=params.min_cos, max_dist_m=max_dist, sharpness=params.sharpness,
                                consistency_views=params.consistency_views,
                                consistency_levels=params.consistency_levels,
                                threads=_threads(ctx), progress=ctx.progress)
    out_obj = Path(out_textured_mesh_obj)
    out_png = out_obj.with_suffix(".png")
    write_png(out_png, img)
    write_textured_obj(out_obj, mesh.vertices, mesh.faces, uv, out_png.name, normals=mesh.attrs.get("normals"))
    mesh.comments = [f"TextureFile {out_png.name}"]
    write_textured_mesh(out_textured_mesh_ply, mesh)
    info["seconds"] = round(time.perf_counter() - t0, 3)
    info["max_dist"] = max_dist
    _missing_photos_gate(ctx, params, views, info)
    ctx.log.info("photo texture: %.1f %% of the texels from %d photos (%.1f %% of the faces seen; %d photo views of "
                 "faces left out as inconsistent with the others: occluders the mesh lacks), %.1f s",
                 100 * info["texels_from_photos_ratio"], len(views), 100 * info["faces_seen_ratio"],
                 info["views_rejected_inconsistent"], info["seconds"])
    info.pop("best_view_faces", None)
    return info


def _missing_photos_gate(ctx, params: PhotoTextureParams, views, info: dict) -> None:
    """The photos that are the best view of no face of the mesh (too far, or the mesh lacks what they show):
    counted in ``info``; over ``degraded_above_missing_ratio`` of the photos, the run ends degraded."""
    missing = sorted(v.name for v in views if not info["best_view_faces"].get(v.name))
    info["photos_missing_mesh"] = len(missing)
    info["photos_missing_mesh_ratio"] = round(len(missing) / max(len(views), 1), 4)
    ctx.log.info("photo texture: %d of %d photos see the mesh (%d miss it: %s)", len(views) - len(missing),
                 len(views), len(missing), ", ".join(missing[:6]) + (" ..." if len(missing) > 6 else ""))
    if info["photos_missing_mesh_ratio"] > params.degraded_above_missing_ratio:
        ctx.degraded(f"{len(missing)} of {len(views)} photos miss the mesh ({', '.join(missing[:6])}"
                     f"{' ...' if len(missing) > 6 else ''}): the region of interest or the dense step lost what "
                     f"they show, or they stand over {info.get('max_dist', params.max_dist_m):g} from it",
                     "check the roi step's box and depth limit (roi.json), or raise steps.roi.max_depth_m and "
                     "steps.photo_texture.max_dist_m")


# ----------------------------------------------------------------------------- registration

from .report import twinkit_register_report_sections  # noqa: E402,F401 (this plugin's section of the run report)

@hookimpl
def twinkit_register_steps(register):
    register("sfm", sfm, params=SfmParams)
    register("georeference", georeference, params=GeorefParams)
    register("roi", roi, params=RoiParams)
    register("dense", dense, params=DenseParams)
    register("photo_texture", photo_texture, params=PhotoTextureParams)
