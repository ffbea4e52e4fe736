"""Time per stage of the photo branch: the demo site (the whole recipe) and Sceaux (sfm -> textured mesh).

    .venv/bin/python plugins/twinkit-photo/bench/bench_photo.py [--out /tmp/photo_bench] [--only demo|sceaux]

Demo: runs ``twinkit recipe=image_site site=demo`` into <out>/outputs (a fresh folder, so every step runs)
and reads each step's step.json. Sceaux (../shared/data/photos/sceaux_castle, skipped when absent): runs
the steps one by one through twinkit.testing.run_plugin (installed plugins by name; no georeference: the
model is levelled and kept at its own scale). Prints markdown tables. Heavy: several minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
REUSE_SFM = False  # --reuse-sfm: keep a previous Sceaux sfm result in --out
SCEAUX = REPO.parent / "shared" / "data" / "photos" / "sceaux_castle"


def _table(rows, cols):
    out = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        out.append("| " + " | ".join(str(r.get(c, "")) for c in cols) + " |")
    return "\n".join(out)


def bench_demo(out: Path) -> str:
    outputs = out / "outputs"
    cmd = [str(REPO / ".venv" / "bin" / "twinkit"), "recipe=image_site", "site=demo", f"engine.outputs_dir={outputs}"]
    t = time.perf_counter()
    rc = subprocess.call(cmd, cwd=REPO)
    wall = time.perf_counter() - t
    rows = []
    for sj in sorted((outputs / "demo").glob("[0-9][0-9]_*/step.json")):
        d = json.loads(sj.read_text())
        m = d.get("metrics") or {}
        keys = ("registered", "registered_ratio", "mean_reprojection_error_px", "camera_centre_error_mean_m",
                "camera_centre_error_shape_m", "points", "faces", "cloud_to_mesh_mean_m")
        note = ", ".join(f"{k}={m[k]:.4g}" if isinstance(m[k], float) else f"{k}={m[k]}" for k in keys if k in m)
        rows.append({"step": sj.parent.name, "status": d.get("status"), "seconds": round(d.get("duration_s", 0), 1),
                     "peak MB": round(d.get("peak_rss_mb") or 0), "result": note})
    ev = outputs / "demo"
    gt = ""
    for f in ev.glob("*_evaluate/recon_metrics.json"):
        r = json.loads(f.read_text())
        if "gt" in r:
            gt = (f"\nmesh -> ground truth: mean {r['gt']['accuracy_mesh_to_gt_m']['mean']:.4f} m, "
                  f"median {r['gt']['accuracy_mesh_to_gt_m'].get('median', float('nan')):.4f} m; "
                  f"ground truth covered within 5 cm: {100 * r['gt']['gt_covered_within_5cm']:.1f} %")
    return f"### demo site (exit code {rc}, wall {wall:.0f} s)\n\n" + _table(rows, ["step", "status", "seconds", "peak MB", "result"]) + gt


def bench_sceaux(out: Path) -> str:
    if not SCEAUX.exists():
        return "### Sceaux: skipped (../shared/data/photos/sceaux_castle not present)"
    from twinkit.testing import run_plugin
    import twinkit_photo.plugin as photo

    rows = []

    def step(kind, name, inputs, params=None, label=None, **overrides):
        """One plugin run through the registry (the point-cloud steps are the twinkit-pointcloud package's)."""
        t = time.perf_counter()
        res = run_plugin(kind, name, out / "sceaux" / (label or name), inputs, params, **overrides)
        rows.append({"step": label or name, "seconds": round(time.perf_counter() - t, 1)})
        return res

    prev = out / "sceaux" / "sfm" / "result"
    if REUSE_SFM and (prev / "sfm_report.json").exists():
        s = {"sfm": prev / "sfm", "sfm_report.json": prev / "sfm_report.json"}
        rows.append({"step": "sfm (reused)", "seconds": json.loads(s["sfm_report.json"].read_text())["timings_s"]["total"]})
    else:
        s = step("step", "sfm", {"in_photos_dir": SCEAUX}, photo.SfmParams())
    rep = json.loads(s["sfm_report.json"].read_text())
    rows[-1]["result"] = (f"{rep['registered']}/{rep['photos']} registered, reprojection "
                          f"{rep['mean_reprojection_error_px']:.3f} px, {rep['sparse_points']} points; "
                          f"features {rep['timings_s']['features']} s, matching {rep['timings_s']['matching']} s, "
                          f"mapping {rep['timings_s']['mapping']} s")
    g = step("step", "georeference", {"in_sfm_dir": s["sfm"]}, photo.GeorefParams(method="none"))
    r = step("step", "roi", {"in_cameras_site_json": g["cameras_site.json"],
                                    "in_sparse_site_ply": g["sparse_site.ply"]},
             photo.RoiParams(margin_m=1.0, above_ground_m=5.0, below_ground_m=5.0, max_depth_m=0.0,
                             ground_threshold_m=0.02))
    d = step("step", "dense", {"in_photos_dir": SCEAUX, "in_cameras_site_json": g["cameras_site.json"],
                                      "in_sparse_site_ply": g["sparse_site.ply"], "in_roi_json": r["roi.json"]},
             photo.DenseParams(voxel_m=0.0))
    meta = json.loads(d["points_meta.json"].read_text())
    rows[-1]["result"] = f"{meta['counts']['written']} points from {meta['dense']['depth_maps']} depth maps"
    p = step("reconstructor", "poisson", {"in_points_ply": d["points.ply"]}, depth=9)
    c = step("step", "clean_mesh", {"in_dense_mesh_ply": p["dense_mesh.ply"], "in_points_ply": d["points.ply"]},
             max_dist_m=0.0, density_quantile=0.05)
    m = step("step", "simplify", {"in_clean_mesh_ply": c["clean_mesh.ply"]}, target_faces=100000)
    step("step", "bake_texture", {"in_mesh_ply": m["mesh.ply"], "in_clean_mesh_ply": c["clean_mesh.ply"]},
         label="bake_texture", texture_px=2048)
    total = sum(r["seconds"] for r in rows)
    return f"### Sceaux castle (11 photos, 2832 x 2128; total {total:.0f} s)\n\n" + _table(rows, ["step", "seconds", "result"])


def bench_dense_true_poses(out: Path, site_dir: Path) -> str:
    """The dense stage alone: the demo photos with their true poses (cameras.json), dense -> Poisson ->
    clean, mesh compared with gt_mesh.ply. Isolates the CPU stereo from the structure from motion."""
    import numpy as np
    import open3d as o3d
    from twinkit.mesh import read_ply
    from twinkit.testing import run_plugin
    import twinkit_photo.plugin as photo
    from twinkit_photo.files import write_cloud

    cj = json.loads((site_dir / "cameras.json").read_text())
    intr = cj["intrinsics"]
    cams = [{"image": c["image"], "model": "PINHOLE", "width": intr["width"], "height": intr["height"],
             "params": [intr["fx"], intr["fy"], intr["cx"], intr["cy"]], "K": intr["K"],
             "R_world_from_camera": c["R_world_from_camera"], "center": c["center"]} for c in cj["cameras"]]
    work = out / "dense_true"
    work.mkdir(parents=True, exist_ok=True)
    (work / "cameras_site.json").write_text(json.dumps({"cameras": cams}))
    sparse = read_ply(site_dir / "cloud.ply").vertices[::300]  # stands in for SfM points (depth ranges only)
    write_cloud(work / "sparse_site.ply", sparse)
    np.savez_compressed(work / "sparse_site.npz", vis_image=np.array([], str), vis_point=np.array([], np.int64))
    rows = []

    def step(kind, name, inputs, params=None, **overrides):
        """One plugin run through the registry (the point-cloud steps are the twinkit-pointcloud package's)."""
        t = time.perf_counter()
        res = run_plugin(kind, name, work / name, inputs, params, **overrides)
        rows.append({"step": name, "seconds": round(time.perf_counter() - t, 1)})
        return res

    r = step("step", "roi", {"in_cameras_site_json": work / "cameras_site.json",
                                    "in_sparse_site_ply": work / "sparse_site.ply"}, photo.RoiParams())
    d = step("step", "dense", {"in_photos_dir": site_dir / "photos", "in_cameras_site_json": work / "cameras_site.json",
                                      "in_sparse_site_ply": work / "sparse_site.ply", "in_roi_json": r["roi.json"]},
             photo.DenseParams())
    p = step("reconstructor", "poisson", {"in_points_ply": d["points.ply"]}, depth=10)
    c = step("step", "clean_mesh", {"in_dense_mesh_ply": p["dense_mesh.ply"], "in_points_ply": d["points.ply"]},
             max_dist_m=0.08)
    gt = o3d.io.read_triangle_mesh(str(site_dir / "gt_mesh.ply"))
    sc = o3d.t.geometry.RaycastingScene()
    sc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(gt))
    P = read_ply(d["points.ply"]).vertices.astype(np.float32)
    mesh = o3d.io.read_triangle_mesh(str(c["clean_mesh.ply"]))
    V = np.asarray(mesh.vertices, np.float32)
    dp = sc.compute_distance(o3d.core.Tensor(P)).numpy()
    dm = sc.compute_distance(o3d.core.Tensor(V)).numpy()
    rows[1]["result"] = f"{len(P)} points; point -> truth mean {dp.mean():.4f} m, median {np.median(dp):.4f} m"
    rows[3]["result"] = f"{len(mesh.triangles)} faces; mesh -> truth mean {dm.mean():.4f} m, median {np.median(dm):.4f} m"
    return ("### dense stage with the true poses (demo photos, cameras.json)\n\n" +
            _table(rows, ["step", "seconds", "result"]))


def bench_lund(out: Path) -> str:
    """Structure from motion only on the walked Lund sequence (29 photos with GPS)."""
    folder = REPO.parent / "shared" / "data" / "photos" / "lund_street"
    if not folder.exists():
        return "### Lund: skipped (../shared/data/photos/lund_street not present)"
    from twinkit.testing import plugin_from_module, run_step
    import twinkit_photo.plugin as photo

    rows = []
    for label, params in (("auto (exhaustive, 4096 features)", photo.SfmParams()),
                          ("sequential+spatial, 2048 features", photo.SfmParams(matching="sequential+spatial",
                                                                                max_features=2048))):
        t = time.perf_counter()
        res = run_step(plugin_from_module(photo, "step", "sfm"), out / "lund" / label.split()[0], {"in_photos_dir": folder},
                       params)
        rep = json.loads(res["sfm_report.json"].read_text())
        rows.append({"setting": label, "seconds": round(time.perf_counter() - t, 1),
                     "registered": f"{rep['registered']}/{rep['photos']}",
                     "reprojection px": rep["mean_reprojection_error_px"],
                     "attempts": "; ".join(f"{a['init']}: {a['registered']}" for a in rep["attempts"])})
    return "### Lund street (29 photos, 1024 x 768, walked forward)\n\n" + _table(
        rows, ["setting", "seconds", "registered", "reprojection px", "attempts"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="/tmp/twinkit_photo_bench")
    ap.add_argument("--only", choices=["demo", "sceaux", "dense_true", "lund"])
    ap.add_argument("--site-dir", default="", help="a generated demo site folder (01_site) for dense_true; "
                    "default: the one the demo run made")
    ap.add_argument("--reuse-sfm", action="store_true", help="Sceaux: reuse the sfm result already in --out")
    a = ap.parse_args()
    global REUSE_SFM
    REUSE_SFM = a.reuse_sfm
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    parts = []
    if a.only in (None, "demo"):
        parts.append(bench_demo(out))
    if a.only in (None, "dense_true"):
        site_dir = Path(a.site_dir) if a.site_dir else out / "outputs" / "demo" / "01_site"
        parts.append(bench_dense_true_poses(out, site_dir))
    if a.only in (None, "sceaux"):
        parts.append(bench_sceaux(out))
    if a.only in (None, "lund"):
        parts.append(bench_lund(out))
    text = "\n\n".join(parts)
    print(text)
    (out / "results.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
