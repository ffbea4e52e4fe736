"""Speed-up of the tile step with 1, 2, ... worker processes, outside the engine.

Runs the real ``reconstruct_tile`` step function on every tile of an existing plan (the
``03_plan_tiles`` folder of a tiled run: ``tiles.json`` and ``tile_points/``) in a spawn process
pool of each size, one thread per tile, biggest tiles first (as the engine orders them), and prints
the wall time of each pool and the speed-up against one worker. Nothing else runs in the pool, so
the figure is the tile step's own scaling on the machine at hand; run it on a quiet machine.

    .venv/bin/python plugins/twinkit-tiles/bench/bench_tile_workers.py <run>/demo/03_plan_tiles --workers 1 2
    # on another machine: copy the plan folder and the repository, PYTHONPATH=.:plugins/twinkit-tiles:plugins/twinkit-pointcloud

Writes JSON next to this file (``--json``) with the per-tile seconds of every pool.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from types import SimpleNamespace


def _one(args: tuple) -> dict:
    plan_dir, item, out_dir = args
    from twinkit_tiles.plugin import ReconstructTileParams, reconstruct_tile

    ctx = SimpleNamespace(log=logging.getLogger("bench"), threads=1)
    t0 = time.perf_counter()
    rec = reconstruct_tile(ReconstructTileParams(threads=1), ctx, in_tile_points_dir=Path(plan_dir) / "tile_points",
                           item=item, out_tile_mesh_ply=Path(out_dir) / f"tile_{item['index']:03d}.ply")
    return {"tile": item["index"], "seconds": round(time.perf_counter() - t0, 3), "faces": rec["faces"],
            "peak_rss_mb": rec["tile_peak_rss_mb"], "pid": os.getpid()}


def run_pool(plan_dir: Path, items: list, workers: int) -> dict:
    import multiprocessing as mp

    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as ex:
            per = list(ex.map(_one, [(str(plan_dir), it, out) for it in items]))
        wall = time.perf_counter() - t0
    return {"workers": workers, "wall_s": round(wall, 2), "sum_tile_s": round(sum(p["seconds"] for p in per), 2),
            "per_tile": per}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("plan_dir", type=Path, help="a 03_plan_tiles folder (tiles.json + tile_points/)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--json", default=str(Path(__file__).with_name("results_workers.json")))
    a = ap.parse_args()
    plan = json.loads((a.plan_dir / "tiles.json").read_text())
    items = sorted(plan["items"], key=lambda i: -float(i.get("cost", i.get("points", 0))))
    res = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "node": platform.node()},
           "tiles": len(items), "points": sum(i["points"] for i in items), "pools": []}
    for w in a.workers:
        r = run_pool(a.plan_dir, items, w)
        res["pools"].append(r)
        print(f"{w} worker(s): {r['wall_s']} s wall, {r['sum_tile_s']} s summed over tiles", flush=True)
    base = res["pools"][0]
    print(f"\n{len(items)} tiles, {res['points']:,} points, {os.cpu_count()} CPUs\n")
    print("| workers | wall s | sum of tile s | speed-up vs " + f"{base['workers']} |")
    print("|---:|---:|---:|---:|")
    for r in res["pools"]:
        print(f"| {r['workers']} | {r['wall_s']} | {r['sum_tile_s']} | {base['wall_s'] / r['wall_s']:.2f}x |")
    Path(a.json).write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    sys.exit(main())
