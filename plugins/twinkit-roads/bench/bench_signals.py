"""Benchmark place_signals against the demo site's ground truth; prints Markdown tables.

    .venv/bin/python plugins/twinkit-roads/bench/bench_signals.py [--run outputs/demo] [--run outputs/demo_s7/demo]

Needs finished `recipe=pointcloud_site site=demo` runs (any seed). For each run:
- ground-truth traffic lights / signs: the label-6 / label-7 faces of 01_site/gt_mesh.ply, grouped
  into instances (faces closer than 0.6 m: one head with its pedestrian head, one plate; the raw
  connected components are single box faces, because the generated mesh splits vertices at UV seams);
- "before": the traffic-light signals of NN_apply_alignment/aligned.xodr (netconvert's guesses);
- "after": place_signals run here with default settings on the segmentation's labels.npy
  (NN_backproject), the same without the poles carrying unlabelled heads (pole_heads=false), and,
  as an upper bound, on the ground-truth labels (NN_gt_labels/gt_labels.npy).
Distances are horizontal, from each ground-truth light to the nearest traffic-light signal where
carla.Map (0.9.16, offline) puts it (`get_all_landmarks`).
"""
from __future__ import annotations

import argparse
import json
import xml.etree.ElementTree as ET
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.signals import CARLA_LIGHT_TYPES

ROOT = Path(__file__).resolve().parents[3]
RUNS = [ROOT / "outputs" / "demo", ROOT / "outputs" / "demo_s7" / "demo"]


def gt_instances(gt_mesh: Path, label: int, link_m: float = 0.6) -> list[np.ndarray]:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from twinkit.mesh import read_ply

    m = read_ply(gt_mesh)
    fl = np.asarray(m.face_attrs["label"])
    F = m.faces[fl == label]
    if len(F) == 0:
        return []
    C = m.vertices[F].mean(1)
    pairs = cKDTree(C).query_pairs(link_m, output_type="ndarray")
    A = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(C), len(C)))
    n, cc = connected_components(A, directed=False)
    out = []
    for k in range(n):
        P = m.vertices[np.unique(F[cc == k])]
        out.append(P.mean(0))
    return sorted(out, key=lambda p: (round(p[0], 1), round(p[1], 1)))


def landmark_xy(xodr_text: str, lights: bool) -> np.ndarray:
    from twinkit.street.lanes import LaneMap

    pts = [lm.xyz[:2] for lm in LaneMap(xodr_text, "bench").landmarks() if (lm.type in CARLA_LIGHT_TYPES) == lights]
    return np.array(pts, float).reshape(-1, 2)


def nearest(p: np.ndarray, pts: np.ndarray) -> float:
    if len(pts) == 0:
        return float("nan")
    return float(np.min(np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1])))


def one(folder: Path, pattern: str) -> Path | None:
    hits = sorted(folder.glob(pattern))
    return hits[-1] if hits else None


def run_place(run: Path, labels: Path, tmp: Path, params=None) -> tuple[str, dict]:
    xodr = one(run, "*_apply_alignment/aligned.xodr")
    mesh = one(run, "*_texture/textured_mesh.ply")
    out = run_step(plugin_from_module(roads, "step", "place_signals"), tmp,
                   {"in_aligned_xodr": xodr, "in_textured_mesh_ply": mesh, "in_labels_npy": labels}, params)
    return out["aligned.xodr"].read_text(), json.loads(out["signals.json"].read_text())


def bench_run(run: Path, tmp: Path) -> None:
    site = json.loads((run / "01_site" / "site.json").read_text()) if (run / "01_site" / "site.json").is_file() else {}
    seed = site.get("seed", site.get("site", {}).get("seed", "?")) if isinstance(site, dict) else "?"
    gt_l = gt_instances(run / "01_site" / "gt_mesh.ply", 6)
    gt_s = gt_instances(run / "01_site" / "gt_mesh.ply", 7)
    before = (one(run, "*_apply_alignment/aligned.xodr")).read_text()
    variants = {"netconvert (before)": (before, None)}
    pred = one(run, "*_backproject/labels.npy")
    if pred is not None:
        variants["predicted labels (default)"] = run_place(run, pred, tmp / f"{run.parent.name}_pred")
        variants["predicted labels, pole_heads=false"] = run_place(run, pred, tmp / f"{run.parent.name}_nopole",
                                                                   roads.SignalParams(pole_heads=False))
    gtl = one(run, "*_gt_labels/gt_labels.npy")
    if gtl is not None:
        variants["ground-truth labels (upper bound)"] = run_place(run, gtl, tmp / f"{run.parent.name}_gt")
    print(f"\n### {run.relative_to(ROOT) if run.is_relative_to(ROOT) else run} (seed {seed}): "
          f"{len(gt_l)} ground-truth traffic lights, {len(gt_s)} signs\n")
    names = list(variants)
    print("| ground-truth light (x, y) | " + " | ".join(f"{n}: m" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    dist = {n: [] for n in names}
    pts = {n: landmark_xy(t, True) for n, (t, _) in variants.items()}
    for p in gt_l:
        row = []
        for n in names:
            d = nearest(p, pts[n])
            dist[n].append(d)
            row.append(f"{d:.2f}")
        print(f"| ({p[0]:.2f}, {p[1]:.2f}) | " + " | ".join(row) + " |")
    print("| **median / max** | " + " | ".join(f"**{np.median(dist[n]):.2f} / {np.max(dist[n]):.2f}**" for n in names)
          + " |")
    print("| lights within 1 m | "
          + " | ".join(f"{int(np.sum(np.asarray(dist[n]) <= 1.0))} / {len(gt_l)}" for n in names) + " |")
    print()
    # pairing: on the demo each light serves the approach whose right kerb it stands on (layout.py)

    from twinkit_roads.reflines import reference_lines

    refs = reference_lines(ET.fromstring(before))
    print("| labels | approaches paired with the light at their lanes' kerb (demo layout) |")
    print("|---|---|")
    for n, (t, doc) in variants.items():
        if doc is None:
            continue
        ok, total = 0, 0
        for road in sorted({x["road"] for x in doc["signals"] if x["kind"] == "light" and x["source"] == "scan"}):
            inst = next(x["instance_position"] for x in doc["signals"] if x["road"] == road and x["kind"] == "light")
            g = min(gt_l, key=lambda p: np.hypot(p[0] - inst[0], p[1] - inst[1]))
            total += 1
            ok += refs[road].project(g[:2])[1] < 0  # netconvert's light heads control right lanes
        print(f"| {n} | {ok} / {total} |")
    print()
    print("| labels | scanned lights kept | signs kept | clusters rejected | light signals from scan / netconvert | "
          "signs written | signs within 1 m of a true sign | max CARLA position error m |")
    print("|---|---|---|---|---|---|---|---|")
    for n, (t, doc) in variants.items():
        if doc is None:
            continue
        sg = [s for s in doc["signals"] if s["kind"] == "sign"]
        lt = [s for s in doc["signals"] if s["kind"] == "light"]
        ok_signs = sum(1 for s in sg
                       if gt_s and min(np.hypot(*(np.asarray(s["position"][:2]) - g[:2])) for g in gt_s) <= 1.0)
        err = max((s["carla_position_error_m"] or 0.0) for s in doc["signals"]) if doc["signals"] else 0.0
        print(f"| {n} | {sum(i['kind'] == 'light' for i in doc['instances'])} | "
              f"{sum(i['kind'] == 'sign' for i in doc['instances'])} | {len(doc['rejected_clusters'])} | "
              f"{sum(s['source'] == 'scan' for s in lt)} / {sum(s['source'] == 'netconvert' for s in lt)} | "
              f"{len(sg)} | {ok_signs} / {len(sg)} | {err:.3f} |")
    print("\nJunction signal plan as CARLA 0.9.16 runs it (twinkit.street.lights) and the signs' types:\n")
    print(PLAN_HEAD)
    for n, (t, _) in variants.items():
        print(plan_row(n, t, gt_l))
    typed = [(s["id"], s["type"], s["note"]) for s in (variants.get("predicted labels (default)", ("", None))[1] or
                                                       {"signals": []})["signals"] if s["kind"] == "sign"]
    for sid, typ, note in typed:
        print(f"- {sid}: type {typ}: {note}")


def plan_row(name: str, text: str, gt_l: list | None = None) -> str:
    """One Markdown row: CARLA's emulated light plan (twinkit.street.lights) and the signals of a map."""
    from twinkit.street.lights import light_plan

    plan = light_plan(text)
    js = plan["junctions"]
    sigs = list(ET.fromstring(text).iter("signal"))
    lights = [x for x in sigs if x.get("type") in CARLA_LIGHT_TYPES]
    signs = [x for x in sigs if x.get("type") not in CARLA_LIGHT_TYPES]
    near = "-"
    if gt_l:
        pts = landmark_xy(text, True)
        d = [nearest(p, pts) for p in gt_l]
        near = f"{sum(v <= 1.0 for v in d)} / {len(gt_l)}"
    z = [abs(float(x.get("zOffset", 0.0))) for x in lights]
    return (f"| {name} | {len(js)} | {max((v['groups'] for v in js.values()), default=0)} | "
            f"{sum(len(v['conflicts']) for v in js.values())} | {len(lights)} | {near} | "
            f"{max(z, default=0.0):.2f} | {sum(x.get('type') in ('206', '205', '274') for x in signs)} | "
            f"{sum(x.get('type') == '-1' for x in signs)} |")


PLAN_HEAD = ("| map | signalised junctions | light groups per junction (max) | crossing approaches green together "
             "(pairs) | light signals | true lights with a head within 1 m | max abs light zOffset m | signs typed "
             "206/205/274 | signs type -1 |\n|---|---|---|---|---|---|---|---|---|")


def bench_osm(osm: Path, tmp: Path, centre: tuple[float, float], half_m: float = 150.0) -> None:
    """netconvert a real OSM crop (CARLA's importer options, convert.py) and write its signal plan."""
    from twinkit_roads.convert import ConvertParams, run_netconvert
    from twinkit_roads.osmio import crop, read_osm, write_osm_xml
    from twinkit_roads.signals import place_signals

    lon, lat = centre
    dlat, dlon = half_m / 110540.0, half_m / (111320.0 * np.cos(np.radians(lat)))
    box = (lat - dlat, lon - dlon, lat + dlat, lon + dlon)
    data = crop(read_osm(osm), box)
    write_osm_xml(data, tmp / "crop.osm", box)
    proj = f"+proj=tmerc +lat_0={lat} +lon_0={lon} +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m +no_defs"
    run_netconvert(tmp / "crop.osm", tmp / "crop.xodr", proj, ConvertParams())
    before = (tmp / "crop.xodr").read_text()
    from pyproj import Transformer

    from twinkit_roads.signtypes import osm_sign_nodes

    tr = Transformer.from_crs("EPSG:4326", proj, always_xy=True)
    nodes = osm_sign_nodes(tmp / "crop.osm", lambda ll: np.stack(tr.transform(ll[:, 0], ll[:, 1]), 1))
    after, placed, log = place_signals(before, [], osm_signs=nodes)
    kinds = [k for _, _, k in nodes]
    print(f"\n### {osm.name}: {2 * half_m:.0f} m box at ({lat:.5f}, {lon:.5f}), "
          f"{data.count()['traffic_signals']} OSM traffic_signals nodes\n")
    print(PLAN_HEAD)
    print(plan_row("netconvert (before)", before))
    print(plan_row("place_signals, no scan, OSM sign nodes (after)", after))
    print(f"\nOSM sign nodes in the crop: {kinds.count('stop')} stop, {kinds.count('yield')} give way, "
          f"{kinds.count('speed')} speed limit; written from OSM alone: "
          f"{sum(p.source == 'osm' for p in placed)}")
    for ln in log[:12]:
        print(f"- {ln}")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="append", type=Path, help="a finished pointcloud_site demo run folder")
    ap.add_argument("--osm", type=Path, default=ROOT.parent / "shared" / "data" / "osm" / "helsinki_center.osm.pbf",
                    help="a real OSM extract for the junction-plan table (skipped when absent)")
    ap.add_argument("--osm-centre", type=float, nargs=2, default=(24.93795, 60.17006), metavar=("LON", "LAT"),
                    help="centre of the 300 m crop (default: the densest traffic signals of helsinki_center)")
    a = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    runs = [r.resolve() for r in a.run] if a.run else RUNS
    print("## Signals vs the demo site's ground truth (horizontal distance from each true traffic light to the "
          "nearest traffic-light signal, as carla.Map places it)")
    found = False
    with tempfile.TemporaryDirectory() as td:
        for run in runs:
            if not (run / "01_site" / "gt_mesh.ply").is_file() or one(run, "*_apply_alignment/aligned.xodr") is None:
                print(f"\n{run}: no finished demo run with ground truth; "
                      "run `twinkit recipe=pointcloud_site site=demo` first")
                continue
            found = True
            bench_run(run, Path(td))
        if a.osm.is_file():
            bench_osm(a.osm, Path(td), tuple(a.osm_centre))
    return 0 if found else 0


if __name__ == "__main__":
    sys.exit(main())
