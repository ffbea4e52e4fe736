"""Export benchmark: time and file size per format for a ~500k-face mesh with an 8k texture.

    .venv/bin/python plugins/twinkit-export/bench/bench_export.py [--faces 500000] [--texture-px 8192]
        [--obj path/to/textured_mesh.obj --labels path/to/labels.npy]   # a real mesh instead

By default a synthetic labelled street (twinkit_export.synthetic) of the requested size is made;
with --obj and --labels a real textured mesh is used (e.g. the demo run's 06_texture output).
Each step runs through twinkit's own code path (twinkit.testing.run_step: temporary folder,
atomic move), so the times are what a recipe run costs. Prints a Markdown table.
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _size(p: Path) -> int:
    p = Path(p)
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return p.stat().st_size


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f}"


def _level_placement(root: Path) -> dict | None:
    """Share of the package's static faces the emulated import flow leaves in the map level."""
    from twinkit_export.contract_import import placement_summary

    desc = next((root / "Import").glob("*/*.json"), None)
    return placement_summary(root, desc.stem) if desc is not None else None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, default=500_000)
    ap.add_argument("--texture-px", type=int, default=8192)
    ap.add_argument("--obj", type=Path, default=None)
    ap.add_argument("--labels", type=Path, default=None)
    ap.add_argument("--xodr", type=Path, default=Path("/work/shared/data/opendrive/fabriksgatan.xodr"))
    ap.add_argument("--keep", type=Path, default=None, help="copy the outputs here")
    args = ap.parse_args()

    from twinkit.testing import plugin_from_module, run_step

    import twinkit_export.plugin as ep
    from twinkit_export import synthetic

    site = {"name": "bench", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}
    work = Path(tempfile.mkdtemp(prefix="twinkit-export-bench-"))
    try:
        t0 = time.perf_counter()
        if args.obj:
            obj, labels = args.obj, args.labels
            source = f"{obj.name}"
        else:
            n = int(math.sqrt(args.faces / 2)) + 1  # grid of n x n vertices -> 2 (n-1)^2 faces
            v, f, uv, lab = synthetic.make_street(nx=n, ny=n, size_m=120.0)
            obj = synthetic.write_obj(work / "textured_mesh.obj", v, f, uv, texture_px=args.texture_px)
            labels = work / "labels.npy"
            np.save(labels, lab)
            source = f"synthetic street {n}x{n} grid"
        t_make = time.perf_counter() - t0
        rows = []
        placed = None

        def step(kind, name, inputs, label, out_key):
            plug = plugin_from_module(ep, kind, name)
            t = time.perf_counter()
            out = run_step(plug, work / f"run_{name}", inputs, site=site)
            dt = time.perf_counter() - t
            return out, dt

        split, dt = step("step", "split_classes", {"in_labels_npy": labels, "in_textured_mesh_obj": obj},
                         "split", "class_meshes")
        cdir = split["class_meshes"]
        import json

        man = json.loads((cdir / "classes.json").read_text())
        st = man["stats"]
        tex = cdir / man["texture"] if man.get("texture") else None
        rows.append(("split_classes (OBJ read + split + class PLYs)", dt, _size(cdir) - (_size(tex) if tex else 0),
                     "class PLYs, without the texture"))
        fbx, dt = step("exporter", "fbx", {"in_class_meshes_dir": cdir}, "fbx", "twin.fbx")
        rows.append(("FBX (bpy subprocess)", dt, _size(fbx["twin.fbx"]), "+ texture file beside it"))
        usd, dt = step("exporter", "usd", {"in_class_meshes_dir": cdir}, "usd", "twin.usd")
        rows.append(("USD (usd-core, crate) incl. validation", dt, _size(usd["twin.usd"]), "+ texture file beside it"))
        from twinkit_export.usd import validation_report

        t = time.perf_counter()
        rep = validation_report(usd["twin.usd"])
        t_val = time.perf_counter() - t
        glb, dt = step("exporter", "gltf", {"in_class_meshes_dir": cdir}, "gltf", "twin.glb")
        rows.append(("GLB (texture embedded as JPEG q90)", dt, _size(glb["twin.glb"]), "self-contained"))
        if args.xodr.exists():
            pkg, dt = step("exporter", "carla_package", {"in_twin_fbx": fbx["twin.fbx"], "in_class_meshes_dir": cdir,
                                                         "in_aligned_xodr": args.xodr}, "carla", "carla_import")
            rows.append(("CARLA package (copy FBX+texture+XODR, spawn points)", dt, _size(pkg["carla_import"]),
                         "whole Import/<Package> folder"))
            placed = _level_placement(pkg["carla_import"])
        print("\n### twinkit-export benchmark\n")
        print(f"Source: {source}; {st['source_vertices']:,} vertices, {st['source_faces']:,} faces, "
              f"{st['classes']} classes; texture {man.get('texture_px')} px, {_mb(_size(tex)) if tex else 0} MB PNG "
              f"(input made in {t_make:.1f} s).  ")
        print(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
              f"{platform.python_version()}. USD validation alone: {t_val:.1f} s, {rep['errors']} errors, "
              f"{rep['warnings']} warnings ({rep['validators']} validators).\n")
        print("| step / format | time (s) | size (MB) | note |")
        print("|---|---:|---:|---|")
        for name, dt, size, note in rows:
            print(f"| {name} | {dt:.1f} | {_mb(size)} | {note} |")
        if args.xodr.exists() and placed:
            print(f"\nCARLA map level (emulated `make import` + `place_in_map.py`, twinkit_export.contract_import): "
                  f"{100 * placed['placed_share']:.1f} % of the static faces placed with their class's tag and own "
                  f"collision (target 100 %; `make import` alone: {100 * placed['placed_share_import_only']:.1f} %).")
        if args.keep:
            shutil.copytree(work, args.keep, dirs_exist_ok=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
