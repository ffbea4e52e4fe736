"""Benchmark of the point-cloud branch against the thesis's route (pymeshlab), side by side.

    .venv/bin/python plugins/twinkit-pointcloud/bench/bench_pointcloud.py [--cloud PATH | --demo small|default|large] [--depths 10 11 12]

For each depth, two fresh processes run the same settings:

- ours:    open3d screened Poisson -> clean_mesh (distance trim, components, non-manifold, holes)
           -> simplify (fast-simplification, borders kept) -> bake_texture -> evaluate
- meshlab: pymeshlab screened Poisson -> per-vertex distance + select + delete (the thesis's
           "bubbles") -> small components -> repair non-manifold edges -> close holes
           -> quadric edge collapse (planar quadric, weight 0.001, boundary preserved)

Distances (cloud -> mesh surface) of both routes are computed by the same code. Prints
Markdown tables (time and peak resident memory per step, counts, distances, ratios).
Clouds without colours get colours from height so that texture baking does real work.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve()
REPO = HERE.parents[3]
DEFAULT_CLOUD = REPO.parent / "shared" / "data" / "pointclouds" / "lille_street_small_normals.ply"


def _ctx(work: Path, threads: int):
    from twinkit.testing import make_context

    c = make_context(work / "ctx", site={"name": "bench"})
    c.threads = threads
    return c


def prep(cloud: Path, work: Path, threads: int) -> dict:
    import numpy as np

    from twinkit_pointcloud import plugin as P
    from twinkit.mesh import read_ply, write_ply
    from twinkit_pointcloud.metrics import colormap

    ctx = _ctx(work, threads)
    r = P.read_cloud(P.ReadCloudParams(), ctx, in_cloud=cloud, out_points_ply=work / "points.ply",
                     out_points_meta_json=work / "points_meta.json")
    m = read_ply(work / "points.ply")
    if m.colors is None:
        z = m.vertices[:, 2]
        m.attrs["colors"] = colormap(z - z.min(), float(np.ptp(z)) or 1.0)
        write_ply(work / "points.ply", m)
        r["colors"] = "synthesised from height"
    return {"read_cloud": r, "points": m.n_vertices}


def prep_demo(preset: str, work: Path, threads: int) -> dict:
    """Generate the demo site (``preset``; one photo, no shadows: the geometry and the cloud are those
    of the preset) into ``work/site`` and read its E57 cloud like the recipe does. The generator is the
    twinkit-demo-site package's, run through the registry (with the engine's default thread count)."""
    import shutil

    from twinkit.testing import run_plugin
    from twinkit_pointcloud import plugin as P
    from twinkit.mesh import read_ply
    from twinkit.surface.measure import Measure

    site = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
    out = work / "site"
    ctx = _ctx(work, threads)
    ctx.site = site
    with Measure() as m:
        res = run_plugin("site_generator", "demo_intersection", work / "site_run", site=site,
                         size=preset, photo_count=1, shadows=False)
    shutil.rmtree(out, ignore_errors=True)
    os.replace(res["site.json"].parent, out)
    shutil.rmtree(work / "site_run", ignore_errors=True)
    r = P.read_cloud(P.ReadCloudParams(), ctx, in_cloud=out / "cloud.e57", out_points_ply=work / "points.ply",
                     out_points_meta_json=work / "points_meta.json")
    for f in ("cloud.las", "cloud.ply"):  # only the E57 is read; keep the disk free
        (out / f).unlink(missing_ok=True)
    return {"read_cloud": r, "points": read_ply(work / "points.ply").n_vertices, "site_seconds": m.seconds,
            "gt_mesh": str(out / "gt_mesh.ply")}


def gt_eval(mesh_ply: Path, work: Path, threads: int, samples: int = 300_000) -> dict | None:
    """Mesh -> ground truth accuracy and per-class GT area coverage (demo sites only)."""
    from scipy.spatial import cKDTree

    from twinkit.mesh import read_ply
    from twinkit_pointcloud.metrics import (coverage_by_label, distance_near_exact, sample_surface,
                                            sample_surface_by_label, stats)
    from twinkit.surface.closest import Surface

    gt_ply = work / "site" / "gt_mesh.ply"
    if not gt_ply.exists():
        return None
    gt = read_ply(gt_ply)
    m = read_ply(mesh_ply)
    gsurf = Surface(gt.vertices, gt.faces, threads)
    acc = gsurf.distance(m.vertices)
    # area-weighted: a decimated mesh keeps many vertices where the surface is rough (vegetation), few on
    # flat ground, so its per-vertex mean is not comparable with the dense mesh's; samples are
    acc_area = gsurf.distance(sample_surface(m.vertices, m.faces, samples, seed=2))
    S, L, areas = sample_surface_by_label(gt.vertices, gt.faces, gt.face_attrs["label"], samples, 20_000, seed=1)
    dm = distance_near_exact(Surface(m.vertices, m.faces, threads), m.vertices, S, 0.5, threads)
    dc, _ = cKDTree(read_ply(work / "points.ply").vertices).query(S, workers=threads, distance_upper_bound=0.2)
    cov = coverage_by_label(dm, L, areas, dist_to_cloud=dc, observed_m=0.10)
    tot = sum(areas.values())
    return {"accuracy_m": stats(acc_area), "accuracy_per_vertex_m": stats(acc), "per_class": cov,
            "covered_all": sum(r["covered"] * r["area_m2"] for r in cov.values()) / tot}


def run_ours(work: Path, depth: int, a) -> dict:
    from twinkit_pointcloud import plugin as P

    ctx = _ctx(work, a.threads)
    d = work / f"ours_{depth}"
    d.mkdir(exist_ok=True)
    pts = work / "points.ply"
    res = {}
    res["poisson"] = P.poisson(P.PoissonParams(depth=depth, scale=a.scale, point_weight=a.point_weight), ctx,
                               in_points_ply=pts, out_dense_mesh_ply=d / "dense_mesh.ply")
    res["clean"] = P.clean_mesh(P.CleanParams(max_dist_m=a.max_dist_m, max_hole_edges=a.max_hole_edges,
                                              min_component_faces=a.min_component_faces,
                                              **({} if a.gap_dist_m is None else {"gap_dist_m": a.gap_dist_m})), ctx,
                                in_dense_mesh_ply=d / "dense_mesh.ply", in_points_ply=pts,
                                out_clean_mesh_ply=d / "clean_mesh.ply", out_clean_report_json=d / "clean_report.json")
    res["simplify"] = P.simplify(P.SimplifyParams(target_faces=a.target_faces), ctx,
                                 in_clean_mesh_ply=d / "clean_mesh.ply", out_mesh_ply=d / "mesh.ply")
    if not a.no_bake:
        res["bake"] = P.bake_texture(P.BakeParams(texture_px=a.texture_px), ctx, in_mesh_ply=d / "mesh.ply",
                                     in_clean_mesh_ply=d / "clean_mesh.ply",
                                     out_textured_mesh_obj=d / "textured_mesh.obj",
                                     out_textured_mesh_ply=d / "textured_mesh.ply")
        res["evaluate"] = P.evaluate(P.EvalParams(), ctx, in_textured_mesh_ply=d / "textured_mesh.ply",
                                     in_points_ply=pts, out_recon_metrics_json=d / "recon_metrics.json",
                                     in_gt_mesh_ply=(work / "site" / "gt_mesh.ply")
                                     if (work / "site" / "gt_mesh.ply").exists() else None)
    res["dist"] = distances(pts, d / "clean_mesh.ply", d / "mesh.ply", a.threads)
    _add_gt(res, work, d, a)
    return res


def _add_gt(res: dict, work: Path, d: Path, a) -> None:
    g = {k: gt_eval(d / f, work, a.threads) for k, f in (("dense", "clean_mesh.ply"), ("simplified", "mesh.ply"))}
    if g["dense"] is not None:
        res["gt"] = g


def run_meshlab(work: Path, depth: int, a) -> dict:
    import numpy as np
    import pymeshlab

    from twinkit.mesh import Mesh, read_ply, write_ply
    from twinkit.surface.measure import Measure

    d = work / f"meshlab_{depth}"
    d.mkdir(exist_ok=True)
    pts = read_ply(work / "points.ply")
    res = {}
    ms = pymeshlab.MeshSet()
    with Measure() as m:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=pts.vertices, v_normals_matrix=pts.normals.astype(np.float64)), "cloud")
        ms.generate_surface_reconstruction_screened_poisson(depth=depth, scale=a.scale, pointweight=a.point_weight,
                                                            samplespernode=1.5, threads=a.threads, preclean=False)
    mesh_id = ms.current_mesh_id()
    res["poisson"] = {**m.as_dict(), "vertices": ms.current_mesh().vertex_number(), "faces": ms.current_mesh().face_number()}
    with Measure() as m:
        ms.compute_scalar_by_distance_from_another_mesh_per_vertex(measuremesh=mesh_id, refmesh=0, signeddist=False,
                                                                   maxdist=pymeshlab.PureValue(1e6))
        ms.compute_selection_by_condition_per_vertex(condselect=f"q > {a.max_dist_m}")
        ms.meshing_remove_selected_vertices()
        ms.meshing_remove_connected_component_by_face_number(mincomponentsize=a.min_component_faces)
        ms.meshing_repair_non_manifold_edges()
        ms.meshing_close_holes(maxholesize=a.max_hole_edges, selfintersection=False)
        ms.meshing_remove_unreferenced_vertices()
    cm = ms.current_mesh()
    res["clean"] = {**m.as_dict(), "vertices": cm.vertex_number(), "faces": cm.face_number()}
    write_ply(d / "clean_mesh.ply", Mesh(cm.vertex_matrix().copy(), cm.face_matrix().astype(np.int64)))
    with Measure() as m:
        ms.set_selection_none()
        ms.meshing_decimation_quadric_edge_collapse(targetfacenum=a.target_faces, preserveboundary=True,
                                                    planarquadric=True, planarweight=0.001, preservenormal=True,
                                                    autoclean=True)
    sm = ms.current_mesh()
    res["simplify"] = {**m.as_dict(), "vertices": sm.vertex_number(), "faces": sm.face_number()}
    write_ply(d / "mesh.ply", Mesh(sm.vertex_matrix().copy(), sm.face_matrix().astype(np.int64)))
    res["dist"] = distances(work / "points.ply", d / "clean_mesh.ply", d / "mesh.ply", a.threads)
    _add_gt(res, work, d, a)
    return res


def distances(points_ply: Path, dense_ply: Path, simple_ply: Path, threads: int) -> dict:
    from twinkit.mesh import read_ply
    from twinkit.surface.metrics import cloud_to_mesh
    from twinkit_pointcloud.metrics import stats

    p = read_ply(points_ply).vertices
    out = {}
    for name, f in (("dense", dense_ply), ("simplified", simple_ply)):
        m = read_ply(f)
        out[name] = stats(cloud_to_mesh(p, m.vertices, m.faces, threads))
    return out


def uv_compare(work: Path, depth: int, a) -> dict:
    from twinkit.mesh import read_ply
    from twinkit.surface.measure import Measure
    from twinkit_pointcloud.uv import chart_uv, xatlas_uv

    from twinkit.surface.simplify import simplify_quadric

    m = simplify_quadric(read_ply(work / f"ours_{depth}" / "clean_mesh.ply"), a.uv_faces)
    out = {"faces": m.n_faces}
    with Measure() as t:
        _, info = chart_uv(m.vertices, m.faces, a.texture_px)
    out["charts"] = {**t.as_dict(), "charts": info["charts"]}
    try:
        import xatlas  # noqa: F401

        with Measure() as t:
            xatlas_uv(m.vertices, m.faces, a.texture_px)
        out["xatlas"] = t.as_dict()
    except ImportError:
        out["xatlas"] = None
    return out


def _sub(args: list[str], a) -> dict:
    cmd = [sys.executable, str(HERE)] + args + _common(a)
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.stderr.write(p.stderr[-4000:])
        return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}"}
    return json.loads(p.stdout.strip().splitlines()[-1])


def _common(a) -> list[str]:
    return ["--work", str(a.work), "--threads", str(a.threads), "--target-faces", str(a.target_faces),
            "--texture-px", str(a.texture_px), "--max-dist-m", str(a.max_dist_m), "--scale", str(a.scale),
            "--point-weight", str(a.point_weight), "--max-hole-edges", str(a.max_hole_edges),
            "--min-component-faces", str(a.min_component_faces), "--uv-faces", str(a.uv_faces)] + (
        ["--no-bake"] if a.no_bake else []) + ([] if a.gap_dist_m is None else ["--gap-dist-m", str(a.gap_dist_m)])


def _f(x, nd=2):
    return "-" if x is None else f"{x:.{nd}f}"


def _mm(x):
    return "-" if x is None else f"{x * 1000:.2f}"


def report(cloud: Path, prep_res: dict, results: dict, uvres: dict | None, a) -> str:
    L = []
    L.append(f"Cloud: `{cloud.name}`, {prep_res['points']:,} points; threads {a.threads}; target {a.target_faces:,} faces; "
             f"max_dist_m {a.max_dist_m}; scale {a.scale}; point weight {a.point_weight}; holes <= {a.max_hole_edges} edges; "
             f"texture {a.texture_px} px. read_cloud: {_f(prep_res['read_cloud']['seconds'])} s, "
             f"peak {prep_res['read_cloud']['peak_rss_mb']:.0f} MiB.")
    L.append("")
    L.append("| depth | route | step | time s | peak RSS MiB | vertices | faces |")
    L.append("|---|---|---|---:|---:|---:|---:|")
    for depth, rr in results.items():
        for route in ("ours", "meshlab"):
            r = rr.get(route, {})
            if "error" in r:
                L.append(f"| {depth} | {route} | error | {r['error']} | | | |")
                continue
            for step in ("poisson", "clean", "simplify", "bake", "evaluate"):
                s = r.get(step)
                if not s:
                    continue
                L.append(f"| {depth} | {route} | {step} | {_f(s['seconds'])} | {s['peak_rss_mb']:.0f} | "
                         f"{s.get('vertices', 0):,} | {s.get('faces', 0):,} |")
    L.append("")
    L.append("Whole branch, ours (read_cloud + poisson + clean + simplify + bake + evaluate):")
    L.append("")
    L.append("| depth | seconds | minutes | peak RSS MiB |")
    L.append("|---|---:|---:|---:|")
    for depth, rr in results.items():
        r = rr.get("ours", {})
        steps = [r.get(k) for k in ("poisson", "clean", "simplify", "bake", "evaluate")]
        if any(x is None for x in steps):
            continue
        tot = prep_res["read_cloud"]["seconds"] + sum(x["seconds"] for x in steps)
        peak = max([prep_res["read_cloud"]["peak_rss_mb"]] + [x["peak_rss_mb"] for x in steps])
        L.append(f"| {depth} | {tot:.0f} | {tot / 60:.1f} | {peak:.0f} |")
    if any("gt" in rr.get(route, {}) for rr in results.values() for route in ("ours", "meshlab")):
        L.append("")
        L.append("Against the ground-truth mesh: accuracy = mesh surface (area-weighted samples) -> GT surface, mm; coverage = share of the "
                 "GT area of a class with reconstructed surface within 5 cm, % (all of it / the part the scan saw, "
                 "i.e. with an input point within 10 cm):")
        L.append("")
        cls = ("road", "sidewalk", "terrain", "pole", "traffic sign", "traffic light", "building", "car")
        L.append("| depth | route | mesh | acc mean | acc median | acc p95 | GT covered all | "
                 + " | ".join(cls) + " |")
        L.append("|---|---|---|" + "---:|" * (4 + len(cls)))
        for depth, rr in results.items():
            for route in ("ours", "meshlab"):
                g = rr.get(route, {}).get("gt")
                if not g:
                    continue
                for mesh in ("dense", "simplified"):
                    x = g[mesh]
                    pc = x["per_class"]

                    def cv(c):
                        if c not in pc:
                            return "-"
                        co = pc[c]["covered_observed"]
                        return f"{pc[c]['covered'] * 100:.1f} / {'-' if co is None else f'{co * 100:.1f}'}"
                    L.append(f"| {depth} | {route} | {mesh} | {_mm(x['accuracy_m']['mean'])} | "
                             f"{_mm(x['accuracy_m']['median'])} | {_mm(x['accuracy_m']['p95'])} | "
                             f"{x['covered_all'] * 100:.1f} | " + " | ".join(cv(c) for c in cls) + " |")
    L.append("")
    L.append("Cloud -> mesh surface distance, mm (same code for both routes):")
    L.append("")
    L.append("| depth | route | dense mean | dense median | dense p95 | dense max | simplified mean | simplified median | simplified p95 | simplified max |")
    L.append("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for depth, rr in results.items():
        for route in ("ours", "meshlab"):
            r = rr.get(route, {})
            if "dist" not in r:
                continue
            dd, ss = r["dist"]["dense"], r["dist"]["simplified"]
            L.append(f"| {depth} | {route} | {_mm(dd['mean'])} | {_mm(dd.get('median'))} | {_mm(dd['p95'])} | {_mm(dd['max'])} | "
                     f"{_mm(ss['mean'])} | {_mm(ss.get('median'))} | {_mm(ss['p95'])} | {_mm(ss['max'])} |")
    L.append("")
    L.append("Ratios ours / meshlab (time: < 1 = ours faster; distance: < 1 = ours closer to the cloud):")
    L.append("")
    has_gt = any("gt" in rr.get("ours", {}) and "gt" in rr.get("meshlab", {}) for rr in results.values())
    L.append("| depth | poisson time | clean time | simplify time | poisson+clean+simplify time | dense mean dist | simplified mean dist |"
             + (" dense GT accuracy | simplified GT accuracy | GT covered (ours/meshlab) |" if has_gt else ""))
    L.append("|---|---:|---:|---:|---:|---:|---:|" + ("---:|---:|---:|" if has_gt else ""))
    for depth, rr in results.items():
        o, m = rr.get("ours", {}), rr.get("meshlab", {})
        if "dist" not in o or "dist" not in m:
            continue

        def ratio(step):
            return o[step]["seconds"] / max(m[step]["seconds"], 1e-9)

        tot = sum(o[s]["seconds"] for s in ("poisson", "clean", "simplify")) / max(
            sum(m[s]["seconds"] for s in ("poisson", "clean", "simplify")), 1e-9)
        gr = ""
        if "gt" in o and "gt" in m:
            gr = (f" {o['gt']['dense']['accuracy_m']['mean'] / m['gt']['dense']['accuracy_m']['mean']:.2f} |"
                  f" {o['gt']['simplified']['accuracy_m']['mean'] / m['gt']['simplified']['accuracy_m']['mean']:.2f} |"
                  f" {o['gt']['dense']['covered_all'] / m['gt']['dense']['covered_all']:.2f} |")
        L.append(f"| {depth} | {ratio('poisson'):.2f} | {ratio('clean'):.2f} | {ratio('simplify'):.2f} | {tot:.2f} | "
                 f"{o['dist']['dense']['mean'] / m['dist']['dense']['mean']:.2f} | "
                 f"{o['dist']['simplified']['mean'] / m['dist']['simplified']['mean']:.2f} |" + gr)
    if uvres:
        L.append("")
        L.append(f"UV unwrap of the simplified mesh ({uvres['faces']:,} faces):")
        L.append("")
        L.append("| method | time s | peak RSS MiB | charts |")
        L.append("|---|---:|---:|---:|")
        L.append(f"| charts (built in) | {_f(uvres['charts']['seconds'])} | {uvres['charts']['peak_rss_mb']:.0f} | {uvres['charts']['charts']:,} |")
        if uvres.get("xatlas"):
            L.append(f"| xatlas | {_f(uvres['xatlas']['seconds'])} | {uvres['xatlas']['peak_rss_mb']:.0f} | - |")
    return "\n".join(L)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cloud", type=Path, default=DEFAULT_CLOUD)
    ap.add_argument("--demo", choices=["small", "default", "large"], default=None,
                    help="benchmark a generated demo site of this preset (with ground truth) instead of --cloud")
    ap.add_argument("--gap-dist-m", type=float, default=None, help="clean_mesh gap_dist_m (default: the step's)")
    ap.add_argument("--meshlab-depths", type=int, nargs="*", default=None,
                    help="depths at which the pymeshlab route also runs (default: all of --depths)")
    ap.add_argument("--depths", type=int, nargs="+", default=[10, 11, 12])
    ap.add_argument("--target-faces", type=int, default=200_000)
    ap.add_argument("--texture-px", type=int, default=4096)
    ap.add_argument("--max-dist-m", type=float, default=0.10)
    ap.add_argument("--scale", type=float, default=1.1)
    ap.add_argument("--point-weight", type=float, default=4.0)
    ap.add_argument("--max-hole-edges", type=int, default=30)
    ap.add_argument("--min-component-faces", type=int, default=200)
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--no-meshlab", action="store_true")
    ap.add_argument("--no-bake", action="store_true")
    ap.add_argument("--uv-depth", type=int, default=10, help="depth whose simplified mesh is used for the UV comparison (0: skip)")
    ap.add_argument("--uv-faces", type=int, default=50_000, help="faces of the mesh used for the UV comparison")
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--report-only", type=Path, default=None, help="print the tables of a saved bench_results.json")
    ap.add_argument("--one", nargs=2, metavar=("ROUTE", "DEPTH"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        route, depth = a.one
        if route == "prep":
            res = prep_demo(a.demo, a.work, a.threads) if a.demo else prep(a.cloud, a.work, a.threads)
        elif route == "ours":
            res = run_ours(a.work, int(depth), a)
        elif route == "meshlab":
            res = run_meshlab(a.work, int(depth), a)
        elif route == "uv":
            res = uv_compare(a.work, int(depth), a)
        print(json.dumps(res, default=str))
        return
    if a.report_only:
        saved = json.loads(a.report_only.read_text())
        res = {int(k): v for k, v in saved["results"].items()}
        print(report(a.cloud, saved["prep"], res, saved.get("uv"), a))
        return
    if a.demo:
        a.cloud = Path(f"demo site '{a.demo}' (cloud.e57)")
    elif not a.cloud.exists():
        sys.exit(f"{a.cloud}: not found (the shared sample data is in ../shared/data/pointclouds)")
    tmp = None
    if a.work is None:
        tmp = tempfile.TemporaryDirectory(prefix="twinkit-bench-")
        a.work = Path(tmp.name)
    a.work.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    prep_res = _sub(["--one", "prep", "0", "--cloud", str(a.cloud)] + (["--demo", a.demo] if a.demo else []), a)
    if "error" in prep_res:
        sys.exit(f"prep failed: {prep_res['error']}")
    results: dict = {}
    for depth in a.depths:
        results[depth] = {"ours": _sub(["--one", "ours", str(depth)], a)}
        if not a.no_meshlab and (a.meshlab_depths is None or depth in a.meshlab_depths):
            results[depth]["meshlab"] = _sub(["--one", "meshlab", str(depth)], a)
        print(f"depth {depth} done ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
        # partial results survive an interrupted run
        (a.work / "bench_results.json").write_text(json.dumps({"prep": prep_res, "results": results}, indent=1, default=str))
        (a.work / "bench_partial.md").write_text(report(a.cloud, prep_res, results, None, a))
    uvres = None
    if a.uv_depth in a.depths and "error" not in results[a.uv_depth]["ours"]:
        uvres = _sub(["--one", "uv", str(a.uv_depth)], a)
        if "error" in uvres:
            uvres = None
    print(report(a.cloud, prep_res, results, uvres, a))
    (a.work / "bench_results.json").write_text(json.dumps({"prep": prep_res, "results": results, "uv": uvres},
                                                          indent=1, default=str))
    print(f"\nTotal {time.time() - t0:.0f} s.", file=sys.stderr)


if __name__ == "__main__":
    main()
