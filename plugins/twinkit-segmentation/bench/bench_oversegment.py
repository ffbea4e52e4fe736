"""Felzenszwalb over-segmentation speed on a synthetic mesh (the issue's target: <= 10 s for 1M vertices).

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_oversegment.py            # 1M-vertex grid
    .venv/bin/python plugins/twinkit-segmentation/bench/bench_oversegment.py --side 548 # ~300k vertices
    .venv/bin/python plugins/twinkit-segmentation/bench/bench_oversegment.py --mesh outputs/demo/<step>/textured_mesh.ply

Prints wall and CPU seconds per stage (edges, weights, sort, union-find, small-segment merge).
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--side", type=int, default=1000, help="grid side in vertices (1000 -> 1M vertices, 3M edges)")
    ap.add_argument("--mesh", default=None, help="a PLY mesh instead of the grid")
    ap.add_argument("--k", type=float, default=0.3)
    ap.add_argument("--min-vertices", type=int, default=10)
    ap.add_argument("--max-vertices", type=int, default=5000)
    ap.add_argument("--target-s", type=float, default=10.0)
    ap.add_argument("--method", default="auto", choices=["auto", "numba", "rounds", "python"],
                    help="union-find: compiled loop (numba), vectorised rounds, plain Python loop")
    a = ap.parse_args()

    from twinkit_segmentation import oversegment as o
    from twinkit.surface.compiled import compiled
    from twinkit.mesh import edges as mesh_edges, read_mesh
    from twinkit_segmentation.segmesh import unit_normals
    from twinkit_segmentation.synthetic import grid

    if a.mesh:
        m = read_mesh(a.mesh)
        v, f, n, col = m.vertices, m.faces, unit_normals(m), m.colors
        what = a.mesh
    else:
        v, f, n = grid(0, 100, 0, 100, 0.0, 100 / (a.side - 1))
        rng = np.random.default_rng(1)
        n = n + rng.normal(0, 0.05, n.shape)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        col = rng.integers(0, 255, (len(v), 3)).astype(np.uint8)
        what = f"{a.side}x{a.side} grid, noisy normals, random colours"
    rows = []

    def timed(name, fn):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        rows.append((name, time.perf_counter() - t, time.process_time() - c))
        return out

    e = timed("edges (CSR dedup)", lambda: mesh_edges(f, len(v)))
    w = timed("edge weights", lambda: o.edge_weights(v, n, col, e, 1.0, 1.0))
    order = timed("stable argsort", lambda: np.argsort(w, kind="stable"))

    def fh():
        parent = np.arange(len(v), dtype=np.int64)
        size = np.ones(len(v), dtype=np.int64)
        thresh = np.full(len(v), a.k)
        o._union(parent, size, e[order, 0], e[order, 1], w[order].astype(np.float64), thresh, a.k,
                 a.max_vertices, method=a.method)
        return o._find(parent, parent)
    if a.method in ("auto", "numba") and compiled(o._union_sequential) is not None:  # JIT compile (cached on disk) first
        timed("numba compile / cache load", lambda: o.felzenszwalb_mesh(v[:3], np.array([[0, 1, 2]]), n[:3], None))
    labels = timed(f"union-find ({a.method})", fh)
    timed("merge small segments", lambda: o._merge_small(labels, e, order, a.min_vertices, a.max_vertices,
                                                         a.method))
    t, c = time.perf_counter(), time.process_time()
    seg = o.felzenszwalb_mesh(v, f, n, col, a.k, a.min_vertices, a.max_vertices, 1.0, 1.0, method=a.method)
    total = (time.perf_counter() - t, time.process_time() - c)
    print(f"{what}: {len(v):,} vertices, {len(e):,} edges, {seg.max() + 1:,} segments, union-find {a.method}")
    print("| stage | wall s | CPU s |\n|---|---:|---:|")
    for name, wall, cpu in rows:
        print(f"| {name} | {wall:.2f} | {cpu:.2f} |")
    print(f"| **felzenszwalb_mesh, end to end** | **{total[0]:.2f}** | **{total[1]:.2f}** |")
    print(f"target {a.target_s:.0f} s: {'met' if total[0] <= a.target_s else 'NOT met'}")


if __name__ == "__main__":
    main()
