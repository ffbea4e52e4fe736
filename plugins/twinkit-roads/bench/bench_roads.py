"""Benchmark twinkit-roads; prints Markdown tables.

    .venv/bin/python plugins/twinkit-roads/bench/bench_roads.py [--demo /tmp/roads_out/demo]

1. OSM -> OpenDRIVE per shared OSM file (site base point at the file's centre, its CRS the UTM zone):
   read time, netconvert + carla.Map check time, roads, junctions, traffic lights, waypoints.
2. Alignment on the demo site (a finished `recipe=roads_demo` run, or generated here):
   lane centre-line RMSE to the truth before/after, from labels and from the ground.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.align import centreline_rmse
from twinkit_roads.osmio import read_osm, write_osm_xml

SHARED = Path(__file__).resolve().parents[4] / "shared" / "data" / "osm"


def utm(lon: float, lat: float) -> str:
    return f"EPSG:{(32600 if lat >= 0 else 32700) + int((lon + 180) // 6) + 1}"


def bench_conversion(tmp: Path) -> None:
    print("| OSM file | highway ways | read s | netconvert s | total (netconvert + carla check) s | roads | "
          "junctions | traffic lights | carla waypoints (2 m) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("helsinki_center.osm.pbf", "west_oakland.osm.bz2", "bavarian_village.osm"):
        src = SHARED / name
        if not src.is_file():
            print(f"| {name} | absent | | | | | | | |")
            continue
        t0 = time.perf_counter()
        data = read_osm(src)
        t_read = time.perf_counter() - t0
        s, w, n, e = data.bounds()
        lat, lon = (s + n) / 2, (w + e) / 2
        site = {"name": name, "crs": utm(lon, lat), "base_point": {"lat": lat, "lon": lon, "alt": 0.0},
                "osm_radius_m": 500.0}
        osm = tmp / f"{name}.osm"
        write_osm_xml(data, osm)
        out = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp / name, {"in_osm_osm": osm},
                       site=site)
        r = json.loads(out["roads_check.json"].read_text())
        print(f"| {name} | {data.count()['highway_ways']} | {t_read:.2f} | {r['netconvert_s']:.2f} | "
              f"{r['conversion_s']:.2f} | {r['roads']} | {r['junctions']} | {r['traffic_lights']} | "
              f"{r['carla']['waypoints']} |")


def bench_alignment(demo: Path | None, tmp: Path) -> None:
    site_cfg = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
    if demo is not None and (demo / "01_site" / "roads_truth.json").is_file():
        truth_json = demo / "01_site" / "roads_truth.json"
        xodr = next(demo.glob("*_osm_to_opendrive/roads.xodr"))
        mesh = next(demo.glob("*_texture/textured_mesh.ply"))
        gt = demo / "01_site" / "gt_mesh.ply"
        label = f"reconstructed mesh of {demo}"
    else:
        from twinkit.testing import run_plugin  # the twinkit-demo-site package's generator, through the registry

        site = run_plugin("site_generator", "demo_intersection", tmp / "site", site=dict(site_cfg, size="small"))
        truth_json, gt = site["roads_truth.json"], site["gt_mesh.ply"]
        xodr = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp / "conv",
                        {"in_osm_osm": site["roads.osm"]}, site=site_cfg)["roads.xodr"]
        mesh, label = gt, "ground-truth mesh (no reconstruction given)"
    truth = [np.asarray(t["points"]) for t in json.loads(truth_json.read_text())["lanes"]]
    b = (-28.0, -28.0, 28.0, 28.0)
    before, _ = centreline_rmse(xodr.read_text(), truth, b)
    print(f"\nAlignment on the demo site ({label}); OSM shifted ~3.5 m and rotated 0.8 deg by the generator.\n")
    print("| road surface from | lane centre-line RMSE before (m) | after (m) | fit residual (m) | yaw (deg) | "
          "tx, ty (m) | align s |")
    print("|---|---|---|---|---|---|---|")
    from scipy.spatial import cKDTree
    from twinkit.mesh import read_ply

    g = read_ply(gt)
    gv, glab = g.vertices, np.asarray(g.attrs["label"]).astype(np.uint8)
    from twinkit.artefacts import read_textured_mesh

    mv = read_textured_mesh(mesh).vertices
    labels = glab[cKDTree(gv).query(mv)[1]]
    np.save(tmp / "labels.npy", labels)
    np.save(tmp / "gt_labels.npy", glab)
    cases = [("reconstructed mesh, labels (ground truth transferred to it)", mesh, tmp / "labels.npy"),
             ("reconstructed mesh, ground (no segmentation)", mesh, None),
             ("ground-truth mesh, its labels (clean curbs: the method's own precision)", gt, tmp / "gt_labels.npy")]
    for i, (how, m, lab) in enumerate(cases):
        inputs = {"in_roads_xodr": xodr, "in_textured_mesh_ply": m}
        if lab is not None:
            inputs["in_labels_npy"] = lab
        t0 = time.perf_counter()
        al = run_step(plugin_from_module(roads, "step", "align_roads"), tmp / f"al{i}", inputs, site=site_cfg)
        dt = time.perf_counter() - t0
        a = json.loads(al["alignment.json"].read_text())
        from twinkit_roads.align import transform_xodr
        from twinkit_roads.kerbs import set_lane_offsets

        moved = set_lane_offsets(transform_xodr(xodr.read_text(), math.radians(a["yaw_deg"]), a["tx_m"], a["ty_m"],
                                                a["dz_m"]), a.get("lane_offsets_m") or {})
        after, _ = centreline_rmse(moved, truth, b)
        print(f"| {how} | {before:.3f} | {after:.3f} | {a['residual_rmse_m']:.3f} | {a['yaw_deg']:.3f} | "
              f"{a['tx_m']:.2f}, {a['ty_m']:.2f} | {dt:.1f} |")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--demo", type=Path, default=Path("/tmp/roads_out/demo"),
                    help="outputs of `twinkit recipe=roads_demo site=demo` (generated here if absent)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        bench_conversion(tmp)
        bench_alignment(args.demo if args.demo.is_dir() else None, tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
