"""Benchmark road_source=scan (roads derived from the scan, no OSM) on finished demo runs; prints a
Markdown table.

    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py [--run outputs/demo] [--run ...]

Needs a finished `twinkit recipe=pointcloud_site site=demo` run (any road_source: only the mesh, the
labels and the truth are read): NN_texture/textured_mesh.ply, NN_backproject/labels.npy (predicted),
NN_gt_labels/gt_labels.npy, 01_site/roads_truth.json. For each label source the scan road source runs
here (through the registry, the engine's code path, default parameters) and is scored as the OSM route
is in apply_alignment: RMSE of the driving-lane centre points (carla.Map, 1 m, outside junctions, 2 m
inside the truth's ends) to the nearest true centre line; lanes on road: share of the driving lanes'
area (outside junctions) on road-labelled surface of the ground-truth labels (and of the labels used).
When the run itself used road_source=scan, its apply_alignment numbers (after align_roads' curb fit)
are printed too.

    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py --coverage --run RUN [--run ...]

Coverage mode, any finished run (a real cloud's too): how much of the street inside the capture the network
from the scan covers, and which check dropped how much. The street: the true lane centre lines
(roads_truth.json, the demo) or the middle of the road-labelled ground (the skeleton of the run's own labels'
road faces where the road is at least 3 m wide; ``scan.street_axis``). Covered: a street point within half the
carriageway plus ``--tol`` of a road's axis, running its way; with the map at hand (the final network), a second
figure also counts the street points on the driving lanes of the map's junctions. The run's scan_roads.json (road_source=scan) gives the final
network and, per stage (derived, trim_unsupported, each lane_check round), the roads kept; a run without it
gets the scan source run here (predicted labels, default parameters).

    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py --coverage --run RUN --truth-cloud SCAN.ply
    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py --labelled [bench/results/labelled]

With hand labels: the street is drawn from a labelled cloud's own classes (a PLY with x, y, z and
``cs_trainid``, as ../shared/data/labelled/semantickitti/), moved onto the mesh (each vertex takes its nearest
labelled point's class within ``--truth-max-m``, 0.5 m; farther vertices none), not from the run's predicted
labels, which on colourless and aerial clouds are what is being judged. ``--labelled`` does this for every run
``bench/bench_labelled.py`` left in its output folder (``<folder>/runs/<scan>``, the labels' steps only: the
scan source runs here on its mesh and predicted labels), and adds a what-if row per scan: the hand labels
given to the scan source as its labels (what the derivation does with perfect labels). Without arguments
(``make bench``) the demo table is followed by this one when bench_labelled's runs and ../shared exist.

    .venv/bin/python plugins/twinkit-roads/bench/bench_scan_roads.py --scorecard [outputs/bench_real_scans]

Issue 46's item 1 on every real capture ``bench_real_scans.py`` ran through the main job (the shared clouds and
the hand-labelled sweeps, roads from the scan): the street covered by the final map, with and without its
junctions' lanes (the hand-labelled road as the reference where there is one, else the street centre lines drawn by
hand in drawn_streets.json, else the road-labelled ground), the median distance from the street to the roads' axes,
and the drop test's gate and widest hole over the driving lanes, and why its failing rays fail (drop_test.json ``failing``: through ground the scan never
measured, through holes in the mesh, on a step or a bump; how many at a lane's edge); ``make bench`` prints it last
when those runs exist.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twinkit.testing import run_plugin

ROOT = Path(__file__).resolve().parents[3]
LABELLED = ROOT.parent / "shared" / "data" / "labelled" / "semantickitti"
LABELLED_RUNS = ROOT / "bench" / "results" / "labelled"
REAL_RUNS = ROOT / "outputs" / "bench_real_scans"  # plugins/twinkit-pointcloud/bench/bench_real_scans.py's runs
DRAWN = Path(__file__).with_name("drawn_streets.json")  # street centre lines drawn by hand on unlabelled real clouds


def one(folder: Path, pattern: str) -> Path | None:
    hits = sorted(folder.glob(pattern))
    return hits[-1] if hits else None


def bench_run(run: Path, tmp: Path, sources: list[str]) -> list[dict]:
    from twinkit.artefacts import read_textured_mesh
    from twinkit_roads.scan import lanes_on_road

    site_json = json.loads((run / "01_site" / "site.json").read_text()) if (run / "01_site" / "site.json").is_file() else {}
    import yaml  # noqa: F401 -- (hydra's dependency) only to fail early when the environment is wrong

    mesh_p = one(run, "*_texture/textured_mesh.ply")
    pred = one(run, "*_backproject/labels.npy")
    gt_p = one(run, "*_gt_labels/gt_labels.npy")
    truth = one(run, "01_site/roads_truth.json")
    if not (mesh_p and gt_p and truth):
        sys.exit(f"{run}: not a finished demo run (textured_mesh.ply, gt_labels.npy, roads_truth.json needed)")
    site = _site(run)
    mesh = read_textured_mesh(mesh_p)
    gt = np.load(gt_p)
    rows = []
    for src in sources:
        inputs = {"in_textured_mesh_ply": mesh_p, "in_roads_truth_json": truth, "in_gt_labels_npy": gt_p}
        if pred is not None:
            inputs["in_labels_npy"] = pred
        t0 = time.perf_counter()
        labels, _, variant = src.partition(":")
        extra = {"use_curbs": False} if variant == "nocurbs" else {}
        out = run_plugin("road_source", "scan", tmp / src.replace(":", "_"), inputs, site=site, labels=labels, **extra)
        dt = time.perf_counter() - t0
        doc = json.loads(out["scan_roads.json"].read_text())
        text = out["opendrive.xodr"].read_text(encoding="utf-8")
        on_gt = lanes_on_road(text, mesh.vertices, mesh.faces, gt)
        rows.append({"labels": src, "roads": len(doc["roads"]),
                     "junctions": sum(n["kind"] == "junction" for n in doc["nodes"]),
                     "driving_lanes": sum(r["lanes"] * (2 if r["two_way"] else 1) for r in doc["roads"]),
                     "sidewalk_lanes": sum((r["sidewalk_left_m"] > 0) + (r["sidewalk_right_m"] > 0) for r in doc["roads"]),
                     "widths": ", ".join(f"{r['carriageway_m']:.2f}" for r in doc["roads"]),
                     "rmse": doc.get("centreline_rmse_m"), "points": doc.get("centreline_points"),
                     "on_gt": on_gt["on_road_share"], "centre_on_gt": on_gt["centre_on_road_share"],
                     "on_used": (doc.get("lanes_on_road") or {}).get("on_road_share"), "s": dt,
                     "png": out["scan_roads.png"]})
    del site_json
    return rows


def _site(run: Path) -> dict:
    """The demo site's georeference (the scan source writes the site frame's PROJ string)."""
    import yaml

    conf = yaml.safe_load((ROOT / "conf" / "site" / "demo.yaml").read_text())
    return {k: conf[k] for k in ("name", "crs", "base_point") if k in conf}


def pipeline_numbers(run: Path) -> dict | None:
    """apply_alignment's numbers when the run used road_source=scan (roads_check.json source scan)."""
    chk = one(run, "*_osm_to_opendrive/roads_check.json")
    rec = one(run, "*_apply_alignment/step.json")
    if not chk or not rec or json.loads(chk.read_text()).get("source") != "scan":
        return None
    m = json.loads(rec.read_text()).get("metrics") or {}
    return {k: m.get(k) for k in ("centreline_rmse_before_m", "centreline_rmse_after_m", "tx_m", "ty_m", "yaw_deg")}


def truth_vertex_labels(vertices: np.ndarray, cloud_ply: Path, points_meta: Path | None, max_m: float) -> np.ndarray:
    """(n,) uint8 CityScapes trainIds of a mesh's vertices from a hand-labelled cloud (``cs_trainid``): each vertex
    takes its nearest labelled point's class within ``max_m``, 255 (none) beyond. The cloud's points are moved
    into the run's frame by the shift read_cloud recorded (``points_meta.json`` ``frame.shift_m``)."""
    from plyfile import PlyData
    from scipy.spatial import cKDTree

    pv = PlyData.read(str(cloud_ply))["vertex"].data
    if "cs_trainid" not in pv.dtype.names:
        sys.exit(f"{cloud_ply}: no cs_trainid field (a hand-labelled cloud is needed)")
    xyz = np.stack([pv["x"], pv["y"], pv["z"]], axis=1).astype(np.float64)
    if points_meta is not None and points_meta.is_file():
        xyz -= np.asarray((json.loads(points_meta.read_text()).get("frame") or {}).get("shift_m") or [0, 0, 0], float)
    cls = np.asarray(pv["cs_trainid"], np.uint8)
    keep = cls != 255
    d, idx = cKDTree(xyz[keep]).query(np.asarray(vertices, np.float64), workers=-1)
    out = cls[keep][idx].astype(np.uint8)
    out[d > max_m] = 255
    return out


def coverage_rows(run: Path, tmp: Path, tol: float, truth_labels: np.ndarray | None = None,
                  mask_labels: np.ndarray | None = None,
                  drawn: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[str, float, list[dict]]:
    """The street's reference, its length (m) and one row per stage of the scan network: roads, axis length,
    street covered (m, share) and what the stage dropped (m of street); the final row also has ``offset_m``, the
    median distance from the covered street points to the nearest road axis. ``truth_labels`` (per vertex): the
    street from these hand labels; ``drawn``: the street's points every 0.25 m and their directions (site frame,
    ``drawn_reference``); ``mask_labels`` (per vertex): the scan source runs here with these as its labels."""
    from twinkit.artefacts import read_textured_mesh
    from twinkit_roads.scan import covered, in_junctions, read_truth, street_axis
    from twinkit_roads.scan.geometry import resample
    from twinkit_roads.scan.measures import directions

    mesh_p = one(run, "*_texture/textured_mesh.ply")
    labels_p = one(run, "*_backproject/labels.npy")
    truth_p = one(run, "01_site/roads_truth.json")
    doc_p = one(run, "*_fetch_roads/scan_roads.json")
    if mesh_p is None:
        sys.exit(f"{run}: no textured_mesh.ply (a finished pointcloud_site run is needed)")
    if mask_labels is not None:
        tmp.mkdir(parents=True, exist_ok=True)
        labels_p = tmp / "mask_labels.npy"
        np.save(labels_p, np.asarray(mask_labels, np.uint8))
        doc_p = None
    if doc_p is None or "stages" not in json.loads(doc_p.read_text()):
        inputs = {"in_textured_mesh_ply": mesh_p, **({"in_labels_npy": labels_p} if labels_p else {}),
                  **({"in_roads_truth_json": truth_p} if truth_p else {})}
        for name, pattern in (("in_points_meta_json", "*_read_cloud/points_meta.json"),
                              ("in_points_ply", "*_read_cloud/points.ply")):
            if one(run, pattern) is not None:  # as the pipeline gives them: the point spacing, the measured ground
                inputs[name] = one(run, pattern)
        out = run_plugin("road_source", "scan", tmp / run.name, inputs, site=_site(run))
        doc_p = out["scan_roads.json"]
    doc = json.loads(doc_p.read_text())
    mesh = read_textured_mesh(mesh_p)
    if drawn is not None:
        (ref, dirs), step, what = drawn, 0.25, "drawn street centre lines"
    elif truth_labels is not None:
        (ref, dirs), step = street_axis(mesh.vertices, mesh.faces, truth_labels), 0.25
        what = "hand-labelled road"
    elif truth_p is not None:
        lines = [resample(ln, 0.25) for ln in read_truth(truth_p) or []]
        ref, step = np.concatenate(lines), 0.25
        dirs = np.concatenate([directions(ln, 1.0) for ln in lines])
        inside = _inside(ref, np.asarray(mesh.vertices)[:, :2])
        ref, dirs, what = ref[inside], dirs[inside], "roads_truth lane centres"
    elif labels_p is None:
        sys.exit(f"{run}: no roads_truth.json and no labels.npy: nothing says where the street is")
    else:
        (ref, dirs), step = street_axis(mesh.vertices, mesh.faces, np.load(labels_p)), 0.25
        what = "road-labelled ground"
    street_m = len(ref) * step
    stages = list(doc.get("stages", []))
    stages.append({"stage": "final", "roads": len(doc["roads"]),
                   "length_m": round(sum(r["length_m"] for r in doc["roads"]), 1),
                   "arms": [{"axis": r["axis"], "width_m": r["carriageway_m"]} for r in doc["roads"]]})
    rows, prev = [], None
    xodr = doc_p.parent / "opendrive.xodr"
    for st in stages:
        cov = covered(ref, dirs, st["arms"], tol)
        m = float(cov.sum() * step)
        rows.append({"stage": st["stage"], "roads": st["roads"], "length_m": st["length_m"], "covered_m": m,
                     "share": m / street_m if street_m else 0.0, "dropped_m": (prev - m) if prev is not None else None})
        if st["stage"] == "final" and xodr.is_file():  # the map's junction lanes serve the street through them
            both = cov | in_junctions(ref, xodr.read_text(encoding="utf-8"))
            rows[-1]["share_with_junctions"] = float(both.sum() * step) / street_m if street_m else 0.0
        if st["stage"] == "final":
            rows[-1]["offset_m"] = _axis_offset(ref[cov], st["arms"])
        prev = m
    if doc.get("no_roads"):
        rows.append({"stage": f"no roads: {doc['no_roads']}", "roads": 0, "length_m": 0.0, "covered_m": 0.0,
                     "share": 0.0, "dropped_m": prev})
    return what, street_m, rows


def _axis_offset(pts: np.ndarray, arms: list[dict]) -> float | None:
    """The median distance (m) from street points to the nearest road axis of ``arms`` (None without both)."""
    from twinkit_roads.scan.geometry import on_polyline

    lines = [np.asarray(a["axis"], float)[:, :2] for a in arms if len(a["axis"]) >= 2]
    if not len(pts) or not lines:
        return None
    return float(np.median(np.min([on_polyline(pts, ln)[0] for ln in lines], axis=0)))


def drawn_reference(run: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """The street drawn by hand for a real cloud without hand labels (``drawn_streets.json``, keyed by the run's
    name), moved into the run's site frame by the shift read_cloud recorded (``points_meta.json`` ``frame``):
    points every 0.25 m and their directions, none when the capture holds no street; None when nothing is drawn
    for it. Exits when the run's frame is not the drawing's CRS shifted."""
    from twinkit_roads.scan.geometry import resample
    from twinkit_roads.scan.measures import directions

    entry = json.loads(DRAWN.read_text()).get(run.name)
    if not isinstance(entry, dict):
        return None
    meta = one(run, "*_read_cloud/points_meta.json")
    frame = json.loads(meta.read_text()).get("frame", {}) if meta else {}
    if not entry["lines"]:
        return np.zeros((0, 2)), np.zeros((0, 2))
    if frame.get("target_crs") != entry["crs"] or frame.get("shift_m") is None:
        sys.exit(f"{run}: its site frame ({frame.get('target_crs')}) is not {entry['crs']} shifted, as "
                 f"{DRAWN.name} draws {run.name}'s streets: run it with bench_real_scans.py")
    shift = np.asarray(frame["shift_m"][:2], float)
    lines = [resample(np.asarray(ln, float) - shift, 0.25) for ln in entry["lines"]]
    return np.concatenate(lines), np.concatenate([directions(ln, 1.0) for ln in lines])


def _inside(pts: np.ndarray, xy: np.ndarray, cell: float = 2.0) -> np.ndarray:
    """Points over the capture: a 2 m cell holding mesh vertices."""
    lo = xy.min(0)
    occ = {tuple(c) for c in np.floor((xy - lo) / cell).astype(int)}
    return np.array([tuple(c) in occ for c in np.floor((pts - lo) / cell).astype(int)], bool)


def print_coverage(runs: list[Path], base: Path, tol: float, truth_cloud: Path | None = None,
                   truth_max_m: float = 0.5) -> None:
    print(f"| run | street (reference) m | stage | roads | axis length m | street covered m (tol {tol} m) | share | "
          "dropped by this stage m |")
    print("|---|---|---|---|---|---|---|---|")
    for i, run in enumerate(runs):
        truth = None
        if truth_cloud is not None:
            from twinkit.artefacts import read_textured_mesh

            mesh = read_textured_mesh(one(run.resolve(), "*_texture/textured_mesh.ply"))
            truth = truth_vertex_labels(mesh.vertices, truth_cloud, one(run.resolve(), "*_read_cloud/points_meta.json"),
                                        truth_max_m)
        what, street_m, rows = coverage_rows(run.resolve(), base / f"run{i}", tol, truth_labels=truth)
        _print_rows(str(run), what, street_m, rows)


def _print_rows(name: str, what: str, street_m: float, rows: list[dict]) -> None:
    for r in rows:
        print(f"| {name} | {street_m:.1f} ({what}) | {_stage_cells(r)} |")


def _stage_cells(r: dict) -> str:
    """A stage row's cells: stage, roads, axis length, street covered, share, dropped."""
    drop = f"{r['dropped_m']:.1f}" if r["dropped_m"] is not None else "-"
    share = f"{100 * r['share']:.0f} %"
    if "share_with_junctions" in r:  # the final map's junction lanes serve the street through them
        share += f" ({100 * r['share_with_junctions']:.0f} % with the junctions' lanes)"
    return f"{r['stage']} | {r['roads']} | {r['length_m']:.1f} | {r['covered_m']:.1f} | {share} | {drop}"


def labelled_coverage(out: Path, base: Path, tol: float, truth_max_m: float = 0.5) -> list[dict]:
    """Per run that bench_labelled left in ``out`` (``runs/<scan>``, its scan in ../shared/data/labelled): the
    final coverage of the street drawn from the hand labels, with the predicted labels (as the pipeline runs)
    and with the hand labels given to the scan source (what-if). Prints the per-stage table; returns the rows."""
    from twinkit.artefacts import read_textured_mesh

    summary = []
    print(f"| scan | street (hand-labelled road) m | labels given to the scan source | stage | roads | "
          f"axis length m | street covered m (tol {tol} m) | share | dropped by this stage m |")
    print("|---|---|---|---|---|---|---|---|---|")
    for run in sorted(p for p in (out / "runs").glob("*") if p.is_dir()):
        scan = LABELLED / f"{run.name}.ply"
        if not scan.is_file() or one(run, "*_texture/textured_mesh.ply") is None:
            continue
        mesh = read_textured_mesh(one(run, "*_texture/textured_mesh.ply"))
        truth = truth_vertex_labels(mesh.vertices, scan, one(run, "*_read_cloud/points_meta.json"), truth_max_m)
        row = {"scan": run.name}
        for given, mask in (("predicted", None), ("hand labels (what-if)", truth)):
            _, street_m, rows = coverage_rows(run, base / run.name / given.split()[0], tol, truth_labels=truth,
                                              mask_labels=mask)
            for r in rows:
                print(f"| {run.name} | {street_m:.1f} | {given} | {_stage_cells(r)} |")
            final = next(r for r in rows if r["stage"] == "final")
            row.update({"street_m": street_m, given: final["share"],
                        given + " with junctions": final.get("share_with_junctions", final["share"])})
        summary.append(row)
    if summary:
        print("\n| scan | street m | covered, predicted labels | with the junctions' lanes | covered, hand labels "
              "(what-if) | with the junctions' lanes |")
        print("|---|---:|---:|---:|---:|---:|")
        keys = ("predicted", "predicted with junctions", "hand labels (what-if)",
                "hand labels (what-if) with junctions")
        for r in summary:
            print(f"| {r['scan']} | {r['street_m']:.1f} | " + " | ".join(f"{100 * r[k]:.0f} %" for k in keys) + " |")
        means = [f"{100 * np.mean([r[k] for r in summary]):.0f} %" for k in keys]
        print(f"| **mean** | | **{means[0]}** | {means[1]} | {means[2]} | {means[3]} |")
    return summary


def scorecard(out: Path, base: Path, tol: float, truth_max_m: float = 0.5) -> list[dict]:
    """Issue 46's item 1 on every real capture that ``bench_real_scans.py`` ran through the main job (``out/<name>``,
    roads from the scan): the street covered by the final map (its roads, and with its junctions' lanes), against
    the hand-labelled road where the capture has hand labels (``../shared/data/labelled``), else the street centre
    lines drawn by hand (``drawn_streets.json``), else its own road-labelled ground; how far the roads' axes lie
    from the street; the drop test's gate over the driving lanes and its widest hole. Met: 90 % of the street with
    the junctions' lanes, the gate at 99.9 %, no hole over 0.25 m; on a capture drawn without a street (a park),
    no road. Prints the table; returns the rows."""
    from twinkit.artefacts import read_textured_mesh
    from twinkit.surface.watertight import ground_share

    rows = []
    for run in sorted(p for p in out.glob("*") if p.is_dir() and one(p, "*_fetch_roads/scan_roads.json")):
        mesh_p, dt_p = one(run, "*_texture/textured_mesh.ply"), one(run, "*_drop_test/drop_test.json")
        if mesh_p is None:
            continue
        scan = LABELLED / f"{run.name}.ply"
        truth = None
        if scan.is_file():
            truth = truth_vertex_labels(read_textured_mesh(mesh_p).vertices, scan,
                                        one(run, "*_read_cloud/points_meta.json"), truth_max_m)
        drawn = None if truth is not None else drawn_reference(run)
        what, street_m, stages = coverage_rows(run, base / run.name, tol, truth_labels=truth, drawn=drawn)
        final = next((r for r in stages if r["stage"] == "final"), None)
        lane = json.loads(dt_p.read_text())["lanes"].get("driving") if dt_p else None
        gate = ground_share(lane) if lane else None
        row = {"capture": run.name, "reference": what, "street_m": street_m,
               "covered": final["share"] if final else 0.0,
               "with_junctions": final.get("share_with_junctions", final["share"]) if final else 0.0,
               "offset_m": final.get("offset_m") if final else None,
               "roads": final["roads"] if final else 0, "roads_m": final["length_m"] if final else 0.0,
               "gate_pct": gate, "widest_hole_m": lane.get("widest_hole_m") if lane else None,
               "failing": (lane or {}).get("failing")}
        if street_m == 0:  # a capture with no street (drawn so): met when its map has no road
            row["met"] = row["roads"] == 0
        else:
            row["met"] = (row["with_junctions"] >= 0.9 and gate is not None and gate >= 99.9
                          and (row["widest_hole_m"] or 0.0) <= 0.25)
        rows.append(row)
    if rows:
        print("| capture | street m (reference) | covered by its roads | with the junctions' lanes (>= 90 %) | "
              "road axis to the street m (median) | drop test gate, driving (>= 99.9 %) | widest hole m (<= 0.25) | "
              "failing rays: never measured / holes / steps (at a lane's edge) | item 1 met |")
        print("|---|---|---:|---:|---:|---:|---:|---|---|")
        for r in rows:
            gate = "-" if r["gate_pct"] is None else f"{r['gate_pct']:.2f} %"
            hole = "-" if r["widest_hole_m"] is None else f"{r['widest_hole_m']:.2f}"
            why = r["failing"]
            causes = "-" if not why else (f"{why['fall_unscanned']} / {why['fall_hole']} / {why['step_or_bump']} "
                                          f"({why.get('at_lane_edge', '-')})")
            offset = "-" if r["offset_m"] is None else f"{r['offset_m']:.2f}"
            if r["street_m"] == 0:
                cov = f"no street: {r['roads']} roads ({r['roads_m']:.0f} m)"
                cov = f"{cov} | {cov}"
            else:
                cov = f"{100 * r['covered']:.0f} % | {100 * r['with_junctions']:.0f} %"
            print(f"| {r['capture']} | {r['street_m']:.1f} ({r['reference']}) | {cov} | {offset} | {gate} | {hole} | "
                  f"{causes} | {'yes' if r['met'] else 'no'} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", action="append", type=Path, help="a finished demo run folder (default outputs/demo)")
    ap.add_argument("--labels", default="gt,predicted,none,gt:nocurbs,predicted:nocurbs",
                    help="label sources to compare (comma separated; ':nocurbs': the labels alone, use_curbs=false)")
    ap.add_argument("--keep", type=Path, help="keep the outputs (pictures) in this folder")
    ap.add_argument("--coverage", action="store_true", help="street coverage per check instead (any run)")
    ap.add_argument("--tol", type=float, default=1.0, help="coverage: metres beyond half the carriageway")
    ap.add_argument("--truth-cloud", type=Path, help="coverage: the street from this hand-labelled cloud (cs_trainid)")
    ap.add_argument("--truth-max-m", type=float, default=0.5,
                    help="hand labels reach the vertices within this distance of a labelled point (m)")
    ap.add_argument("--labelled", nargs="?", const=LABELLED_RUNS, type=Path,
                    help="coverage against the hand labels on bench_labelled's runs in this folder")
    ap.add_argument("--scorecard", nargs="?", const=REAL_RUNS, type=Path,
                    help="issue 46 item 1 on bench_real_scans.py's runs in this folder (coverage and drop test)")
    a = ap.parse_args()
    runs = a.run or [ROOT / "outputs" / "demo"]
    if a.scorecard is not None:
        with tempfile.TemporaryDirectory() as d:
            if not scorecard(a.scorecard, a.keep or Path(d), a.tol, a.truth_max_m):
                sys.exit(f"no runs with roads from the scan in {a.scorecard} (run bench_real_scans.py)")
        return
    if a.labelled is not None:
        with tempfile.TemporaryDirectory() as d:
            if not labelled_coverage(a.labelled, a.keep or Path(d), a.tol, a.truth_max_m):
                sys.exit(f"no bench_labelled runs with their scans in {a.labelled}/runs (run bench/bench_labelled.py)")
        return
    if a.coverage:
        with tempfile.TemporaryDirectory() as d:
            print_coverage(runs, a.keep or Path(d), a.tol, a.truth_cloud, a.truth_max_m)
        return
    sources = [s.strip() for s in a.labels.split(",") if s.strip()]
    with tempfile.TemporaryDirectory() as d:
        base = a.keep or Path(d)
        print("| run | labels | roads | junctions | driving lanes | sidewalk lanes | carriageway widths m | "
              "lane centre RMSE m | points | lanes on road (truth labels) | centres on road (truth) | "
              "lanes on road (labels used) | s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for run in runs:
            run = run.resolve()
            for r in bench_run(run, base / run.name, sources):
                name = run.relative_to(ROOT) if run.is_relative_to(ROOT) else run
                used = f"{100 * r['on_used']:.1f} %" if r["on_used"] is not None else "-"
                print(f"| {name} | {r['labels']} | {r['roads']} | {r['junctions']} | {r['driving_lanes']} | "
                      f"{r['sidewalk_lanes']} | {r['widths']} | {r['rmse']:.3f} | {r['points']} | "
                      f"{100 * r['on_gt']:.1f} % | {100 * r['centre_on_gt']:.1f} % | {used} | {r['s']:.1f} |")
            pn = pipeline_numbers(run)
            if pn:
                print(f"\n{run.name}: the run's own apply_alignment (road_source=scan, after align_roads): "
                      f"RMSE {pn['centreline_rmse_before_m']} m before, {pn['centreline_rmse_after_m']} m after the "
                      f"curb fit (t = {pn['tx_m']}, {pn['ty_m']} m, yaw {pn['yaw_deg']} deg)\n")
    if a.run is None and LABELLED.is_dir() and (LABELLED_RUNS / "runs").is_dir():
        print("\n### Coverage of the hand-labelled street on the real SemanticKITTI sweeps (bench_labelled's runs)\n")
        with tempfile.TemporaryDirectory() as d:
            labelled_coverage(LABELLED_RUNS, a.keep or Path(d), a.tol, a.truth_max_m)
    if a.run is None and REAL_RUNS.is_dir():
        print("\n### Issue 46 item 1 on the real captures (bench_real_scans.py's runs: the main job, roads from the "
              "scan)\n")
        with tempfile.TemporaryDirectory() as d:
            scorecard(REAL_RUNS, a.keep or Path(d), a.tol, a.truth_max_m)


if __name__ == "__main__":
    main()
