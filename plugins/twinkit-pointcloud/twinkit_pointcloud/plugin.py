"""twinkit steps of the point-cloud branch (entry point ``pointcloud`` in group ``twinkit``).

Heavy libraries are imported inside the step functions only.
"""
from pathlib import Path
from typing import Any

from twinkit import hookimpl
from twinkit import artefacts as A
from twinkit.jsonio import write_json

from .params import BakeParams, CleanParams, EvalParams, PoissonParams, ReadCloudParams, SimplifyParams
from .report import twinkit_register_report_sections  # noqa: F401 (this plugin's sections of the run report)


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
    from twinkit import InputError
    from twinkit.mesh import Mesh
    from twinkit.surface import density
    from twinkit.surface.measure import Measure

    from .cloudfile import cloud_meta, ply_comments, point_attrs, read_metrics
    from .localframe import apply_cloud_frame
    from .normals import cloud_normals
    from .readers import drop_platform, read_any, validate_and_frame
    from .street import flat_capture, not_a_street

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
        dens = density.measure(cloud.points, scanner_positions=cloud.raw.scanner_positions)
        if params.drop_platform:
            cloud, dens = drop_platform(cloud, dens, ctx.log)
        raw = cloud.raw
        if not params.use_colors and raw.colors is not None:
            ctx.log.info("%s: colours dropped (use_colors=false)", in_cloud.name)
            raw.colors = None
        pts = cloud.points
        size = pts.max(axis=0) - pts.min(axis=0)
        refusal = flat_capture(in_cloud.name, size, pts) or not_a_street(in_cloud.name, size,
                                                                          params.min_street_extent_m)
        if refusal:
            raise InputError(refusal)
        normals, n_source, orientation, n_check = cloud_normals(pts, raw, params, in_cloud.name, ctx.log)
        if raw.colors is None:
            ctx.log.warning("%s: the cloud has no colours; the texture will show %s (bake_texture colourless)",
                            in_cloud.name, "its intensity" if raw.intensity is not None else "a shaded grey")
        ctx.log.info("%s: %s", in_cloud.name, density.describe(dens))
        meta = cloud_meta(in_cloud, raw, cloud, n_read, pts, (n_source, orientation, n_check), cloud_frame, dens)
        for note in cloud.frame.notes:
            ctx.log.info("%s: %s", in_cloud.name, note)
        A.write_points(out_points_ply, Mesh(vertices=pts, attrs=point_attrs(raw, normals),
                                            comments=ply_comments(in_cloud, cloud.frame.shift)))
        meta["time"] = {"seconds": round(meas_now(meas), 3)}
        A.write_points_meta(out_points_meta_json, meta)
    return read_metrics(pts, raw, cloud, n_source, n_check, cloud_frame, dens, meas.as_dict())


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
        with ctx.substep("read"):
            cloud = A.read_points(in_points_ply)
            pts = cloud.vertices
        if len(pts) < 10:
            raise InputError(f"{Path(in_points_ply).name}: too few points ({len(pts)}) for a surface")
        with ctx.substep("normals"):
            normals = cloud.normals
            if normals is None or not np.isfinite(normals).all() or (np.linalg.norm(normals, axis=1) < 0.5).mean() > 0.5:
                ctx.log.info("points have no usable normals: estimating them")
                normals = estimate_normals(pts, k=params.normals_k)
                normals, _ = orient_normals(pts, normals, params.normals_orientation)
        with ctx.substep("depth"):
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
        with ctx.substep("poisson"):
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
        with ctx.substep("write"):
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
        with ctx.substep("read"):
            dense = _read_mesh_input(in_dense_mesh_ply, "dense mesh")
            cloud = A.read_points(in_points_ply)
            auto = _clean_auto(params, cloud, ctx.log)
        with ctx.substep("clean"):
            opt = CleanOptions(max_dist_m=auto["max_dist_m"], gap_dist_m=params.gap_dist_m, gap_plane_m=params.gap_plane_m,
                               density_quantile=params.density_quantile,
                               min_component_faces=params.min_component_faces,
                               min_component_ratio=params.min_component_ratio,
                               min_component_points=params.min_component_points,
                               local_trim_factor=params.local_trim_factor, local_trim_max_m=params.local_trim_max_m,
                               repair_non_manifold=params.repair_non_manifold, max_hole_edges=params.max_hole_edges,
                               fill_ground_cell_m=auto["fill_ground_cell_m"], fill_ground_max_gap_m=params.fill_ground_max_gap_m,
                               fill_ground_stitch=params.fill_ground_stitch,
                               fill_ground_smooth_cells=auto["fill_ground_smooth_cells"],
                               fill_ground_sliver_max_m=params.fill_ground_sliver_max_m,
                               fill_ground_diagonal_gap_m=params.fill_ground_diagonal_gap_m, threads=_threads(ctx))
            mesh, rep = _clean(dense, cloud.vertices, opt, log=ctx.log, normals=cloud.normals, colors=cloud.colors)
        with ctx.substep("write"):
            mesh.comments = ["twinkit-pointcloud clean_mesh; dist_to_cloud_m = distance to the nearest input point"]
            A.write_clean_mesh(out_clean_mesh_ply, mesh)
        with ctx.substep("maps"):
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
        # a trim that removed most faces already says why the fill took their place: one cause, one reason
        trimmed = removed is not None and removed > params.max_trim_share
        fill = _mostly_fill(rep, mesh, auto, 1.0 if trimmed else params.max_fill_share, ctx)
        rep["time"] = {"seconds": round(meas_now(meas), 3)}
        write_json(out_clean_report_json, rep)
    out = {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "max_dist_m": opt.max_dist_m,
           "fill_ground_cell_m": opt.fill_ground_cell_m, "capture": auto.get("capture"),
           "trim_removed_share": removed, "fill_share": fill,
           "dist_mean_m": rep["output"]["dist_to_cloud_m"]["mean"], **meas.as_dict()}
    if border is not None:
        out["open_border_inside_m"] = border["inside_m"]
        out["open_border_inside_m_per_m2"] = border["inside_m_per_m2"]
    return out


def _clean_auto(params: CleanParams, cloud, log) -> dict:
    """The clean step's automatic settings (-1) from the cloud's measured spacing (twinkit.surface.density)."""
    from twinkit.surface import density

    out: dict = {"max_dist_m": params.max_dist_m, "fill_ground_cell_m": params.fill_ground_cell_m,
                 "fill_ground_smooth_cells": params.fill_ground_smooth_cells}
    if params.max_dist_m >= 0 and params.fill_ground_cell_m >= 0 and params.fill_ground_smooth_cells >= 0:
        return out
    m = density.measure(cloud.vertices)
    out.update(spacing_m=m["spacing_m"], spacing_p90_m=m["spacing_p90_m"], capture=m["capture"],
               ground_two_way_share=m["ground_two_way_share"])
    if params.fill_ground_smooth_cells < 0:
        rings = m["ground_two_way_share"] is not None and m["ground_two_way_share"] < density.RING_CAPTURE_SHARE
        out["fill_ground_smooth_cells"] = 5 if rings else 0
    if params.max_dist_m < 0:
        out["max_dist_m"] = density.trim_distance(m)
    if params.fill_ground_cell_m < 0:
        s = m["spacing_m"]
        out["fill_ground_cell_m"] = round(max(0.10, s if s == s else 0.10), 3)
    log.info("clean: %s; trim distance %.3g m, ground-fill cell %.3g m%s (auto)", density.describe(m),
             out["max_dist_m"], out["fill_ground_cell_m"],
             f", the shadows' heights smoothed over {out['fill_ground_smooth_cells']} cells (ground in rings)"
             if out["fill_ground_smooth_cells"] else "")
    return out


def _removed_most(rep: dict, max_share: float, ctx) -> float | None:
    """The share of the faces the distance trim removed; more than ``max_share``: degraded, with the numbers."""
    trim = rep.get("distance_trim")
    n_in = rep["input"]["faces"]
    if not trim or not n_in:
        return None
    share = 1.0 - trim["faces"] / n_in
    fill = (rep.get("ground_fill") or {}).get("faces_added")
    ctx.gate("faces removed by the trim", 100 * share, 100 * max_share, "<=", "%",
             why="a trim that removes most of the mesh was set below the cloud's spacing",
             reason=f"the distance trim ({trim['max_dist_m']:.3g} m) removed {100 * share:.1f} % of the "
                    f"{n_in:,} faces ({trim['faces']:,} left)" + (f"; the ground fill added {fill:,}" if fill else ""),
             hint="the trim distance is probably below the cloud's point spacing: leave "
                  "steps.clean_mesh.max_dist_m at -1 (auto) or set it to 2-3 x the spacing (clean_report.json)")
    return round(share, 4)


def _mostly_fill(rep: dict, mesh, auto: dict, max_share: float, ctx) -> float | None:
    """The ground fill's share of the clean mesh's area (written to ``rep["ground_fill"]["area_share"]``); more
    than ``max_share`` (1 = never): degraded, with the figures (the twin is mostly invented ground: a sparse
    capture)."""
    from twinkit.mesh import face_areas

    gf = rep.get("ground_fill")
    if not gf or not gf.get("area_m2") or not mesh.n_faces:
        return None
    total = float(face_areas(mesh.vertices, mesh.faces).sum())
    share = round(min(1.0, gf["area_m2"] / total), 4) if total > 0 else 1.0
    gf["area_share"] = share
    ctx.log.info("ground fill: %.1f %% of the mesh's %.0f m^2", 100 * share, total)
    spacing = auto.get("spacing_m")
    ctx.gate("ground fill share", 100 * share, 100 * max_share, "<=", "%",
             why="a mesh mostly made of fill is invented ground: a capture too sparse for a street twin",
             reason=f"the ground fill makes {100 * share:.0f} % of the mesh's surface ({gf['area_m2']:,.0f} of "
                    f"{total:,.0f} m^2, more than {100 * max_share:.0f} %): the capture is too sparse for a street "
                    "twin" + (f" (median point spacing {spacing:.2g} m)" if spacing == spacing and spacing else ""),
             hint="scan the street more densely (several sweeps or a mobile scan); what the twin shows beyond "
                  "the scanned points is invented ground (clean_report.json ground_fill, docs/pointcloud.md "
                  '"Sparse and partial captures")')
    return share


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

    from twinkit.surface.closest import Surface
    from twinkit.surface.measure import Measure
    from twinkit.surface.simplify import resample_attributes
    from twinkit.surface.texture import write_png

    from .texture import bake_colors
    from .uv import chart_uv, xatlas_uv

    params = params or BakeParams()
    size = int(params.texture_px)
    if size != -1 and (size < 256 or size > 16384 or size & (size - 1)):
        raise InputError(f"bake_texture: texture_px={size} must be a power of two from 256 to 16384 "
                         f"(4096, 8192 or 16384 for a site)")
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
        with ctx.substep("uv"):
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
        threads = _threads(ctx)
        with ctx.substep("bake"):
            surf = Surface(dense.vertices, dense.faces, threads) if colors is not None else None
            img, binfo = bake_colors(mesh.vertices, mesh.faces, uv, size, dense.vertices, dense.faces, colors,
                                     threads=threads, surface=surf,
                                     progress=lambda it: ctx.progress(it, desc="bake texture"))
        with ctx.substep("write"):
            write_png(png, img, threads=threads)
            if colors is not None:
                dense.attrs["colors"] = colors
                mesh = resample_attributes(mesh, dense, threads, surface=surf)
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
            **binfo, **meas.as_dict()}


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

    from .metrics import (coverage_by_label, distance_near_exact, far_from_mesh, sample_surface,
                          sample_surface_by_label, stats, topdown_map, vertex_tree)

    params = params or EvalParams()
    with Measure() as meas, _Outputs(out_recon_metrics_json):
        mesh = A.read_textured_mesh(in_textured_mesh_ply)
        cloud = A.read_points(in_points_ply)
        from scipy.spatial import cKDTree

        with ctx.substep("cloud_to_mesh"):
            c2m = cloud_to_mesh(cloud.vertices, mesh.vertices, mesh.faces, _threads(ctx))
            ctree = cKDTree(cloud.vertices)
            m2c, _ = ctree.query(mesh.vertices, workers=_threads(ctx))
        res: dict[str, Any] = {
            "counts": {"points": cloud.n_vertices, "vertices": mesh.n_vertices, "faces": mesh.n_faces},
            "cloud_to_mesh_m": stats(c2m),
            "mesh_to_cloud_m": stats(m2c),
            "cloud_within_m": {str(t): float((c2m <= t).mean()) for t in (0.01, 0.02, 0.05, 0.1)},
            "cloud_far": far_from_mesh(c2m, cloud.attrs.get("classification"), params.far_m),
        }
        far = res["cloud_far"]
        ctx.log.info("%.1f %% of the cloud's points are farther than %.2g m from the mesh%s", 100 * far["share"],
                     far["far_m"], "".join(f"; {k} {100 * v['share']:.1f} %"
                                           for k, v in (far.get("per_class") or {}).items()))
        ctx.gate(f"points farther than {far['far_m']:.2g} m", 100 * far["share"], 100 * params.far_max_share, "<=",
                 "%", why="points far from the mesh lose their labels",
                 reason=f"{100 * far['share']:.1f} % of the cloud's points are farther than {far['far_m']:.2g} m "
                        f"from the mesh (more than {100 * params.far_max_share:.0f} %): their labels are lost",
                 hint="the clean-up removed surface the points support: see clean_report.json; try "
                      "steps.clean_mesh.min_component_faces=0 or a larger steps.clean_mesh.max_dist_m "
                      '(docs/pointcloud.md "Coverage of sparse scans")')
        with ctx.substep("ground_truth"):
            if in_gt_mesh_ply is not None:
                gt = A.read_gt_mesh(in_gt_mesh_ply)
                gsurf = Surface(gt.vertices, gt.faces, _threads(ctx))
                acc = gsurf.distance(mesh.vertices)
                samples = sample_surface(gt.vertices, gt.faces, params.gt_samples)
                msurf = Surface(mesh.vertices, mesh.faces, _threads(ctx))
                vtree = vertex_tree(mesh.vertices)
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
            "far_share": res["cloud_far"]["share"],
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
