"""Speed of the texture bake (``bake_colors``) and of the atlas PNG at 8192 px on a ~500 k-face mesh.

    .venv/bin/python plugins/twinkit-pointcloud/bench/bench_bake.py [--run outputs/demo] [--px 8192]
                     [--threads 2] [--compare]

Without ``--run``: a synthetic street-sized terrain (60 x 60 m, wavy, coloured by a pattern), the dense mesh
1.44 M faces, the simplified one 500 k faces. ``--run``: a pipeline run's ``NN_simplify/mesh.ply`` and
``NN_clean/clean_mesh.ply`` (the inputs of ``bake_texture``). UVs: ``chart_uv``. ``--compare`` bakes
again with the numpy code (no numba; issue 48's code before) and prints how the two atlases differ.
Prints wall and CPU seconds and the load average (the machine may be shared: compare CPU seconds).
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def terrain(n: int, size_m: float = 60.0):
    """An n x n vertex grid over a wavy ground: (vertices, faces, colours from a pattern)."""
    x, y = np.meshgrid(np.linspace(0, size_m, n), np.linspace(0, size_m, n))
    z = 0.3 * np.sin(x / 3.0) * np.cos(y / 4.0) + 0.05 * np.sin(x * 2.1 + y * 1.3)
    v = np.c_[x.ravel(), y.ravel(), z.ravel()]
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]]).astype(np.int64)
    chk = ((np.floor(v[:, 0]) + np.floor(v[:, 1])) % 2)[:, None]
    col = np.clip(np.c_[60 + 3 * v[:, 0], 60 + 3 * v[:, 1], 40 + 400 * (z.ravel() + 0.35)] + 40 * chk, 0, 255)
    return v, f, col.astype(np.uint8)


def inputs(run: Path | None):
    """(simplified vertices, faces, dense vertices, faces, colours, where from)."""
    from twinkit.mesh import read_ply

    if run is None:
        sv, sf, _ = terrain(501)
        dv, df, dc = terrain(850)
        return sv, sf, dv, df, dc, "synthetic terrain"
    simple = read_ply(sorted(run.glob("[0-9][0-9]_simplify"))[-1] / "mesh.ply")
    dense = read_ply(sorted(run.glob("[0-9][0-9]_clean"))[-1] / "clean_mesh.ply")
    return simple.vertices, simple.faces, dense.vertices, dense.faces, dense.colors, str(run)


def bake(args, sv, sf, uv, dv, df, dc) -> tuple[np.ndarray, dict]:
    from twinkit_pointcloud.texture import bake_colors

    w, c, load = time.perf_counter(), _cpu(), os.getloadavg()[0]
    img, info = bake_colors(sv, sf, uv, args.px, dv, df, dc, threads=args.threads)
    return img, {"wall_s": time.perf_counter() - w, "cpu_s": _cpu() - c, "load": load, **info}


def main(argv: list[str]) -> int:
    import twinkit.surface.compiled as C
    from twinkit.surface.texture import write_png
    from twinkit_pointcloud.uv import chart_uv

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path)
    ap.add_argument("--px", type=int, default=8192)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--compare", action="store_true")
    args = ap.parse_args(argv)
    sv, sf, dv, df, dc, where = inputs(args.run)
    uv, _ = chart_uv(sv, sf, args.px)
    print(f"## Texture bake, {args.px} px: {where}, {len(sf):,} faces onto a dense mesh of {len(df):,} faces, "
          f"{args.threads} threads\n")
    print("| code | texels baked | wall s | CPU s | load (1 min) |\n|---|---:|---:|---:|---:|")
    from twinkit_pointcloud.texture import bake_colors

    bake_colors(sv, sf[:100], uv[:100], 64, dv, df[:100], dc)  # loads (or first compiles) the numba code
    img, r = bake(args, sv, sf, uv, dv, df, dc)
    print(f"| compiled (numba) | {r['texels_baked']:,} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['load']:.1f} |")
    with tempfile.TemporaryDirectory() as tmp:
        w, c = time.perf_counter(), _cpu()
        write_png(Path(tmp) / "atlas.png", img, threads=args.threads)
        png = (time.perf_counter() - w, _cpu() - c, (Path(tmp) / "atlas.png").stat().st_size / 1e6)
    if args.compare:
        C.ENABLED = False
        ref, r0 = bake(args, sv, sf, uv, dv, df, dc)
        C.ENABLED = True
        print(f"| numpy | {r0['texels_baked']:,} | {r0['wall_s']:.1f} | {r0['cpu_s']:.1f} | {r0['load']:.1f} |")
        d = np.abs(img.astype(np.int16) - ref).max(axis=2)
        print(f"\natlases: {100 * (d > 0).mean():.4f} % of texels differ, max {d.max()}, mean {d.mean():.6f} levels")
    print(f"\nPNG: {png[0]:.1f} s wall, {png[1]:.1f} CPU s, {png[2]:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
