"""Measure the peak resident memory of one tile's reconstruction (open3d Poisson + clean-up) against
the number of points, the XY area and the voxel size; fits the coefficients of the memory model in
``twinkit_tiles/tiling.py``. Each case runs in a fresh process (peak = ru_maxrss of that process).

    .venv/bin/python plugins/twinkit-tiles/bench/calibrate_memory.py POINTS.ply --crops 20,40,60 --voxels 0.04,0.025
    .venv/bin/python plugins/twinkit-tiles/bench/calibrate_memory.py - --records outputs/demo/04_reconstruct_tiles/step.json
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time


def one(path: str, crop_m: float, voxel_m: float) -> dict:
    import resource

    import numpy as np
    from twinkit.mesh import read_ply
    from twinkit.surface.cleanup import CleanOptions, clean_mesh

    from twinkit_tiles.tiling import exact_voxel_poisson

    c = read_ply(path)
    xy = c.vertices[:, :2]
    ctr = (xy.min(0) + xy.max(0)) / 2
    sel = (np.abs(xy - ctr) <= crop_m / 2).all(axis=1)
    pts, nrm = c.vertices[sel], c.normals[sel]
    col = c.colors[sel] if c.colors is not None else None
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    mesh, depth, scale = exact_voxel_poisson(pts, nrm, col, voxel_m, threads=1)
    faces = mesh.n_faces
    clean, _ = clean_mesh(mesh, pts, CleanOptions(max_dist_m=0.1, threads=1))
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    ext = pts[:, :2].max(0) - pts[:, :2].min(0)
    return {"crop_m": crop_m, "voxel_m": voxel_m, "points": int(len(pts)), "area_m2": float(ext[0] * ext[1]),
            "depth": depth, "dense_faces": int(faces), "clean_faces": int(clean.n_faces),
            "seconds": round(dt, 2), "base_mb": round(base, 1), "peak_mb": round(peak, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("points")
    ap.add_argument("--crops", default="20,40,60")
    ap.add_argument("--voxels", default="0.04,0.025")
    ap.add_argument("--one", nargs=2, type=float, help=argparse.SUPPRESS)
    ap.add_argument("--json", default="")
    ap.add_argument("--records", nargs="*", default=[],
                    help="also fit on the per-tile records of reconstruct_tiles step.json files (points, dense faces, peak)")
    a = ap.parse_args()
    if a.one:
        print(json.dumps(one(a.points, a.one[0], a.one[1])))
        return
    rows = []
    for path in a.records:
        rec = json.loads(open(path).read())
        if "rows" in rec:  # an earlier --json output of this script
            rows.extend(rec["rows"])
            continue
        for it in rec["metrics"]["per_item"]:
            rows.append({"crop_m": None, "voxel_m": None, "points": it["points"], "area_m2": None,
                         "depth": it.get("depth"), "dense_faces": it["dense_faces"], "clean_faces": it.get("faces"),
                         "seconds": it.get("duration_s"), "base_mb": None, "peak_mb": it["peak_rss_mb"],
                         "source": path})
    for v in ([float(x) for x in a.voxels.split(",")] if a.points != "-" else []):
        for c in [float(x) for x in a.crops.split(",")]:
            out = subprocess.run([sys.executable, __file__, a.points, "--one", str(c), str(v)],
                                 capture_output=True, text=True)
            if out.returncode:
                print(out.stderr[-2000:], file=sys.stderr)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            rows.append(r)
            print(json.dumps(r), flush=True)
    import numpy as np

    A = np.array([[1.0, r["points"] / 1e6, r["dense_faces"] / 1e6] for r in rows])
    y = np.array([r["peak_mb"] for r in rows])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    fpm = [r["dense_faces"] / r["area_m2"] * (r["voxel_m"] / 0.01) ** 2 for r in rows if r["area_m2"]] or [0.0]
    fit = {"BASE_MB": round(float(coef[0]), 1), "MB_PER_MPOINT": round(float(coef[1]), 1),
           "MB_PER_MFACE": round(float(coef[2]), 1), "FACES_PER_M2_AT_1CM": round(float(np.median(fpm)), 1),
           "faces_per_point": [round(r["dense_faces"] / r["points"], 2) for r in rows]}
    print("| voxel m | crop m | points | depth | dense faces | s | peak MiB |\n|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        r["pred_mb"] = round(float(coef[0] + coef[1] * r["points"] / 1e6 + coef[2] * r["dense_faces"] / 1e6), 1)
    for r in rows:
        print(f"| {r['voxel_m']} | {r['crop_m']} | {r['points']:,} | {r['depth']} | {r['dense_faces']:,} | "
              f"{r['seconds']} | {r['peak_mb']:.0f} |  (fit {r['pred_mb']:.0f})")
    print("fit:", json.dumps(fit))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"rows": rows, "fit": fit}, fh, indent=2)


if __name__ == "__main__":
    main()
