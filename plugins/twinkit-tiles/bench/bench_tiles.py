"""Tiled vs untiled reconstruction of the demo site through the real ``twinkit`` command.

For each preset: the tiled recipe with 2 local workers (full pipeline), the tile step again with
1 worker (``rerun=[reconstruct_tiles]``; speedup = 1-worker / 2-worker time of that step), optionally
with the Dask executor (2 workers), and the same recipe with one tile covering the whole site (the
untiled run: same code, same voxel, no seams). Prints markdown tables and writes JSON.

    .venv/bin/python plugins/twinkit-tiles/bench/bench_tiles.py --presets small --tile-m 30 --voxel 0.03
    .venv/bin/python plugins/twinkit-tiles/bench/bench_tiles.py --presets default --tile-m 20 --voxel 0.02 --no-untiled

The machine must be quiet for the speedup to mean anything (the figure is the ratio of two runs
of the same step, so a machine loaded by other jobs makes it pessimistic).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]


def twinkit(out: Path, preset: str, *args: str) -> tuple[float, str]:
    cmd = [sys.executable, "-m", "twinkit", "recipe=tiled_site", "site=demo", f"site.size={preset}",
           f"engine.outputs_dir={out}", *args]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=str(REPO))
    dt = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr[-4000:]}")
    return dt, r.stderr


def rec(ws: Path, folder: str) -> dict:
    return json.loads((ws / folder / "step.json").read_text())


def collect(ws: Path) -> dict:
    plan = json.loads((ws / "03_plan_tiles" / "tiles.json").read_text())
    tiles = rec(ws, "04_reconstruct_tiles")
    seams = json.loads((ws / "05_merge_tiles" / "tile_seams.json").read_text())
    m = json.loads((ws / "08_evaluate" / "recon_metrics.json").read_text())
    per = tiles["metrics"]["per_item"]
    return {
        "grid": plan["grid"], "tiles": len(plan["items"]),
        "tile_step_s": tiles["duration_s"],
        "per_tile": [{"tile": p.get("tile"), "points": p.get("points"), "depth": p.get("depth"),
                      "faces": p.get("faces"), "seconds": p.get("duration_s"), "peak_rss_mb": p.get("peak_rss_mb"),
                      "pid": p.get("pid")} for p in per],
        "merge_s": rec(ws, "05_merge_tiles")["duration_s"], "merge_peak_mb": rec(ws, "05_merge_tiles")["peak_rss_mb"],
        "seams": {k: v for k, v in seams.items() if k != "seams"},
        "accuracy_mean_mm": 1000 * m["gt"]["accuracy_mesh_to_gt_m"]["mean"] if m.get("gt") else None,
        "accuracy_median_mm": 1000 * m["gt"]["accuracy_mesh_to_gt_m"]["median"] if m.get("gt") else None,
        "cloud_to_mesh_median_mm": 1000 * m["cloud_to_mesh_m"]["median"],
        "faces_final": m["counts"]["faces"],
        "steps": {f.name: rec(ws, f.name).get("duration_s") for f in sorted(ws.iterdir())
                  if (f / "step.json").exists()},
        "peaks": {f.name: rec(ws, f.name).get("peak_rss_mb") for f in sorted(ws.iterdir())
                  if (f / "step.json").exists()},
    }


def near_lines_untiled(ws: Path, tiled_seams: dict, band_m: float) -> dict:
    """The untiled mesh's open border near the tiled run's seam lines and control lines (same measure
    as tile_seams.json's ``open_near_lines``): what a seam should not exceed."""
    from twinkit.mesh import read_ply
    from twinkit_tiles.seam_stats import open_near_line_sets

    m = read_ply(ws / "05_merge_tiles" / "clean_mesh.ply")
    ax = {"x": 0, "y": 1}
    planes = [(ax[a], float(v)) for a, v in tiled_seams["planes"]]
    controls = [(ax[a], float(v)) for a, v in tiled_seams["open_near_lines"]["control_planes"]]
    return open_near_line_sets(m, {"seams": planes, "controls": controls}, band_m)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", default="small")
    ap.add_argument("--tile-m", type=float, default=30.0)
    ap.add_argument("--overlap-m", type=float, default=2.0)
    ap.add_argument("--voxel", type=float, default=0.03)
    ap.add_argument("--target-faces", type=int, default=500000)
    ap.add_argument("--texture-px", type=int, default=4096)
    ap.add_argument("--out", default="/tmp/twinkit_bench_tiles")
    ap.add_argument("--json", default=str(Path(__file__).with_name("results.json")))
    ap.add_argument("--no-untiled", action="store_true", help="skip the untiled run (when it would not fit)")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--no-one-worker", action="store_true")
    a = ap.parse_args()
    common = [f"steps.plan_tiles.overlap_m={a.overlap_m}", f"steps.plan_tiles.voxel_m={a.voxel}",
              f"steps.simplify.target_faces={a.target_faces}", f"steps.bake_texture.texture_px={a.texture_px}",
              "steps.evaluate_reconstruction.gt_samples=1000000"]
    results = {"machine": {"cpus": os.cpu_count(), "load_avg_start": os.getloadavg()}, "args": vars(a), "presets": {}}
    for preset in a.presets.split(","):
        out = Path(a.out) / preset
        ws = out / "demo"
        R: dict = {}
        # forced like the others: a repeated benchmark into the same folder would else report the stored step's time
        dt, _ = twinkit(out, preset, f"steps.plan_tiles.tile_m={a.tile_m}", "executor=local", "executor.workers=2",
                        "rerun=[reconstruct_tiles]", *common)
        R["tiled_2_workers"] = collect(ws) | {"wall_s": round(dt, 1), "load_avg": os.getloadavg()}
        print(f"[{preset}] tiled, 2 workers: tile step {R['tiled_2_workers']['tile_step_s']} s", flush=True)
        if not a.no_one_worker:
            dt, _ = twinkit(out, preset, f"steps.plan_tiles.tile_m={a.tile_m}", "executor=local", "executor.workers=1",
                            "rerun=[reconstruct_tiles]", *common)
            R["tiled_1_worker"] = collect(ws) | {"wall_s": round(dt, 1), "load_avg": os.getloadavg()}
            print(f"[{preset}] tiled, 1 worker: tile step {R['tiled_1_worker']['tile_step_s']} s", flush=True)
        if not a.no_dask:
            dt, _ = twinkit(out, preset, f"steps.plan_tiles.tile_m={a.tile_m}", "executor=dask",
                            "executor.n_workers=2", "rerun=[reconstruct_tiles]", *common)
            R["tiled_dask_2_workers"] = collect(ws) | {"wall_s": round(dt, 1), "load_avg": os.getloadavg()}
            print(f"[{preset}] tiled, dask 2 workers: tile step {R['tiled_dask_2_workers']['tile_step_s']} s", flush=True)
        if not a.no_untiled:
            dt, _ = twinkit(out, preset, "steps.plan_tiles.tile_m=100000", "executor=local", "executor.workers=1",
                            *common)
            R["untiled"] = collect(ws) | {"wall_s": round(dt, 1), "load_avg": os.getloadavg()}
            tiled = R["tiled_2_workers"]["seams"]
            if tiled.get("open_near_lines"):
                R["untiled"]["open_near_lines"] = near_lines_untiled(ws, tiled, tiled["open_near_lines"]["seams"]["band_m"])
            print(f"[{preset}] untiled: {R['untiled']['tile_step_s']} s", flush=True)
        results["presets"][preset] = R
        Path(a.json).write_text(json.dumps(results, indent=2))
    print(report(results))


def report(results: dict) -> str:
    lines = []
    for preset, R in results["presets"].items():
        lines.append(f"\n### demo `{preset}` (voxel {results['args']['voxel']} m, tile {results['args']['tile_m']} m, "
                     f"overlap {results['args']['overlap_m']} m)\n")
        lines.append("| run | tiles | tile step s | max tile peak RSS MiB | merge s | seam edges before -> after | "
                     "stitch faces | gap mean mm | boundary edges | accuracy mean mm | accuracy median mm | load avg |")
        lines.append("|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|")
        for run, r in R.items():
            s = r["seams"]
            peak = max((p["peak_rss_mb"] or 0) for p in r["per_tile"])
            lines.append(f"| {run} | {r['tiles']} | {r['tile_step_s']} | {peak:.0f} | {r['merge_s']} | "
                         f"{s['seam_boundary_edges_before']} -> {s['seam_boundary_edges_after']} | {s['stitched_faces']} | "
                         f"{s.get('gap_mean_mm')} | {s['boundary_edges_after']} | "
                         f"{r['accuracy_mean_mm']:.2f} | {r['accuracy_median_mm']:.2f} | {r['load_avg'][0]:.1f} |")
        if "tiled_1_worker" in R:
            sp = R["tiled_1_worker"]["tile_step_s"] / R["tiled_2_workers"]["tile_step_s"]
            line = f"\nSpeedup of the tile step, 2 local workers vs 1: **{sp:.2f}x**"
            if "tiled_dask_2_workers" in R:
                spd = R["tiled_1_worker"]["tile_step_s"] / R["tiled_dask_2_workers"]["tile_step_s"]
                line += f"; 2 Dask workers (LocalCluster start included) vs 1 local worker: **{spd:.2f}x**"
            lines.append(line)
        if "untiled" in R:
            d = R["tiled_2_workers"]["accuracy_mean_mm"] - R["untiled"]["accuracy_mean_mm"]
            lines.append(f"\nMean distance to ground truth, tiled - untiled: **{d:+.2f} mm**")
        t_near = R["tiled_2_workers"]["seams"].get("open_near_lines")
        if t_near:
            b = t_near["seams"]["band_m"]
            lines.append(f"\nOpen border within {b} m of a line, per metre of surface the lines cut (seam lines: "
                         f"{t_near['seams']['planes']}, control lines half-way between them: {t_near['controls']['planes']}):\n")
            lines.append("| mesh | at the seam lines | at the control lines |\n|---|---:|---:|")
            rows = [("tiled", t_near)] + ([("untiled, same lines", R["untiled"]["open_near_lines"])]
                                          if "open_near_lines" in R.get("untiled", {}) else [])
            for name, nl in rows:
                lines.append(f"| {name} | {nl['seams']['open_per_section']} ({nl['seams']['open_m']} m / "
                             f"{nl['seams']['section_m']} m) | {nl['controls']['open_per_section']} "
                             f"({nl['controls']['open_m']} m / {nl['controls']['section_m']} m) |")
        lines.append("\nPer tile (2 local workers):\n\n| tile | points | depth | faces | s | peak RSS MiB | worker pid |")
        lines.append("|---:|---:|---:|---:|---:|---:|---:|")
        for p in R["tiled_2_workers"]["per_tile"]:
            lines.append(f"| {p['tile']} | {p['points']:,} | {p['depth']} | {p['faces']:,} | {p['seconds']} | "
                         f"{p['peak_rss_mb']} | {p['pid']} |")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--report":
        print(report(json.loads(Path(sys.argv[2]).read_text())))
    else:
        main()
