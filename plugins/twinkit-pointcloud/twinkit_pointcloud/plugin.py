"""twinkit steps of the point-cloud branch (entry point ``pointcloud`` in group ``twinkit``).

Heavy libraries are imported inside the step functions only.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twinkit import hookimpl
from twinkit import artefacts as A
from twinkit.jsonio import write_json
from twinkit.ranges import param

from .report import twinkit_register_report_sections  # noqa: F401 (this plugin's sections of the run report)


# ----------------------------------------------------------------------------- parameters

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
    min_component_faces: int = param(200, ge=0, help="Drop connected components with fewer faces than this.")
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
    colormap_max_m: float = param(0.0, ge=0,
                                  help="The distance colour map of the report saturates at this distance (m); 0 = "
                                       "max_dist_m (or the p99 distance).")
    max_trim_share: float = param(0.9, gt=0, le=1,
                                  help="The run is marked degraded when the distance trim removes more than this "
                                       "share of the faces.")


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
                                 "cm) over the simplified mesh's area, 1024..8192.")
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


# ----------------------------------------------------------------------------- helpers



class _Outputs:
    """Removes whatever outputs (and companions) were written if the step fails: no partial outputs."""

    def __init__(self, *paths: Path):
        self.paths = [Path(p) for p in paths]

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            for p in self.paths:
                for q in p.parent.glob(p.stem + ".*"):
                    try:
                        q.unlink()
                    except OSError:
                        pass
        return False


def _read_mesh_input(path: Path, what: str):
    from twinkit import InputError

    from twinkit.mesh import read_ply

    try:
        m = read_ply(path)
    except Exception as exc:
        raise InputError(f"{Path(path).name}: cannot read the {what} ({type(exc).__name__}: {exc}); "
                         f"re-run the step that made it") from exc
    if what.endswith("mesh") and (m.faces is None or m.n_faces == 0):
        raise InputError(f"{Path(path).name}: the {what} has no faces; re-run the step that made it")
    return m


def _threads(ctx) -> int:
    return max(1, int(getattr(ctx, "threads", 1) or 1))


# ----------------------------------------------------------------------------- steps

def read_cloud(params: ReadCloudParams, ctx, *, in_cloud: Path, out_points_ply: Path,
               out_points_meta_json: Path) -> dict:
    """Read an E57 / LAS / LAZ / PLY cloud into the site frame (float64 shift, then float32 PLY)."""
    import numpy as np

    from twinkit.mesh import Mesh
    from twinkit.surface.measure import Measure
    from .localframe import apply_cloud_frame
    from .normals import check_file_normals, estimate_normals, orient_normals
    from .readers import read_any, validate_and_frame

    params = params or ReadCloudParams()
    in_cloud = Path(in_cloud)
    with Measure() as meas, _Outputs(out_points_ply, out_points_meta_json):
        raw = read_any(in_cloud)
        n_read = raw.n
        cloud_frame = apply_cloud_frame(raw, ctx.site, ctx.log)  # site.cloud_frame: a local cloud into the CRS
        cloud = validate_and_frame(raw, ctx.site, min_points=params.min_points,
                                   drop_invalid=params.drop_invalid_points, log=ctx.log,
                                   max_offset_m=params.max_offset_km * 1000.0,
                                   bounds_margin_m=params.bounds_margin_m)
        raw = cloud.raw
        if not params.use_colors and raw.colors is not None:
            ctx.log.info("%s: colours dropped (use_colors=false)", in_cloud.name)
            raw.colors = None
        pts = cloud.points
        from twinkit import InputError

        from .street import not_a_street

        refusal = not_a_street(in_cloud.name, pts.max(axis=0) - pts.min(axis=0), params.min_street_extent_m)
        if refusal:
            raise InputError(refusal)
        normals = raw.normals
        normals_source = "file" if normals is not None else None
        orientation = None
        normals_check = None
        if normals is not None and params.reorient_existing_normals:
            normals, orientation = orient_normals(pts, normals, params.normals_orientation,
                                                  scanner_index=raw.scanner, scanner_positions=raw.scanner_positions)
        elif normals is not None and params.file_normals_flip_share < 1:
            normals, normals_check = check_file_normals(pts, normals, params.normals_orientation,
                                                        scanner_index=raw.scanner,
                                                        scanner_positions=raw.scanner_positions,
                                                        min_share=params.file_normals_flip_share)
            log = ctx.log.warning if normals_check["flipped"] else ctx.log.info
            log("%s: normals from the file: %.1f %% point into the surface against a consistent orientation (%s)%s; "
                "near-horizontal normals pointing down %.1f %% -> %.1f %%", in_cloud.name,
                100 * normals_check["disagreeing_share"], normals_check["method"],
                f", {normals_check['flipped']} flipped" if normals_check["flipped"] else
                f", kept as they are ({normals_check['kept_because']})" if normals_check["kept_because"] else
                ", kept as they are",
                100 * normals_check["near_horizontal_down_before"], 100 * normals_check["near_horizontal_down_after"])
        if normals is None and params.estimate_normals:
            ctx.log.info("%s: no normals in the file: estimating them (k=%d)", in_cloud.name, params.normals_k)
            normals = estimate_normals(pts, k=params.normals_k)
            normals, orientation = orient_normals(pts, normals, params.normals_orientation,
                                                  scanner_index=raw.scanner, scanner_positions=raw.scanner_positions)
            normals_source = "estimated"
        if raw.colors is None:
            ctx.log.warning("%s: the cloud has no colours; the texture will show %s (bake_texture colourless)",
                            in_cloud.name, "its intensity" if raw.intensity is not None else "a shaded grey")
        from twinkit.surface import density

        dens = density.measure(pts, scanner_positions=raw.scanner_positions)
        ctx.log.info("%s: %s", in_cloud.name, density.describe(dens))
        attrs: dict[str, np.ndarray] = {}
        if normals is not None:
            attrs["normals"] = normals.astype(np.float32)
        if raw.colors is not None:
            attrs["colors"] = raw.colors
        if raw.intensity is not None:
            attrs["intensity"] = raw.intensity.astype(np.float32)
        if raw.classification is not None:
            attrs["classification"] = raw.classification
        if raw.scanner is not None:
            attrs["scanner"] = raw.scanner.astype(np.int32)
        for k, v in raw.extra.items():
            if k not in attrs and v.ndim == 1:
                attrs[k] = v
        comments = [f"twinkit-pointcloud read_cloud from {in_cloud.name}",
                    f"site frame shift {cloud.frame.shift[0]:.3f} {cloud.frame.shift[1]:.3f} {cloud.frame.shift[2]:.3f}"]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        meta = {
            "source": {"file": in_cloud.name, "format": raw.format, "fields": raw.source_fields},
            "counts": {"read": n_read, "dropped_invalid": cloud.dropped_invalid, "written": int(len(pts))},
            "fields": {"normals": normals_source, "normals_orientation": orientation, "normals_check": normals_check,
                       "colors": raw.colors is not None, "intensity": raw.intensity is not None,
                       "classification": raw.classification is not None, "scanner": raw.scanner is not None,
                       "extra": sorted(raw.extra)},
            "frame": dict(cloud.frame.as_dict(), cloud_frame=cloud_frame),
            "scanner_positions_m": (None if raw.scanner_positions is None else
                                    [[None if not np.isfinite(c) else float(c) for c in row]
                                     for row in raw.scanner_positions]),
            "bounds_m": [lo.tolist(), hi.tolist()],
            "density": dens,
            "notes": raw.notes,
        }
        for note in cloud.frame.notes:
            ctx.log.info("%s: %s", in_cloud.name, note)
        A.write_points(out_points_ply, Mesh(vertices=pts, attrs=attrs, comments=comments))
        meta["time"] = {"seconds": round(meas_now(meas), 3)}
        A.write_points_meta(out_points_meta_json, meta)
    out = {"points": int(len(pts)), "normals": normals_source, "colors": raw.colors is not None,
           "shift_m": cloud.frame.shift, "spacing_m": dens["spacing_m"], "capture": dens["capture"],
           **meas.as_dict()}
    if normals_check is not None:
        out["normals_flipped"] = normals_check["flipped"]
        out["normals_disagreeing_share"] = normals_check["disagreeing_share"]
    if cloud_frame is not None:
        out["cloud_frame"] = {k: v for k, v in cloud_frame.items() if k != "transform"} or {"transform": True}
    return out


def meas_now(m) -> float:
    import time

    return time.perf_counter() - m._t0


def poisson(params: PoissonParams, ctx, *, in_points_ply: Path, out_dense_mesh_ply: Path) -> dict:
    """Screened Poisson reconstruction of the cloud (normals estimated if absent)."""
    import numpy as np
    from twinkit import InputError

    from twinkit.mesh import write_ply
    from twinkit.surface.measure import Measure
    from .normals import estimate_normals, orient_normals
    from twinkit.surface.poisson import depth_for_voxel, poisson_open3d, poisson_pymeshlab, voxel_for_depth

    params = params or PoissonParams()
    with Measure() as meas, _Outputs(out_dense_mesh_ply):
        cloud = A.read_points(in_points_ply)
        pts = cloud.vertices
        if len(pts) < 10:
            raise InputError(f"{Path(in_points_ply).name}: too few points ({len(pts)}) for a surface")
        normals = cloud.normals
        if normals is None or not np.isfinite(normals).all() or (np.linalg.norm(normals, axis=1) < 0.5).mean() > 0.5:
            ctx.log.info("points have no usable normals: estimating them")
            normals = estimate_normals(pts, k=params.normals_k)
            normals, _ = orient_normals(pts, normals, params.normals_orientation)
        if params.voxel_m > 0:
            depth = depth_for_voxel(pts, params.voxel_m, params.scale)
        elif params.depth < 0:
            from twinkit.surface import density

            dm = density.measure(pts)
            depth = density.poisson_depth(dm, params.scale)
            ctx.log.info("poisson: %s; depth %d (auto)", density.describe(dm), depth)
        else:
            depth = int(params.depth)
        voxel = voxel_for_depth(pts, depth, params.scale)
        ctx.log.info("screened Poisson (%s) depth %d (voxel %.4f m) on %d points",
                     params.backend, depth, voxel, len(pts))
        kw = dict(depth=depth, scale=params.scale, point_weight=params.point_weight,
                  samples_per_node=params.samples_per_node)
        if params.backend == "open3d":
            mesh = poisson_open3d(pts, normals, cloud.colors, linear_fit=params.linear_fit,
                                  threads=params.threads or _threads(ctx), **kw)
        elif params.backend == "pymeshlab":
            mesh = poisson_pymeshlab(pts, normals, cloud.colors, threads=params.threads or _threads(ctx), **kw)
        else:
            raise InputError(f"poisson: unknown backend '{params.backend}' (open3d or pymeshlab)")
        if mesh.n_faces == 0:
            raise InputError(f"{Path(in_points_ply).name}: Poisson produced no surface (depth {depth}); "
                             f"check the normals or lower the depth")
        mesh.comments = [f"twinkit-pointcloud poisson depth {depth} voxel_m {voxel:.5f}"]
        write_ply(out_dense_mesh_ply, mesh)
    return {"depth": depth, "voxel_m": voxel, "vertices": mesh.n_vertices, "faces": mesh.n_faces, **meas.as_dict()}


def clean_mesh(params: CleanParams, ctx, *, in_dense_mesh_ply: Path, in_points_ply: Path,
               out_clean_mesh_ply: Path, out_clean_report_json: Path) -> dict:
    """Trim bubbles (distance) and low-density parts, keep large components, repair, close small holes."""
    import numpy as np

    from twinkit.surface.cleanup import CleanOptions, clean_mesh as _clean
    from twinkit.surface.measure import Measure
    from .metrics import topdown_map

    params = params or CleanParams()
    with Measure() as meas, _Outputs(out_clean_mesh_ply, out_clean_report_json):
        dense = _read_mesh_input(in_dense_mesh_ply, "dense mesh")
        cloud = A.read_points(in_points_ply)
        auto = _clean_auto(params, cloud, ctx.log)
        opt = CleanOptions(max_dist_m=auto["max_dist_m"], gap_dist_m=params.gap_dist_m, gap_plane_m=params.gap_plane_m,
                           density_quantile=params.density_quantile,
                           min_component_faces=params.min_component_faces,
                           min_component_ratio=params.min_component_ratio,
                           repair_non_manifold=params.repair_non_manifold, max_hole_edges=params.max_hole_edges,
                           fill_ground_cell_m=auto["fill_ground_cell_m"], fill_ground_max_gap_m=params.fill_ground_max_gap_m,
                           fill_ground_stitch=params.fill_ground_stitch, threads=_threads(ctx))
        mesh, rep = _clean(dense, cloud.vertices, opt, log=ctx.log, normals=cloud.normals, colors=cloud.colors)
        mesh.comments = ["twinkit-pointcloud clean_mesh; dist_to_cloud_m = distance to the nearest input point"]
        A.write_clean_mesh(out_clean_mesh_ply, mesh)
        d = mesh.attrs["dist_to_cloud_m"]
        vmax = params.colormap_max_m or opt.max_dist_m or float(np.quantile(d, 0.99))
        topdown_map(mesh.vertices, d, Path(out_clean_report_json).with_suffix(".png"), vmax,
                    title="clean mesh: vertex -> nearest point distance")
        rep["colormap_png"] = Path(out_clean_report_json).with_suffix(".png").name
        border = _ground_border_report(mesh, cloud, params.fill_ground_max_gap_m,
                                       Path(out_clean_report_json).with_name("open_border.png"), ctx.log)
        if border is not None:
            rep["open_border"] = border
        rep["auto"] = auto
        removed = _removed_most(rep, params.max_trim_share, ctx)
        rep["time"] = {"seconds": round(meas_now(meas), 3)}
        write_json(out_clean_report_json, rep)
    out = {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "max_dist_m": opt.max_dist_m,
           "fill_ground_cell_m": opt.fill_ground_cell_m, "capture": auto.get("capture"),
           "trim_removed_share": removed,
           "dist_mean_m": rep["output"]["dist_to_cloud_m"]["mean"], **meas.as_dict()}
    if border is not None:
        out["open_border_inside_m"] = border["inside_m"]
        out["open_border_inside_m_per_m2"] = border["inside_m_per_m2"]
    return out


def _clean_auto(params: CleanParams, cloud, log) -> dict:
    """The clean step's automatic settings (-1) from the cloud's measured spacing (twinkit.surface.density)."""
    from twinkit.surface import density

    out: dict = {"max_dist_m": params.max_dist_m, "fill_ground_cell_m": params.fill_ground_cell_m}
    if params.max_dist_m >= 0 and params.fill_ground_cell_m >= 0:
        return out
    m = density.measure(cloud.vertices)
    out.update(spacing_m=m["spacing_m"], spacing_p90_m=m["spacing_p90_m"], capture=m["capture"])
    if params.max_dist_m < 0:
        out["max_dist_m"] = density.trim_distance(m)
    if params.fill_ground_cell_m < 0:
        s = m["spacing_m"]
        out["fill_ground_cell_m"] = round(max(0.10, s if s == s else 0.10), 3)
    log.info("clean: %s; trim distance %.3g m, ground-fill cell %.3g m (auto)", density.describe(m),
             out["max_dist_m"], out["fill_ground_cell_m"])
    return out


def _removed_most(rep: dict, max_share: float, ctx) -> float | None:
    """The share of the faces the distance trim removed; more than ``max_share``: degraded, with the numbers."""
    trim = rep.get("distance_trim")
    n_in = rep["input"]["faces"]
    if not trim or not n_in:
        return None
    share = 1.0 - trim["faces"] / n_in
    if share > max_share:
        fill = (rep.get("ground_fill") or {}).get("faces_added")
        ctx.degraded(f"the distance trim ({trim['max_dist_m']:.3g} m) removed {100 * share:.1f} % of the "
                     f"{n_in:,} faces ({trim['faces']:,} left)" + (f"; the ground fill added {fill:,}" if fill else ""),
                     "the trim distance is probably below the cloud's point spacing: leave "
                     "steps.clean_mesh.max_dist_m at -1 (auto) or set it to 2-3 x the spacing (clean_report.json)")
    return round(share, 4)


def _ground_border_report(mesh, cloud, fill_limit_m: float, png: Path, log) -> dict | None:
    from twinkit.surface.watertight import ground_border_report

    if cloud.normals is None:
        return None
    return ground_border_report(mesh.vertices, mesh.faces, cloud.vertices, cloud.normals, fill_limit_m, png, log)


def simplify(params: SimplifyParams, ctx, *, in_clean_mesh_ply: Path, out_mesh_ply: Path) -> dict:
    """Decimate to a target face count; colours re-sampled from the dense mesh."""
    from twinkit.mesh import write_ply
    from twinkit.surface.measure import Measure
    from twinkit.surface.simplify import simplify_mesh

    params = params or SimplifyParams()
    with Measure() as meas, _Outputs(out_mesh_ply):
        dense = A.read_clean_mesh(in_clean_mesh_ply)
        mesh, method = simplify_mesh(dense, params.target_faces, method=params.method,
                                     cluster_above_faces=params.cluster_above_faces,
                                     preserve_border=params.preserve_border,
                                     aggressiveness=params.aggressiveness, threads=_threads(ctx))
        err = mesh.attrs.pop("dist_to_dense_m", None)
        closed = [c for c in mesh.comments if c.startswith("holes closed after simplification")]
        mesh.comments = [f"twinkit-pointcloud simplify {method} target {params.target_faces}"] + closed
        write_ply(out_mesh_ply, mesh)
    out = {"method": method, "vertices": mesh.n_vertices, "faces": mesh.n_faces,
           "input_faces": dense.n_faces, **meas.as_dict()}
    if closed:
        out["holes_closed"] = int(closed[0].rsplit(":", 1)[1])
    if dense.n_faces > params.target_faces and mesh.n_faces > params.target_faces * (1 + params.max_overshoot):
        over = mesh.n_faces / params.target_faces - 1
        out["overshoot"] = round(over, 4)
        ctx.degraded(f"simplify left {mesh.n_faces:,} faces for a target of {params.target_faces:,} "
                     f"({100 * over:.0f} % over)", "open borders and thin parts cannot collapse with "
                     "preserve_border=true; try steps.simplify.preserve_border=false or a lower target")
    if err is not None and len(err):
        out["vertex_to_dense_mean_m"] = float(err.mean())
        out["vertex_to_dense_max_m"] = float(err.max())
    return out


def bake_texture(params: BakeParams, ctx, *, in_mesh_ply: Path, in_clean_mesh_ply: Path,
                 out_textured_mesh_obj: Path, out_textured_mesh_ply: Path,
                 in_points_ply: Path | None = None) -> dict:
    """UV-unwrap the simplified mesh and bake the dense mesh's colours into a texture (OBJ+MTL+PNG, PLY)."""
    import numpy as np
    from twinkit import InputError

    from twinkit.surface.measure import Measure, StepTimer
    from twinkit.surface.simplify import resample_attributes
    from twinkit.surface.texture import write_png

    from .texture import bake_colors
    from .uv import chart_uv, xatlas_uv

    params = params or BakeParams()
    size = int(params.texture_px)
    if size != -1 and (size < 256 or size > 16384 or size & (size - 1)):
        raise InputError(f"bake_texture: texture_px={size} must be a power of two from 256 to 16384 "
                         f"(4096, 8192 or 16384 for a site)")
    timer = StepTimer()
    out_obj = Path(out_textured_mesh_obj)
    png = out_obj.with_suffix(".png")
    with Measure() as meas, _Outputs(out_textured_mesh_obj, out_textured_mesh_ply):
        mesh = _read_mesh_input(in_mesh_ply, "mesh")
        dense = A.read_clean_mesh(in_clean_mesh_ply)
        auto_size = None
        if size == -1:
            from twinkit.surface import density

            area, _ = density.mesh_texel(mesh.vertices, mesh.faces)
            _, texel = density.mesh_texel(dense.vertices, dense.faces)
            size = auto_size = density.texture_size(area, texel)
            ctx.log.info("bake: %.0f m^2 of surface, texel %.1f mm (a quarter of the dense mesh's median edge, >= 1 cm): "
                         "texture %d px (auto)", area, 1000 * texel, size)
        with timer("uv"):
            if params.uv_method == "charts":
                uv, uinfo = chart_uv(mesh.vertices, mesh.faces, size, pad_px=params.pad_px)
            elif params.uv_method == "xatlas":
                uv, uinfo = xatlas_uv(mesh.vertices, mesh.faces, size)
            else:
                raise InputError(f"bake_texture: unknown uv_method '{params.uv_method}' (charts or xatlas)")
        colors = dense.colors
        colourless = None
        if colors is None:
            colors, colourless = _colourless(params.colourless, dense, in_points_ply, ctx)
        with timer("bake"):
            img, binfo = bake_colors(mesh.vertices, mesh.faces, uv, size, dense.vertices, dense.faces, colors,
                                     threads=_threads(ctx),
                                     progress=lambda it: ctx.progress(it, desc="bake texture"))
        with timer("write"):
            write_png(png, img)
            if colors is not None:
                dense.attrs["colors"] = colors
                mesh = resample_attributes(mesh, dense, _threads(ctx))
                mesh.attrs.pop("dist_to_dense_m", None)
            else:
                mesh.attrs["colors"] = np.full((mesh.n_vertices, 3), 128, np.uint8)
            normals = mesh.attrs.get("normals")
            A.write_textured_obj(out_obj, mesh.vertices, mesh.faces, uv, png.name, normals=normals)
            mesh.face_attrs["texcoord"] = uv.reshape(-1, 6).astype(np.float32)
            mesh.comments = [f"TextureFile {png.name}"]
            A.write_textured_mesh(out_textured_mesh_ply, mesh)
    return {"texture_px": size, "texture_px_auto": auto_size is not None, "uv_method": params.uv_method,
            "neutral_texture": colors is None or colourless == "grey", "colourless": colourless,
            "vertices": mesh.n_vertices, "faces": mesh.n_faces, **{f"uv_{k}": v for k, v in uinfo.items()},
            **binfo, "substeps": timer.table, **meas.as_dict()}


def _colourless(mode: str, dense, in_points_ply, ctx):
    """Vertex colours for a dense mesh whose cloud had none (shading.py): (colours, the mode used)."""
    import numpy as np

    from twinkit.mesh import vertex_normals
    from .shading import AUTO_WITHOUT_INTENSITY, vertex_colours

    intensity = None
    if mode in ("auto", "intensity") and in_points_ply is not None:
        cloud = A.read_points(in_points_ply)
        inten = cloud.attrs.get("intensity")
        if inten is not None and np.isfinite(inten).any() and float(np.nanstd(inten)) > 0:
            from scipy.spatial import cKDTree

            _, idx = cKDTree(cloud.vertices).query(dense.vertices, workers=_threads(ctx))
            intensity = np.asarray(inten, np.float64)[idx]
    if mode == "auto":
        mode = "intensity" if intensity is not None else AUTO_WITHOUT_INTENSITY
    elif mode == "intensity" and intensity is None:
        ctx.log.warning("bake: colourless=intensity but the cloud has no usable intensity: shaded instead")
        mode = "shaded"
    normals = dense.attrs.get("normals")
    if normals is None or len(normals) != dense.n_vertices:
        normals = vertex_normals(dense.vertices, dense.faces)
    if mode == "grey":
        ctx.log.warning("the cloud has no colours: neutral grey texture (colourless=grey); the 2D model will see "
                        "flat grey views")
    else:
        ctx.log.warning("the cloud has no colours: the texture shows %s grey (colourless=%s, "
                        "docs/pointcloud.md 'Clouds without colour')",
                        "its intensity, lit," if mode == "intensity" else f"a {mode} rendering in", mode)
    return vertex_colours(mode, dense.vertices, normals, intensity, faces=dense.faces), mode


def evaluate(params: EvalParams, ctx, *, in_textured_mesh_ply: Path, in_points_ply: Path,
             out_recon_metrics_json: Path, in_gt_mesh_ply: Path | None = None) -> dict:
    """Cloud <-> mesh distances (and against a ground-truth mesh when given), counts, a colour map."""
    import numpy as np

    from twinkit import cityscapes
    from twinkit.surface.closest import Surface
    from twinkit.surface.measure import Measure
    from twinkit.surface.metrics import cloud_to_mesh

    from .metrics import (coverage_by_label, distance_near_exact, sample_surface,
                          sample_surface_by_label, stats, topdown_map)

    params = params or EvalParams()
    with Measure() as meas, _Outputs(out_recon_metrics_json):
        mesh = A.read_textured_mesh(in_textured_mesh_ply)
        cloud = A.read_points(in_points_ply)
        from scipy.spatial import cKDTree

        c2m = cloud_to_mesh(cloud.vertices, mesh.vertices, mesh.faces, _threads(ctx))
        ctree = cKDTree(cloud.vertices)
        m2c, _ = ctree.query(mesh.vertices, workers=_threads(ctx))
        res: dict[str, Any] = {
            "counts": {"points": cloud.n_vertices, "vertices": mesh.n_vertices, "faces": mesh.n_faces},
            "cloud_to_mesh_m": stats(c2m),
            "mesh_to_cloud_m": stats(m2c),
            "cloud_within_m": {str(t): float((c2m <= t).mean()) for t in (0.01, 0.02, 0.05, 0.1)},
        }
        if in_gt_mesh_ply is not None:
            gt = A.read_gt_mesh(in_gt_mesh_ply)
            gsurf = Surface(gt.vertices, gt.faces, _threads(ctx))
            acc = gsurf.distance(mesh.vertices)
            samples = sample_surface(gt.vertices, gt.faces, params.gt_samples)
            msurf = Surface(mesh.vertices, mesh.faces, _threads(ctx))
            vtree = cKDTree(mesh.vertices)
            comp = distance_near_exact(msurf, mesh.vertices, samples, params.exact_within_m, _threads(ctx), vtree)
            # area-weighted accuracy: comparable between a dense and a decimated mesh (per-vertex is not)
            acc_area = gsurf.distance(sample_surface(mesh.vertices, mesh.faces, min(params.gt_samples, 500_000), seed=2))
            res["gt"] = {"accuracy_mesh_to_gt_m": stats(acc), "accuracy_area_weighted_m": stats(acc_area),
                         "completeness_gt_to_mesh_m": stats(comp),
                         "chamfer_m": float(acc.mean() + comp.mean()) / 2.0,
                         "gt_covered_within_5cm": float((comp <= 0.05).mean())}
            glab = gt.face_attrs.get("label")
            if glab is not None and len(glab) == gt.n_faces:
                s2, l2, areas = sample_surface_by_label(gt.vertices, gt.faces, np.asarray(glab), params.gt_samples,
                                                        params.gt_min_samples_per_class, seed=1)
                d_mesh = distance_near_exact(msurf, mesh.vertices, s2, params.exact_within_m, _threads(ctx), vtree)
                # bounded: a kd-tree query for a sample metres from every point (an unseen roof) is slow
                d_cloud, _ = ctree.query(s2, workers=_threads(ctx), distance_upper_bound=2 * params.observed_m)
                res["gt"]["per_class"] = coverage_by_label(d_mesh, l2, areas, within_m=params.coverage_within_m,
                                                           dist_to_cloud=d_cloud, observed_m=params.observed_m)
                res["gt"]["per_class_settings"] = {"covered_within_m": params.coverage_within_m,
                                                   "observed_m": params.observed_m}
                acc_lab = np.asarray(glab)[gsurf.closest(mesh.vertices)[0]]
                res["gt"]["accuracy_by_class_mean_m"] = {
                    cityscapes.name_of(int(c)): float(acc[acc_lab == c].mean()) for c in np.unique(acc_lab)}
        vmax = params.colormap_max_m or float(np.quantile(c2m, 0.95)) or 0.01
        png = Path(out_recon_metrics_json).with_suffix(".png")
        topdown_map(cloud.vertices, c2m, png, vmax, size_px=params.image_px, title="cloud -> mesh distance")
        res["colormap_png"] = png.name
        res["colormap_max_m"] = vmax
        res["time"] = {"seconds": round(meas_now(meas), 3)}
        write_json(out_recon_metrics_json, res)
    return {"cloud_to_mesh_mean_m": res["cloud_to_mesh_m"]["mean"], "cloud_to_mesh_p95_m": res["cloud_to_mesh_m"]["p95"],
            "vertices": mesh.n_vertices, "faces": mesh.n_faces, **meas.as_dict()}


# ----------------------------------------------------------------------------- registration

@hookimpl
def twinkit_register_steps(register):
    from .preflight import read_cloud_preflight

    register("read_cloud", read_cloud, params=ReadCloudParams, preflight=read_cloud_preflight)
    register("clean_mesh", clean_mesh, params=CleanParams)
    register("simplify", simplify, params=SimplifyParams)
    register("bake_texture", bake_texture, params=BakeParams)
    register("evaluate_reconstruction", evaluate, params=EvalParams)


@hookimpl
def twinkit_register_reconstructors(register):
    register("poisson", poisson, params=PoissonParams)
