"""Crop first: a city-sized OSM extract cut to the site box + margin before netconvert. Prints Markdown tables.

    .venv/bin/python plugins/twinkit-roads/bench/bench_crop.py [--repeat 3]

For several base points in helsinki_center.osm.pbf (CRS EPSG:3067) and site boxes of 300 m and 600 m
across (site.osm_radius_m 150 / 300) and crop margins (--margins): the road source (read, crop, write) and
osm_to_opendrive (netconvert, carla.Map check) per stage, median of --repeat runs, against the whole
extract converted once per base point; then how far the cropped network's lane centres inside the site
box lie from the whole network's (nearest of the whole network's driving-lane waypoints at 5 cm spacing).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.sources import file_source

SHARED = Path(__file__).resolve().parents[4] / "shared" / "data" / "osm"
SPOTS = {"Rautatientori": (60.1710, 24.9440), "Erottaja": (60.1664, 24.9440), "Kluuvi": (60.1735, 24.9500)}


def waypoints(xodr: Path, step: float = 0.25) -> np.ndarray:
    from twinkit.street.lanes import LaneMap

    return LaneMap(xodr.read_text(), "b").waypoints(step).xyz[:, :2]


def lane_offsets(cropped: Path, whole: Path, half: float) -> tuple:
    """Over the cropped network's waypoints inside the site box: distance to the nearest waypoint of the whole
    network; (median, 99th percentile, max, share over 5 cm, distance of the worst point to the box edge, n)."""
    from scipy.spatial import cKDTree

    a, b = waypoints(cropped, 0.5), waypoints(whole, 0.05)  # 5 cm spacing: at most 2.5 cm from sampling
    a = a[(np.abs(a) <= half).all(1)]
    d, _ = cKDTree(b).query(a)
    i = int(np.argmax(d))
    edge = float(half - np.abs(a[i]).max())
    return (float(np.median(d)), float(np.percentile(d, 99)), float(d.max()), float(np.mean(d > 0.05)), edge, len(a))


def run(tmp: Path, site: dict, src: Path, crop: bool, margin: float = 50.0) -> dict:
    """The road source (called directly, for its per-stage metrics) and osm_to_opendrive (through the engine)."""
    from twinkit.testing import make_context

    tmp.mkdir(parents=True, exist_ok=True)
    fs = roads.FileSourceParams(crop_radius_m=-1.0 if crop else 0.0, crop_margin_m=margin)
    s = file_source(fs, make_context(tmp, site=site), out_osm_osm=tmp / "osm.osm", in_osm=src)
    b = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp / "conv", {"in_osm_osm": tmp / "osm.osm"},
                 site=site)
    c = json.loads(b["roads_check.json"].read_text())
    return {"xodr": b["roads.xodr"], "check": c, "src": s}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--margins", default="50,100,150", help="crop margins (m) to compare")
    args = ap.parse_args()
    src = SHARED / "helsinki_center.osm.pbf"
    if not src.is_file():
        print(f"absent: {src}")
        return 1
    import logging

    logging.disable(logging.WARNING)

    rows, acc = [], []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for spot, (lat, lon) in SPOTS.items():
            whole_site = {"name": "w", "crs": "EPSG:3067", "base_point": {"lat": lat, "lon": lon, "alt": 0.0},
                          "osm_radius_m": 150.0}
            w = run(tmp / f"{spot}_whole", whole_site, src, crop=False)
            wc = w["check"]
            ws = w["src"]
            rows.append((spot, "whole extract", "-", ws["ways"], ws["read_s"], 0.0, ws["write_s"], wc["netconvert_s"],
                         wc["check_s"], wc["conversion_s"], wc["roads"], wc["junctions"]))
            for half, margin in ((h, float(m)) for h in (150.0, 300.0) for m in args.margins.split(",")):
                site = dict(whole_site, osm_radius_m=half)
                times = []
                for i in range(args.repeat):
                    r = run(tmp / f"{spot}_{half}_{margin}_{i}", site, src, crop=True, margin=margin)
                    times.append((r["src"]["read_s"], r["src"]["crop_s"], r["src"]["write_s"],
                                  r["check"]["netconvert_s"], r["check"]["check_s"], r["check"]["conversion_s"]))
                med = [statistics.median(v) for v in zip(*times)]
                c = r["check"]
                rows.append((spot, f"{2 * half:.0f} m", f"{half + margin:.0f}", r["src"]["ways"], *med, c["roads"],
                             c["junctions"]))
                acc.append((spot, f"{2 * half:.0f} m", f"{margin:.0f}", *lane_offsets(r["xodr"], w["xodr"], half)))
    print("| base point | site box | crop half side m | ways kept | read s | crop s | write s | netconvert s | "
          "carla check s | convert + check s | roads | junctions |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | " + " | ".join(f"{v:.2f}" for v in r[4:10])
              + f" | {r[10]} | {r[11]} |")
    print()
    print("| base point | site box | margin m | cropped waypoints inside the box | offset to the whole network: "
          "median m | 99 % m | max m | share > 5 cm | worst point's distance to the box edge m |")
    print("|---|---|---|---|---|---|---|---|---|")
    for a in acc:
        print(f"| {a[0]} | {a[1]} | {a[2]} | {a[8]} | {a[3]:.3f} | {a[4]:.3f} | {a[5]:.3f} | {100 * a[6]:.2f} % | "
              f"{a[7]:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
