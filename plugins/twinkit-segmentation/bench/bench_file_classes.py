"""The scan file's own classes as a prior of the label fusion (docs/segmentation.md "File classes"), measured
on real classified clouds: the labels without and with them, against the file's classes.

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_file_classes.py [--site-dirs outputs/ign] [--run]

Each site folder is a ``recipe=pointcloud_site`` run up to ``predict_views`` on a classified LAS/LAZ (its
points.ply keeps ``classification``); nothing is rendered or predicted again: ``backproject`` (its defaults)
runs twice on the stored votes, with ``file_classes`` false and true. ``--run`` first makes outputs/ign from
../shared/data/pointclouds/ign_lidarhd_village_street.laz (IGN LiDAR HD, aerial; 300 views, a 2048 px texture:
25 minutes to predict_views on the shared 2-core machine, plus the exports).

Printed per site: the share of the file's points of each ASPRS class (ground, building, ...) whose label
(the label of the nearest mesh vertex) the file's class rules out, car on the file's ground, and the
agreement: labelled points whose label the file's class allows.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twinkit import cityscapes

ROOT = Path(__file__).resolve().parents[3]
IGN = ROOT.parent / "shared" / "data" / "pointclouds" / "ign_lidarhd_village_street.laz"
RUN_IGN = ["recipe=pointcloud_site", "site=mex", "site.name=ign", "site.crs=EPSG:2154",
           "site.base_point.lat=46.632496", "site.base_point.lon=5.225686", "site.base_point.alt=185",
           f"site.inputs.cloud={IGN}", "road_source=none",
           # fewer views and a smaller texture than the defaults, only to keep the run short (both runs of the
           # comparison fuse the same stored votes)
           "steps.sample_views.max_views=300", "steps.bake_texture.texture_px=2048"]


def _one(site: Path, pattern: str) -> Path | None:
    hits = sorted(site.glob(f"*/{pattern}"))
    return hits[-1] if hits else None


def fuse(site: Path, file_classes: bool, work: Path) -> tuple[np.ndarray, dict, float]:
    from twinkit.testing import installed_plugin, run_step
    from twinkit_segmentation.steps import BackprojectParams

    inputs = {"in_textured_mesh_ply": _one(site, "textured_mesh.ply"), "in_segments_npy": _one(site, "segments.npy"),
              "in_vertex_votes_npy": _one(site, "vertex_votes.npy"), "in_points_ply": _one(site, "points.ply")}
    t0 = time.perf_counter()
    out = run_step(installed_plugin("step", "backproject"), work / f"fc{int(file_classes)}", inputs,
                   params=BackprojectParams(file_classes=file_classes))
    import json

    metrics = json.loads((out["labels.npy"].parent / "step.json").read_text())["metrics"]
    return np.load(out["labels.npy"]), metrics, time.perf_counter() - t0


def point_table(points: np.ndarray, codes: np.ndarray, vertices: np.ndarray, runs: dict) -> list[str]:
    from scipy.spatial import cKDTree

    from twinkit.cityscapes import ASPRS_NAMES, ASPRS_TO_TRAINIDS, N_CLASSES, NAMES, asprs_allowed

    _, nearest = cKDTree(vertices).query(points, workers=-1)
    allowed = asprs_allowed()
    lines = ["| file class | points | " + " | ".join(f"ruled out, {k}" for k in runs) + " | "
             + " | ".join(f"car, {k}" for k in runs) + " | most common labels (%), " + " / ".join(runs) + " |",
             "|---|---:|" + "---:|" * (2 * len(runs)) + "---|"]
    agree = {k: [0, 0] for k in runs}
    for code in sorted(set(np.unique(codes).tolist())):
        m = codes == code
        cells_out, cells_car, common = [], [], []
        for k, labels in runs.items():
            lab = labels[nearest[m]]
            known = lab < N_CLASSES
            ok = allowed[code][np.minimum(lab, N_CLASSES - 1)] & known
            voting = code in ASPRS_TO_TRAINIDS
            if voting:
                agree[k][0] += int(ok.sum())
                agree[k][1] += int(known.sum())
            cells_out.append(f"{100 * (1 - ok[known].mean()):.1f} %" if voting and known.any() else "(silent)")
            cells_car.append(f"{100 * (lab == cityscapes.CAR).mean():.1f} %")
            vals, cnt = np.unique(lab[known], return_counts=True)
            top = np.argsort(-cnt)[:3]
            common.append(", ".join(f"{NAMES[vals[i]]} {100 * cnt[i] / max(known.sum(), 1):.0f}" for i in top) or "-")
        lines.append(f"| {code} {ASPRS_NAMES.get(code, 'user/reserved')} | {int(m.sum())} | " + " | ".join(cells_out)
                     + " | " + " | ".join(cells_car) + " | " + " / ".join(common) + " |")
    lines.append("")
    lines.append("Agreement with the file (labelled points of a class that votes whose label it allows): "
                 + ", ".join(f"{k} {100 * a / max(n, 1):.1f} % of {n}" for k, (a, n) in agree.items()))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--site-dirs", default="outputs/ign")
    ap.add_argument("--run", action="store_true", help="make outputs/ign first (the IGN LiDAR HD extract)")
    a = ap.parse_args(argv)
    if a.run:
        twinkit = Path(sys.executable).with_name("twinkit")
        subprocess.run([str(twinkit), *RUN_IGN], cwd=ROOT, check=False)
    from twinkit.mesh import read_ply

    from twinkit_segmentation.fileclasses import read_point_classes

    print("# The file's own classes in the label fusion\n")
    for s in a.site_dirs.split(","):
        site = (ROOT / s).resolve() if not Path(s).is_absolute() else Path(s)
        need = ["textured_mesh.ply", "segments.npy", "vertex_votes.npy", "points.ply"]
        missing = [n for n in need if _one(site, n) is None]
        if missing:
            print(f"{s}: skipped, no {', '.join(missing)} (make it with: .venv/bin/twinkit {' '.join(RUN_IGN)}, "
                  f"or --run)\n")
            continue
        got = read_point_classes(_one(site, "points.ply"))
        if got is None:
            print(f"{s}: skipped, its points.ply has no classification\n")
            continue
        points, codes = got
        vertices = read_ply(_one(site, "textured_mesh.ply")).vertices
        with tempfile.TemporaryDirectory() as tmp:
            before, m0, t0 = fuse(site, False, Path(tmp))
            after, m1, t1 = fuse(site, True, Path(tmp))
        fc = m1.get("file_classes") or {}
        print(f"## {s}: {len(points)} points, {len(vertices)} vertices; point spacing {fc.get('point_spacing_m')} m, "
              f"a vertex takes the class of a point within {fc.get('reach_m')} m\n")
        print(f"backproject without the file's classes {t0:.1f} s, with them {t1:.1f} s; vertices with a class "
              f"that votes: {fc.get('vertices_with_class')} of {fc.get('vertices')}; of these, labelled against "
              f"the file: views alone {100 * fc.get('against_file_before', 0):.1f} %, fused "
              f"{100 * fc.get('against_file_after', 0):.1f} %\n")
        print("\n".join(point_table(points, codes, vertices, {"without": before, "with": after})))
        changed = before != after
        print(f"\n{int(changed.sum())} vertices changed label ({100 * changed.mean():.1f} %)\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
