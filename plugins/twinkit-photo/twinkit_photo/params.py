"""The photo steps' parameters: one dataclass per step, each field with its range and one line of help.

``twinkit plugins step/<name>`` prints them. Why a default is what it is (the measurements on the demo,
Lund and Sceaux) is in docs/photo.md, "Decisions".
"""
from __future__ import annotations

from dataclasses import dataclass

from twinkit.ranges import param


@dataclass
class SfmParams:
    """Structure from motion (pycolmap, CPU)."""

    matching: str = param("auto", choices=("auto", "exhaustive", "sequential", "spatial", "sequential+spatial"),
                          help="which photo pairs are matched: auto picks exhaustive for small sets, else by GPS "
                               "and file order")
    exhaustive_max: int = param(40, ge=0, help="auto: exhaustive matching up to this many photos")
    overlap: int = param(10, ge=1, help="sequential: each photo with its next N photos (file-name order)")
    spatial_neighbors: int = param(12, ge=1, help="spatial: nearest photos by EXIF GPS")
    mapper: str = param("incremental", choices=("incremental", "global"),
                        help="incremental (COLMAP) or global (GLOMAP) mapping")
    max_image_px: int = param(1600, ge=0, help="features are found on photos downscaled to this long side "
                                               "(0 = full size)")
    max_features: int = param(4096, ge=1, help="most SIFT features per photo")
    camera_model: str = param("SIMPLE_RADIAL", help="COLMAP camera model of the intrinsics that are refined")
    single_camera: bool = param(True, help="one set of intrinsics per camera group (same size, EXIF make/model, "
                                           "focal); false: one per photo")
    intrinsics: str = param("auto", help="auto: K.txt beside the photos, else the site's cameras.json, else EXIF; "
                                         "exif: EXIF only")
    min_registered_ratio: float = param(0.5, ge=0, le=1, help="fewer registered photos than this share: error")
    degraded_below_ratio: float = param(0.8, ge=0, le=1,
                                        help="fewer registered photos than this share: the run ends degraded")
    seed: int = param(0, ge=0, help="random seed of matching and mapping")
    deterministic: bool = param(True, help="one thread for matching and mapping, so a re-run gives the same model "
                                           "(false: faster)")


@dataclass
class GeorefParams:
    """Model frame -> site frame."""

    method: str = param("auto", choices=("auto", "gcp", "gps", "none"),
                        help="auto: ground-control points, else EXIF GPS, else none (levelled and centred only)")
    gps_threshold_m: float = param(8.0, gt=0, help="RANSAC inlier distance for GPS fixes, metres (about 3 sigma "
                                                   "of phone GPS)")
    gps_use_z: bool = param(False, help="fit the scale to the GPS heights too (false: x, y only; GPS heights are "
                                        "the noisiest)")
    height_from: str = param("gps", choices=("gps", "ground"),
                             help="ground: put the sparse ground plane at ground_z_m instead of the GPS height")
    ground_z_m: float = param(0.0, help="height_from=ground: the ground's height in the site frame, metres")
    scale: float = param(1.0, gt=0, help="method none: metres per model unit")
    eye_height_m: float = param(1.6, ge=0, le=10,
                                help="method none without a scale or known distance: the photos were taken this "
                                     "high above the ground, metres; the scale is estimated from the cameras' "
                                     "height over the sparse ground plane, marked as an estimate, and the run "
                                     "stays degraded (0 = no estimate: model units)")
    min_gcp_views: int = param(2, ge=1, help="a ground-control point needs this many registered photos to be used")
    gcp_outlier_m: float = param(0.05, gt=0, help="a GCP whose residual exceeds this (and 3x the median), metres, "
                                                  "is left out of the fit")
    outlier_factor: float = param(3.0, ge=0,
                                  help="a camera this many times gps_threshold_m from its GPS fix, or standing off "
                                       "the walk, is an outlier left out of the later steps (0 = keep every camera)")
    min_ground_support: float = param(0.2, ge=0, le=1,
                                      help="levelling: a ground plane counts only with this share of the sparse "
                                           "points")
    ground_agree_deg: float = param(2.0, ge=0, le=90,
                                    help="levelling: a ground plane counts only within this angle of the photos' "
                                         "up (or 3x its standard error)")
    vertical_lines: bool = param(True, help="refine the photos' horizon with vertical lines (building edges) in "
                                            "the photos")
    up_model: list[float] = param(default_factory=list,
                                  help="the up vector [x, y, z] in the SfM model frame (sfm/sparse_model.ply); "
                                       "replaces levelling")
    distance_points_model: list[float] = param(default_factory=list,
                                               help="a known distance's two points [x1, y1, z1, x2, y2, z2] in "
                                                    "the SfM model frame (with distance_m)")
    distance_m: float = param(0.0, ge=0, help="the known distance in metres (method none: sets the scale; "
                                              "0 = no known distance)")
    transform_model_to_site: list[float] = param(default_factory=list,
                                                 help="a 4x4 similarity model -> site, 16 numbers row by row; "
                                                      "replaces levelling and fit")


@dataclass
class RoiParams:
    """Automatic region of interest and ground plane (edit roi.json to override)."""

    margin_m: float = param(12.0, ge=0, help="the box reaches this far around the camera positions, horizontally")
    below_ground_m: float = param(1.0, ge=0, help="the box reaches this far below the ground plane")
    above_ground_m: float = param(25.0, gt=0, help="the box reaches at least this far above the ground plane")
    ground_threshold_m: float = param(0.10, gt=0, help="RANSAC inlier distance for the ground plane")
    max_depth_m: float = param(40.0, ge=0, help="dense matching ignores anything farther from a photo (0 = no "
                                                "limit)")


@dataclass
class DenseParams:
    """Dense reconstruction: CPU PatchMatch (or plane-sweep) stereo + consistency fusion (pycolmap patch-match with CUDA)."""

    backend: str = param("auto", choices=("auto", "cpu", "patchmatch"),
                         help="auto: COLMAP patch-match when pycolmap has CUDA, else the CPU matcher")
    cpu_method: str = param("patchmatch", choices=("patchmatch", "sweep"),
                            help="the CPU matcher: patchmatch (slanted planes, propagation) or sweep (plane sweep "
                                 "over four plane families)")
    max_image_px: int = param(640, ge=16, le=16384, help="working resolution (long side)")
    planes: int = param(192, ge=2, le=4096, help="sweep: most planes per plane family of the coarse sweep")
    neighbors: int = param(4, ge=1, help="photos each photo is matched against")
    window_px: int = param(7, ge=1, le=63, help="sweep: NCC window size")
    min_ncc: float = param(0.55, ge=-1, le=1, help="sweep: keep a depth whose NCC reaches this")
    min_consistent: int = param(2, ge=0, help="other depth maps that must agree with a kept point")
    confirm_max_scale: float = param(3.0, ge=0,
                                     help="where fewer other photos could confirm a point (seeing it from at most "
                                          "this many times its distance), one agreeing map is enough "
                                          "(0 = min_consistent everywhere)")
    rel_tol: float = param(-1.0, gt=0, also=(-1,),
                           help="depth maps agree when |depth difference| < rel_tol * depth; -1 = auto from the "
                                "SfM model's reprojection error (0.3 % .. 1 %)")
    average_depths: bool = param(True, help="a kept point's depth is the mean of the depth maps that agree with it")
    min_triangulation_deg: float = param(3.0, ge=0, le=60,
                                         help="a kept point needs an agreeing photo that sees it at least this "
                                              "angle apart")
    voxel_m: float = param(0.02, ge=0, help="merge duplicate points per voxel of this size (0 = off)")
    coarse_scale: float = param(0.25, gt=0, le=1, help="sweep: resolution of the coarse sweep, relative")
    refine_passes: int = param(2, ge=0, help="sweep: refinement passes after the coarse sweep")
    pm_window: int = param(5, ge=3, le=15, help="patchmatch: window samples per side")
    pm_dilation: int = param(2, ge=1, le=8, help="patchmatch: pixels between window samples")
    pm_iters_coarse: int = param(4, ge=0, le=32, help="patchmatch: iterations at half the working resolution")
    pm_iters_fine: int = param(3, ge=0, le=32, help="patchmatch: then iterations at the working resolution")
    pm_top_k: int = param(2, ge=1, le=16, help="patchmatch: a pixel's cost is the mean NCC cost of its best top_k "
                                               "neighbours")
    pm_min_ncc: float = param(0.5, ge=-1, le=1, help="patchmatch: keep a depth whose aggregated NCC reaches this")
    pm_geometric: bool = param(True, help="patchmatch: a second, geometric-consistency pass against the "
                                          "neighbours' depth maps (about doubles the time)")
    pm_geom_weight: float = param(0.3, ge=0, help="patchmatch geometric pass: cost per pixel of forward-backward "
                                                  "error ...")
    pm_geom_max_px: float = param(3.0, gt=0, help="... counted up to this many pixels")
    degraded_below_points_per_photo: int = param(1000, ge=0,
                                                 help="fewer kept points per depth map than this: the run ends "
                                                      "degraded")


@dataclass
class PhotoTextureParams:
    """Texture from the photos (project and blend the best views per texel)."""

    max_views: int = param(6, ge=1, help="photos blended per face: the best ones that pass the consistency check")
    sharpness: float = param(0.0, ge=0, help="blend weight score ** sharpness, score = cos(view angle) / distance "
                                             "(0 = plain mean)")
    min_cos: float = param(0.15, ge=0, le=1, help="ignore views more grazing than this cosine (about 81 degrees)")
    max_dist_m: float = param(40.0, gt=0, help="ignore views farther than this")
    consistency_views: int = param(8, ge=0,
                                   help="photo-consistency check: of a face's best this-many photos, leave out those "
                                        "whose colour disagrees with the consensus (0 = off)")
    consistency_levels: float = param(45.0, gt=0, help="photo-consistency check: RGB distance (0-255) from the "
                                                       "consensus that counts as disagreeing")
    degraded_above_missing_ratio: float = param(0.5, ge=0, le=1,
                                                help="more photos than this share that texture no face of the "
                                                     "mesh: the run ends degraded")
