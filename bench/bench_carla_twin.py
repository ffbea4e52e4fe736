"""How the twin behaves in CARLA (issue 45), on demo seeds 0, 3 and 7 at the default size; prints Markdown tables.

    .venv/bin/python bench/bench_carla_twin.py [--seeds 0,3,7] [--out bench/outputs/carla_twin] [--run DIR ...]

Runs ``twinkit recipe=pointcloud_site site=demo site.seed=N`` for each seed into ``--out`` (the engine's cache
makes a second bench run cheap), or reads finished runs given with ``--run`` (a site folder such as
``outputs/demo``). Every number is read from what the run wrote for CARLA (the package under ``NN_carla``, its
OpenDRIVE in the site frame, actors.json, twin.usd) against the demo's ground truth (``01_site``):

- signals: light groups per signalised junction and pairs of conflicting approaches green together in CARLA's
  cycle (emulated offline, ``twinkit.street.lights``), scanned lights with a head within 1 m, the highest
  signal zOffset, stop / yield / speed-limit signs typed and signs left with type -1;
- the share of the static classes' faces placed in the map level after the import flow (``contract_import``);
- crosswalks carla.Map reports and the painted zebras with one within 1 m;
- sidewalk pieces per block, parked vehicles on OpenDRIVE sidewalk lanes (``contract_sidewalks``);
- lane waypoints (every 1 m) without the map's ground beneath (``contract_ground``);
- lifted actors whose ground-truth class is not theirs, and true objects not lifted;
- the USD georeference error at 150 m, read the way the geospatial schemas read it (ENU at the reference);
- the package checker's violations;
- the drop test (``NN_drop_test/drop_test.json``): per lane kind (driving, parking, sidewalk) the share of rays
  that find the ground and the widest hole, and the run's status (its last manifest: ok, or degraded and why).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _step(run: Path, name: str) -> Path | None:
    hits = sorted(p for p in run.glob(f"[0-9][0-9]_{name}") if p.is_dir())
    return hits[-1] if hits else None


def run_seed(out: Path, seed: int) -> Path:
    """Run the demo pipeline for ``seed`` into ``out/s<seed>``; returns the site folder."""
    dest = out / f"s{seed}"
    cmd = [sys.executable, "-m", "twinkit", "recipe=pointcloud_site", "site=demo", f"site.seed={seed}",
           f"engine.outputs_dir={dest}"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env={**os.environ})
    print(f"<!-- seed {seed}: pipeline {time.perf_counter() - t0:.0f} s, exit {p.returncode} -->", flush=True)
    if p.returncode not in (0, 3):  # 3: finished with a degraded stage (reported, the outputs exist)
        sys.stderr.write(p.stdout[-3000:] + p.stderr[-3000:])
    return dest / "demo"


def _bench_module(rel: str, name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / rel)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def site_xodr(run: Path) -> Path:
    """The last roads step's OpenDRIVE in the site frame (the one the package carries, before its frame)."""
    for name in ("place_crosswalks", "parking_lanes", "place_signals", "apply_alignment"):
        d = _step(run, name)
        if d is not None and (d / "aligned.xodr").is_file():
            return d / "aligned.xodr"
    raise SystemExit(f"{run}: no aligned.xodr (a finished pointcloud_site run?)")


def crosswalk_row(run: Path) -> dict:
    from twinkit.street.lanes import LaneMap
    from twinkit_roads.crosswalks import nearest_errors

    truth = [np.asarray(c["polygon"], float)
             for c in json.loads((run / "01_site" / "roads_truth.json").read_text())["crossings"]]
    got = LaneMap(site_xodr(run).read_text(), "bench").crosswalks()
    err = nearest_errors(got, truth)
    found = [e for e in err if e is not None and e <= 1.0]
    return {"crosswalks": len(got), "zebras": len(truth), "zebras_found": len(found),
            "crosswalk_err_max_m": round(max(found), 3) if found else None}


def signals_row(run: Path) -> dict:
    """CARLA's emulated light plan of the run's map (twinkit.street.lights) and its signals against the
    ground-truth traffic lights (the roads bench's ``gt_instances``)."""
    import xml.etree.ElementTree as ET

    from twinkit.street.lights import light_plan
    from twinkit_roads.signals import CARLA_LIGHT_TYPES

    sig = _bench_module("plugins/twinkit-roads/bench/bench_signals.py", "bench_signals")
    text = site_xodr(run).read_text()
    js = light_plan(text)["junctions"]
    sigs = list(ET.fromstring(text).iter("signal"))
    lights = [x for x in sigs if x.get("type") in CARLA_LIGHT_TYPES]
    signs = [x for x in sigs if x.get("type") not in CARLA_LIGHT_TYPES]
    truth = sig.gt_instances(run / "01_site" / "gt_mesh.ply", 6)
    pts = sig.landmark_xy(text, True)
    return {"signalised_junctions": len(js), "groups_max": max((v["groups"] for v in js.values()), default=0),
            "conflicting_pairs": sum(len(v["conflicts"]) for v in js.values()), "light_signals": len(lights),
            "true_lights_within_1m": f"{sum(sig.nearest(p, pts) <= 1.0 for p in truth)} / {len(truth)}",
            "light_zoffset_max_m": round(max((abs(float(x.get("zOffset", 0.0))) for x in lights), default=0.0), 2),
            "signs_typed": sum(x.get("type") in ("206", "205", "274") for x in signs),
            "signs_generic": sum(x.get("type") == "-1" for x in signs)}


def usd_error(run: Path, radius_m: float = 150.0) -> float:
    """Largest horizontal error (m) of points ``radius_m`` from the base point, taken through each mesh prim's
    world transform and read as ENU at the stage's reference position, against their true lon/lat."""
    from pxr import Usd, UsdGeom
    from pyproj import Geod

    from twinkit.geo import SiteFrame
    from twinkit.geo.enu import enu_to_lonlat

    site = json.loads((run / "01_site" / "site.json").read_text())
    stage = Usd.Stage.Open(str(_step(run, "usd") / "twin.usd"))
    root = stage.GetDefaultPrim()
    lat, lon, h = root.GetAttribute("omni:geospatial:wgs84:reference:referencePosition").Get()
    a = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    pts = np.c_[radius_m * np.cos(a), radius_m * np.sin(a), np.zeros_like(a)]
    truth = SiteFrame.from_site(site).local_to_lonlat(pts[:, :2])
    worst = 0.0
    for prim in (p for p in root.GetChildren() if p.IsA(UsdGeom.Mesh)):
        m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
        got = enu_to_lonlat((np.c_[pts, np.ones(len(pts))] @ m)[:, :3], lat, lon, h)
        err = np.abs(Geod(ellps="WGS84").inv(got[:, 0], got[:, 1], truth[:, 0], truth[:, 1])[2])
        worst = max(worst, float(err.max()))
    return worst


def actors_row(run: Path) -> dict:
    mov = _bench_module("plugins/twinkit-export/bench/bench_movables.py", "bench_movables")
    mov_dir = _step(run, "lift_movables") / "movables"
    acts = json.loads((mov_dir / "actors.json").read_text()).get("actors", [])
    wrong = mov.truth_class_mismatch(run, mov_dir, acts)
    gt = mov.gt_objects(run)
    found = [np.asarray(a["box"]["center"], float) for a in acts]
    missed = sum(1 for _, p in gt if not found or min(np.linalg.norm(q[:2] - p[:2]) for q in found) > 1.5)
    return {"lifted": len(acts), "truth_objects": len(gt), "wrong_class": len(wrong), "truth_not_lifted": missed}


def sidewalk_row(root: Path, pkg: Path, m: dict) -> dict:
    """The map FBX's Road_Sidewalk per block and the parked vehicles on OpenDRIVE sidewalk lanes
    (``contract_sidewalks``, in the package's frame)."""
    from twinkit_export import fbxbin
    from twinkit_export.contract_sidewalks import parked_on_sidewalk, sidewalk_blocks

    xodr = (pkg / m["xodr"]).read_text()
    geo = {n: (v, f) for n, v, f in fbxbin.mesh_arrays(pkg / m["source"]) if n == "Road_Sidewalk"}
    br = sidewalk_blocks(*geo["Road_Sidewalk"], xodr).summary() if "Road_Sidewalk" in geo else {}
    actors = json.loads((root / "actors.json").read_text()).get("actors", []) if (root / "actors.json").is_file() \
        else []
    return {"sidewalk_blocks": f"{br.get('blocks_with_sidewalk', 0) - br.get('blocks_split', 0)} / "
                               f"{br.get('blocks_with_sidewalk', 0)}",
            "sidewalk_stray": br.get("stray_pieces"), "parked_on_sidewalk": len(parked_on_sidewalk(actors, xodr))}


def drop_row(run: Path) -> dict:
    """The drop test's share of rays on the ground and widest hole per lane kind, and the last run's status."""
    row: dict = {}
    d = _step(run, "drop_test")
    if d is not None and (d / "drop_test.json").is_file():
        lanes = json.loads((d / "drop_test.json").read_text()).get("lanes", {})
        for kind in ("driving", "parking", "sidewalk"):
            lane = lanes.get(kind)
            judged = lane.get("target_on", "hit_pct") if lane else "hit_pct"
            off_kerb = f", {lane[judged]} % off the kerb line" if lane and judged != "hit_pct" else ""
            row[f"drop_{kind}"] = "-" if not lane else \
                f"{lane['hit_pct']} %{off_kerb} (target {lane['target_pct']}); hole {lane['widest_hole_m']} m"
    manifests = sorted((run / "runs").glob("*/manifest.json"))
    if manifests:
        m = json.loads(manifests[-1].read_text())
        row["status"] = m.get("status")
        row["degraded_by"] = "; ".join(sorted({e.get("step", "?") for e in m.get("degraded") or []})) or "-"
    return row


def package_row(run: Path) -> dict:
    from twinkit_export.carla_contract import check_package
    from twinkit_export.contract_ground import lanes_over_map_ground, map_ground
    from twinkit_export.contract_import import placement_summary

    root = _step(run, "carla") / "carla_import"
    pkg_json = next((root / "Import").glob("*/*.json"))
    package = pkg_json.stem
    rep = check_package(root, package)
    desc = json.loads(pkg_json.read_text())
    m = desc["maps"][0]
    ground = map_ground(pkg_json.parent / m["source"])
    lanes = lanes_over_map_ground(pkg_json.parent / m["xodr"], ground, 1.0)
    place = placement_summary(root, package, rep) or {}
    walk = sidewalk_row(root, pkg_json.parent, m)
    rules = sorted({v.rule for v in rep.violations})
    return {**walk, "placed_share": place.get("placed_share"), "waypoints_off_ground": int(lanes.off.sum()),
            "waypoints": int(len(lanes.off)), "violations": len(rep.violations), "rules": ", ".join(rules) or "-",
            "report": rep}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,3,7")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "outputs" / "carla_twin")
    ap.add_argument("--run", action="append", type=Path, help="a finished demo site folder instead (repeatable)")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    args = ap.parse_args(argv)
    runs = [(f"{r.parent.name}/{r.name}", r) for r in args.run] if args.run else \
        [(f"seed {s}", run_seed(args.out, int(s))) for s in args.seeds.split(",")]
    rows = []
    for name, run in runs:
        row = {"run": name}
        row.update(signals_row(run))
        row.update(crosswalk_row(run))
        row.update(actors_row(run))
        row.update(drop_row(run))
        row["usd_err_150m_m"] = round(usd_error(run), 4)
        pkg = package_row(run)
        pkg.pop("report")
        row.update(pkg)
        rows.append(row)
    print("## The twin in CARLA (issue 45 targets)\n")
    cols = [("signalised junctions", "signalised_junctions"), ("light groups per junction (max)", "groups_max"),
            ("crossing approaches green together (pairs)", "conflicting_pairs"), ("light signals", "light_signals"),
            ("true lights with a head within 1 m", "true_lights_within_1m"),
            ("max light zOffset (m)", "light_zoffset_max_m"), ("signs typed stop/yield/speed", "signs_typed"),
            ("signs left with type -1", "signs_generic"),
            ("crosswalks CARLA reports", "crosswalks"), ("zebras with one within 1 m", "zebras_found"),
            ("zebras", "zebras"), ("blocks whose sidewalk is one surface", "sidewalk_blocks"),
            ("sidewalk pieces on the carriageway", "sidewalk_stray"),
            ("parked vehicles on OpenDRIVE sidewalk lanes", "parked_on_sidewalk"),
            ("static faces placed in the level", "placed_share"),
            ("lane waypoints (carla.Map, 1 m) without ground", "waypoints_off_ground"),
            ("lifted actors", "lifted"), ("lifted, wrong truth class", "wrong_class"),
            ("truth objects not lifted", "truth_not_lifted"), ("USD error at 150 m (m)", "usd_err_150m_m"),
            ("checker violations", "violations"), ("rules violated", "rules"),
            ("drop test, driving lanes: share (target); widest hole", "drop_driving"),
            ("drop test, parking lanes", "drop_parking"), ("drop test, sidewalk lanes", "drop_sidewalk"),
            ("run status", "status"), ("degraded by", "degraded_by")]
    print("| measure | " + " | ".join(r["run"] for r in rows) + " |")
    print("|---|" + "---:|" * len(rows))
    for label, key in cols:
        print(f"| {label} | " + " | ".join(str(r.get(key)) for r in rows) + " |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
