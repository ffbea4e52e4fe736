"""The dense step's pipeline around :mod:`dense` and :mod:`patchmatch`: the backend, the region of interest,
the fusion tolerance, the depth-map passes, and the cloud's end (crop, voxel merge, points.ply and
points_meta.json, the thin-cloud gate).

Site frame throughout (metres when the georeference was scaled). points_meta.json has the layout the
point-cloud branch's ``read_cloud`` writes, with a "dense" block of this branch's own.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from twinkit import InputError

FUSION_TOL_BASE = 0.003  # relative depth agreement for a model that reprojects within FUSION_TOL_AT_PX
FUSION_TOL_AT_PX = 0.35
FUSION_TOL_MAX = 0.01


# --------------------------------------------------------------------------- validate, choose the method

def choose_backend(backend: str, has_model: bool) -> str:
    """"cpu" or "patchmatch" (COLMAP's, CUDA): auto takes patchmatch where pycolmap has CUDA. ``has_model``:
    the sfm model and georef.json are given (COLMAP's route needs them)."""
    if backend in ("auto", "patchmatch"):
        import pycolmap

        cuda = bool(getattr(pycolmap, "has_cuda", False))
        if backend == "patchmatch" and not cuda:
            raise InputError("steps.dense.backend=patchmatch needs pycolmap built with CUDA (this one has none); "
                             "use steps.dense.backend=cpu")
        backend = "patchmatch" if cuda else "cpu"
    if backend not in ("cpu", "patchmatch"):
        raise InputError(f"dense: unknown backend '{backend}' (auto, cpu or patchmatch)")
    if backend == "patchmatch" and not has_model:
        raise InputError("steps.dense.backend=patchmatch needs the sfm step's model (sfm/) and the georeference step's "
                         "georef.json; run the image_site recipe, or use steps.dense.backend=cpu")
    return backend


def roi_limits(roi_doc: dict, roi_json: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(box min (3,), box max (3,), max_depth_m; 0 = none) of roi.json, checked."""
    try:
        bmin = np.asarray(roi_doc["box"]["min"], float)
        bmax = np.asarray(roi_doc["box"]["max"], float)
        max_depth = float(roi_doc.get("max_depth_m", 0.0) or 0.0)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{roi_json}: needs box.min and box.max (3 numbers each) ({exc}); fix the file or "
                         f"delete it to get the automatic one back") from None
    if np.any(bmax <= bmin):
        raise InputError(f"{roi_json}: box.max must exceed box.min on every axis")
    return bmin, bmax, max_depth


def read_transform(georef_json: Path):
    """georef.json's model -> site similarity as (scale, R (3, 3), t (3,))."""
    from .files import read_json

    tf = read_json(georef_json, "georeference")
    try:
        T = tf["transform"]
        return float(T["scale"]), np.asarray(T["R"], float), np.asarray(T["t"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{georef_json}: no usable 'transform' ({exc}); re-run the georeference step") from None


def read_sparse(sparse_ply: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The site-frame sparse points (N, 3) and which of them each photo sees ({name: int64 indices}), from
    sparse_site.ply and the sparse_site.npz beside it."""
    from twinkit.mesh import read_ply

    sp = read_ply(sparse_ply).vertices
    visz = np.load(Path(sparse_ply).with_suffix(".npz"))
    vis: dict[str, list] = {}
    for name, p in zip(visz["vis_image"].tolist(), visz["vis_point"].tolist()):
        vis.setdefault(name, []).append(p)
    return sp, {k: np.asarray(v, np.int64) for k, v in vis.items()}


def fusion_tolerance(rel_tol: float, sfm_report_json: Path | None) -> tuple[float, str]:
    """The fusion's relative depth tolerance and where it came from: the given one, or (-1) scaled with the
    SfM model's mean reprojection error -- the poses' own disagreement with the photos, which no pair of
    depth maps computed from them can beat."""
    if rel_tol > 0:
        return float(rel_tol), "given"
    err = None
    if sfm_report_json is not None and Path(sfm_report_json).is_file():
        try:
            err = float(json.loads(Path(sfm_report_json).read_text())["mean_reprojection_error_px"])
        except (OSError, ValueError, KeyError, TypeError):
            err = None
    if err is None or not err > 0:
        return FUSION_TOL_BASE, "auto: no SfM reprojection error known"
    tol = min(FUSION_TOL_MAX, FUSION_TOL_BASE * max(1.0, err / FUSION_TOL_AT_PX))
    return tol, f"auto: SfM mean reprojection error {err:.2f} px"


def cpu_options(params, rel_tol: float, max_depth: float, threads: int):
    """The step's parameters as (dense.DenseOptions, patchmatch.PMOptions)."""
    from .dense import DenseOptions
    from .patchmatch import PMOptions

    opt = DenseOptions(max_image_px=params.max_image_px, planes=params.planes, neighbors=params.neighbors,
                       window_px=params.window_px, min_ncc=params.min_ncc, min_consistent=params.min_consistent,
                       rel_tol=rel_tol, average_depths=params.average_depths,
                       min_triangulation_deg=params.min_triangulation_deg, max_depth_m=max_depth,
                       coarse_scale=params.coarse_scale, confirm_max_scale=params.confirm_max_scale,
                       refine_passes=params.refine_passes, threads=threads)
    pm = PMOptions(window=params.pm_window, dilation=params.pm_dilation, iters_coarse=params.pm_iters_coarse,
                   iters_fine=params.pm_iters_fine, top_k=params.pm_top_k, min_ncc=params.pm_min_ncc,
                   geom_weight=params.pm_geom_weight, geom_max_px=params.pm_geom_max_px, threads=opt.threads)
    return opt, pm


# --------------------------------------------------------------------------- compute

def depth_maps(views: list, nb: dict, method: str, geometric_pass: bool, opt, pm, progress, log) -> tuple[int, bool]:
    """A depth map per view with a usable neighbour (``v.depth``, in place): PatchMatch (then, with
    ``geometric_pass`` and two maps or more, its geometric-consistency pass) or the plane sweep.
    Returns (depth maps made, whether the geometric pass ran)."""
    from . import dense as D

    n_maps = 0
    for i in progress(range(len(views)), total=len(views), desc="depth maps"):
        v = views[i]
        if not nb[i] or v.dmax <= v.dmin or v.dmin <= 0:
            log.info("dense: %s has no usable neighbour; no depth map", v.name)
            continue
        if method == "patchmatch":
            v.depth, _ = D.patchmatch_view(v, [views[j] for j in nb[i]], opt, pm)
        else:
            v.depth, _ = D.plane_sweep(v, [views[j] for j in nb[i]], opt)
        n_maps += 1
    geometric = method == "patchmatch" and geometric_pass and n_maps > 1
    if geometric:
        photometric = [v.depth for v in views]
        for i in progress(range(len(views)), total=len(views), desc="depth maps, geometric pass"):
            v = views[i]
            if v.depth is None:
                continue
            v.depth, _ = D.patchmatch_geom_view(v, [views[j] for j in nb[i]], [photometric[j] for j in nb[i]], opt, pm)
        del photometric
    return n_maps, geometric


# --------------------------------------------------------------------------- report

def cpu_dense_info(params, views: list, nb: dict, n_maps: int, geometric: bool, rel_tol: float, rel_why: str,
                   xyz: np.ndarray, src: np.ndarray, bmin, bmax) -> dict:
    """points_meta.json's "dense" block for the CPU route: method, maps, tolerance, each photo's neighbours,
    valid-pixel share and fused points inside the region of interest (``src``: the photo of each point)."""
    in_roi = np.all((xyz >= bmin) & (xyz <= bmax), axis=1)
    per_photo = np.bincount(src[in_roi], minlength=len(views)) if len(src) else np.zeros(len(views), int)
    return {"backend": "cpu", "method": params.cpu_method, "depth_maps": n_maps, "photos": len(views),
            "geometric_pass": geometric,
            "working_px": params.max_image_px, "rel_tol": rel_tol, "rel_tol_from": rel_why,
            "confirm_max_scale": params.confirm_max_scale,
            "neighbours": {views[i].name: [views[j].name for j in nb[i]] for i in nb},
            "valid_ratio": {v.name: (None if v.depth is None else float((v.depth > 0).mean())) for v in views},
            "per_photo": {v.name: int(per_photo[i]) for i, v in enumerate(views) if v.depth is not None}}


def dense_gate(degraded, written: int, n_maps: int, params, backend: str) -> None:
    """A dense cloud far too thin for a street: say so through ``degraded(reason, hint)`` (the run ends
    degraded), with what to try."""
    per = written / max(n_maps, 1)
    if per < params.degraded_below_points_per_photo:
        degraded(f"dense stereo ({backend}) kept {written:,} points from {n_maps} photos ({per:,.0f} per photo, "
                 f"under {params.degraded_below_points_per_photo:,}): the mesh will cover a small part of what "
                 f"was photographed",
                 ("steps.dense.cpu_method=patchmatch (the CPU PatchMatch: a walked street keeps 7x the points); "
                  if params.cpu_method == "sweep" and backend == "cpu" else
                  "steps.dense.rel_tol=0.01 (a looser agreement between depth maps); " if backend == "cpu" else "")
                 + "photos with more overlap and texture; on a CUDA machine steps.dense.backend=patchmatch")


# --------------------------------------------------------------------------- write

def write_dense(xyz, rgb, nrm, bmin, bmax, voxel_m: float, in_photos_dir, out_points_ply, out_points_meta_json,
                method: str, normals_from: str, dense_info: dict, times: dict) -> tuple[int, int]:
    """Both routes' end: keep the points inside the region of interest, merge duplicates per voxel, write
    points.ply and points_meta.json (the format read_cloud writes, with its density block) through the artefact
    catalogue. Returns (points written, points fused)."""
    from twinkit.artefacts import write_points, write_points_meta

    from . import dense as D
    from .files import cloud

    n_fused = int(len(xyz))
    keep = np.all((xyz >= bmin) & (xyz <= bmax), axis=1)
    xyz, rgb, nrm = D.voxel_merge(xyz[keep], rgb[keep], nrm[keep], voxel_m)
    if len(xyz) < 100:
        raise InputError(f"{in_photos_dir}: dense matching ({method}) kept only {len(xyz)} points inside the region "
                         f"of interest; check roi.json (box) and the photos' overlap")
    write_points(out_points_ply, cloud(xyz, rgb, nrm, comments=[f"twinkit-photo dense ({method})"]))
    lo, hi = xyz.min(0), xyz.max(0)
    write_points_meta(out_points_meta_json, {  # its density block measured from the points written
        "source": {"file": Path(in_photos_dir).name, "format": "photos (dense stereo)",
                   "fields": ["x", "y", "z", "normals", "colors"]},
        "counts": {"read": n_fused, "dropped_invalid": int(n_fused - keep.sum()), "written": int(len(xyz))},
        "fields": {"normals": normals_from, "normals_orientation": "towards the photo", "colors": True,
                   "intensity": False, "classification": False, "scanner": False, "extra": []},
        "frame": {"kind": "site", "note": "from the georeference step"},
        "bounds_m": [lo.tolist(), hi.tolist()],
        "dense": dense_info, "time": times}, points=xyz)
    return int(len(xyz)), n_fused
