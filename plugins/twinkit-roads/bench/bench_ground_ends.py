"""Benchmark the trim of the map's ends to the scanned ground (ground_ends.py); prints a Markdown table.

    .venv/bin/python plugins/twinkit-roads/bench/bench_ground_ends.py --run outputs/demo [--run ...] [--json out.json]

Needs finished `recipe=pointcloud_site site=demo` runs (any seed). For each run, apply_alignment is run here twice
on the run's own roads.xodr, alignment.json and textured mesh: with ``trim_to_ground=false`` (the map as before
the trim) and with the defaults. Measured on both (against the textured mesh the step trims to):

- driving waypoints every 1 m without ground beneath (CARLA's ``generate_waypoints``; the package rule
  ``lanes_over_ground`` counts the same), and lane samples of every lane every 0.25 m;
- the network: roads, lanes per road (id, type), junction connections, CARLA's lane topology (a lane's segment to
  itself left out: CARLA lists one for some lanes that end nowhere) -- equal before and after, or the row says no;
- the cut per map end, and the no-op check: the same map against the same ground stretched to twice its size
  comes back unchanged.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.ground_ends import trim_to_ground

ROOT = Path(__file__).resolve().parents[3]
RUNS = [ROOT / "outputs" / "demo"]


def _step(run: Path, name: str) -> Path:
    hits = sorted(run.glob(f"[0-9][0-9]_{name}"))
    if not hits:
        raise SystemExit(f"{run}: no *_{name} step folder (a finished pointcloud_site run?)")
    return hits[-1]


def network(text: str) -> dict:
    """Roads, lanes per road, junction connections, lane topology (without a lane's segment to itself)."""
    from twinkit.street.lanes import LaneMap

    root = ET.fromstring(text)
    topo = {(a[0], a[2], b[0], b[2]) for a, b in LaneMap(text).topology() if (a[0], a[2]) != (b[0], b[2])}
    return {"roads": sorted(r.get("id") for r in root.findall("road")),
            "lanes": {r.get("id"): sorted((ln.get("id"), ln.get("type")) for ln in r.iter("lane"))
                      for r in root.findall("road")},
            "connections": sorted((j.get("id"), c.get("incomingRoad"), c.get("connectingRoad"))
                                  for j in root.findall("junction") for c in j.findall("connection")),
            "topology": sorted(topo)}


def measure(text: str, mesh) -> dict:
    from twinkit.street.lane_ground import lanes_over_ground
    from twinkit.street.lanes import LaneMap

    lm = LaneMap(text)
    drv = lanes_over_ground(lm, mesh.vertices, mesh.faces, step_m=1.0)
    every = lanes_over_ground(lm, mesh.vertices, mesh.faces, step_m=0.25, every_lane=True)
    return {"driving_waypoints": int(len(drv.ground)), "driving_off_ground": int(drv.off.sum()),
            "lane_samples": int(len(every.ground)), "lane_samples_off_ground": int(every.off.sum()),
            "off_by_type": every.summary(0)["by_type"]}


def bench_run(run: Path, tmp: Path) -> dict:
    from twinkit.mesh import read_ply

    site = json.loads((run / "01_site" / "site.json").read_text())
    mesh_ply = _step(run, "texture") / "textured_mesh.ply"
    inputs = {"in_roads_xodr": _step(run, "osm_to_opendrive") / "roads.xodr",
              "in_alignment_json": _step(run, "align_roads") / "alignment.json", "in_textured_mesh_ply": mesh_ply}
    step = plugin_from_module(roads, "step", "apply_alignment")
    t0 = time.perf_counter()
    before = run_step(step, tmp / "before", inputs, roads.ApplyParams(trim_to_ground=False), site=site)
    after = run_step(step, tmp / "after", inputs, roads.ApplyParams(), site=site)
    seconds = time.perf_counter() - t0
    b, a = before["aligned.xodr"].read_text(), after["aligned.xodr"].read_text()
    mesh = read_ply(mesh_ply)
    _, rep = trim_to_ground(b, mesh.vertices, mesh.faces)
    nb, na = network(b), network(a)
    v2 = mesh.vertices.copy()
    v2[:, :2] = (v2[:, :2] - v2[:, :2].mean(0)) * 2.0 + v2[:, :2].mean(0)
    noop, _ = trim_to_ground(b, v2, mesh.faces)
    return {"run": str(run), "seed": site.get("seed"), "before": measure(b, mesh), "after": measure(a, mesh),
            "ends": rep["ends"], "same_network": {k: nb[k] == na[k] for k in nb},
            "topology_pairs": [len(nb["topology"]), len(na["topology"])], "no_op_inside_ground": noop == b,
            "apply_alignment_s_both": round(seconds, 2)}


def table(rows: list[dict]) -> str:
    out = ["| run (seed) | driving waypoints off the ground, before -> after (of) | every lane, 0.25 m: before -> after "
           "| ends cut (m) | network unchanged (roads, lanes, connections, topology) | no-op inside the ground |",
           "|---|---|---|---|---|---|"]
    for r in rows:
        b, a = r["before"], r["after"]
        cuts = ", ".join(f"{'/'.join(e['ends'])} {e['trim_m']:.2f}" for e in r["ends"] if e["trim_m"] > 0) or "none"
        same = ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in r["same_network"].items())
        out.append(f"| {Path(r['run']).parent.name}/{Path(r['run']).name} ({r['seed']}) | {b['driving_off_ground']} -> "
                   f"{a['driving_off_ground']} ({b['driving_waypoints']} -> {a['driving_waypoints']}) | "
                   f"{b['lane_samples_off_ground']} -> {a['lane_samples_off_ground']} | {cuts} | {same} | "
                   f"{'yes' if r['no_op_inside_ground'] else 'NO'} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="append", type=Path, help="a finished demo run's folder (repeatable)")
    ap.add_argument("--json", type=Path, help="also write the measurements here")
    args = ap.parse_args(argv)
    runs = args.run or [r for r in RUNS if r.is_dir()]
    if not runs:
        print("no run found: give --run outputs/demo (a finished recipe=pointcloud_site site=demo run)")
        return 0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, run in enumerate(runs):
            rows.append(bench_run(run.resolve(), Path(tmp) / str(i)))
    print(table(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=lambda o: o.tolist() if isinstance(o, np.ndarray)
                                        else str(o)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
