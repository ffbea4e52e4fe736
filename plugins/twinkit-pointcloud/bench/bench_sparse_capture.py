"""Issue 46 item 5: how much of the clean mesh is ground fill, and how many points are far from it, on real
clouds and their sparse subsamples (docs/pointcloud.md "Sparse and partial captures").

    python plugins/twinkit-pointcloud/bench/bench_sparse_capture.py NAME CLOUD [N] [--out DIR]

CLOUD is a PLY (with or without normals) or a LAS/LAZ/E57 file; N > 0 keeps N points at random, N < 0 keeps
about -N points as one sweep would (a probability falling with the square of the range from the middle of
the cloud), 0 keeps all. Runs poisson and clean_mesh with their defaults and prints one JSON line: the
median spacing, the fill's share of the mesh's area, the shares of points farther than 0.1 / 0.5 m from the
clean mesh and what the step marked degraded.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def load(src: Path, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
    """The cloud centred on its mean, subsampled as ``n`` says (see the module doc); normals when the file has them."""
    from twinkit.mesh import read_ply
    from twinkit_pointcloud.readers import read_any

    if src.suffix.lower() == ".ply":
        m = read_ply(src)
        pts, nrm = m.vertices.astype(np.float64), m.attrs.get("normals")
    else:
        pts, nrm = np.asarray(read_any(src).xyz, np.float64), None
    pts = pts - pts.mean(axis=0)
    rng = np.random.default_rng(seed)
    if n < 0:
        p = 1.0 / (np.hypot(pts[:, 0], pts[:, 1]) + 1.0) ** 2
        for _ in range(5):
            p = np.minimum(1.0, p * -n / p.sum())
        keep = rng.random(len(pts)) < p
    elif 0 < n < len(pts):
        keep = np.zeros(len(pts), bool)
        keep[rng.choice(len(pts), n, replace=False)] = True
    else:
        keep = np.ones(len(pts), bool)
    return pts[keep], None if nrm is None else nrm[keep]


def main() -> None:
    from twinkit import artefacts as A
    from twinkit.mesh import Mesh, face_areas, read_ply
    from twinkit.surface import density
    from twinkit.surface.metrics import cloud_to_mesh
    from twinkit.testing import make_context
    from twinkit_pointcloud import plugin as P
    from twinkit_pointcloud.normals import estimate_normals, orient_normals

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("cloud", type=Path)
    ap.add_argument("n", type=int, nargs="?", default=0)
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_sparse_capture"))
    a = ap.parse_args()
    ctx = make_context(a.out / a.name, site={"name": a.name}, step_id="clean")
    w = ctx.workdir
    pts, nrm = load(a.cloud, a.n)
    if nrm is None:
        nrm, _ = orient_normals(pts, estimate_normals(pts), "auto")
    A.write_points(w / "points.ply", Mesh(vertices=pts.astype(np.float32), attrs={"normals": np.asarray(nrm, np.float32)}))
    P.poisson(P.PoissonParams(), ctx, in_points_ply=w / "points.ply", out_dense_mesh_ply=w / "dense_mesh.ply")
    out = P.clean_mesh(P.CleanParams(), ctx, in_dense_mesh_ply=w / "dense_mesh.ply", in_points_ply=w / "points.ply",
                       out_clean_mesh_ply=w / "clean_mesh.ply", out_clean_report_json=w / "clean_report.json")
    m = read_ply(w / "clean_mesh.ply")
    d = cloud_to_mesh(pts.astype(np.float32), m.vertices, m.faces)
    print(json.dumps({"name": a.name, "points": len(pts), "spacing_m": round(density.measure(pts)["spacing_m"], 3),
                      "mesh_area_m2": round(float(face_areas(m.vertices, m.faces).sum()), 1),
                      "fill_share": out["fill_share"], "far_0.1": round(float((d > 0.1).mean()), 3),
                      "far_0.5": round(float((d > 0.5).mean()), 3),
                      "degraded": [r["reason"] for r in ctx.degraded_reasons]}))


if __name__ == "__main__":
    main()
