"""Issue 28's targets on the real clouds of ../shared/data/pointclouds, with the defaults.

    .venv/bin/python plugins/twinkit-pointcloud/bench/bench_real_scans.py [--only lille autzen ign seq00_000000 ...]
        [--report-only] [--mesh-only]

Each cloud runs the whole main job with the defaults (``recipe=pointcloud_site``: mesh, labels, roads from the
scan since no OSM is given, FBX/USD/GLB, CARLA package) with nothing but the cloud, its CRS and a base point
(the cloud's centre, computed here from the file's header, as a user would read it off a map), one run at a
time, into outputs/bench_real_scans/. The indoor pump scan is expected to be refused at once (exit 2, "not a
street"). The hand-labelled sweeps of ../shared/data/labelled/semantickitti run too, each from a copy without its
labels (bench_scan_roads.py --scorecard scores the roads of all these runs, issue 46). Then it prints one table:

- the measured point spacing and capture type and the settings chosen from them (trim, depth, texture, views);
- the run's time and exit code;
- cloud -> mesh median against 0.5 x the spacing (target: <=);
- Autzen and IGN: the share of the file's ASPRS building points (class 6) within 2 x the spacing of the mesh
  ("the mesh keeps the buildings");
- Lille (no ground truth but the geometry): of the vertical faces more than 2 m above the local ground,
  the share labelled building / wall / vegetation / pole (target >= 80 %) and building / wall (>= 50 %);
  of the low (< 0.5 m) horizontal faces, the share road / sidewalk / terrain (>= 90 %).
A cloud missing from ../shared is skipped with a line saying so.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from twinkit import cityscapes

HERE = Path(__file__).resolve()
REPO = HERE.parents[3]
DATA = REPO.parent / "shared" / "data" / "pointclouds"
OUT = REPO / "outputs" / "bench_real_scans"

CLOUDS = {
    "lille": {"file": "lille_street_small_normals.ply", "args": ["site=lille"]},
    "ign": {"file": "ign_lidarhd_village_street.laz", "crs": "EPSG:2154"},
    "autzen": {"file": "autzen_trim.laz", "crs": "EPSG:32610"},  # the file is in US feet (Oregon LCC)
    # an indoor scan of a pump (4.6 x 4.5 m): not a street, to be refused before any step runs (exit 2)
    "pump": {"file": "pump_colored_scan.e57", "args": ["site=mex", "site.name=pump"]},
}
#: the hand-labelled single sweeps (../shared/data/labelled/semantickitti), run from a copy without their labels
LABELLED = REPO.parent / "shared" / "data" / "labelled" / "semantickitti"
for _scan in ("seq00_000000", "seq00_000001", "seq00_000002", "spvnas_sample_000000"):
    CLOUDS[_scan] = {"file": f"{_scan}.ply", "labelled": True, "args": ["site=lille", f"site.name={_scan}"]}
BUILDING_WALL = (cityscapes.BUILDING, cityscapes.WALL)
FACADE_OK = (cityscapes.BUILDING, cityscapes.WALL, cityscapes.POLE, cityscapes.VEGETATION)


def centre_latlon(path: Path) -> tuple[float, float, float]:
    """The cloud's centre as lat/lon/alt from its header (the file's CRS)."""
    import laspy
    from pyproj import CRS, Transformer

    with laspy.open(path) as f:
        h = f.header
        crs = h.parse_crs()
        lo, hi = h.mins, h.maxs
    c = (lo + hi) / 2
    tr = Transformer.from_crs(CRS.from_user_input(crs).sub_crs_list[0] if crs.is_compound else crs, "EPSG:4326",
                              always_xy=True)
    lon, lat = tr.transform(c[0], c[1])
    return float(lat), float(lon), 0.0


def label_free(src: Path) -> Path:
    """A copy of a hand-labelled scan with x, y, z and intensity only (bench/bench_labelled.py's), under OUT."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_labelled", REPO / "bench" / "bench_labelled.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.label_free_copy(src, OUT / "clouds" / src.name)


def run_one(name: str, cfg: dict, mesh_only: bool = False) -> dict:
    src = (LABELLED if cfg.get("labelled") else DATA) / cfg["file"]
    if not src.is_file():
        return {"name": name, "skipped": f"{src} not present"}
    args = list(cfg.get("args", []))
    if cfg["file"].endswith(".e57"):
        args.append(f"site.inputs.cloud={src}")
    if cfg.get("labelled"):  # the truth never reaches the pipeline
        args.append(f"site.inputs.cloud={label_free(src)}")
    if not args:
        lat, lon, alt = centre_latlon(src)
        args = ["site=mex", f"site.name={name}", f"site.crs={cfg['crs']}", f"site.base_point.lat={lat:.6f}",
                f"site.base_point.lon={lon:.6f}", f"site.base_point.alt={alt}", f"site.inputs.cloud={src}"]
    cmd = [str(REPO / ".venv" / "bin" / "twinkit"), "recipe=pointcloud_site",
           f"engine.outputs_dir={OUT}", *args, *(mesh_only_args() if mesh_only else [])]
    t0 = time.perf_counter()
    log = OUT / f"{name}.log"
    OUT.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as fh:
        rc = subprocess.call(cmd, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT)
    res = {"name": name, "rc": rc, "seconds": round(time.perf_counter() - t0, 1), "cmd": " ".join(cmd[1:]),
           "mesh_only": mesh_only}
    (OUT / f"{name}.json").write_text(json.dumps(res, indent=1))
    return res


MESH_STEPS = [("read_cloud", "step/read_cloud", {"in_cloud": "${oc.select:site.cloud_file,cloud}"}),
              ("reconstruct", "reconstructor", None), ("clean", "step/clean_mesh", None),
              ("simplify", "step/simplify", None), ("texture", "step/bake_texture", None),
              ("evaluate", "step/evaluate_reconstruction", None)]


def mesh_only_args() -> list[str]:
    """A recipe override with the mesh steps only (--mesh-only: the mesh targets without the labels and exports)."""
    items = []
    for sid, uses, inputs in MESH_STEPS:
        inp = f", inputs: {{in_cloud: '{inputs['in_cloud']}'}}" if inputs else ""
        items.append(f"{{id: {sid}, uses: {uses}{inp}}}")
    return ["recipe.steps=[" + ", ".join(items) + "]"]


def _step(site: str, step: str) -> Path | None:
    hits = sorted((OUT / site).glob(f"[0-9][0-9]_{step}"))
    return hits[-1] if hits else None


def _metrics(site: str, step: str) -> dict:
    d = _step(site, step)
    if d is None or not (d / "step.json").is_file():
        return {}
    return json.loads((d / "step.json").read_text()).get("metrics") or {}


def measure(name: str, cfg: dict) -> dict:
    import numpy as np

    from twinkit.mesh import read_ply
    from twinkit.surface.closest import Surface

    res = json.loads((OUT / f"{name}.json").read_text()) if (OUT / f"{name}.json").is_file() else {"name": name}
    log = OUT / f"{name}.log"
    if log.is_file():  # why the run did not end with exit 0: its last error or degraded line
        lines = log.read_text(errors="replace").splitlines()
        # an error, or the degraded summary's items (a run whose steps were all reused prints only those)
        why = [ln for ln in lines if ln.startswith("twinkit: error:")]
        why += [ln.strip() for i, ln in enumerate(lines) if ln.startswith("  - ")
                and any(p.startswith("twinkit: DEGRADED result") for p in lines[max(0, i - 5):i])]
        res["why"] = why[-1][:160] if why else ""
    fr = _metrics(name, "fetch_roads")
    if fr:
        res["roads"] = f"{fr.get('roads')} roads, {fr.get('driving_lanes')} lanes"
        if fr.get("kept_share") is not None:  # of the road length first derived, what the checks kept
            res["roads"] += f" ({100 * fr['kept_share']:.0f} % kept)"
    dt = _metrics(name, "drop_test")
    res.update(drop_driving=dt.get("driving_hit_pct"), drop_fall=dt.get("driving_fall_through_pct"),
               drop_gate=gate_driving(_step(name, "drop_test")), drop_hole=dt.get("driving_widest_hole_m"))
    pts_dir = _step(name, "read_cloud")
    if pts_dir is None:
        return res
    meta = json.loads((pts_dir / "points_meta.json").read_text())
    dens = meta.get("density") or {}
    res.update(spacing_m=dens.get("spacing_m"), capture=dens.get("capture"))
    res["depth"] = _metrics(name, "reconstruct").get("depth")
    cm = _metrics(name, "clean")
    res.update(trim_m=cm.get("max_dist_m"), trim_removed=cm.get("trim_removed_share"))
    res["texture_px"] = _metrics(name, "texture").get("texture_px")
    sv = _metrics(name, "sample_views")
    res.update(views=sv.get("views"), views_sampled=sv.get("sampled_views"))
    rv = _metrics(name, "render_views")
    res["blank_share"] = rv.get("blank_share")
    ev = _step(name, "evaluate")
    if ev is not None and (ev / "recon_metrics.json").is_file():
        rm = json.loads((ev / "recon_metrics.json").read_text())
        res["c2m_median_m"] = rm["cloud_to_mesh_m"]["median"]
    tex = _step(name, "texture")
    if tex is None:
        return res
    mesh = read_ply(tex / "textured_mesh.ply")
    if cfg["file"].endswith(".laz"):
        cloud = read_ply(pts_dir / "points.ply")
        cls = cloud.attrs.get("classification")
        if cls is not None:
            b = cloud.vertices[np.asarray(cls) == cityscapes.TRAFFIC_LIGHT]
            if len(b):
                d = Surface(mesh.vertices, mesh.faces, 1).distance(b)
                res["building_kept"] = float((d <= 2 * res["spacing_m"]).mean())
    bp = _step(name, "backproject")
    if bp is not None and (bp / "labels.npy").is_file():
        from twinkit.street.ground import LocalGround
        from twinkit_pointcloud.shading import GROUND_CELL_M

        lab = np.load(bp / "labels.npy")
        v, f = mesh.vertices, mesh.faces
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        area = 0.5 * np.linalg.norm(fn, axis=1)
        fn /= np.maximum(2 * area[:, None], 1e-12)
        ground = LocalGround(v, cell_m=GROUND_CELL_M, window="min", window_m=3 * GROUND_CELL_M, pad_cells=0)
        h = ground.height()[f].mean(axis=1)  # the height shading's ground
        fl = lab[f[:, 0]]  # a face's label: its first vertex's
        vert = (np.abs(fn[:, 2]) < 0.3) & (h > 2.0) & (fl != 255)
        low = (np.abs(fn[:, 2]) > 0.9) & (h < 0.5) & (fl != 255)
        if vert.any():
            res["facade_ok"] = float(area[vert & np.isin(fl, FACADE_OK)].sum() / area[vert].sum())
            res["facade_building"] = float(area[vert & np.isin(fl, BUILDING_WALL)].sum() / area[vert].sum())
        if low.any():
            res["ground_ok"] = float(area[low & np.isin(fl, cityscapes.GROUND)].sum() / area[low].sum())
    return res


def gate_driving(step_dir: Path | None) -> float | None:
    """The drop test's gate figure over the driving lanes, from its drop_test.json (``ground_share``, as the step
    reads it); None without it."""
    from twinkit.surface.watertight import ground_share

    f = step_dir / "drop_test.json" if step_dir is not None else None
    lane = json.loads(f.read_text())["lanes"].get("driving") if f is not None and f.is_file() else None
    return ground_share(lane) if lane else None


def _f(x, fmt="{:.3f}"):
    return "-" if x is None else fmt.format(x)


def table(rows: list[dict]) -> str:
    head = ("| cloud | capture | spacing m | trim m | trim removed | depth | texture px | views (sampled) | blank views "
            "| c2m median m | <= 0.5 x spacing | buildings kept | facades ok (>= 80 %) | facades building (>= 50 %) "
            "| low ground ok (>= 90 %) | roads from the scan | drop test driving % (fall through %) "
            "| drop test gate driving (>= 99.9 %), widest hole m (<= 0.25) | time s | exit "
            "| why not 0 |")
    out = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in rows:
        if r.get("skipped"):
            out.append(f"| {r['name']} | skipped: {r['skipped']} |")
            continue
        sp, c2m = r.get("spacing_m"), r.get("c2m_median_m")
        ok = "-" if sp is None or c2m is None else ("yes" if c2m <= 0.5 * sp else "no")
        pct = lambda k: _f(r.get(k) if r.get(k) is None else 100 * r[k], "{:.1f} %")  # noqa: E731
        out.append(f"| {r['name']} | {r.get('capture', '-')} | {_f(sp)} | {_f(r.get('trim_m'))} | {pct('trim_removed')} "
                   f"| {r.get('depth', '-')} | {r.get('texture_px', '-')} | {r.get('views') or '-'} ({r.get('views_sampled') or '-'}) "
                   f"| {pct('blank_share')} | {_f(c2m)} | {ok} | {pct('building_kept')} | {pct('facade_ok')} "
                   f"| {pct('facade_building')} | {pct('ground_ok')} | {r.get('roads', '-')} "
                   f"| {_f(r.get('drop_driving'), '{:.1f}')} ({_f(r.get('drop_fall'), '{:.1f}')}) "
                   f"| {_f(r.get('drop_gate'), '{:.2f}')}, {_f(r.get('drop_hole'), '{:.2f}')} "
                   f"| {r.get('seconds', '-')} | {r.get('rc', '-')} | {r.get('why') or '-'} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=list(CLOUDS), choices=list(CLOUDS))
    ap.add_argument("--report-only", action="store_true", help="measure the runs already in outputs/")
    ap.add_argument("--mesh-only", action="store_true", help="the mesh steps only (no labels, no exports)")
    a = ap.parse_args(argv)
    rows = []
    for name in a.only:
        r = {} if a.report_only else run_one(name, CLOUDS[name], a.mesh_only)
        if r.get("skipped"):
            rows.append(r)
            continue
        rows.append(measure(name, CLOUDS[name]))
        print(f"{name}: {json.dumps(rows[-1])}", file=sys.stderr, flush=True)
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
