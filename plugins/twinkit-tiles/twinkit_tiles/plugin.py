"""twinkit steps for large scenes (entry point ``tiles`` in group ``twinkit``):

- ``plan_tiles``: points.ply -> tiles.json + tile_points/ (one chunk per padded tile)
- ``reconstruct_tile`` (run with ``foreach: tiles.json``): one chunk -> tile_mesh.ply cut to the core
- ``merge_tiles``: every tile_mesh.ply -> clean_mesh.ply (stitched, crack-free) + tile_seams.json (+ .png)
- ``evaluate_seam_labels``: labels.npy of the merged mesh -> seam_labels.json (do labels change at seams?)
- executor ``dask``: fanned-out items on a Dask distributed cluster (local, existing, or SLURM)

Heavy libraries are imported inside the functions only.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional

from twinkit import artefacts as A
from twinkit import hookimpl
from twinkit.ranges import param

from .report import twinkit_register_report_sections  # noqa: F401 (this plugin's sections of the run report)


@dataclass
class PlanTilesParams:
    """How the site is cut into tiles."""

    tile_m: float = param(0.0, ge=0,
                          help="Core size of a tile (m); 0 = automatic, from memory_budget_gb and the point "
                               "density.")
    overlap_m: float = param(2.0, ge=0,
                             help="Each tile also reconstructs this much (m) of its neighbours; the overlap only "
                                  "guides the cut and is removed after it.")
    memory_budget_gb: float = param(4.0, gt=0,
                                    help="Automatic tile size: the predicted peak memory of one tile (GB) stays "
                                         "below this. Lower it on small machines or with many workers.")
    voxel_m: float = param(0.03, gt=0,
                           help="Finest Poisson voxel (m) of every tile (passed to reconstruct_tile through "
                                "tiles.json).")
    max_tiles: int = param(256, ge=1,
                           help="Refuse a plan with more tiles than this (guards against a tiny tile_m or a wrong "
                                "unit).")
    seam_search_m: float = param(1.0, ge=0,
                                 help="Move each seam by up to this (m) to where the fewest upright surfaces "
                                      "(poles, trunks, crowns, cars) cross it; 0 = evenly spaced seams.")
    target_faces: int = param(6_000_000, ge=0,
                              help="> 0: simplify each tile after its cut to its share (by the points in its core) "
                                   "of this many faces, keeping seam borders; this bounds the memory of the merge "
                                   "and of the steps after it (full-density large site: 6.7 GB at 6 M, 20.5 GB "
                                   "for its 33 M faces unsimplified). 0 = full resolution.")


@dataclass
class ReconstructTileParams:
    """Poisson + clean-up of one padded tile, then the exact cut to its core."""

    point_weight: float = param(4.0, ge=0,
                                help="Poisson screening weight: higher follows the points more closely, lower is "
                                     "smoother.")
    samples_per_node: float = param(1.5, ge=1, le=100,
                                    help="Poisson: minimum number of points per octree node (higher = smoother on "
                                         "noisy clouds).")
    max_dist_m: float = param(0.10, ge=0,
                              help='Trim vertices farther than this (m) from every point of the tile ("bubbles").')
    gap_dist_m: float = param(0.5, ge=0,
                              help="Exception to max_dist_m: keep vertices up to this far (m) that lie on the "
                                   "points' tangent planes (clean_mesh's gap rule); 0 = off.")
    gap_plane_m: float = param(0.02, ge=0,
                               help='What "on the tangent planes" means for gap_dist_m: median distance (m) to the '
                                    "tangent planes of the nearest points at most this.")
    density_quantile: float = param(0.0, ge=0, lt=1,
                                    help="Trim vertices below this quantile of the Poisson density; 0 = off.")
    min_component_faces: int = param(200, ge=0,
                                     help="Drop connected components with fewer faces than this (judged on the "
                                          "padded tile).")
    max_hole_edges: int = param(60, ge=0,
                                help="Close holes with up to this many boundary edges (before the cut, so no cap is "
                                     "put on a seam).")
    threads: int = param(1, ge=0,
                         help="Threads per tile: 1 = the parallelism comes from the workers; 0 = all the threads "
                              "the step may use.")
    seam_band_m: float = param(1.0, ge=0,
                               help="Within this distance (m) of an interior seam the tile trims only loosely "
                                    "(seam_loose_dist_m); merge_tiles then trims that band once, for both sides. 0 "
                                    "= off.")
    seam_loose_dist_m: float = param(1.0, ge=0,
                                     help="The loose trim distance (m) used inside seam_band_m (never below "
                                          "max_dist_m); 0 = off.")


@dataclass
class MergeTilesParams:
    """Stitching of the tiles into one mesh."""

    max_gap_m: float = param(0.10, ge=0,
                             help="Tile borders farther apart than this (m) are not stitched; they are counted as "
                                  "open.")
    seam_tol_m: float = param(0.001, ge=0,
                              help="An edge within this distance (m) of a seam plane counts as a seam edge in the "
                                   "statistics.")
    max_hole_edges: int = param(120, ge=0,
                                help="After stitching, fill loops that touch a seam with up to this many edges; 0 = "
                                     "off.")
    vote_reach_m: float = param(0.15, ge=0,
                                help="The seam-band trim asks each tile's full-resolution surface: the tile's "
                                     "nearest vote within this distance (m), and within vote_plane_m of its tangent "
                                     "plane, is that tile's verdict. A vertex is kept when some tile says \"keep\", "
                                     'dropped when every tile says "drop", and judged on its own where no tile '
                                     "voted. 0 = off.")
    vote_plane_m: float = param(0.05, ge=0,
                                help="A vote counts only for vertices this close (m) to its tangent plane (not for "
                                     "a bubble above it).")
    drop_hanging_faces: bool = param(True,
                                     help="After the seam-band trim, remove a face left on a seam edge whose other "
                                          "side was trimmed, so the trim's boundary crosses the seam instead of "
                                          "running along it (docs/tiles.md).")
    vote_radius_m: float = param(0.0, ge=0,
                                 help='Also keep a vertex that has any "keep" vote this close (m); 0 = off. Wider '
                                      "radii keep surface the trim would drop (docs/tiles.md).")
    line_band_m: float = param(0.05, ge=0,
                               help="Open borders within this distance (m) of the seams, and of the control lines, "
                                    "are counted separately in tile_seams.json.")
    fill_ground_cell_m: float = param(0.10, ge=0,
                                      help="Fill the ground's occlusion shadows on the merged mesh on a grid of "
                                           "this cell size (m), over the whole site at once so the fill has no tile "
                                           "edges (clean_mesh's ground fill); 0 = off.")
    fill_ground_max_gap_m: float = param(8.0, ge=0,
                                         help="Fill a ground shadow only where ground lies on both sides of it at "
                                              "most this far apart (m).")


@dataclass
class EvaluateSeamLabelsParams:
    """Label agreement across the seams of a tiled, segmented mesh."""

    band_m: float = param(1.0, gt=0,
                          help="Label accuracy within this distance (m) of a seam is compared with the accuracy "
                               "farther away (needs ground truth).")
    planes: List[str] = param(default_factory=list, free=True,
                              help="Check these planes instead of tiles.json's seams, e.g. [\"x=-10\", \"y=10\"] (the "
                                   "same lines on an untiled run); empty = the seams.")


_SLURM_WORD = dict(pattern=r"[\w.:@+-]*", words="letters, digits and . : @ + - only (it is written into the SLURM job script)")


@dataclass
class DaskExecutorParams:
    """Run fanned-out items on a Dask distributed cluster."""

    address: Optional[str] = param(None, free=True,
                                   help="Address of an existing Dask scheduler (e.g. tcp://host:8786); null = start "
                                        "a cluster (see cluster).")
    n_workers: int = param(2, ge=1, help="Worker processes of the local cluster, or SLURM jobs with cluster=slurm.")
    threads_per_worker: int = param(1, ge=1, help="Threads of each worker process.")
    memory_limit: str = param("auto", **_SLURM_WORD,
                              help="Memory limit per worker, e.g. 6GiB; auto = the machine's RAM / n_workers; 0 = "
                                   "no limit.")
    cluster: str = param("local", choices=("local", "slurm"),
                         help="Which cluster to start when address is null: local processes, or SLURM jobs (needs "
                              "dask-jobqueue).")
    slurm_queue: str = param("", **_SLURM_WORD,
                             help="cluster=slurm: the partition (queue) to submit to; empty = the site's default.")
    slurm_cores: int = param(4, ge=1, help="cluster=slurm: cores of each job.")
    slurm_memory: str = param("16GB", **_SLURM_WORD, help="cluster=slurm: memory of each job, e.g. 16GB.")
    slurm_walltime: str = param("02:00:00", **_SLURM_WORD,
                                help="cluster=slurm: wall-time limit of each job (HH:MM:SS).")
    slurm_account: str = param("", **_SLURM_WORD, help="cluster=slurm: the account to charge; empty = the default.")


# ----------------------------------------------------------------------------- steps

def _input_error(msg: str):
    from twinkit import InputError

    return InputError(msg)


def plan_tiles(params: PlanTilesParams, ctx, *, in_points_ply: Path, out_tiles_json: Path,
               out_tile_points_dir: Path) -> dict:
    """Split the site into overlapping XY tiles; write one point chunk per padded tile and tiles.json."""
    import numpy as np
    from twinkit.mesh import Mesh, write_ply
    from twinkit.surface.measure import Measure

    from .tiling import choose_grid, estimate_tile_mb, in_box

    params = params or PlanTilesParams()
    if params.voxel_m <= 0:
        raise _input_error(f"plan_tiles: voxel_m must be > 0 (got {params.voxel_m})")
    if params.overlap_m < 0:
        raise _input_error(f"plan_tiles: overlap_m must be >= 0 (got {params.overlap_m})")
    with Measure() as meas:
        cloud = A.read_points(in_points_ply)
        if cloud.n_vertices < 10:
            raise _input_error(f"{Path(in_points_ply).name}: too few points ({cloud.n_vertices}) to tile")
        if cloud.normals is None:
            raise _input_error(f"{Path(in_points_ply).name}: the points have no normals; run read_cloud with "
                               f"estimate_normals=true")
        xy = cloud.vertices[:, :2]
        grid, why = choose_grid(xy, params.tile_m, params.overlap_m, params.memory_budget_gb, params.voxel_m,
                                params.max_tiles)
        moved = []
        if params.seam_search_m > 0:
            from .tiling import place_seams

            if params.seam_search_m > params.overlap_m:
                raise _input_error(f"plan_tiles: seam_search_m ({params.seam_search_m}) must not exceed overlap_m "
                                   f"({params.overlap_m}): a seam must stay inside both tiles' overlap")
            upright = np.abs(cloud.normals[:, 2]) < 0.7
            xs, ys = grid.lines()
            grid.xs, rx = place_seams(cloud.vertices[:, 0], upright, xs, params.seam_search_m)
            grid.ys, ry = place_seams(cloud.vertices[:, 1], upright, ys, params.seam_search_m)
            moved = [{"axis": "x"} | r for r in rx] + [{"axis": "y"} | r for r in ry]
            for r in moved:
                ctx.log.info("seam %s=%.2f moved %+.2f m: %d -> %d upright points on it", r["axis"], r["line"],
                             r["moved_m"], r["upright_points_before"], r["upright_points_after"])
        tiles = grid.tiles()
        out_tile_points_dir.mkdir(parents=True, exist_ok=True)
        if params.target_faces < 0:
            raise _input_error(f"plan_tiles: target_faces must be >= 0 (got {params.target_faces})")
        items = []
        inf = float("inf")
        column: tuple = (None, None)  # (its padded x range, the indices of the points in it): one pass per column
        for t in ctx.progress(sorted(tiles, key=lambda t: (t["ix"], t["iy"])), total=len(tiles), desc="plan_tiles"):
            box = t["padded"]
            if column[0] != (box[0], box[2]):
                column = ((box[0], box[2]), np.flatnonzero((xy[:, 0] >= box[0]) & (xy[:, 0] <= box[2])))
            sel = column[1][in_box(xy[column[1]], box)]
            n = len(sel)
            name = f"tile_{t['index']:03d}.ply"
            if n < 10:
                ctx.log.info("tile %d has %d points: skipped", t["index"], n)
                continue
            chunk = Mesh(vertices=cloud.vertices[sel], attrs={k: v[sel] for k, v in cloud.attrs.items()})
            write_ply(out_tile_points_dir / name, chunk, xyz_dtype="f8")
            pxy = cloud.vertices[sel, :2]
            ext = pxy.max(axis=0) - pxy.min(axis=0)
            core = [-inf if c is None else c for c in t["core"][:2]] + [inf if c is None else c for c in t["core"][2:]]
            predicted = round(estimate_tile_mb(n, float(ext[0] * ext[1]), params.voxel_m), 1)
            # "cost" makes the engine start the biggest tiles first (better balance between workers)
            items.append(t | {"chunk": name, "points": n, "core_points": int(in_box(xy[sel], core).sum()),
                              "voxel_m": params.voxel_m, "predicted_mb": predicted, "cost": predicted})
        items.sort(key=lambda i: i["index"])
        if params.target_faces > 0:
            total = max(1, sum(i["core_points"] for i in items))
            for i in items:
                i["target_faces"] = max(1000, int(round(params.target_faces * i["core_points"] / total)))
        plan = {"grid": why | {"x0": grid.x0, "y0": grid.y0, "x1": grid.x1, "y1": grid.y1,
                               "overlap_m": grid.overlap_m, "voxel_m": params.voxel_m,
                               "target_faces": params.target_faces, "seams_moved": moved},
                "items": items}
        Path(out_tiles_json).write_text(json.dumps(plan, indent=2))
    ctx.log.info("%d x %d tiles of %.1f m (overlap %.1f m), %d with points", grid.nx, grid.ny, why["tile_m"],
                 params.overlap_m, len(items))
    return {"tiles": len(items), "nx": grid.nx, "ny": grid.ny, "tile_m": why["tile_m"],
            "max_tile_points": max(i["points"] for i in items),
            "max_predicted_mb": max(i["predicted_mb"] for i in items), **meas.as_dict()}


def reconstruct_tile(params: ReconstructTileParams, ctx, *, in_tile_points_dir: Path, item: dict,
                     out_tile_mesh_ply: Path, out_seam_votes_npz: Path) -> dict:
    """Poisson on one padded tile at the plan's voxel size, clean-up, exact cut to the tile's core."""
    import os

    from twinkit.mesh import read_ply, write_ply
    from twinkit.surface.cleanup import CleanOptions, clean_mesh
    from twinkit.surface.measure import Measure
    from twinkit.surface.simplify import simplify_mesh

    import numpy as np

    from .cut import cut_to_box
    from .edges import edge_counts
    from .tiling import exact_voxel_poisson

    params = params or ReconstructTileParams()
    threads = params.threads if params.threads > 0 else max(1, int(getattr(ctx, "threads", 1) or 1))
    chunk_path = Path(in_tile_points_dir) / item["chunk"]
    with Measure() as meas:
        try:
            cloud = read_ply(chunk_path)
        except Exception as exc:
            raise _input_error(f"{chunk_path}: cannot read the tile's points ({exc}); re-run plan_tiles") from exc
        pts = cloud.vertices
        mesh, depth, scale = exact_voxel_poisson(pts, cloud.normals, cloud.colors, float(item["voxel_m"]),
                                                 point_weight=params.point_weight,
                                                 samples_per_node=params.samples_per_node, threads=threads)
        dense_faces = mesh.n_faces
        opt = CleanOptions(max_dist_m=params.max_dist_m, gap_dist_m=params.gap_dist_m, gap_plane_m=params.gap_plane_m,
                           density_quantile=params.density_quantile,
                           min_component_faces=params.min_component_faces, max_hole_edges=params.max_hole_edges,
                           threads=threads)
        loose = None
        core = item["core"]
        planes = [(a, float(core[k])) for k, a in ((0, 0), (1, 1), (2, 0), (3, 1)) if core[k] is not None]
        if params.seam_band_m > 0 and params.seam_loose_dist_m > 0 and planes:
            from .edges import near_planes

            opt.loose_dist_m = max(params.seam_loose_dist_m, params.max_dist_m)
            loose = lambda V: near_planes(V, planes, params.seam_band_m)  # noqa: E731
        votes = {"points": np.zeros((0, 3), np.float32), "normals": np.zeros((0, 3), np.float32),
                 "keep": np.zeros(0, bool)}
        if mesh.n_faces:
            try:
                mesh, crep = clean_mesh(mesh, pts, opt, normals=cloud.normals, loose=loose)
                if "loose_samples" in crep:
                    votes = crep["loose_samples"]
            except Exception as exc:  # e.g. nothing within max_dist_m: an empty tile
                ctx.log.warning("tile %d: clean-up left nothing (%s)", item["index"], exc)
                mesh.faces = mesh.faces[:0]
        # the exact trim's verdict on this tile's full-resolution surface near the seams, on both sides
        # of them (the padded tile reaches into its neighbours): merge_tiles keeps a place near a seam
        # when either tile's surface there passes, so the two sides decide alike
        np.savez_compressed(out_seam_votes_npz, points=np.asarray(votes["points"], np.float32),
                            normals=np.asarray(votes["normals"], np.float16), keep=np.asarray(votes["keep"], bool))
        padded_faces = mesh.n_faces
        mesh = cut_to_box(mesh, item["core"]) if mesh.n_faces else mesh
        cut_faces = mesh.n_faces
        target = int(item.get("target_faces") or 0)
        if target and mesh.n_faces > target:
            # borders kept: the cut vertices stay exactly on the seam planes for the zipper
            mesh, _ = simplify_mesh(mesh, target, method="quadric", preserve_border=True, threads=threads)
            mesh.attrs.pop("dist_to_dense_m", None)
        band = params.seam_band_m if loose is not None else 0.0
        mesh.comments = [f"twinkit-tiles tile {item['index']} depth {depth} voxel_m {item['voxel_m']}",
                         # what merge_tiles needs to finish the trim near the seams the same way
                         f"twinkit-tiles trim max_dist_m {params.max_dist_m} gap_dist_m {params.gap_dist_m} "
                         f"gap_plane_m {params.gap_plane_m} seam_band_m {band} "
                         f"min_component_faces {params.min_component_faces} max_hole_edges {params.max_hole_edges}"]
        write_ply(out_tile_mesh_ply, mesh, xyz_dtype="f8")
    ec = edge_counts(mesh.faces) if mesh.n_faces else {}
    return {"tile": item["index"], "points": int(len(pts)), "depth": depth, "scale": round(scale, 4),
            "dense_faces": int(dense_faces), "padded_clean_faces": int(padded_faces), "cut_faces": int(cut_faces), "faces": mesh.n_faces,
            "boundary_edges": ec.get("boundary_edges", 0), "pid": os.getpid(),
            "seam_votes": int(len(votes["keep"])), "seam_votes_keep": int(np.count_nonzero(votes["keep"])),
            "tile_peak_rss_mb": round(meas.peak_rss_mb, 1), "tile_delta_peak_mb": round(meas.delta_peak_mb, 1),
            "seconds": round(meas.seconds, 3)}


def merge_tiles(params: MergeTilesParams, ctx, *, in_tiles_json: Path, in_tile_mesh_ply: list, in_points_ply: Path,
                out_clean_mesh_ply: Path, out_tile_seams_json: Path, in_seam_votes_npz: list | None = None) -> dict:
    """Stitch the tile meshes into one crack-free mesh (clean_mesh.ply, read by simplify and bake_texture)."""
    from twinkit.surface.measure import Measure
    from twinkit.surface.watertight import ground_border_report

    from .edges import seam_planes
    from .merge import (fill_ground, log_merge, merge_metrics, merge_report, near_lines_report, open_seams,
                        read_tile_meshes, seams_before, tile_trim, trim_bands)
    from .seam_map import seam_map_png
    from .seam_stats import faces_outside_core, open_seam_runs, seam_boundary_edges
    from .stitch import close_seam_holes, merge_grid

    params = params or MergeTilesParams()
    tiles = json.loads(Path(in_tiles_json).read_text())["items"]
    paths = in_tile_mesh_ply if isinstance(in_tile_mesh_ply, list) else [in_tile_mesh_ply]
    if len(paths) != len(tiles):
        raise _input_error(f"{Path(in_tiles_json).name}: {len(tiles)} tiles but {len(paths)} tile meshes; "
                           f"re-run the tile steps")
    threads = max(1, int(getattr(ctx, "threads", 1) or 1))
    with Measure() as meas:
        keep, tiles_k, meshes_k = read_tile_meshes(paths, tiles)
        planes = seam_planes(tiles)
        before, seam_len, before_total = seams_before(meshes_k, planes, params.seam_tol_m)
        merged, seams = merge_grid(tiles_k, meshes_k, params.max_gap_m, log=ctx.log)
        after_zipper = seam_boundary_edges(merged, planes, params.seam_tol_m, tile_faces_only=True)
        merged, holes = close_seam_holes(merged, planes, params.max_hole_edges, params.seam_tol_m)
        trim = tile_trim(meshes_k[0].comments)
        band_rep, cloud = None, None
        if trim.get("seam_band_m", 0) > 0:
            cloud = A.read_points(in_points_ply)
            merged, holes2, band_rep = trim_bands(merged, planes, trim, cloud, params, threads, in_seam_votes_npz,
                                                  ctx.log)
            holes += holes2
        tile_attr = merged.face_attrs["tile"]
        runs = open_seam_runs(merged, planes, reach_m=2 * params.max_gap_m, tol_m=params.seam_tol_m)
        cracks, kinds, ends, open_len = open_seams(runs)
        png = Path(out_tile_seams_json).with_suffix(".png")
        seam_map_png(merged, planes, runs, png,
                     title=f"{len(keep)} tiles: {cracks} open seam edges of {before} "
                           f"({kinds['facing_surface']} facing surface, red; {kinds['surface_ends']} surface ends, orange)")
        # doubled surface: tile faces outside their own core (0 by construction of the cut)
        outside = faces_outside_core(merged, tiles_k)
        merged.face_attrs = {}
        ground = None
        if params.fill_ground_cell_m > 0:
            cloud = A.read_points(in_points_ply) if cloud is None else cloud
            merged, ground = fill_ground(merged, cloud, params, threads, ctx.log)
        cloud = A.read_points(in_points_ply) if cloud is None else cloud
        # the merged mesh's open border at ground level, inside the site and on its edge (picture beside)
        ground_border = ground_border_report(merged.vertices, merged.faces, cloud.vertices, cloud.normals,
                                             params.fill_ground_max_gap_m,
                                             Path(out_tile_seams_json).with_name("open_border.png"), ctx.log)
        del cloud
        near_lines = near_lines_report(merged, planes, params.line_band_m)
        merged.comments = [f"twinkit-tiles merge of {len(keep)} tiles"]
        A.write_clean_mesh(out_clean_mesh_ply, merged)
        report = merge_report(tiles, keep, planes, merged, tile_attr, seams, before_total, before=before,
                              after_zipper=after_zipper, holes=holes, cracks=cracks, kinds=kinds, ends=ends,
                              seam_len=seam_len, open_len=open_len, runs=runs, png=png, outside=outside,
                              ground=ground, ground_border=ground_border, band_rep=band_rep, near_lines=near_lines)
        Path(out_tile_seams_json).write_text(json.dumps(report, indent=2))
    log_merge(ctx.log, len(keep), report, seam_len, near_lines, params.line_band_m, png.name)
    return merge_metrics(report, near_lines, ground_border, meas.as_dict())


def evaluate_seam_labels(params: EvaluateSeamLabelsParams, ctx, *, in_tiles_json: Path, in_textured_mesh_ply: Path,
                         in_labels_npy: Path, in_gt_labels_npy: Path | None = None,
                         out_seam_labels_json: Path) -> dict:
    """Do the semantic labels change where the tiles meet? Label changes along mesh edges crossing the
    seam planes vs. crossing control planes through the tiles' interiors (and, with ground truth, the
    changes the ground truth does not have; accuracy near the seams vs. elsewhere) -> seam_labels.json."""
    from .seam_labels import seam_label_stats
    from .edges import seam_planes

    params = params or EvaluateSeamLabelsParams()
    planes = seam_planes(json.loads(Path(in_tiles_json).read_text())["items"])
    if params.planes:
        planes = []
        for text in params.planes:
            axis, _, val = str(text).replace(" ", "").partition("=")
            try:
                planes.append(("xy".index(axis), float(val)))
            except ValueError:
                raise _input_error(f"evaluate_seam_labels.planes: {text!r} is not like 'x=-10' or 'y=12.5'") from None
    mesh = A.read_textured_mesh(in_textured_mesh_ply)
    labels = A.read_labels(in_labels_npy)
    gt = A.read_labels(in_gt_labels_npy) if in_gt_labels_npy is not None else None
    for name, arr in (("labels", labels), ("ground truth", gt)):
        if arr is not None and len(arr) != mesh.n_vertices:
            raise _input_error(f"{Path(in_textured_mesh_ply).name} has {mesh.n_vertices} vertices but the {name} "
                               f"have {len(arr)}; re-run the segmentation steps on this mesh")
    rep = seam_label_stats(mesh.vertices, mesh.faces, labels, planes, gt, params.band_m)
    rep["seam_planes"] = len(planes)
    Path(out_seam_labels_json).write_text(json.dumps(rep, indent=1))
    if not planes:
        ctx.log.info("one tile: no seam to check")
    else:
        ctx.log.info("labels change on %.2f %% of the edges crossing a seam, %.2f %% at control planes%s",
                     rep["seam_change_pct"] or 0.0, rep["control_change_pct"] or 0.0,
                     "" if gt is None else f" (not in the ground truth: {rep['seam_changes_not_in_gt_pct']} % vs "
                                           f"{rep['control_changes_not_in_gt_pct']} %)")
    return {k: v for k, v in rep.items() if not isinstance(v, list)}


def dask_executor(params: DaskExecutorParams):
    """Run fanned-out items on a Dask distributed cluster (a local one on 127.0.0.1 by default)."""
    from .dask_executor import DaskExecutor

    return DaskExecutor(address=params.address, n_workers=params.n_workers,
                        threads_per_worker=params.threads_per_worker, memory_limit=params.memory_limit,
                        cluster=params.cluster,
                        slurm={"queue": params.slurm_queue, "cores": params.slurm_cores,
                               "memory": params.slurm_memory, "walltime": params.slurm_walltime,
                               "account": params.slurm_account})


@hookimpl
def twinkit_register_steps(register):
    register("plan_tiles", plan_tiles, params=PlanTilesParams)
    register("reconstruct_tile", reconstruct_tile, params=ReconstructTileParams)
    register("merge_tiles", merge_tiles, params=MergeTilesParams)
    register("evaluate_seam_labels", evaluate_seam_labels, params=EvaluateSeamLabelsParams)


@hookimpl
def twinkit_register_executors(register):
    register("dask", dask_executor, params=DaskExecutorParams)
