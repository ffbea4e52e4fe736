"""The parameters of the point-cloud branch's steps (read_cloud, poisson, clean_mesh, simplify, bake_texture, evaluate)."""
from dataclasses import dataclass

from twinkit.ranges import param


@dataclass
class ReadCloudParams:
    """Reading a cloud into the site frame."""

    estimate_normals: bool = param(True,
                                   help="Estimate normals (PCA over normals_k neighbours) when the file has none.")
    normals_k: int = param(24, ge=3, le=1000, help="Neighbours used for the PCA normals.")
    normals_orientation: str = param("auto", choices=("auto", "scanner", "mst", "up"),
                                     help="How estimated normals are turned outwards: auto, toward the scanner "
                                          "positions, along a minimum spanning tree (mst), or up (see normals.py).")
    reorient_existing_normals: bool = param(False,
                                            help="True: re-orient the file's own normals wholesale with "
                                                 "normals_orientation instead of only flipping the inward ones.")
    file_normals_flip_share: float = param(0.01, ge=0, le=1,
                                           help="The file's normals are compared with a consistent orientation of "
                                                "the same points; those pointing into the surface are flipped when "
                                                "more than this share disagrees. 0 = always flip them, 1 = never "
                                                'flip (only measure); docs/pointcloud.md "Normals from the file".')
    min_points: int = param(10, ge=1, help='A cloud with fewer points is refused with a "too few points" error.')
    drop_invalid_points: bool = param(True,
                                      help="Drop points with NaN or infinite coordinates with a warning; false: "
                                           "refuse the file instead.")
    max_offset_km: float = param(20.0, gt=0,
                                 help="Without site bounds: a cloud whose centre lies farther than this from the "
                                      "base point (km) is refused as being in the wrong CRS.")
    bounds_margin_m: float = param(50.0, ge=0,
                                   help="With site bounds: the margin (m) around them that the cloud may reach "
                                        "before it is refused as being in the wrong CRS.")
    max_base_point_offset_m: float = param(250.0, ge=0,
                                           help="Preflight: a base point farther than this (m) outside the cloud's "
                                                "bounding box is refused; 0 = off (docs/pointcloud.md).")
    use_colors: bool = param(True,
                             help="False: ignore the file's colours (runs the colourless path on a coloured cloud, "
                                  "to measure it).")
    min_street_extent_m: float = param(10.0, ge=0,
                                       help="A cloud shorter than this (m) along its longer horizontal side is "
                                            "refused as not a street (an object or an indoor scan); checked in the "
                                            "preflight from the header's box and again from the points. 0 = off.")
    drop_platform: bool = param(True,
                                help="On a single spinning sweep, leave out the returns of the vehicle carrying the "
                                     "sensor: small clusters wholly inside the blind circle round the sensor, where "
                                     "the lowest beam has not yet reached the ground (twinkit.surface.rings."
                                     "platform_returns). False: keep them (the mesh gets a lump where the car "
                                     "stood).")


@dataclass
class PoissonParams:
    """Screened Poisson reconstruction."""

    depth: int = param(-1, ge=2, le=14, also=(-1,),
                       help="Octree depth of the Poisson solver (voxel = scene size x scale / 2**depth); higher = "
                            "finer and slower. -1 = auto: the depth whose voxel is about the cloud's median point "
                            "spacing, 6..11.")
    voxel_m: float = param(0.0, ge=0,
                           help="> 0: derive the depth from this target voxel size (m) instead of depth; 0 = use "
                                "depth.")
    scale: float = param(1.1, ge=1, le=10,
                         help="Size of the reconstruction cube relative to the bounding cube of the samples.")
    point_weight: float = param(4.0, ge=0,
                                help="Screening weight: higher follows the points more closely (interpolation), "
                                     "lower gives a smoother surface.")
    samples_per_node: float = param(1.5, ge=1, le=100,
                                    help="Minimum number of points per octree node; raise it for noisy clouds "
                                         "(smoother), lower it for clean ones.")
    linear_fit: bool = param(False,
                             help="open3d backend only: place the iso-surface vertices by linear interpolation (the "
                                  "solver's linear_fit).")
    backend: str = param("open3d", choices=("open3d", "pymeshlab"),
                         help="Poisson implementation: open3d, or pymeshlab (an optional dependency).")
    normals_k: int = param(24, ge=3, le=1000,
                           help="Neighbours for PCA normals; used only when the points have no normals.")
    normals_orientation: str = param("auto", choices=("auto", "scanner", "mst", "up"),
                                     help="How normals estimated here are oriented (auto, scanner, mst, up); used "
                                          "only when the points have no normals.")
    threads: int = param(1, ge=0,
                         help="Threads of the solver. 1 = the same mesh on every machine and run; 0 = the step's "
                              "share of the cores (faster, but the mesh differs from run to run).")


@dataclass
class CleanParams:
    """Trimming and repair of the dense mesh."""

    max_dist_m: float = param(-1.0, ge=0, also=(-1,),
                              help='Remove mesh vertices farther than this (m) from every input point ("bubbles"). '
                                   "0 = off; -1 = auto: 2 x the cloud's p90 point spacing, never below 0.10 m.")
    gap_dist_m: float = param(0.5, ge=0,
                              help="Exception to max_dist_m: keep vertices up to this far (m) from the points when "
                                   "they lie on the points' tangent planes (bridges small gaps); 0 = off.")
    gap_plane_m: float = param(0.02, ge=0,
                               help="What \"on the tangent planes\" means for gap_dist_m: the vertex's median "
                                    "distance (m) to the tangent planes of its k nearest points is at most this.")
    density_quantile: float = param(0.0, ge=0, lt=1,
                                    help="Remove vertices below this quantile of the Poisson density (weakly "
                                         "supported surface); 0 = off.")
    min_component_faces: int = param(200, ge=0, help="Drop connected components with fewer faces than this ...")
    min_component_points: int = param(3, ge=0,
                                      help="... unless at least this many input points stand on them (nearest "
                                           "vertex within the trim distance): a pole, a trunk or far foliage seen "
                                           "by a few points stays, a piece around a stray point goes; 0 = drop by "
                                           'size alone (docs/pointcloud.md "Coverage of sparse scans").')
    local_trim_factor: float = param(0.0, ge=0,
                                     help="The distance trim per vertex is at least this x the local point spacing "
                                          "at its nearest point (the nearest-neighbour distance of the density of "
                                          "its 8 nearest samples; the same factor as the auto max_dist_m on the "
                                          "median spacing), so the surface between the sparse samples of the far "
                                          "range stays; 0 = off (max_dist_m everywhere).")
    local_trim_max_m: float = param(0.5, ge=0, help="... never more than this (m).")
    min_component_ratio: float = param(0.0, ge=0, le=1,
                                       help="Also drop components smaller than this fraction of the largest one; 0 "
                                            "= off.")
    repair_non_manifold: bool = param(True, help="Repair non-manifold edges and vertices after the trim.")
    max_hole_edges: int = param(60, ge=0, help="Close holes whose boundary has at most this many edges; < 3 = off.")
    fill_ground_cell_m: float = param(-1.0, ge=0, also=(-1,),
                                      help="Fill the ground's occlusion shadows on a grid of this cell size (m). 0 "
                                           "= off; -1 = auto: the median point spacing, never below 0.10 m (a grid "
                                           "finer than the samples only costs time).")
    fill_ground_max_gap_m: float = param(8.0, ge=0,
                                         help="Fill a ground shadow only where ground lies on both sides of it at "
                                              "most this far apart (m).")
    fill_ground_stitch: bool = param(True,
                                     help="Join the ground fill to the mesh's own open border (one surface, no "
                                          "seam); false: add the fill as separate grid patches.")
    fill_ground_smooth_cells: int = param(-1, ge=0, le=15, also=(-1,),
                                          help="The shadows' heights are the median over this many cells square "
                                               "of the fill and the measured ground around (a streak one cell wide "
                                               "where rows of the interpolation end on different rings goes); 0 = "
                                               "off; -1 = auto: 5 where the cloud's ground is sampled in rings "
                                               "(density ground_two_way_share under 0.5: a spinning sweep), else "
                                               'off (docs/pointcloud.md "The fill without streaks").')
    fill_ground_sliver_max_m: float = param(0.10, ge=0,
                                            help="Before the fill, take out the closed shells on the ground it "
                                                 "covers that are at most this thick (m, volume over area seen from "
                                                 "above): Poisson's skin around a lone scan line, which the fill "
                                                 "would stop short of, leaving a slit along it; 0 = keep them "
                                                 '(docs/pointcloud.md "Slivers under the fill").')
    fill_ground_diagonal_gap_m: float = param(3.0, ge=0,
                                              help="After the passes along rows and columns, one along the "
                                                   "diagonals: an empty cell between ground cells at most this far "
                                                   "apart diagonally is a shadow too (m). It closes the notches of "
                                                   "the staircase that rows and columns leave where the ground's edge "
                                                   "runs askew to the grid (a sweep's far range), which a lane's edge "
                                                   "falls through; 0 = off (docs/pointcloud.md \"The fill's "
                                                   "staircase\").")
    colormap_max_m: float = param(0.0, ge=0,
                                  help="The distance colour map of the report saturates at this distance (m); 0 = "
                                       "max_dist_m (or the p99 distance).")
    max_trim_share: float = param(0.9, gt=0, le=1,
                                  help="The run is marked degraded when the distance trim removes more than this "
                                       "share of the faces.")
    max_fill_share: float = param(0.5, gt=0, le=1,
                                  help="The run is marked degraded when the ground fill makes more than this share "
                                       "of the clean mesh's area: the twin is then mostly invented ground, the "
                                       'capture too sparse for a street (docs/pointcloud.md "Sparse and partial '
                                       'captures": 3-25 % on the real clouds and the demo, 74 % on sparse sweeps).')


@dataclass
class SimplifyParams:
    """Decimation to a target face count."""

    target_faces: int = param(500_000, ge=1, help="Number of faces to decimate the mesh to.")
    method: str = param("auto", choices=("auto", "quadric", "clustering"),
                        help="Decimation method: quadric (edge collapse), clustering (vertex clustering, fast on "
                             "huge meshes), or auto (clustering first above cluster_above_faces, then quadric).")
    cluster_above_faces: int = param(20_000_000, ge=1,
                                     help="With method=auto: meshes with more faces than this are first reduced by "
                                          "clustering.")
    preserve_border: bool = param(True,
                                  help="Never collapse the edges of open boundaries (keeps the mesh's outline and "
                                       "hole borders).")
    aggressiveness: float = param(7.0, gt=0,
                                  help="fast-simplification's aggressiveness: lower is slower and more faithful.")
    max_overshoot: float = param(0.2, ge=0,
                                 help="The run is marked degraded when the result has more than target_faces x (1 + "
                                      "this) faces.")


@dataclass
class BakeParams:
    """UV atlas and colour baking."""

    texture_px: int = param(-1, ge=256, le=16384, also=(-1,),
                            help="Side of the texture atlas in texels: a power of two from 256 (4096, 8192 or 16384 "
                                 "usually). -1 = auto: texels of a quarter of the dense mesh's median edge (>= 1 "
                                 "cm) over the simplified mesh's area, the nearest power of two, 1024..8192. The "
                                 "colours live on the dense mesh's vertices: finer texels only interpolate them "
                                 "(the demo: 4096; 8192 was 0.2 colour levels closer to the vertex colours, no "
                                 "closer to the truth, same mIoU, 4x the bake).")
    uv_method: str = param("charts", choices=("charts", "xatlas"),
                           help="UV unwrapping: charts (built in) or xatlas (an optional dependency, slower).")
    pad_px: int = param(2, ge=0, le=64, help="Gutter around each chart in the atlas, in texels.")
    colourless: str = param("auto", choices=("auto", "intensity", "shaded", "height", "grey"),
                            help="What the texture shows for a cloud without colours: intensity, shaded (lit "
                                 "geometry), height, or a flat grey; auto = intensity when the cloud has it, else "
                                 "shaded.")


@dataclass
class EvalParams:
    """Distances between the cloud, the mesh and an optional ground-truth mesh."""

    colormap_max_m: float = param(0.0, ge=0,
                                  help="The distance colour maps saturate at this distance (m); 0 = the p95 of the "
                                       "cloud -> mesh distances.")
    gt_samples: int = param(1_000_000, ge=1000, help="Points sampled on the ground-truth surface for the distances.")
    gt_min_samples_per_class: int = param(20_000, ge=0,
                                          help="Per-class coverage: at least this many samples for each "
                                               "ground-truth label.")
    coverage_within_m: float = param(0.05, gt=0,
                                     help="A ground-truth sample counts as covered when the mesh is within this "
                                          "distance (m).")
    observed_m: float = param(0.10, gt=0,
                              help="A ground-truth sample counts as seen by the scan when an input point is within "
                                   "this distance (m).")
    exact_within_m: float = param(0.5, gt=0,
                                  help="Ground truth -> mesh distances are exact up to this distance (m), "
                                       "nearest-vertex distances beyond.")
    image_px: int = param(1024, ge=64, le=16384, help="Size of the evaluation images (px).")
    far_m: float = param(0.5, gt=0,
                         help="A cloud point farther than this (m) from the mesh counts as lost (its label cannot "
                              "reach the twin); the share is reported overall and per class of the file.")
    far_max_share: float = param(0.25, ge=0, le=1,
                                 help="The run is marked degraded when more than this share of the points is "
                                      'farther than far_m from the mesh (docs/pointcloud.md "Coverage of sparse '
                                      'scans").')
