"""Structure from motion with pycolmap (CPU): SIFT features, matching, incremental or global mapping.

Matching modes:
  exhaustive  every pair (small sets, unordered photos)
  sequential  each photo with its next ``overlap`` photos in file-name order (walked sequences)
  spatial     each photo with its nearest neighbours by EXIF GPS (pose priors in the database)
  auto        exhaustive up to ``exhaustive_max`` photos, otherwise sequential, plus spatial when
              most photos have GPS.

Walked forward-motion sequences (lund_street) defeat COLMAP's default initialisation (it asks for a
16 degree triangulation angle between the first two views and rejects pure forward motion); when the
first attempt registers too few photos, mapping is retried with a relaxed initialisation and the
model that registers the most photos wins.
"""
from __future__ import annotations

import shutil
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twinkit import InputError


@dataclass
class SfmOptions:
    matching: str = "auto"
    exhaustive_max: int = 40
    overlap: int = 10
    spatial_neighbors: int = 12
    mapper: str = "incremental"  # incremental | global
    max_image_px: int = 1600
    max_features: int = 8192
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool = True  # one camera per group of photos (camera_groups); false: one per photo
    groups: list | None = None  # lists of photo names that share a camera (None: all in one)
    intrinsics: list | None = None  # 3x3 K to start from (pixels of the full-size image)
    retry_below_ratio: float = 0.9
    threads: int = 2
    seed: int = 0
    deterministic: bool = True  # one thread for matching and mapping: the same photos give the same model


@dataclass
class SfmResult:
    reconstruction: object  # pycolmap.Reconstruction
    n_images: int
    registered: list[str]
    attempts: list[dict] = field(default_factory=list)
    timings_s: dict = field(default_factory=dict)
    matching: str = ""


def _pairing_counts(db_path: Path) -> dict:
    import sqlite3

    con = sqlite3.connect(str(db_path))
    try:
        n_pairs = con.execute("select count(*) from two_view_geometries where rows > 0").fetchone()[0]
        n_priors = 0
        try:
            n_priors = con.execute("select count(*) from pose_priors").fetchone()[0]
        except sqlite3.Error:
            pass
    finally:
        con.close()
    return {"verified_pairs": int(n_pairs), "pose_priors": int(n_priors)}


def _best_model(recs: dict):
    if not recs:
        return None
    return max(recs.values(), key=lambda r: r.num_reg_images())


def run_sfm(image_dir: Path, names: list[str], work: Path, opt: SfmOptions, *, has_gps: bool, log) -> SfmResult:
    """Features, matching and mapping of the photos ``names`` in ``image_dir``; the COLMAP database and the
    mapping attempts go to ``work``. The model that registers the most photos wins."""
    import pycolmap

    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    if db.exists():
        db.unlink()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pycolmap.set_random_seed(int(opt.seed))
    # COLMAP's multi-threaded RANSAC and mapping are not reproducible: on lund_street two runs of the
    # same settings registered 29 and 21 photos. One thread makes every run the same (measured: 69 s).
    solve_threads = 1 if opt.deterministic else opt.threads
    _extract_features(db, image_dir, names, opt)
    timings["features"] = round(time.perf_counter() - t0, 3)

    t0 = time.perf_counter()
    n = len(names)
    matching = _match(db, n, opt, has_gps, solve_threads)
    timings["matching"] = round(time.perf_counter() - t0, 3)
    counts = _pairing_counts(db)
    log.info("sfm: %d photos, matching %s: %d verified pairs", n, matching, counts["verified_pairs"])
    if counts["verified_pairs"] == 0:
        raise InputError(f"{image_dir}: no two photos share enough features to be matched; the photos must "
                         f"overlap (take one every few steps, 60-80 % overlap)")

    t0 = time.perf_counter()
    best, attempts = _map(db, image_dir, work, n, opt, has_gps, solve_threads, log)
    timings["mapping"] = round(time.perf_counter() - t0, 3)
    if best is None:
        raise InputError(f"{image_dir}: structure from motion registered no photos ({counts['verified_pairs']} "
                         f"matched pairs); take more overlapping photos or try steps.sfm.matching=exhaustive")
    registered = sorted(best.images[i].name for i in best.reg_image_ids())
    return SfmResult(best, n, registered, attempts, timings, matching)


def _extract_features(db: Path, image_dir: Path, names: list[str], opt: SfmOptions) -> None:
    """SIFT features of every photo into the database, one COLMAP camera per group (or per photo)."""
    import pycolmap

    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = opt.threads
    ext.max_image_size = int(opt.max_image_px) if opt.max_image_px > 0 else -1
    ext.sift.max_num_features = int(opt.max_features)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = opt.camera_model
    if opt.intrinsics is not None:
        K = np.asarray(opt.intrinsics, float)
        f, cx, cy = 0.5 * (K[0, 0] + K[1, 1]), K[0, 2], K[1, 2]
        params = {"SIMPLE_PINHOLE": [f, cx, cy], "PINHOLE": [K[0, 0], K[1, 1], cx, cy],
                  "SIMPLE_RADIAL": [f, cx, cy, 0.0], "RADIAL": [f, cx, cy, 0.0, 0.0]}.get(opt.camera_model)
        if params is None:
            raise InputError(f"sfm: known intrinsics need camera_model SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL or "
                             f"RADIAL, not {opt.camera_model}")
        reader.camera_params = ",".join(f"{v:.6f}" for v in params)
    if opt.single_camera:
        # one COLMAP camera per group: in SINGLE mode COLMAP skips every photo whose size differs from the first
        # one's, so a set mixing portrait and landscape shots lost all of one kind. Each call adds one camera.
        for group in (opt.groups or [list(names)]):
            pycolmap.extract_features(db, image_dir, image_names=list(group), camera_mode=pycolmap.CameraMode.SINGLE,
                                      reader_options=reader, extraction_options=ext, device=pycolmap.Device.cpu)
    else:
        pycolmap.extract_features(db, image_dir, image_names=list(names), camera_mode=pycolmap.CameraMode.AUTO,
                                  reader_options=reader, extraction_options=ext, device=pycolmap.Device.cpu)


def _match(db: Path, n: int, opt: SfmOptions, has_gps: bool, solve_threads: int) -> str:
    """Match the photo pairs of the matching mode (auto resolved for ``n`` photos); the mode used."""
    import pycolmap

    matching = opt.matching
    if matching == "auto":
        matching = "exhaustive" if n <= opt.exhaustive_max else "sequential"
        if has_gps and matching == "sequential":
            matching = "sequential+spatial"
    mopt = pycolmap.FeatureMatchingOptions()
    mopt.num_threads = solve_threads
    for part in matching.split("+"):
        if part == "exhaustive":
            pycolmap.match_exhaustive(db, matching_options=mopt, device=pycolmap.Device.cpu)
        elif part == "sequential":
            po = pycolmap.SequentialPairingOptions()
            po.overlap = int(opt.overlap)
            po.quadratic_overlap = True
            pycolmap.match_sequential(db, matching_options=mopt, pairing_options=po, device=pycolmap.Device.cpu)
        elif part == "spatial":
            if not has_gps:
                raise InputError("sfm: matching=spatial needs EXIF GPS in the photos; none of them has it. "
                                 "Use matching=sequential or exhaustive")
            po = pycolmap.SpatialPairingOptions()
            po.max_num_neighbors = int(opt.spatial_neighbors)
            po.ignore_z = True
            po.max_distance = 1000.0
            pycolmap.match_spatial(db, matching_options=mopt, pairing_options=po, device=pycolmap.Device.cpu)
        else:
            raise InputError(f"sfm: unknown matching '{part}' (exhaustive, sequential, spatial, "
                             f"sequential+spatial or auto)")
    return matching


def _incremental_options(attempt: str, opt: SfmOptions, solve_threads: int):
    """COLMAP's incremental mapping options for one attempt (default, relaxed_init, relaxed_init+gps_prior)."""
    import pycolmap

    popt = pycolmap.IncrementalPipelineOptions()
    popt.num_threads = solve_threads
    popt.random_seed = int(opt.seed)
    popt.min_model_size = 3
    if opt.intrinsics is not None:
        popt.ba_refine_focal_length = False  # a known calibration stays fixed
    if attempt.startswith("relaxed_init"):
        # forward motion: accept a small initial triangulation angle and weaker image registrations
        popt.mapper.init_min_tri_angle = 4.0
        popt.mapper.init_max_forward_motion = 0.999
        popt.mapper.init_min_num_inliers = 30
        popt.mapper.abs_pose_min_num_inliers = 15
        popt.mapper.abs_pose_min_inlier_ratio = 0.1
        popt.mapper.filter_min_tri_angle = 0.5
        popt.min_num_matches = 10
        popt.init_num_trials = 400
    if attempt.endswith("gps_prior"):
        popt.use_prior_position = True  # EXIF GPS as position priors in bundle adjustment
    return popt


def _map(db: Path, image_dir: Path, work: Path, n: int, opt: SfmOptions, has_gps: bool, solve_threads: int, log):
    """Mapping attempts (default, then relaxed initialisation, then with GPS priors) until one registers
    ``retry_below_ratio`` of the photos; (the best model or None, the attempts' summary)."""
    import pycolmap

    attempts = []
    best = None
    plan = ["default", "relaxed_init"] + (["relaxed_init+gps_prior"] if has_gps and opt.mapper == "incremental" else [])
    for attempt in plan:
        out = work / f"sparse_{attempt}"
        if out.exists():
            shutil.rmtree(out)
        out.mkdir()
        if opt.mapper == "global":
            gopt = pycolmap.GlobalPipelineOptions()
            gopt.num_threads = solve_threads
            recs = pycolmap.global_mapping(db, image_dir, out, options=gopt)
        elif opt.mapper == "incremental":
            recs = pycolmap.incremental_mapping(db, image_dir, out, options=_incremental_options(attempt, opt,
                                                                                                 solve_threads))
        else:
            raise InputError(f"sfm: unknown mapper '{opt.mapper}' (incremental or global)")
        rec = _best_model(recs)
        k = rec.num_reg_images() if rec is not None else 0
        attempts.append({"init": attempt, "models": len(recs), "registered": int(k)})
        log.info("sfm: mapping (%s, %s init): %d models, best registers %d of %d photos",
                 opt.mapper, attempt, len(recs), k, n)
        if rec is not None and (best is None or k > best.num_reg_images()):
            best = rec
        if best is not None and best.num_reg_images() >= opt.retry_below_ratio * n:
            break
    return best, attempts


def camera_table(rec) -> list[dict]:
    """Per registered image: name, K, world-from-camera R and centre (model frame), OpenCV convention."""
    rows = []
    for iid in sorted(rec.reg_image_ids()):
        im = rec.images[iid]
        cam = rec.cameras[im.camera_id]
        cfw = im.cam_from_world() if callable(getattr(im, "cam_from_world", None)) else im.cam_from_world
        R_cw = np.asarray(cfw.rotation.matrix(), float)
        t_cw = np.asarray(cfw.translation, float)
        R_wc = R_cw.T
        centre = -R_wc @ t_cw
        K = np.asarray(cam.calibration_matrix(), float)
        rows.append({"image": im.name, "camera_id": int(im.camera_id), "model": cam.model.name,
                     "width": int(cam.width), "height": int(cam.height), "params": [float(v) for v in cam.params],
                     "K": K.tolist(), "R_world_from_camera": R_wc.tolist(), "center": centre.tolist(),
                     "num_points3D": int(im.num_points3D)})
    return rows


def sparse_points(rec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ids = list(rec.points3D.keys())
    xyz = np.array([rec.points3D[i].xyz for i in ids], float).reshape(-1, 3)
    rgb = np.array([rec.points3D[i].color for i in ids], np.uint8).reshape(-1, 3)
    err = np.array([rec.points3D[i].error for i in ids], float)
    return xyz, rgb, err


# --------------------------------------------------------------------------- the sfm step's parts

def choose_intrinsics(mode: str, folder: Path, infos: list, cameras_json: Path | None) -> tuple[list | None, str]:
    """The intrinsics to start from and where they came from: (K 3x3 in pixels at full photo size, or None
    for EXIF, source). ``auto``: K.txt beside the photos, else the site's cameras.json when its size matches
    (one photo size only), else EXIF; ``exif``: EXIF."""
    from .files import read_json
    from .images import read_k_txt

    sizes = {(i.width, i.height) for i in infos}
    K, k_source = None, "exif"
    if mode == "auto":
        K = read_k_txt(folder)
        if K is not None:
            k_source = "K.txt"
        elif cameras_json is not None and len(sizes) == 1:
            intr = read_json(cameras_json, "camera file").get("intrinsics") or {}
            if "K" in intr and (intr.get("width"), intr.get("height")) in sizes:
                K, k_source = intr["K"], Path(cameras_json).name
    elif mode != "exif":
        raise InputError(f"sfm: intrinsics='{mode}' must be auto or exif")
    if K is not None and len(sizes) != 1:
        K, k_source = None, "exif"
    return K, k_source


def sfm_options(params, K, groups: list[dict], threads: int) -> SfmOptions:
    """The sfm step's parameters, the starting intrinsics ``K`` (or None) and the camera groups as
    :class:`SfmOptions`."""
    return SfmOptions(matching=params.matching, exhaustive_max=params.exhaustive_max, overlap=params.overlap,
                      spatial_neighbors=params.spatial_neighbors, mapper=params.mapper,
                      max_image_px=params.max_image_px, max_features=params.max_features,
                      camera_model=params.camera_model, single_camera=params.single_camera, intrinsics=K,
                      groups=[g["photos"] for g in groups],
                      threads=threads, seed=params.seed, deterministic=params.deterministic)


def run_sfm_in_temp(folder: Path, names: list[str], opt: SfmOptions, *, has_gps: bool, log) -> SfmResult:
    """:func:`run_sfm` in a throw-away folder (COLMAP database and attempts), removed afterwards."""
    import tempfile

    work = Path(tempfile.mkdtemp(prefix="twinkit_sfm_"))
    try:
        with colmap_log_into(log, work):
            return run_sfm(folder, names, work, opt, has_gps=has_gps, log=log)
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextmanager
def colmap_log_into(log, folder: Path):
    """COLMAP's own log (glog: a line per photo, pair and bundle adjustment) goes to ``log`` at debug level
    (run.log) instead of the console; its errors still reach the console. The console gets one line."""
    import pycolmap

    glog = pycolmap.logging
    also = glog.alsologtostderr
    glog.alsologtostderr = False
    glog.set_log_destination(glog.INFO, str(Path(folder) / "colmap."))
    try:
        yield
    finally:
        glog.set_log_destination(glog.INFO, "")  # closes (and flushes) the file
        glog.alsologtostderr = also
        lines = [ln for f in sorted(Path(folder).glob("colmap.*")) for ln in f.read_text(errors="replace").splitlines()]
        for ln in lines:
            log.debug("colmap: %s", ln)
        log.info("sfm: COLMAP's log (%d lines) is in the run log", len(lines))


def check_registration(names: list[str], registered: list[str], min_ratio: float, degraded_ratio: float,
                       folder: Path, degraded) -> tuple[float, list[str]]:
    """(registered share, unregistered names); an InputError under ``min_ratio``, ``degraded(...)`` under
    ``degraded_ratio``."""
    n_reg = len(registered)
    ratio = n_reg / len(names)
    missing = sorted(set(names) - set(registered))
    listed = f"{', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}"
    if ratio < min_ratio:
        raise InputError(f"{folder}: structure from motion registered only {n_reg} of {len(names)} photos "
                         f"({100 * ratio:.0f} % < steps.sfm.min_registered_ratio {100 * min_ratio:.0f} %); "
                         f"unregistered: {listed}. Take more "
                         f"overlapping photos, try steps.sfm.matching=exhaustive or sequential, or lower the ratio")
    if ratio < degraded_ratio:
        degraded(f"structure from motion registered only {n_reg} of {len(names)} photos; unregistered: {listed}",
                 "take more overlapping photos, or try steps.sfm.matching=exhaustive")
    return ratio, missing


def visibility(rec) -> tuple[list[str], list[int]]:
    """Which sparse point each registered photo sees, as two parallel lists (photo name, index into
    :func:`sparse_points`' order): the dense step's depth ranges and neighbours."""
    pid = {p: k for k, p in enumerate(rec.points3D.keys())}
    vis_img, vis_pt = [], []
    for iid in rec.reg_image_ids():
        im = rec.images[iid]
        ids = [pid[p.point3D_id] for p in im.points2D if p.has_point3D()]
        vis_img += [im.name] * len(ids)
        vis_pt += ids
    return vis_img, vis_pt


def write_model(out: Path, rec, infos: list) -> int:
    """The sfm/ folder: COLMAP's model, sparse.npz (xyz, rgb, error, visibility), cameras_model.json (model
    frame, OpenCV convention, with the EXIF GPS fixes) and sparse_model.ply. Returns the sparse point count."""
    from twinkit.jsonio import write_json

    from .files import write_cloud

    out.mkdir(parents=True, exist_ok=True)
    rec.write(str(out))
    cams = camera_table(rec)
    xyz, rgb, err = sparse_points(rec)
    vis_img, vis_pt = visibility(rec)
    np.savez_compressed(out / "sparse.npz", xyz=xyz, rgb=rgb, error=err, vis_image=np.array(vis_img),
                        vis_point=np.array(vis_pt, np.int64))
    gps = {i.name: [i.lat, i.lon, i.alt] for i in infos if i.has_gps}
    write_json(out / "cameras_model.json", {"frame": "SfM model frame (arbitrary scale and orientation)",
                                             "convention": "OpenCV camera, R_world_from_camera, center",
                                             "cameras": cams, "exif_gps": gps})
    write_cloud(out / "sparse_model.ply", xyz, rgb, comments=["twinkit-photo sfm sparse points, model frame"])
    return int(len(xyz))


def mean_reprojection_error(rec) -> float:
    """The model's mean reprojection error in pixels (NaN with no registered photo)."""
    return float(rec.compute_mean_reprojection_error()) if len(rec.reg_image_ids()) else float("nan")


def sfm_report(rec, res: SfmResult, infos: list, groups: list[dict], ratio: float, missing: list[str], *,
               mapper: str, k_source: str, n_gps: int, n_points: int, reproj: float, total_s: float) -> dict:
    """sfm_report.json: registration, reprojection error, tracks, matching, attempts, intrinsics, timings."""
    n_reg = len(res.registered)
    track = float(np.mean([rec.points3D[p].track.length() for p in rec.points3D])) if n_points else 0.0
    return {
        "photos": len(infos), "registered": n_reg, "registered_ratio": round(ratio, 4),
        "unregistered": missing, "mean_reprojection_error_px": round(reproj, 4),
        "sparse_points": n_points, "mean_track_length": round(track, 3),
        "matching": res.matching, "mapper": mapper, "attempts": res.attempts,
        "intrinsics_from": k_source, "photos_with_gps": n_gps,
        "camera_groups": [dict(g, photos=len(g["photos"]),
                               registered=sum(1 for n in g["photos"] if n in set(res.registered))) for g in groups],
        "cameras": [{"id": int(cid), "model": c.model.name, "params": [float(v) for v in c.params]}
                    for cid, c in rec.cameras.items()],
        "timings_s": {**res.timings_s, "total": round(total_s, 3)},
    }
