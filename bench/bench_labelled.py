"""The twin's labels on real hand-labelled lidar: the four SemanticKITTI scans in
../shared/data/labelled/semantickitti/ (README there), each run as a site of its own.

For each scan: a copy with x, y, z and intensity only (the truth never reaches the pipeline), the
default recipe's steps up to the labels (recipes/pointcloud_labels.yaml: pointcloud_site without roads
and exports, as pointcloud_site runs with road_source=none on a site without OSM), then the labels moved onto the scan's points
by nearest mesh vertex in the run's frame and scored on the points with a class
(twinkit_segmentation.metrics.score_points): coarse accuracy (twinkit.cityscapes.COARSE), accuracy,
mean IoU over the classes present, IoU per class, the share of labelled points far from the mesh, and
the upper bound of the transfer (every vertex given its nearest truth point's class).

Prints a Markdown table (per scan and mean) and, when an earlier run of this bench left one in the
output folder, its table and the difference. Writes labelled.json, labelled.md, the label-free copies
(clouds/), the runs (runs/<scan>/NN_<step>/...) and a picture of one scan's labels beside its truth
(labelled_<scan>.png) into the output folder.

Run:  .venv/bin/python bench/bench_labelled.py [--scans seq00_000000,...] [--out DIR]
      .venv/bin/python bench/bench_labelled.py --only-score RUN_DIR [RUN_DIR ...] --out MY_DIR
          [--compare OTHER/labelled.json]   (score existing runs; compare with another run's table)
A RUN_DIR is a site folder (<out>/runs/<scan>) or anything holding its step folders; the scan is found
by the name of the file read_cloud read. Skips (exit 0) when ../shared is absent.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LABELLED = ROOT.parent / "shared" / "data" / "labelled" / "semantickitti"
DEFAULT_OUT = ROOT / "bench" / "results" / "labelled"
RECIPE = "pointcloud_labels"
CLOUD_FIELDS = ("x", "y", "z", "intensity")
COLUMNS = ("road", "sidewalk", "building", "vegetation", "terrain", "car", "pole")
PICTURE_SCAN = "seq00_000000"
PICTURE_HALF_M = 40.0      # the picture shows the dense middle of the sweep: +-40 m around the sensor
PICTURE_CELL_M = 0.1


# ----------------------------------------------------------------------------- inputs

def read_scan(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A labelled scan: (xyz (p, 3) float64 sensor frame, metres; intensity (p,) float32; cs_trainid (p,) uint8)."""
    from plyfile import PlyData

    v = PlyData.read(str(path))["vertex"].data
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    return xyz, np.asarray(v["intensity"], np.float32), np.asarray(v["cs_trainid"], np.uint8)


def label_free_copy(src: Path, dst: Path) -> Path:
    """Write ``dst``: the scan's x, y, z (float32) and intensity only, binary PLY; nothing else of ``src``."""
    from plyfile import PlyData, PlyElement

    v = PlyData.read(str(src))["vertex"].data
    out = np.empty(len(v), dtype=[(f, "<f4") for f in CLOUD_FIELDS])
    for f in CLOUD_FIELDS:
        out[f] = v[f]
    dst.parent.mkdir(parents=True, exist_ok=True)
    PlyData([PlyElement.describe(out, "vertex")]).write(str(dst))
    return dst


def run_scan(name: str, cloud: Path, runs_dir: Path, overrides: tuple[str, ...] = ()) -> tuple[Path, float]:
    """Run the labels' steps of the default recipe on ``cloud`` as site ``name`` (with Hydra ``overrides``, a
    variant to measure): (site folder, seconds)."""
    cmd = [sys.executable, "-m", "twinkit", f"recipe={RECIPE}", "site=lille", f"site.name={name}",
           f"site.inputs.cloud={cloud}", f"engine.outputs_dir={runs_dir}", *overrides]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode not in (0, 4):  # 4: a degraded result (a sweep's mesh is mostly ground fill): still scored
        raise RuntimeError(f"{name}: twinkit failed ({p.returncode}):\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}")
    if p.returncode == 4:
        print(f"{name}: degraded result (exit 4): " + " ".join(
            line.strip() for line in (p.stdout + p.stderr).splitlines() if line.strip().startswith("- "))[:400], flush=True)
    return runs_dir / name, time.perf_counter() - t0


# ----------------------------------------------------------------------------- a run's files

def _one(run_dir: Path, pattern: str) -> Path | None:
    hits = sorted(run_dir.glob(pattern))
    return hits[-1] if hits else None


def run_files(run_dir: Path) -> dict:
    """The files of a run that scoring needs: the textured mesh, the final labels (road_evidence's
    when it ran, else backproject's), points_meta.json. Raises FileNotFoundError naming what is missing."""
    run_dir = Path(run_dir)
    files = {"mesh": _one(run_dir, "*_texture/textured_mesh.ply"),
             "labels": _one(run_dir, "*_road_evidence/labels.npy") or _one(run_dir, "*_backproject/labels.npy"),
             "points_meta": _one(run_dir, "*_read_cloud/points_meta.json")}
    missing = [k for k, v in files.items() if v is None]
    if missing:
        raise FileNotFoundError(f"{run_dir}: no {', '.join(missing)} (a finished run's step folders?)")
    return files


def step_times(run_dir: Path) -> dict[str, float]:
    """Seconds per step (step.json ``duration_s``) of a run, by step folder name."""
    out = {}
    for sj in sorted(Path(run_dir).glob("[0-9][0-9]_*/step.json")):
        out[sj.parent.name] = float(json.loads(sj.read_text()).get("duration_s", float("nan")))
    return out


def run_frame_points(xyz: np.ndarray, points_meta: Path) -> np.ndarray:
    """The scan's points in the run's frame: read_cloud keeps a local cloud's coordinates, less the
    float64 shift it records (``frame.shift_m``); a ``cloud_frame`` placement is not expected here."""
    frame = json.loads(Path(points_meta).read_text())["frame"]
    if frame.get("cloud_frame") or frame.get("reprojected"):
        raise ValueError(f"{points_meta}: the cloud was placed or reprojected; the bench runs it as it is")
    return xyz - np.asarray(frame.get("shift_m") or [0.0, 0.0, 0.0], np.float64)


def score_run(run_dir: Path, scan: Path) -> tuple[dict, np.ndarray]:
    """Score one run against its scan: (score_points' dict plus ``scan``/``run``/``steps_s``, per-point labels)."""
    from twinkit import artefacts as A
    from twinkit_segmentation.metrics import score_points, transfer_nearest

    files = run_files(run_dir)
    mesh = A.read_textured_mesh(files["mesh"])
    labels = A.read_labels(files["labels"], len(mesh.vertices))
    xyz, _, truth = read_scan(scan)
    pts = run_frame_points(xyz, files["points_meta"])
    res = score_points(mesh.vertices, labels, pts, truth, faces=mesh.faces)
    res.update(scan=scan.stem, run=str(run_dir), labels_from=files["labels"].parent.name,
               vertices=int(len(mesh.vertices)), steps_s=step_times(run_dir))
    votes = _one(run_dir, "*_classify_geometry/geometry_votes.npy")
    if votes is not None:  # the 3D classifier alone through the same mesh: what the fusion and the cues add
        gv = np.load(votes)
        alone = np.where(gv.sum(axis=1) > 0, gv.argmax(axis=1), 255).astype(np.uint8)
        g = score_points(mesh.vertices, alone, pts, truth, upper_bound=False)
        res["geometry_alone"] = {k: g[k] for k in ("miou", "accuracy", "coarse_accuracy", "per_class")}
    point_labels, _ = transfer_nearest(mesh.vertices, labels, pts)
    return res, point_labels


def scan_of_run(run_dir: Path) -> Path:
    """The labelled scan a run read (by the file name read_cloud recorded)."""
    meta = json.loads(run_files(run_dir)["points_meta"].read_text())
    return LABELLED / meta["source"]["file"]


# ----------------------------------------------------------------------------- tables and picture

def _row(r: dict) -> dict[str, float]:
    per = r["per_class"]
    row = {"coarse acc": r["coarse_accuracy"], "acc": r["accuracy"], "mIoU": r["miou"]}
    for c in COLUMNS:
        row[c] = per[c]["iou"] if c in per else float("nan")
    if "far_share" in r:
        row["far>0.5 m %"] = 100.0 * r["far_share"]["0.5"]
        row["far>0.2 m %"] = 100.0 * r["far_share"]["0.2"]
        row["bound mIoU"] = r["upper_bound"]["miou"] if "upper_bound" in r else float("nan")
    return row


def rows(results: list[dict], part: str | None = None) -> dict[str, dict[str, float]]:
    """Table rows by scan name, and ``mean`` (of each column over the scans that have it). ``part``: score
    the results' ``part`` (e.g. ``geometry_alone``) instead of the results themselves, where they have it."""
    if part is not None:
        results = [{**r[part], "scan": r["scan"]} for r in results if part in r]
    out = {r["scan"]: _row(r) for r in results}
    if out:
        keys = next(iter(out.values())).keys()
        out["mean"] = {k: float(np.nanmean([v[k] for v in out.values()])) if any(
            np.isfinite(v[k]) for v in out.values()) else float("nan") for k in keys}
    return out


def markdown(table: dict[str, dict[str, float]]) -> str:
    """A Markdown table of :func:`rows` (IoU and accuracies in percent)."""
    if not table:
        return "(no scans)\n"
    keys = list(next(iter(table.values())).keys())
    lines = ["| scan | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
    for name, row in table.items():
        lines.append(f"| {name} | " + " | ".join("-" if not np.isfinite(row[k]) else f"{row[k]:.1f}"
                                                for k in keys) + " |")
    return "\n".join(lines) + "\n"


def difference(now: dict[str, dict[str, float]], before: dict[str, dict[str, float]]) -> dict:
    """Column-wise now - before for the rows both have (NaN where either lacks the value)."""
    return {name: {k: row[k] - before[name].get(k, float("nan")) for k in row}
            for name, row in now.items() if name in before}


def picture(xyz: np.ndarray, truth: np.ndarray, pred: np.ndarray, path: Path, title: str) -> Path:
    """Top view of a scan's points: the twin's labels (left) beside the truth (right), CityScapes
    colours, ignored points (truth 255) grey in both, the highest point of each 0.1 m cell on top."""
    from PIL import Image, ImageDraw

    from twinkit.cityscapes import IGNORE, colorize

    n = int(round(2 * PICTURE_HALF_M / PICTURE_CELL_M))
    inside = (np.abs(xyz[:, 0]) < PICTURE_HALF_M) & (np.abs(xyz[:, 1]) < PICTURE_HALF_M)
    order = np.argsort(xyz[inside, 2])                       # low first: the highest point is painted last
    p, t, q = xyz[inside][order], truth[inside][order], pred[inside][order]
    col = np.clip(((PICTURE_HALF_M + p[:, 0]) / PICTURE_CELL_M).astype(int), 0, n - 1)     # x forward: right
    row = np.clip(((PICTURE_HALF_M - p[:, 1]) / PICTURE_CELL_M).astype(int), 0, n - 1)     # y left: up
    panels = []
    for lab in (q, t):
        img = np.full((n, n, 3), 255, np.uint8)
        rgb = colorize(lab)
        rgb[t == IGNORE] = (170, 170, 170)
        img[row, col] = rgb
        panels.append(img)
    gap = np.full((n, 8, 3), 255, np.uint8)
    im = Image.fromarray(np.concatenate([panels[0], gap, panels[1]], axis=1))
    draw = ImageDraw.Draw(im)
    draw.text((6, 4), f"{title}: twin labels", fill=(0, 0, 0))
    draw.text((n + 14, 4), "truth (SemanticKITTI -> CityScapes)", fill=(0, 0, 0))
    path.parent.mkdir(parents=True, exist_ok=True)
    im.save(path, optimize=True)
    return path


# ----------------------------------------------------------------------------- main

def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scans", default="", help="comma-separated scan names (file stems); default all")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (copies, runs, tables)")
    ap.add_argument("--runs", type=Path, default=None, help="where the runs go (default: OUT/runs)")
    ap.add_argument("--only-score", nargs="+", type=Path, metavar="RUN_DIR",
                    help="score these existing runs instead of running the pipeline")
    ap.add_argument("--override", action="append", default=[], metavar="KEY=VALUE",
                    help="a Hydra override for every run (repeatable), e.g. steps.classify_geometry.model=STEM: "
                         "a variant measured against the defaults")
    ap.add_argument("--compare", type=Path, default=None,
                    help="labelled.json of an earlier run to compare with (default: the output folder's own)")
    args = ap.parse_args(argv)
    if not LABELLED.is_dir():
        print(f"skipped: {LABELLED} is absent")
        return 0
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    results, wall = [], {}
    if args.only_score:
        jobs = [(scan_of_run(d), d.resolve()) for d in args.only_score]
    else:
        wanted = [s for s in args.scans.split(",") if s]
        scans = [p for p in sorted(LABELLED.glob("*.ply")) if not wanted or p.stem in wanted]
        unknown = set(wanted) - {p.stem for p in scans}
        if unknown:
            ap.error(f"no scan {sorted(unknown)} in {LABELLED}")
        jobs = []
        for scan in scans:
            cloud = label_free_copy(scan, out / "clouds" / scan.name)
            run_dir, wall[scan.stem] = run_scan(scan.stem, cloud, (args.runs or out / "runs").resolve(),
                                                 tuple(args.override))
            jobs.append((scan, run_dir))
    for scan, run_dir in jobs:
        res, point_labels = score_run(run_dir, scan)
        if scan.stem in wall:
            res["wall_s"] = round(wall[scan.stem], 1)
        results.append(res)
        if scan.stem == PICTURE_SCAN or len(jobs) == 1:
            xyz, _, truth = read_scan(scan)
            picture(xyz, truth, point_labels, out / f"labelled_{scan.stem}.png", scan.stem)
    table = rows(results)
    prev_path = out / "labelled.json"
    compare = args.compare or prev_path
    before = json.loads(compare.read_text()).get("table", {}) if compare.is_file() else {}
    text = "## Labels on the hand-labelled SemanticKITTI scans (percent; far: share of labelled points)\n\n"
    text += markdown(table)
    alone = rows(results, "geometry_alone")
    if alone:
        text += ("\n### The 3D classifier alone (`geometry_votes.npy`'s most probable class), through the same mesh\n\n"
                 + markdown(alone) + "\nWhat the fusion, the cues and the smoothing add: the table above less this "
                 "one.\n")
    if before:
        text += f"\n### Previous run ({compare})\n\n" + markdown(before)
        text += "\n### Difference (this run - previous)\n\n" + markdown(difference(table, before))
    print(text)
    if prev_path.is_file():
        (out / "labelled_previous.json").write_text(prev_path.read_text())
    prev_path.write_text(json.dumps({"table": table, "geometry_alone": alone, "scans": results}, indent=1))
    (out / "labelled.md").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
