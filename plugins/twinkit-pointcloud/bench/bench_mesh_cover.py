"""Issue 44 item 4: does the mesh cover what was scanned? On the labelled SemanticKITTI scans.

    python plugins/twinkit-pointcloud/bench/bench_mesh_cover.py [--scans seq00_000000 ...] [--out DIR]
        [--set clean.min_component_faces=200 ...] [--texture]

Each scan of ``../shared/data/labelled/semantickitti/`` is copied without its label fields (x, y, z,
intensity), then read_cloud, poisson, clean_mesh and simplify (bake_texture with ``--texture``; it does
not move vertices) run with the defaults (``--set step.param=value`` overrides one). Per scan and per
coarse class (ground, building, tree, pole, car, all labelled) it prints the share of the labelled points
farther than 0.2 / 0.5 / 1 m from the final mesh's surface, and where the far ones were lost: the share
already farther than 0.5 m from the dense Poisson mesh (the depth / Poisson), from the mesh after the
distance trim (the trim), after the small-component removal (clean's components) and after simplify.
The JSON of every figure goes to ``OUT/mesh_cover.json``. A scan missing from ../shared is skipped.

``--clouds lille ign autzen`` runs the same on the unlabelled real clouds of ``../shared/data/pointclouds``
(bench_real_scans.py's list; per class by the file's ASPRS classes where it has them), to check that the
clean-up rules hold on other captures.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
REPO = HERE.parents[3]
DATA = REPO.parent / "shared" / "data" / "labelled" / "semantickitti"
SCANS = ("seq00_000000", "seq00_000001", "seq00_000002", "spvnas_sample_000000")
#: coarse classes over CityScapes trainIds (255 = ignore)
COARSE = {"ground": (0, 1, 9), "building": (2, 3, 4), "tree": (8,), "pole": (5, 6, 7), "car": (13, 14, 15, 16)}
FAR = (0.2, 0.5, 1.0)


def strip_labels(src: Path, dst: Path) -> tuple[np.ndarray, np.ndarray]:
    """Write x, y, z, intensity of ``src`` to ``dst``; returns (xyz (n, 3) float64, trainid (n,) int)."""
    from plyfile import PlyData, PlyElement

    v = PlyData.read(str(src))["vertex"].data
    out = np.empty(len(v), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")])
    for k in ("x", "y", "z", "intensity"):
        out[k] = v[k]
    PlyData([PlyElement.describe(out, "vertex")], byte_order="<").write(str(dst))
    return np.c_[v["x"], v["y"], v["z"]].astype(np.float64), np.asarray(v["cs_trainid"], int)


def far_shares(d: np.ndarray, lab: np.ndarray) -> dict:
    """{class: {threshold: share farther}} over the labelled points."""
    ok = lab != 255
    out = {}
    for name, ids in (("all", None), *COARSE.items()):
        m = ok if ids is None else np.isin(lab, ids)
        if m.sum() == 0:
            continue
        out[name] = {"n": int(m.sum()), **{str(t): round(float((d[m] > t).mean()), 4) for t in FAR}}
    return out


def cloud_site(name: str) -> tuple[Path, dict]:
    """(file, site dict) of one of bench_real_scans.py's clouds: the CRS and a base point at its centre."""
    import sys

    sys.path.insert(0, str(HERE.parent))
    from bench_real_scans import CLOUDS, DATA as CLOUD_DATA, centre_latlon

    c = CLOUDS[name]
    f = CLOUD_DATA / c["file"]
    site: dict = {"name": name}
    if "crs" in c:
        lat, lon, alt = centre_latlon(f)
        site.update(crs=c["crs"], base_point={"lat": lat, "lon": lon, "alt": alt})
    return f, site


def run_scan(name: str, out: Path, overrides: dict, texture: bool, cloud: bool = False) -> dict:
    from twinkit.artefacts import read_points
    from twinkit.mesh import read_ply
    from twinkit.surface.metrics import cloud_to_mesh
    from twinkit.testing import make_context

    from twinkit_pointcloud import plugin as P

    w = out / name
    w.mkdir(parents=True, exist_ok=True)
    if cloud:
        src, site = cloud_site(name)
        xyz, lab = None, None
    else:
        xyz, lab = strip_labels(DATA / f"{name}.ply", w / f"{name}_xyz.ply")
        src, site = w / f"{name}_xyz.ply", {"name": name}
    ctx = make_context(w / "work", site=site)
    wd = ctx.workdir
    t: dict = {}

    def prm(cls, key):
        kw = {k.split(".", 1)[1]: v for k, v in overrides.items() if k.split(".", 1)[0] == key}
        return cls(**kw)

    t0 = time.perf_counter()
    P.read_cloud(prm(P.ReadCloudParams, "read"), ctx, in_cloud=src, out_points_ply=wd / "points.ply",
                 out_points_meta_json=wd / "points_meta.json")
    t["read_cloud"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rp = P.poisson(prm(P.PoissonParams, "poisson"), ctx, in_points_ply=wd / "points.ply",
                   out_dense_mesh_ply=wd / "dense_mesh.ply")
    t["poisson"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rc = P.clean_mesh(prm(P.CleanParams, "clean"), ctx, in_dense_mesh_ply=wd / "dense_mesh.ply",
                      in_points_ply=wd / "points.ply", out_clean_mesh_ply=wd / "clean_mesh.ply",
                      out_clean_report_json=wd / "clean_report.json")
    t["clean"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    P.simplify(prm(P.SimplifyParams, "simplify"), ctx, in_clean_mesh_ply=wd / "clean_mesh.ply",
               out_mesh_ply=wd / "mesh.ply")
    t["simplify"] = time.perf_counter() - t0
    final = wd / "mesh.ply"
    if texture:
        t0 = time.perf_counter()
        P.bake_texture(prm(P.BakeParams, "bake"), ctx, in_mesh_ply=wd / "mesh.ply",
                       in_clean_mesh_ply=wd / "clean_mesh.ply", out_textured_mesh_obj=wd / "textured_mesh.obj",
                       out_textured_mesh_ply=wd / "textured_mesh.ply", in_points_ply=wd / "points.ply")
        t["texture"] = time.perf_counter() - t0
        final = wd / "textured_mesh.ply"
    pc = read_points(wd / "points.ply")
    pts = pc.vertices
    if lab is None:  # the file's own ASPRS classes (ground 2, vegetation 3-5, building 6) or none
        cls = pc.attrs.get("classification")
        asprs = {2: 0, 3: 8, 4: 8, 5: 8, 6: 2}
        lab = np.array([asprs.get(int(c), 254) for c in cls]) if cls is not None else np.full(len(pts), 254)
        xyz = pts
    if len(pts) != len(xyz):
        raise SystemExit(f"{name}: read_cloud kept {len(pts)} of {len(xyz)} points; cannot match the labels")
    stages = {"at_poisson": wd / "dense_mesh.ply", "at_clean": wd / "clean_mesh.ply", "final": final}
    res: dict = {"poisson": rp, "clean": {k: rc.get(k) for k in ("max_dist_m", "faces", "trim_removed_share")},
                 "time_s": {k: round(v, 1) for k, v in t.items()}}
    for st, f in stages.items():
        m = read_ply(f)
        d = cloud_to_mesh(pts, m.vertices, m.faces)
        res[st] = {"faces": int(m.n_faces), "far": far_shares(d, lab)}
        if st == "final":
            from scipy.spatial import cKDTree

            dv, _ = cKDTree(m.vertices).query(pts)
            res["final_vertex"] = far_shares(dv.astype(np.float32), lab)
            np.save(w / "final_dist.npy", d)
    rep = json.loads((wd / "clean_report.json").read_text())
    res["clean_report"] = {k: rep.get(k) for k in ("input", "density_trim", "distance_trim", "components", "holes",
                                                     "auto")}
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scans", nargs="*", default=list(SCANS))
    ap.add_argument("--clouds", nargs="*", default=[], help="lille ign autzen (../shared/data/pointclouds)")
    ap.add_argument("--out", default=str(REPO / "outputs" / "bench_mesh_cover"))
    ap.add_argument("--set", nargs="*", default=[], help="step.param=value (read, poisson, clean, simplify, bake)")
    ap.add_argument("--texture", action="store_true")
    a = ap.parse_args()
    ov = {}
    for s in a.set:
        k, v = s.split("=", 1)
        ov[k] = json.loads(v) if v[:1] in "-0123456789[{tf" else v
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    allres = {}
    for name, is_cloud in [(n, False) for n in a.scans] + [(n, True) for n in a.clouds]:
        if not is_cloud and not (DATA / f"{name}.ply").exists():
            print(f"{name}: not in {DATA}, skipped")
            continue
        if is_cloud and not cloud_site(name)[0].exists():
            print(f"{name}: not in ../shared/data/pointclouds, skipped")
            continue
        r = allres[name] = run_scan(name, out, ov, a.texture, is_cloud)
        print(f"== {name}: depth {r['poisson']['depth']}, trim {r['clean']['max_dist_m']} m, faces "
              f"{r['poisson']['faces']} -> {r['clean']['faces']} -> {r['final']['faces']}; time {r['time_s']}")
        print(f"{'class':10s} {'n':>7s} | far>0.2 far>0.5 far>1 (final) | >0.5 after: poisson clean | nearest-vertex >0.5")
        for c, v in r["final"]["far"].items():
            print(f"{c:10s} {v['n']:7d} | {v['0.2']:7.3f} {v['0.5']:7.3f} {v['1.0']:6.3f}        | "
                  f"{r['at_poisson']['far'][c]['0.5']:13.3f} {r['at_clean']['far'][c]['0.5']:5.3f}"
                  f" | {r['final_vertex'][c]['0.5']:.3f}")
        print("clean:", json.dumps(r["clean_report"]))
    (out / "mesh_cover.json").write_text(json.dumps(allres, indent=1))


if __name__ == "__main__":
    main()
