"""Benchmark the demo site generator: time, points, photos and file sizes per preset.

    .venv/bin/python plugins/twinkit-demo-site/bench/bench_demo_site.py [--presets small,default] [--keep DIR]

Prints a Markdown table. Each preset runs once in a fresh temporary folder.
"""
from __future__ import annotations

import argparse
import platform
import resource
import shutil
import tempfile
import time
from pathlib import Path

from twinkit.testing import make_context
from twinkit_demo_site.plugin import DemoSiteParams, generate_demo_site, output_paths


def _size(p: Path) -> int:
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return p.stat().st_size


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f}"


def run(preset: str, folder: Path, seed: int) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    kw = output_paths(folder)
    ctx = make_context(folder, site={"name": "demo"}, step_id="bench")
    t = time.perf_counter()
    m = generate_demo_site(DemoSiteParams(size=preset, seed=seed), ctx, **kw)
    m["seconds"] = time.perf_counter() - t
    m["timings_s"] = {k: v["seconds"] for k, v in ctx.substeps.items()}
    m["sizes"] = {
        "mesh (obj+mtl+png)": sum(_size(folder / f) for f in ("gt_mesh.obj", "gt_mesh.mtl", "gt_mesh.png")),
        "mesh ply": _size(folder / "gt_mesh.ply"),
        "e57": _size(folder / "cloud.e57"), "las": _size(folder / "cloud.las"), "ply": _size(folder / "cloud.ply"),
        "photos": _size(folder / "photos"),
    }
    return m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="small,default")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, default=None, help="keep outputs under this folder")
    a = ap.parse_args()
    rows = []
    for preset in [p.strip() for p in a.presets.split(",") if p.strip()]:
        base = a.keep or Path(tempfile.mkdtemp(prefix="twinkit-demo-bench-"))
        folder = base / preset
        try:
            m = run(preset, folder, a.seed)
        finally:
            if a.keep is None:
                shutil.rmtree(base, ignore_errors=True)
        peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        rows.append((preset, m, peak_gb))
        print(f"[{preset}] {m['seconds']:.1f} s, {m['points']:,} points, stages {m['timings_s']}", flush=True)
    print()
    print(f"Machine: {platform.processor() or platform.machine()}, {__import__('os').cpu_count()} CPUs, Python {platform.python_version()}")
    print()
    print("| preset | seconds | points | mesh faces | photos | mesh obj+mtl+png MB | mesh ply MB | e57 MB | las MB | ply MB | photos MB | peak RSS GB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for preset, m, peak in rows:
        s = m["sizes"]
        print(f"| {preset} | {m['seconds']:.1f} | {m['points']:,} | {m['faces']:,} | {m['photos']} | {_mb(s['mesh (obj+mtl+png)'])} | "
              f"{_mb(s['mesh ply'])} | {_mb(s['e57'])} | {_mb(s['las'])} | {_mb(s['ply'])} | {_mb(s['photos'])} | {peak:.1f} |")


if __name__ == "__main__":
    main()
