"""twinkit steps of the photo branch (entry point ``photo`` in group ``twinkit``).

photos -> sfm -> georeference -> roi -> dense -> (the point-cloud branch: poisson, clean_mesh, simplify,
bake_texture, evaluate_reconstruction). Heavy libraries are imported inside the step functions only.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twinkit import InputError, hookimpl
from twinkit.jsonio import write_json
from twinkit.ranges import param

if TYPE_CHECKING:
    from .georef import Transform


# ----------------------------------------------------------------------------- parameters

@dataclass
class SfmParams:
    """Structure from motion (pycolmap, CPU)."""

    matching: str = param("auto", choices=("auto", "exhaustive", "sequential", "spatial", "sequential+spatial"))  # auto | exhaustive | sequential | spatial | sequential+spatial
    exhaustive_max: int = param(40, ge=0)  # auto: exhaustive matching up to this many photos
    overlap: int = param(10, ge=1)  # sequential: each photo with its next N photos (file-name order)
    spatial_neighbors: int = param(12, ge=1)  # spatial: nearest photos by EXIF GPS
    mapper: str = param("incremental", choices=("incremental", "global"))  # incremental | global (GLOMAP)
    max_image_px: int = param(1600, ge=0)  # features are found on photos downscaled to this long side (0 = full size)
    max_features: int = param(4096, ge=1)
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool = True  # one set of intrinsics per camera group (same size, EXIF make/model, focal); false: per photo
    intrinsics: str = "auto"  # auto (K.txt beside the photos, else the site's cameras.json, else EXIF) | exif
    min_registered_ratio: float = param(0.5, ge=0, le=1)  # fewer registered photos -> error
    degraded_below_ratio: float = param(0.8, ge=0, le=1)  # fewer registered photos -> the run ends "degraded"
    seed: int = param(0, ge=0)
    deterministic: bool = True  # one thread for matching and mapping, so a re-run gives the same model (false: faster)


@dataclass
class GeorefParams:
    """Model frame -> site frame."""

    method: str = param("auto", choices=("auto", "gcp", "gps", "none"))  # auto (gcp, else gps, else none) | gcp | gps | none
    gps_threshold_m: float = param(8.0, gt=0)  # RANSAC inlier distance for GPS fixes (about 3 sigma of phone GPS)
    gps_use_z: bool = False  # scale from x, y only (GPS heights are the noisiest)
    height_from: str = param("gps", choices=("gps", "ground"))  # gps | ground: ground puts the sparse ground plane at ground_z_m
    ground_z_m: float = param(0.0)
    scale: float = param(1.0, gt=0)  # method none: metres per model unit
    min_gcp_views: int = param(2, ge=1)
    gcp_outlier_m: float = param(0.05, gt=0)  # a GCP whose residual exceeds this (and 3x the median) is left out of the fit
    # a camera is an outlier (flagged in georef.json, left out of cameras_site.json and so of the region of
    # interest, the dense step and the photo views) when its GPS fix is this many times gps_threshold_m away
    # from where the fit puts it, or it stands off the walk: farther from its nearest neighbour than 10 times
    # the median neighbour spacing (and, in metres, more than 5 m). 0 = keep every camera
    outlier_factor: float = param(3.0, ge=0)
    # levelling (docs/photo.md "Levelling"): the photos' own horizon (the robust mean of the cameras' up axes),
    # a ground plane only with this share of the sparse points and within ground_agree_deg of the photos' up
    # (or 3x its standard error)
    min_ground_support: float = param(0.2, ge=0, le=1)
    ground_agree_deg: float = param(2.0, ge=0, le=90)
    vertical_lines: bool = True  # refine the photos' horizon with vertical lines (building edges) in the photos
    # the user's own frame, in the SfM model frame (sfm/sparse_model.ply): an up vector [x, y, z]; a known
    # distance: two points [x1, y1, z1, x2, y2, z2] and their distance in metres (method none: sets the scale);
    # a 4x4 similarity model -> site (16 numbers, row by row) replaces levelling and fit (method none)
    up_model: list[float] = param(default_factory=list)
    distance_points_model: list[float] = param(default_factory=list)
    distance_m: float = param(0.0, ge=0)  # 0 = no known distance
    transform_model_to_site: list[float] = param(default_factory=list)


@dataclass
class RoiParams:
    """Automatic region of interest and ground plane (edit roi.json to override)."""

    margin_m: float = param(12.0, ge=0)  # around the camera positions, horizontally
    below_ground_m: float = param(1.0, ge=0)
    above_ground_m: float = param(25.0, gt=0)
    ground_threshold_m: float = param(0.10, gt=0)  # RANSAC inlier distance for the ground plane
    max_depth_m: float = param(40.0, ge=0)  # dense matching ignores anything farther from a photo


@dataclass
class DenseParams:
    """Dense reconstruction: CPU PatchMatch (or plane-sweep) stereo + consistency fusion (pycolmap patch-match with CUDA)."""

    backend: str = param("auto", choices=("auto", "cpu", "patchmatch"))  # auto (patchmatch when pycolmap has CUDA, else cpu) | cpu | patchmatch
    # the CPU backend's matcher: patchmatch (per-pixel slanted planes, propagation, best-of-neighbours NCC;
    # twinkit_photo/patchmatch.py) or sweep (the plane sweep over four plane families). PatchMatch is the default
    # since 28 Nov 2026: with the neighbours chosen by the shared points' angles it meets the demo's 3 cm mesh
    # target (2.75 cm with min_triangulation_deg) and keeps 6-20x the sweep's points on a walked street (docs/photo.md)
    cpu_method: str = param("patchmatch", choices=("patchmatch", "sweep"))
    max_image_px: int = param(640, ge=16, le=16384)  # working resolution (long side)
    planes: int = param(192, ge=2, le=4096)  # most planes per plane family of the coarse sweep
    neighbors: int = param(4, ge=1)
    window_px: int = param(7, ge=1, le=63)
    min_ncc: float = param(0.55, ge=-1, le=1)
    min_consistent: int = param(2, ge=0)  # other depth maps that must agree
    # ... where that many other photos could confirm the point: it lies in their frame and depth range and they
    # see it from at most this many times its distance (farther, a photo sees it at under a third of the
    # resolution and cannot confirm a depth to rel_tol); where fewer could, one agreeing map is enough. A
    # forward walk with photos 8-13 m apart sees the road ahead of a photo only from the photos behind it,
    # 3-5x as far: two agreeing maps there are out of reach (Lund held-out: 26.jpg 4 -> 33 % covered, mean
    # 58.0 -> 63.2 %; demo mesh 2.71 -> 2.70 cm; docs/photo.md). 0 = min_consistent everywhere
    confirm_max_scale: float = param(3.0, ge=0)
    # agreement: |depth difference| < rel_tol * depth. -1 = auto: 0.3 % for photos whose SfM model reprojects
    # within 0.35 px (the demo's GCP-georeferenced model: the tightest tolerance that keeps its 3 cm), growing in
    # proportion to the model's mean reprojection error (sfm_report.json) up to 1 %: depth maps cannot agree
    # better than the poses they were computed from (Lund, 0.68 px: 0.59 %)
    rel_tol: float = param(-1.0, gt=0, also=(-1,))
    average_depths: bool = True  # a kept point's depth is the mean of the depth maps that agree with it
    # a kept point needs an agreeing depth map whose photo sees it at least this angle apart (COLMAP's
    # filter_min_triangulation_angle, 3 degrees): points fused only from near-parallel rays are the noisy ones, and
    # on the demo they toggled the mesh's error between 2.76 and 3.26 cm on a 0.1 % change of rel_tol (2.64-2.70 with it)
    min_triangulation_deg: float = param(3.0, ge=0, le=60)
    voxel_m: float = param(0.02, ge=0)  # merge duplicate points per voxel (0 = off)
    coarse_scale: float = param(0.25, gt=0, le=1)
    refine_passes: int = param(2, ge=0)
    pm_window: int = param(5, ge=3, le=15)  # patchmatch: window samples per side
    pm_dilation: int = param(2, ge=1, le=8)  # patchmatch: pixels between window samples
    pm_iters_coarse: int = param(4, ge=0, le=32)  # patchmatch iterations at half the working resolution
    pm_iters_fine: int = param(3, ge=0, le=32)  # then at the working resolution
    pm_top_k: int = param(2, ge=1, le=16)  # a pixel's cost: mean NCC cost of its best top_k neighbours
    pm_min_ncc: float = param(0.5, ge=-1, le=1)  # patchmatch: keep a depth whose aggregated NCC reaches this
    # patchmatch: a second pass over every photo whose cost adds the forward-backward reprojection error against
    # the neighbours' depth maps (geometric consistency): where the photos alone are ambiguous (a walked street's
    # far road, repeated cobbles) each map settles on the depth its neighbours see. Lund: 48 -> 58 % of held-out
    # pixels covered; about doubles the depth maps' time
    pm_geometric: bool = True
    pm_geom_weight: float = param(0.3, ge=0)  # cost per pixel of forward-backward error ...
    pm_geom_max_px: float = param(3.0, gt=0)  # ... counted up to this many pixels
    # fewer kept points per depth map than this: the run ends "degraded" (the demo keeps ~10,000 per photo; the
    # CPU sweep kept 148 per photo on Lund, a 5 m² mesh)
    degraded_below_points_per_photo: int = param(1000, ge=0)


@dataclass
class PhotoTextureParams:
    """Texture from the photos (project and blend the best views per texel)."""

    # photos blended per face (the best ones that pass the consistency check below), weight score ** sharpness
    # (score = cos(view angle) / distance). The mean of the 6 best consistent photos is nearer the truth than the
    # best photo alone: the demo's texture bench 21.5 -> 22.0 dB, held-out PSNR Sceaux +0.3, Lund +0.2 dB
    # (3 views, sharpness 4 before; docs/photo.md "Blending")
    max_views: int = param(6, ge=1)
    sharpness: float = param(0.0, ge=0)
    min_cos: float = param(0.15, ge=0, le=1)  # ignore views more grazing than about 81 degrees
    max_dist_m: float = param(40.0, gt=0)  # ignore views farther than this
    # photo-consistency check (Waechter et al. 2014): of a face's best this-many photos, those whose colour of the
    # face is over consistency_levels (RGB distance, 0-255) from the consensus of all of them are not used -- a
    # tree, a parked car or a walker in front of the surface in some photos only, which the mesh lacks.
    # Held-out PSNR: Sceaux 15.8 -> 17.7 dB (the chestnut tree's leaves were painted onto the façade), Lund
    # unchanged; the demo's texture bench -0.3 dB (railings reconstructed as a sheet; docs/photo.md). 0 = off
    consistency_views: int = param(8, ge=0)
    consistency_levels: float = param(45.0, gt=0)


# ----------------------------------------------------------------------------- helpers



def _threads(ctx) -> int:
    return max(1, int(getattr(ctx, "threads", 1) or 1))


def _read_json(path: Path, what: str) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc}); re-run the step that made it") from None


def _frame(ctx):
    """The site frame (twinkit.geo), or None when the site has no CRS / base point."""
    from twinkit.geo import SiteFrame

    site = dict(ctx.site or {})
    if not site.get("crs") or not site.get("base_point"):
        return None
    return SiteFrame.from_site(site)


def _photo_infos(folder: Path, log):
    from .images import list_images, read_info

    files = list_images(folder)
    infos = [read_info(p) for p in files]
    for i in infos:
        for note in i.notes:
            log.debug("%s: %s", i.name, note)
    return infos


def _write_cloud(path: Path, xyz, rgb=None, normals=None, comments=()):
    import numpy as np
    from twinkit.mesh import Mesh, write_ply

    attrs = {}
    if normals is not None:
        attrs["normals"] = np.asarray(normals, np.float32)
    if rgb is not None:
        attrs["colors"] = np.asarray(rgb, np.uint8)
    write_ply(path, Mesh(vertices=np.asarray(xyz, float), attrs=attrs, comments=list(comments)))


# ----------------------------------------------------------------------------- sfm

def sfm(params: SfmParams, ctx, *, in_photos_dir: Path, out_sfm_dir: Path, out_sfm_report_json: Path,
        in_cameras_json: Path | None = None) -> dict:
    """Features, matching and mapping with pycolmap; a COLMAP model folder and a report."""
    import numpy as np

    from .images import camera_groups, read_k_txt
    from .sfm import SfmOptions, camera_table, run_sfm, sparse_points

    params = params or SfmParams()
    t_all = time.perf_counter()
    folder = Path(in_photos_dir)
    infos = _photo_infos(folder, ctx.log)
    if len(infos) < 2:
        raise InputError(f"{folder}: only {len(infos)} photo; structure from motion needs at least 2 "
                         f"overlapping photos (better 10 or more)")
    sizes = {(i.width, i.height) for i in infos}
    n_gps = sum(i.has_gps for i in infos)
    K = None
    k_source = "exif"
    if params.intrinsics == "auto":
        K = read_k_txt(folder)
        if K is not None:
            k_source = "K.txt"
        elif in_cameras_json is not None and len(sizes) == 1:
            cams = _read_json(in_cameras_json, "camera file")
            intr = cams.get("intrinsics") or {}
            if "K" in intr and (intr.get("width"), intr.get("height")) in sizes:
                K, k_source = intr["K"], Path(in_cameras_json).name
    elif params.intrinsics != "exif":
        raise InputError(f"sfm: intrinsics='{params.intrinsics}' must be auto or exif")
    if K is not None and len(sizes) != 1:
        K, k_source = None, "exif"
    ctx.log.info("sfm: %d photos in %s (%d with GPS), intrinsics from %s", len(infos), folder.name, n_gps, k_source)
    groups = camera_groups(infos)
    if len(groups) > 1:
        ctx.log.info("sfm: %d camera groups (size, make/model, focal), each with its own intrinsics: %s", len(groups),
                     "; ".join(f"{g['size'][0]}x{g['size'][1]} {g['make'] or ''} {g['model'] or ''}".strip()
                               + f" ({len(g['photos'])})" for g in groups))
    import shutil
    import tempfile

    work = Path(tempfile.mkdtemp(prefix="twinkit_sfm_"))  # COLMAP database and attempts; removed afterwards
    opt = SfmOptions(matching=params.matching, exhaustive_max=params.exhaustive_max, overlap=params.overlap,
                     spatial_neighbors=params.spatial_neighbors, mapper=params.mapper,
                     max_image_px=params.max_image_px, max_features=params.max_features,
                     camera_model=params.camera_model, single_camera=params.single_camera, intrinsics=K,
                     groups=[g["photos"] for g in groups],
                     threads=_threads(ctx), seed=params.seed, deterministic=params.deterministic)
    try:
        res = run_sfm(folder, [i.name for i in infos], work, opt, has_gps=n_gps >= max(3, len(infos) // 2),
                      log=ctx.log)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    rec = res.reconstruction
    n_reg = len(res.registered)
    ratio = n_reg / len(infos)
    missing = sorted(set(i.name for i in infos) - set(res.registered))
    if ratio < params.min_registered_ratio:
        raise InputError(f"{folder}: structure from motion registered only {n_reg} of {len(infos)} photos "
                         f"({100 * ratio:.0f} % < sfm.min_registered_ratio {100 * params.min_registered_ratio:.0f} %); "
                         f"unregistered: {', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}. Take more "
                         f"overlapping photos, try sfm.matching=exhaustive or sequential, or lower the ratio")
    if ratio < params.degraded_below_ratio:
        ctx.degraded(f"structure from motion registered only {n_reg} of {len(infos)} photos; unregistered: "
                     f"{', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}",
                     "take more overlapping photos, or try steps.sfm.matching=exhaustive")
    out = Path(out_sfm_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec.write(str(out))
    cams = camera_table(rec)
    xyz, rgb, err = sparse_points(rec)
    # visibility: which sparse point each registered photo sees (for dense depth ranges and neighbours)
    pid = {p: k for k, p in enumerate(rec.points3D.keys())}
    vis_img, vis_pt = [], []
    for iid in rec.reg_image_ids():
        im = rec.images[iid]
        ids = [pid[p.point3D_id] for p in im.points2D if p.has_point3D()]
        vis_img += [im.name] * len(ids)
        vis_pt += ids
    np.savez_compressed(out / "sparse.npz", xyz=xyz, rgb=rgb, error=err, vis_image=np.array(vis_img),
                        vis_point=np.array(vis_pt, np.int64))
    gps = {i.name: [i.lat, i.lon, i.alt] for i in infos if i.has_gps}
    write_json(out / "cameras_model.json", {"frame": "SfM model frame (arbitrary scale and orientation)",
                                             "convention": "OpenCV camera, R_world_from_camera, center",
                                             "cameras": cams, "exif_gps": gps})
    _write_cloud(out / "sparse_model.ply", xyz, rgb, comments=["twinkit-photo sfm sparse points, model frame"])
    reproj = float(rec.compute_mean_reprojection_error()) if n_reg else float("nan")
    track = float(np.mean([rec.points3D[p].track.length() for p in rec.points3D])) if len(xyz) else 0.0
    report = {
        "photos": len(infos), "registered": n_reg, "registered_ratio": round(ratio, 4),
        "unregistered": missing, "mean_reprojection_error_px": round(reproj, 4),
        "sparse_points": int(len(xyz)), "mean_track_length": round(track, 3),
        "matching": res.matching, "mapper": params.mapper, "attempts": res.attempts,
        "intrinsics_from": k_source, "photos_with_gps": n_gps,
        "camera_groups": [dict(g, photos=len(g["photos"]),
                               registered=sum(1 for n in g["photos"] if n in set(res.registered))) for g in groups],
        "cameras": [{"id": int(cid), "model": c.model.name, "params": [float(v) for v in c.params]}
                    for cid, c in rec.cameras.items()],
        "timings_s": {**res.timings_s, "total": round(time.perf_counter() - t_all, 3)},
    }
    write_json(out_sfm_report_json, report)
    ctx.log.info("sfm: registered %d / %d photos (%.1f %%), mean reprojection error %.3f px, %d sparse points",
                 n_reg, len(infos), 100 * ratio, reproj, len(xyz))
    return {"registered": n_reg, "photos": len(infos), "registered_ratio": round(ratio, 4),
            "mean_reprojection_error_px": round(reproj, 4), "sparse_points": int(len(xyz)),
            "timings_s": report["timings_s"]}


# ----------------------------------------------------------------------------- georeference

def _outlier_cameras(names: list[str], centres, gps_residual: dict, params: GeorefParams,
                     metric: bool = True) -> dict[str, str]:
    """Cameras not to trust: a GPS fix far beyond the RANSAC threshold from where the fit puts the camera, or
    a camera standing off the walk (a misregistered photo). {name: why}."""
    import numpy as np

    out: dict[str, str] = {}
    if params.outlier_factor <= 0:
        return out
    for n, e in gps_residual.items():
        if e > params.outlier_factor * params.gps_threshold_m:
            out[n] = f"{e:.1f} m from its own GPS fix (RANSAC threshold {params.gps_threshold_m:g} m)"
    P = np.asarray(centres, float)
    if len(P) >= 5:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(P).query(P, k=2)
        nn = d[:, 1]
        spacing = float(np.median(nn))
        limit = max(5.0 if metric else 0.0, 10.0 * spacing)
        for n, e in zip(names, nn):
            if e > limit and n not in out:
                unit = "m" if metric else "model units"
                out[n] = f"{e:.1f} {unit} from the nearest other camera (median spacing {spacing:.1f}): off the walk"
    return out


def _suggest_site(model: dict, names: list[str]) -> str:
    """With EXIF GPS and no site CRS: the UTM zone of the photos and a base point (their mean position)."""
    import numpy as np

    ll = np.array([model["exif_gps"][n] for n in names], dtype=float)
    lat, lon = float(np.nanmean(ll[:, 0])), float(np.nanmean(ll[:, 1]))
    alt = float(np.nanmean(ll[:, 2])) if np.isfinite(ll[:, 2]).any() else 0.0
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    epsg = (32600 if lat >= 0 else 32700) + zone
    return (f"set site.crs=EPSG:{epsg} (WGS 84 / UTM zone {zone}{'N' if lat >= 0 else 'S'}, the photos' zone; "
            f"or your country's grid) and site.base_point={{lat: {lat:.6f}, lon: {lon:.6f}, alt: {alt:.1f}}} "
            f"(the photos' mean GPS position) in conf/site/<site>.yaml")


def _user_transform(m16) -> "Transform":
    """georeference.transform_model_to_site (16 numbers, a 4x4 similarity row by row) as a Transform."""
    import numpy as np

    from .georef import Transform

    M = np.asarray(m16, float).reshape(4, 4)
    A = M[:3, :3]
    det = float(np.linalg.det(A))
    if not np.allclose(M[3], [0, 0, 0, 1], atol=1e-9) or det <= 0:
        raise InputError("georeference.transform_model_to_site: not a similarity (last row must be 0 0 0 1 and the "
                         "3x3 part a rotation times a positive scale)")
    s = det ** (1.0 / 3.0)
    R = A / s
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-3):
        raise InputError("georeference.transform_model_to_site: the 3x3 part is not a rotation times one scale "
                         "(shear or unequal scales); give a similarity")
    U, _, Vt = np.linalg.svd(R)
    return Transform(s, U @ Vt, M[:3, 3].copy())


def georeference(params: GeorefParams, ctx, *, in_sfm_dir: Path, out_cameras_site_json: Path,
                 out_georef_json: Path, out_sparse_site_ply: Path, in_gcp_json: Path | None = None,
                 in_cameras_json: Path | None = None, in_photos_dir: Path | None = None) -> dict:
    """Level the model, then map it into the site frame from GCPs, EXIF GPS or (without either) as is."""
    import numpy as np

    from twinkit.geo.similarity import closed_form_similarity

    from .georef import Transform, level, read_gcp_file, robust_umeyama, triangulate

    params = params or GeorefParams()
    t0 = time.perf_counter()
    sfm_dir = Path(in_sfm_dir)
    model = _read_json(sfm_dir / "cameras_model.json", "SfM cameras")
    sp = np.load(sfm_dir / "sparse.npz")
    rows = {c["image"]: c for c in model["cameras"]}
    names = sorted(rows)
    C = np.array([rows[n]["center"] for n in names], float)
    Rwc = np.array([rows[n]["R_world_from_camera"] for n in names], float)
    frame = _frame(ctx)
    info: dict[str, Any] = {}
    method = params.method
    lv = {"up_model": list(params.up_model) or None, "min_ground_support": params.min_ground_support,
          "ground_agree_deg": params.ground_agree_deg}

    def with_lines() -> dict:
        """The levelling options, with the vertical lines of the photos (only the routes that level need them)."""
        if params.vertical_lines and in_photos_dir is not None and Path(in_photos_dir).is_dir() and not params.up_model:
            from .georef import camera_horizon, vertical_from_lines

            t_v = time.perf_counter()
            v = vertical_from_lines(Path(in_photos_dir), [rows[n] for n in names], camera_horizon(Rwc)[0])
            v[1]["seconds"] = round(time.perf_counter() - t_v, 3)
            return {**lv, "vertical": v}
        return lv
    if params.up_model and len(params.up_model) != 3:
        raise InputError(f"georeference.up_model has {len(params.up_model)} numbers; give 3 (x, y, z in the SfM "
                         f"model frame, e.g. read off sfm/sparse_model.ply) or none")
    known = None  # the known distance's length in model units
    if params.distance_points_model or params.distance_m:
        if len(params.distance_points_model) != 6 or params.distance_m <= 0:
            raise InputError("georeference: a known distance needs distance_points_model (6 numbers: two points "
                             "x1, y1, z1, x2, y2, z2 in the SfM model frame) and distance_m > 0 (their distance in "
                             "metres)")
        pa, pb = np.asarray(params.distance_points_model, float).reshape(2, 3)
        known = float(np.linalg.norm(pa - pb))
        if known <= 0:
            raise InputError("georeference.distance_points_model: the two points are the same point")
    gcps = []
    gps_site: dict[str, list] = {}
    if in_gcp_json is not None and method in ("auto", "gcp"):
        gcps = read_gcp_file(in_gcp_json, frame)
    if method == "gcp" and in_gcp_json is None:
        raise InputError("georeference.method=gcp needs a ground-control-point file: set site.inputs.gcp=<file.json>")
    # ---- GCPs
    gcp_rows = []
    for g in gcps:
        X, nv = triangulate(rows, g["observations"])
        if X is not None and nv >= params.min_gcp_views:
            gcp_rows.append((g["id"], X, g["site_xyz"], nv))
    if method == "auto":
        gps_ok = [n for n in names if n in model.get("exif_gps", {})]
        if in_gcp_json is not None and len(gcp_rows) < 3:
            # the user gave a GCP file: say why it was not used and what was used instead
            why = (f"only {len(gcp_rows)} of its {len(gcps)} points are seen in >= {params.min_gcp_views} "
                   f"registered photos (3 needed)")
            instead = ("EXIF GPS" if len(gps_ok) >= 3 and frame is not None else
                       "nothing: the model is only levelled and centred")
            ctx.log.warning("georeference: the GCP file %s cannot be used: %s; using %s instead",
                            Path(in_gcp_json).name, why, instead)
            info["gcp_unused"] = {"file": Path(in_gcp_json).name, "why": why, "used_instead": instead,
                                  "points": len(gcps), "usable": len(gcp_rows)}
        if len(gcp_rows) >= 3:
            method = "gcp"
        elif len(gps_ok) >= 3 and frame is not None:
            method = "gps"
        else:
            method = "none"
            if len(gps_ok) >= 3 and frame is None:
                ctx.log.warning("georeference: %d photos carry EXIF GPS but the site has no crs/base_point, so "
                                "the GPS is not used: %s", len(gps_ok), _suggest_site(model, gps_ok))
                info["gps_unused"] = {"photos_with_gps": len(gps_ok), "why": "the site has no crs or base_point",
                                      "suggestion": _suggest_site(model, gps_ok)}
            else:
                ctx.log.warning("georeference: no usable GCPs and fewer than 3 registered photos with EXIF GPS: "
                                "the model is only levelled and centred (scale %.3f); give site.inputs.gcp for a "
                                "metric, georeferenced result", params.scale)
    if len(params.transform_model_to_site) not in (0, 16):
        raise InputError(f"georeference.transform_model_to_site has {len(params.transform_model_to_site)} numbers; "
                         f"give 16 (a 4x4 similarity, row by row) or none")
    if params.transform_model_to_site:
        method = "transform"
    if method == "gcp":
        if len(gcp_rows) < 3:
            raise InputError(f"{in_gcp_json}: only {len(gcp_rows)} ground-control points are seen in "
                             f">= {params.min_gcp_views} registered photos with a known position; need 3")
        src = np.array([r[1] for r in gcp_rows])
        dst = np.array([r[2] for r in gcp_rows])
        T, keep = robust_umeyama(src, dst, params.gcp_outlier_m)
        res = np.linalg.norm(T.apply(src) - dst, axis=1)
        left_out = [r[0] for r, k in zip(gcp_rows, keep) if not k]
        if left_out:
            ctx.log.warning("georeference: %d of %d ground-control points left out of the fit (residual over "
                            "%.3f m and 3x the median): %s; check their positions and clicks",
                            len(left_out), len(gcp_rows), params.gcp_outlier_m, ", ".join(left_out))
        info["gcp"] = {"used": int(keep.sum()), "left_out": left_out,
                       "residual_m": {r[0]: float(e) for r, e in zip(gcp_rows, res)},
                       "views": {r[0]: int(r[3]) for r in gcp_rows},
                       "rmse_m": float(np.sqrt(np.mean(res[keep] ** 2)))}
    elif method == "gps":
        from twinkit.geo import fit_similarity

        if frame is None:
            gps_ok = [n for n in names if n in model.get("exif_gps", {})]
            raise InputError("georeference.method=gps needs the site's crs and base_point (conf/site/<site>.yaml)"
                             + (f"; {_suggest_site(model, gps_ok)}" if gps_ok else ""))
        R_lvl, linfo = level(C, Rwc, sp["xyz"], ctx.log, **with_lines())
        info["level"] = linfo
        gps_names = [n for n in names if n in model.get("exif_gps", {})]
        if len(gps_names) < 3:
            raise InputError(f"{sfm_dir}: only {len(gps_names)} registered photos carry EXIF GPS; need 3 for "
                             f"method=gps (give a GCP file with site.inputs.gcp, or georeference.method=none)")
        ll = np.array([model["exif_gps"][n] for n in gps_names], dtype=float)
        xy = frame.lonlat_to_local(ll[:, [1, 0]])
        z = np.where(np.isfinite(ll[:, 2]), ll[:, 2] - frame.alt, 0.0)
        dst = np.c_[xy, z]
        far = float(np.linalg.norm(np.median(dst[:, :2], 0)))
        if far > 20000.0:
            raise InputError(f"{sfm_dir.parent.name}: the photos' EXIF GPS lies {far / 1000:.0f} km from the site's "
                             f"base point; set site.base_point (and site.crs) to the place the photos show")
        src = (C[[names.index(n) for n in gps_names]]) @ R_lvl.T
        sim = fit_similarity(src, dst, threshold_m=params.gps_threshold_m, use_z=params.gps_use_z)
        c, s = np.cos(sim.yaw_rad), np.sin(sim.yaw_rad)
        Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        T = Transform(sim.scale, Rz @ R_lvl, np.asarray(sim.t, float))
        res_gps = np.linalg.norm(sim.apply(src)[:, :2] - dst[:, :2], axis=1)
        gps_site = {n: dst[k].tolist() for k, n in enumerate(gps_names)}
        info["gps"] = {**sim.to_json(), "photos_with_gps": len(gps_names),
                       "residual_m": {n: round(float(e), 3) for n, e in zip(gps_names, res_gps)}}
    elif method == "none":
        R_lvl, linfo = level(C, Rwc, sp["xyz"], ctx.log, **with_lines())
        info["level"] = linfo
        scale = float(params.scale)
        if known is not None:
            scale = params.distance_m / known
            info["scale_from"] = "known distance"
        elif params.scale != 1.0:
            info["scale_from"] = "georeference.scale"
        T = Transform(scale, R_lvl, -scale * R_lvl @ C.mean(0))
    elif method == "transform":
        T = _user_transform(params.transform_model_to_site)
        info["level"] = {"up_from": "user transform"}
    else:
        raise InputError(f"georeference: unknown method '{params.method}' (auto, gcp, gps or none)")
    scaled = method in ("gcp", "gps", "transform") or "scale_from" in info
    info["scaled"] = scaled
    info["units"] = "metres" if scaled else "model units (unscaled: no GPS, GCPs, known distance or scale)"
    if known is not None:
        got = float(T.scale * known)
        info["known_distance"] = {"given_m": params.distance_m, "in_site_frame_m": round(got, 4),
                                  "error_m": round(got - params.distance_m, 4)}
    if "level" in info and "final_vs_camera_horizon" in info["level"]:
        info["level_vs_camera_horizon_deg"] = info["level"]["final_vs_camera_horizon"]["total_deg"]
    if not scaled:
        ctx.log.warning("georeference: the site frame is in model units, not metres (no GPS with a site CRS, no "
                        "GCPs, no known distance): later steps' thresholds in metres do not mean metres; give "
                        "georeference.distance_points_model + distance_m, or georeference.scale")
    xyz = T.apply(sp["xyz"]) if len(sp["xyz"]) else np.zeros((0, 3))
    if params.height_from == "ground" and len(xyz) >= 50:
        from .georef import ransac_plane

        plane, inl = ransac_plane(xyz, 0.1, normal_hint=np.array([0, 0, 1.0]), max_angle_deg=20)
        if plane is not None:
            gz = float(np.median(xyz[inl, 2]))
            T = Transform(T.scale, T.R, T.t + np.array([0, 0, params.ground_z_m - gz]))
            xyz = T.apply(sp["xyz"])
            info["height_shift_m"] = params.ground_z_m - gz
    outliers = _outlier_cameras(names, T.apply(C), info.get("gps", {}).get("residual_m", {}), params,
                                metric=method != "none")
    if outliers:
        ctx.log.warning("georeference: %d outlier camera(s) left out of the later steps: %s", len(outliers),
                        "; ".join(f"{n} ({why})" for n, why in outliers.items()))
        if len(outliers) > 0.2 * len(names):
            ctx.degraded(f"{len(outliers)} of {len(names)} registered photos are outlier cameras "
                         f"({', '.join(list(outliers)[:6])})", "check the photos and their GPS; see georef.json")
    info["outlier_cameras"] = outliers
    # per photo, for the report's map and residual table: where the model puts the camera and its GPS fix
    C_site = T.apply(C)
    res_map = info.get("gps", {}).get("residual_m", {})
    info["photos"] = {n: {"camera_m": [round(float(v), 3) for v in C_site[k]],
                          "gps_m": ([round(float(v), 3) for v in gps_site[n]] if n in gps_site else None),
                          "gps_residual_m": res_map.get(n), "outlier": outliers.get(n)}
                      for k, n in enumerate(names)}
    cams_out = []
    for n in names:
        if n in outliers:
            continue
        r = rows[n]
        cams_out.append({**{k: r[k] for k in ("image", "model", "width", "height", "params", "K")},
                         "R_world_from_camera": (T.R @ np.asarray(r["R_world_from_camera"])).tolist(),
                         "center": T.apply(r["center"])[0].tolist()})
    centres = np.array([c["center"] for c in cams_out])
    report: dict[str, Any] = {"method": method, "transform": T.to_json(), **info,
                              "cameras": len(cams_out)}
    if in_cameras_json is not None:
        truth = _read_json(in_cameras_json, "camera truth")
        tmap = {c["image"]: np.asarray(c.get("center", c.get("t_world_from_camera")), float)
                for c in truth.get("cameras", [])}
        common = [k for k, n in enumerate(names) if n in tmap]
        if len(common) >= 3:
            est = centres[common]
            tru = np.array([tmap[names[k]] for k in common])
            e = np.linalg.norm(est - tru, axis=1)
            # the SfM shape alone: best similarity onto the truth (what GCPs could reach at best)
            Tb = closed_form_similarity(est, tru)
            eb = np.linalg.norm(Tb.apply(est) - tru, axis=1)
            report["camera_centre_error_m"] = {"mean": float(e.mean()), "median": float(np.median(e)),
                                               "max": float(e.max()), "n": len(common),
                                               "within_5cm": float((e <= 0.05).mean())}
            report["camera_centre_error_after_best_similarity_m"] = {"mean": float(eb.mean()),
                                                                     "max": float(eb.max())}
            ctx.log.info("georeference (%s): camera centres %.3f m from the truth on average (max %.3f); "
                         "SfM shape alone %.3f m", method, e.mean(), e.max(), eb.mean())
    write_json(out_cameras_site_json, {
        "frame": ("site local (metres, x east, y north, z up)" if method in ("gcp", "gps", "transform") else
                  "levelled model frame (z up, " + ("metres)" if scaled else "model units: unscaled)")),
        "scaled": scaled, "units": "metres" if scaled else "model units",
        "convention": "OpenCV pinhole: X_world = R_world_from_camera @ X_cam + center; K at full photo size",
        "cameras": cams_out})
    _write_cloud(out_sparse_site_ply, xyz, sp["rgb"], comments=[f"twinkit-photo georeference ({method})"])
    np.savez_compressed(Path(out_sparse_site_ply).with_suffix(".npz"), vis_image=sp["vis_image"],
                        vis_point=sp["vis_point"])
    report["time_s"] = round(time.perf_counter() - t0, 3)
    write_json(out_georef_json, report)
    out = {"method": method, "scale": float(T.scale), "outlier_cameras": len(outliers), "scaled": scaled}
    if "level_vs_camera_horizon_deg" in info:
        out["level_vs_camera_horizon_deg"] = info["level_vs_camera_horizon_deg"]
        out["up_from"] = info["level"]["up_from"]
    if "camera_centre_error_m" in report:
        out["camera_centre_error_mean_m"] = report["camera_centre_error_m"]["mean"]
        out["camera_centre_error_shape_m"] = report["camera_centre_error_after_best_similarity_m"]["mean"]
    return out


# ----------------------------------------------------------------------------- roi

def roi(params: RoiParams, ctx, *, in_cameras_site_json: Path, in_sparse_site_ply: Path, out_roi_json: Path) -> dict:
    """Region of interest: a box around the camera positions, standing on a RANSAC ground plane."""
    import numpy as np
    from twinkit.mesh import read_ply

    from .georef import ransac_plane

    params = params or RoiParams()
    cdoc = _read_json(in_cameras_site_json, "site-frame cameras")
    cams = cdoc["cameras"]
    scaled = bool(cdoc.get("scaled", True))
    if not scaled:
        # the margins, the ground threshold and max_depth_m below are metres; this frame is not
        ctx.degraded("the site frame is unscaled (no GPS with a site CRS, no GCPs, no known distance): the region "
                     "of interest, the dense step and the mesh apply thresholds in metres to model units",
                     "give steps.georeference.distance_points_model=[..6 numbers..] and distance_m, or "
                     "steps.georeference.scale, or a site CRS for the photos' GPS")
    C = np.array([c["center"] for c in cams], float)
    pts = read_ply(in_sparse_site_ply).vertices
    ground = {"z_m": float(np.median(C[:, 2]) - 1.6), "normal": [0.0, 0.0, 1.0], "source": "cameras - 1.6 m"}
    if len(pts) >= 50:
        near = pts[np.linalg.norm(pts[:, :2] - C[:, :2].mean(0), axis=1) < 3 * max(5.0, np.ptp(C[:, :2], 0).max())]
        below = near[near[:, 2] < np.median(C[:, 2])]
        plane, inl = ransac_plane(below if len(below) >= 30 else near, params.ground_threshold_m,
                                  normal_hint=np.array([0, 0, 1.0]), max_angle_deg=20.0)
        if plane is not None and inl.sum() >= 20:
            nv, d = plane
            cx, cy = C[:, :2].mean(0)
            z0 = float(-(d + nv[0] * cx + nv[1] * cy) / nv[2])
            ground = {"z_m": z0, "normal": nv.tolist(), "source": "RANSAC on the sparse points",
                      "inliers": int(inl.sum()),
                      "tilt_deg": float(np.degrees(np.arccos(min(1.0, abs(nv[2])))))}
    lo = C[:, :2].min(0) - params.margin_m
    hi = C[:, :2].max(0) + params.margin_m
    zlo, zhi = ground["z_m"] - params.below_ground_m, ground["z_m"] + params.above_ground_m
    if len(pts) >= 50:
        # what the photos look at: the sparse points (within max_depth_m of a camera), 2nd-98th percentile
        from scipy.spatial import cKDTree

        seen = pts
        if params.max_depth_m > 0:
            dist, _ = cKDTree(C).query(pts)
            seen = pts[dist <= params.max_depth_m]
        if len(seen) >= 50:
            q0, q1 = np.quantile(seen, [0.02, 0.98], axis=0)
            lo, hi = np.minimum(lo, q0[:2]), np.maximum(hi, q1[:2])
            zhi = max(zhi, float(q1[2]))
    box = {"min": [float(lo[0]), float(lo[1]), zlo], "max": [float(hi[0]), float(hi[1]), zhi]}
    inside = np.all((pts >= box["min"]) & (pts <= box["max"]), axis=1).mean() if len(pts) else 0.0
    doc = {"_comment": "Edit this file to change what the dense step keeps (the thesis's manual step 3.8.2): "
                       "box min/max in site metres, ground z, max_depth_m. The next run keeps your edit and "
                       "re-runs only the steps after it.",
           "box": box, "ground": ground, "max_depth_m": params.max_depth_m, "scaled": scaled,
           "units": "metres" if scaled else "model units (unscaled)",
           "cameras_xy_extent_m": np.ptp(C[:, :2], 0).tolist(), "sparse_inside_ratio": float(inside)}
    write_json(out_roi_json, doc)
    ctx.log.info("roi: box %s .. %s, ground z %.2f m (%s)", np.round(box["min"], 1), np.round(box["max"], 1),
                 ground["z_m"], ground["source"])
    return {"ground_z_m": ground["z_m"], "sparse_inside_ratio": float(inside), "scaled": scaled}


# ----------------------------------------------------------------------------- dense

def dense(params: DenseParams, ctx, *, in_photos_dir: Path, in_cameras_site_json: Path, in_sparse_site_ply: Path,
          in_roi_json: Path, out_points_ply: Path, out_points_meta_json: Path, in_sfm_dir: Path | None = None,
          in_georef_json: Path | None = None, in_sfm_report_json: Path | None = None) -> dict:
    """Depth map per photo, fused to a coloured cloud with normals (what read_cloud writes): our CPU
    PatchMatch (or plane sweep), or COLMAP's patch-match stereo where pycolmap has CUDA (needs the sfm
    model and georef.json)."""
    import cv2
    import numpy as np
    from twinkit.mesh import read_ply

    from . import dense as D

    params = params or DenseParams()
    backend = params.backend
    if backend in ("auto", "patchmatch"):
        import pycolmap

        cuda = bool(getattr(pycolmap, "has_cuda", False))
        if backend == "patchmatch" and not cuda:
            raise InputError("dense.backend=patchmatch needs pycolmap built with CUDA (this one has none); "
                             "use dense.backend=cpu")
        backend = "patchmatch" if cuda else "cpu"
    if backend not in ("cpu", "patchmatch"):
        raise InputError(f"dense: unknown backend '{params.backend}' (auto, cpu or patchmatch)")
    if backend == "patchmatch" and (in_sfm_dir is None or in_georef_json is None):
        raise InputError("dense.backend=patchmatch needs the sfm step's model (sfm/) and the georeference step's "
                         "georef.json; run the image_site recipe, or use dense.backend=cpu")
    t0 = time.perf_counter()
    cv2.setNumThreads(_threads(ctx))
    cams = _read_json(in_cameras_site_json, "site-frame cameras")["cameras"]
    roi_doc = _read_json(in_roi_json, "region of interest")
    try:
        bmin = np.asarray(roi_doc["box"]["min"], float)
        bmax = np.asarray(roi_doc["box"]["max"], float)
        max_depth = float(roi_doc.get("max_depth_m", 0.0) or 0.0)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{in_roi_json}: needs box.min and box.max (3 numbers each) ({exc}); fix the file or "
                         f"delete it to get the automatic one back") from None
    if np.any(bmax <= bmin):
        raise InputError(f"{in_roi_json}: box.max must exceed box.min on every axis")
    if backend == "patchmatch":
        return _dense_patchmatch(params, ctx, in_photos_dir, in_sfm_dir, in_georef_json, bmin, bmax,
                                 out_points_ply, out_points_meta_json, t0)
    sp = read_ply(in_sparse_site_ply).vertices
    visz = np.load(Path(in_sparse_site_ply).with_suffix(".npz"))
    vis: dict[str, list] = {}
    for name, p in zip(visz["vis_image"].tolist(), visz["vis_point"].tolist()):
        vis.setdefault(name, []).append(p)
    vis_arr = {k: np.asarray(v, np.int64) for k, v in vis.items()}
    rel_tol, rel_why = fusion_tolerance(params.rel_tol, in_sfm_report_json)
    ctx.log.info("dense: fusion tolerance %.2f %% of the depth (%s)", 100 * rel_tol, rel_why)
    opt = D.DenseOptions(max_image_px=params.max_image_px, planes=params.planes, neighbors=params.neighbors,
                         window_px=params.window_px, min_ncc=params.min_ncc, min_consistent=params.min_consistent,
                         rel_tol=rel_tol, average_depths=params.average_depths,
                         min_triangulation_deg=params.min_triangulation_deg, max_depth_m=max_depth, coarse_scale=params.coarse_scale,
                         confirm_max_scale=params.confirm_max_scale,
                         refine_passes=params.refine_passes, threads=_threads(ctx))
    from .patchmatch import PMOptions

    pm = PMOptions(window=params.pm_window, dilation=params.pm_dilation, iters_coarse=params.pm_iters_coarse,
                   iters_fine=params.pm_iters_fine, top_k=params.pm_top_k, min_ncc=params.pm_min_ncc,
                   geom_weight=params.pm_geom_weight, geom_max_px=params.pm_geom_max_px, threads=opt.threads)
    views = D.load_views(Path(in_photos_dir), cams, opt.max_image_px)
    D.depth_ranges(views, sp, vis_arr, max_depth)
    nb = D.choose_neighbors(views, vis_arr, opt, sp)
    ground = roi_doc.get("ground") or {}
    if params.cpu_method == "patchmatch" and "normal" in ground and "z_m" in ground:
        D.near_limit_from_ground(views, ground["normal"], float(ground["z_m"]))  # after the neighbour choice
    t_sweep = time.perf_counter()
    n_maps = 0
    for i in ctx.progress(range(len(views)), total=len(views), desc="depth maps"):
        v = views[i]
        if not nb[i] or v.dmax <= v.dmin or v.dmin <= 0:
            ctx.log.info("dense: %s has no usable neighbour; no depth map", v.name)
            continue
        if params.cpu_method == "patchmatch":
            v.depth, _ = D.patchmatch_view(v, [views[j] for j in nb[i]], opt, pm)
        else:
            v.depth, _ = D.plane_sweep(v, [views[j] for j in nb[i]], opt)
        n_maps += 1
    geometric = params.cpu_method == "patchmatch" and params.pm_geometric and n_maps > 1
    if geometric:
        photometric = [v.depth for v in views]
        for i in ctx.progress(range(len(views)), total=len(views), desc="depth maps, geometric pass"):
            v = views[i]
            if v.depth is None:
                continue
            v.depth, _ = D.patchmatch_geom_view(v, [views[j] for j in nb[i]], [photometric[j] for j in nb[i]], opt, pm)
        del photometric
    t_sweep = time.perf_counter() - t_sweep
    if n_maps == 0:
        raise InputError(f"{in_cameras_site_json}: no photo has a neighbour with a usable baseline "
                         f"({opt.min_angle_deg}-{opt.max_angle_deg} degrees); take photos a step or two apart")
    t_fuse = time.perf_counter()
    xyz, rgb, nrm, _src = D.fuse(views, opt)
    t_fuse = time.perf_counter() - t_fuse
    in_roi = np.all((xyz >= bmin) & (xyz <= bmax), axis=1)
    per_photo = np.bincount(_src[in_roi], minlength=len(views)) if len(_src) else np.zeros(len(views), int)
    written, n_fused = _write_dense(xyz, rgb, nrm, bmin, bmax, params.voxel_m, in_photos_dir, out_points_ply,
                                    out_points_meta_json, f"{params.cpu_method} + fusion",
                                    "depth maps" if params.cpu_method == "sweep" else "patchmatch planes", dense_info={
                                        "backend": "cpu", "method": params.cpu_method, "depth_maps": n_maps, "photos": len(views),
                                        "geometric_pass": geometric,
                                        "working_px": params.max_image_px, "rel_tol": rel_tol, "rel_tol_from": rel_why,
                                        "confirm_max_scale": params.confirm_max_scale,
                                        "neighbours": {views[i].name: [views[j].name for j in nb[i]] for i in nb},
                                        "valid_ratio": {v.name: (None if v.depth is None else float((v.depth > 0).mean()))
                                                        for v in views},
                                        "per_photo": {v.name: int(per_photo[i]) for i, v in enumerate(views)
                                                      if v.depth is not None}},
                                    times={"seconds": round(time.perf_counter() - t0, 3),
                                           "depth_maps_s": round(t_sweep, 3), "fusion_s": round(t_fuse, 3)})
    ctx.log.info("dense: %d depth maps, %d fused points, %d after the region of interest and %.3f m voxels",
                 n_maps, n_fused, written, params.voxel_m)
    _dense_gate(ctx, written, n_maps, params, "cpu")
    return {"points": written, "points_per_photo": round(written / max(n_maps, 1), 1), "depth_maps": n_maps, "fused": n_fused,
            "depth_maps_s": round(t_sweep, 3), "fusion_s": round(t_fuse, 3)}


FUSION_TOL_BASE = 0.003  # relative depth agreement for a model that reprojects within FUSION_TOL_AT_PX
FUSION_TOL_AT_PX = 0.35
FUSION_TOL_MAX = 0.01


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


def _dense_gate(ctx, written: int, n_maps: int, params: DenseParams, backend: str) -> None:
    """A dense cloud far too thin for a street: say so (the run ends degraded), with what to try."""
    per = written / max(n_maps, 1)
    if per < params.degraded_below_points_per_photo:
        ctx.degraded(f"dense stereo ({backend}) kept {written:,} points from {n_maps} photos ({per:,.0f} per photo, "
                     f"under {params.degraded_below_points_per_photo:,}): the mesh will cover a small part of what "
                     f"was photographed",
                     ("steps.dense.cpu_method=patchmatch (the CPU PatchMatch: a walked street keeps 7x the points); "
                      if params.cpu_method == "sweep" and backend == "cpu" else
                      "steps.dense.rel_tol=0.01 (a looser agreement between depth maps); " if backend == "cpu" else "")
                     + "photos with more overlap and texture; on a CUDA machine steps.dense.backend=patchmatch")


def _write_dense(xyz, rgb, nrm, bmin, bmax, voxel_m: float, in_photos_dir, out_points_ply, out_points_meta_json,
                 method: str, normals_from: str, dense_info: dict, times: dict) -> tuple[int, int]:
    """Both routes' end: keep the points inside the region of interest, merge duplicates per voxel, write
    points.ply and points_meta.json (the format read_cloud writes). Returns (points written, points fused)."""
    import numpy as np

    from . import dense as D

    n_fused = int(len(xyz))
    keep = np.all((xyz >= bmin) & (xyz <= bmax), axis=1)
    xyz, rgb, nrm = D.voxel_merge(xyz[keep], rgb[keep], nrm[keep], voxel_m)
    if len(xyz) < 100:
        raise InputError(f"{in_photos_dir}: dense matching ({method}) kept only {len(xyz)} points inside the region "
                         f"of interest; check roi.json (box) and the photos' overlap")
    _write_cloud(out_points_ply, xyz, rgb, nrm, comments=[f"twinkit-photo dense ({method})"])
    lo, hi = xyz.min(0), xyz.max(0)
    from twinkit.artefacts import write_points_meta

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


def _dense_patchmatch(params: DenseParams, ctx, in_photos_dir, in_sfm_dir, in_georef_json, bmin, bmax,
                      out_points_ply, out_points_meta_json, t0) -> dict:
    """COLMAP patch-match + fusion in a throw-away workspace, then the same region of interest, voxel
    merge and outputs as the CPU route."""
    import tempfile

    import numpy as np

    from .mvs import colmap_dense

    tf = _read_json(in_georef_json, "georeference")
    try:
        T = tf["transform"]
        scale, R, t = float(T["scale"]), np.asarray(T["R"], float), np.asarray(T["t"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{in_georef_json}: no usable 'transform' ({exc}); re-run the georeference step") from None
    with tempfile.TemporaryDirectory(prefix="twinkit-mvs-") as tmp:
        xyz, rgb, nrm, info = colmap_dense(Path(in_sfm_dir), scale, R, t, Path(in_photos_dir), Path(tmp),
                                           max_image_px=params.max_image_px, min_consistent=params.min_consistent,
                                           threads=_threads(ctx), log=ctx.log)
    written, n_fused = _write_dense(xyz, rgb, nrm, bmin, bmax, params.voxel_m, in_photos_dir, out_points_ply,
                                    out_points_meta_json, "COLMAP patch-match + fusion", "COLMAP patch-match",
                                    dense_info={"backend": "patchmatch", "depth_maps": info["depth_maps"],
                                                "working_px": params.max_image_px},
                                    times={"seconds": round(time.perf_counter() - t0, 3)})
    ctx.log.info("dense (patch-match): %d depth maps, %d fused points, %d after the region of interest and "
                 "%.3f m voxels", info["depth_maps"], n_fused, written, params.voxel_m)
    _dense_gate(ctx, written, info["depth_maps"], params, "patchmatch")
    return {"backend": "patchmatch", "points": written, "depth_maps": info["depth_maps"], "fused": n_fused}


# ----------------------------------------------------------------------------- texture from the photos

def photo_texture(params: PhotoTextureParams, ctx, *, in_textured_mesh_ply: Path, in_photos_dir: Path,
                  in_cameras_site_json: Path, out_textured_mesh_obj: Path, out_textured_mesh_ply: Path) -> dict:
    """Replace the baked texture (colours from the dense cloud) by the photos, projected and blended per texel."""
    import numpy as np
    from PIL import Image
    from twinkit.mesh import read_ply as read_mesh_ply, write_obj, write_ply
    from twinkit.surface.texture import write_png

    from .projtex import PhotoView, project_texture

    params = params or PhotoTextureParams()
    t0 = time.perf_counter()
    src = Path(in_textured_mesh_ply)
    try:
        mesh = read_mesh_ply(src)
    except Exception as exc:  # noqa: BLE001 - any parse error is the file's fault
        raise InputError(f"{src}: cannot read the textured mesh ({exc}); re-run the texture step") from None
    tc = mesh.face_attrs.get("texcoord")
    png_name = next((c.split(None, 1)[1] for c in mesh.comments if c.startswith("TextureFile")), src.stem + ".png")
    png = src.parent / png_name
    if tc is None or mesh.faces is None or not png.exists():
        raise InputError(f"{src}: needs per-face texture coordinates and its texture image ({png.name}) beside it; "
                         f"give it the output of bake_texture")
    uv = np.asarray(tc, np.float64).reshape(-1, 3, 2)
    base = np.asarray(Image.open(png).convert("RGB"))
    doc = _read_json(in_cameras_site_json, "site-frame cameras")
    views = []
    for c in doc["cameras"]:
        path = Path(in_photos_dir) / c["image"]
        try:
            img = np.asarray(Image.open(path).convert("RGB"))
        except OSError as exc:
            raise InputError(f"{path}: cannot read the photo ({exc}); re-export or remove it") from None
        K = np.asarray(c["K"], float)
        if img.shape[1] != int(c["width"]) or img.shape[0] != int(c["height"]):
            sx, sy = img.shape[1] / float(c["width"]), img.shape[0] / float(c["height"])
            K = np.diag([sx, sy, 1.0]) @ K
        views.append(PhotoView(c["image"], K, np.asarray(c["R_world_from_camera"], float),
                               np.asarray(c["center"], float), img))
    if not views:
        raise InputError(f"{in_cameras_site_json}: no cameras")
    img, info = project_texture(mesh.vertices, mesh.faces, uv, base, views, max_views=params.max_views,
                                min_cos=params.min_cos, max_dist_m=params.max_dist_m, sharpness=params.sharpness,
                                consistency_views=params.consistency_views,
                                consistency_levels=params.consistency_levels,
                                threads=_threads(ctx), progress=ctx.progress)
    out_obj = Path(out_textured_mesh_obj)
    out_png = out_obj.with_suffix(".png")
    write_png(out_png, img)
    write_obj(out_obj, mesh.vertices, mesh.faces, uv, out_png.name, normals=mesh.attrs.get("normals"))
    mesh.comments = [f"TextureFile {out_png.name}"]
    write_ply(out_textured_mesh_ply, mesh)
    info["seconds"] = round(time.perf_counter() - t0, 3)
    ctx.log.info("photo texture: %.1f %% of the texels from %d photos (%.1f %% of the faces seen; %d photo views of "
                 "faces left out as inconsistent with the others: occluders the mesh lacks), %.1f s",
                 100 * info["texels_from_photos_ratio"], len(views), 100 * info["faces_seen_ratio"],
                 info["views_rejected_inconsistent"], info["seconds"])
    info.pop("best_view_faces", None)
    return info


# ----------------------------------------------------------------------------- registration

from .report import twinkit_register_report_sections  # noqa: E402,F401 (this plugin's section of the run report)

@hookimpl
def twinkit_register_steps(register):
    register("sfm", sfm, params=SfmParams)
    register("georeference", georeference, params=GeorefParams)
    register("roi", roi, params=RoiParams)
    register("dense", dense, params=DenseParams)
    register("photo_texture", photo_texture, params=PhotoTextureParams)
