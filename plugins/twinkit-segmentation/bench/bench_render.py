"""render_views' speed per view (issue 48's target: <= 0.05 s per view all-in, was 0.25 s on the small demo).

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_render.py                 # synthetic street
    .venv/bin/python plugins/twinkit-segmentation/bench/bench_render.py \\
        --mesh outputs/demo/06_texture/textured_mesh.ply --views outputs/demo/10_sample_views/views.json

Renders ``--n`` views with ``render_view_set`` (draw, drop, hole mask and fill, files written) and prints
wall and CPU seconds per view with the load average, then each part against the way it was done before
(every face drawn in the mesh's order, scipy's distance transforms, ``np.savez_compressed``, Pillow's PNG).
CPU seconds count every thread of the process (the renderer's rasteriser threads and the file writer).
Timing only: the equality of the pixels is tested in tests/test_view_render.py.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import tempfile
import time
from pathlib import Path

import numpy as np


class _Ctx:
    log = logging.getLogger("bench_render")

    def progress(self, it, total=None, desc=None):
        return it


def _synthetic(n: int):
    """The synthetic street (0.1 m triangles) with ``n`` street-level views around it, untextured."""
    from twinkit_segmentation.synthetic import street_scene

    v, f, _, _ = street_scene(step=0.1)
    rng = np.random.default_rng(0)
    views = [{"id": f"v{i:03d}", "sampler": "bench", "position": [float(rng.uniform(-18, 18)),
              float(rng.uniform(-3, 3)), 1.6], "heading_deg": float(rng.uniform(0, 360)), "pitch_deg": -8.0,
              "hfov_deg": 75.0, "width": 1024, "height": 512} for i in range(n)]

    class M:
        vertices, faces, corner_uv, texture = v, f, None, None
    return M, None, views, f"synthetic street, {len(f):,} faces"


def _timed(fn, reps: int):
    t, c = time.perf_counter(), time.process_time()
    for i in range(reps):
        fn(i)
    return (time.perf_counter() - t) / reps, (time.process_time() - c) / reps


def _parts(mesh, tex, views, tmp: Path) -> list:
    """(part, now wall/CPU, before wall/CPU) per view, on the first views."""
    from PIL import Image

    import twinkit_segmentation.render as R
    from twinkit_segmentation.viewholes import fill_from_nearest, ground_holes
    from twinkit_segmentation.views import view_matrices

    v0 = views[0]
    r = R.Renderer(mesh.vertices, mesh.faces, mesh.corner_uv, tex, int(v0["width"]), int(v0["height"]))
    mats = [view_matrices(v) for v in views[:8] if (v["width"], v["height"]) == (v0["width"], v0["height"])]
    n = len(mats)
    maps = [r.render(*m) for m in mats]
    cull = R.visible_cells
    culled = _timed(lambda i: r.render(*mats[i]), n)
    r.front_to_back = False
    mesh_order = _timed(lambda i: r.render(*mats[i]), n)
    R.visible_cells = lambda lo, hi, mvp: np.ones(len(lo), bool)
    every = _timed(lambda i: r.render(*mats[i]), n)
    R.visible_cells = cull
    r.release()
    below = [R.below_horizon(*m, int(v0["width"]), int(v0["height"])) for m in mats]
    ground_holes(maps[0][1] >= 0, below[0], 16.0)  # compile / load the cached compiled code
    fill_from_nearest(maps[0][0].copy(), ~(maps[0][1] >= 0), maps[0][1] >= 0)
    def holes(i, method):
        hit = maps[i][1] >= 0
        fill_from_nearest(maps[i][0].copy(), ground_holes(hit, below[i], 16.0, method), hit, method)

    rows = [("draw and read back (culled, nearest cells first)", culled, every),
            ("draw and read back (culled, the mesh's face order)", mesh_order, every),
            ("hole mask and fill", _timed(lambda i: holes(i, "auto"), n), _timed(lambda i: holes(i, "scipy"), n))]
    from twinkit.deflate import backend
    from twinkit.surface.texture import write_png

    def on_zlib(fn):  # the same writer with Python's zlib deflating (TWINKIT_DEFLATE=zlib)
        def run(i):
            old = os.environ.get("TWINKIT_DEFLATE")
            os.environ["TWINKIT_DEFLATE"] = "zlib"
            try:
                fn(i)
            finally:
                os.environ.pop("TWINKIT_DEFLATE") if old is None else os.environ.__setitem__("TWINKIT_DEFLATE", old)
        return run

    vmap = lambda i: R.write_vertex_map(tmp / "a.npz", maps[i][1])  # noqa: E731
    png = lambda i: write_png(tmp / "a.png", maps[i][0], row_filter="sub", rle=True)  # noqa: E731
    rows.append((f"vertex map file ({backend()}; before: np.savez_compressed)", _timed(vmap, n),
                 _timed(lambda i: np.savez_compressed(tmp / "b.npz", vertex=maps[i][1]), n)))
    rows.append((f"vertex map file ({backend()}; before: the same on zlib)", _timed(vmap, n), _timed(on_zlib(vmap), n)))
    rows.append((f"PNG (level 1, Sub, {backend()}; on the writer thread; before: Pillow)", _timed(png, n),
                 _timed(lambda i: Image.fromarray(maps[i][0]).save(tmp / "b.png", compress_level=1), n)))
    rows.append((f"PNG (level 1, Sub, {backend()}; before: the same on zlib, run-length)", _timed(png, n),
                 _timed(on_zlib(png), n)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", type=Path, default=None, help="a textured_mesh.ply (default: a synthetic street)")
    ap.add_argument("--views", type=Path, default=None, help="views.json of sample_views (with --mesh)")
    ap.add_argument("--n", type=int, default=48, help="views to render")
    ap.add_argument("--target-s", type=float, default=0.05)
    a = ap.parse_args()

    from twinkit_segmentation.render import load_texture, render_view_set

    if a.mesh:
        from twinkit import artefacts as A

        mesh = A.read_textured_mesh(a.mesh)
        tex = load_texture(mesh.texture) if mesh.texture is not None else None
        views = json.loads(a.views.read_text())["views"][: a.n]
        what = f"{a.mesh} ({len(mesh.faces):,} faces), {a.views.name}"
    else:
        mesh, tex, views, what = _synthetic(a.n)
    with tempfile.TemporaryDirectory() as tmp:
        load0 = os.getloadavg()[0]
        t, c = time.perf_counter(), time.process_time()
        kept, dropped, t_gl, _ = render_view_set(mesh, tex, views, Path(tmp), 0.6, _Ctx())
        wall, cpu = (time.perf_counter() - t) / len(views), (time.process_time() - c) / len(views)
        rows = _parts(mesh, tex, views, Path(tmp))
    print(f"{what}: {len(views)} views ({len(kept)} kept, {len(dropped)} dropped), load average "
          f"{load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    print("| per view | wall s | CPU s |\n|---|---:|---:|")
    print(f"| **render_view_set, all-in** | **{wall:.3f}** | **{cpu:.3f}** |")
    print(f"| of which draw and read back | {t_gl / len(views):.3f} | |")
    print("\n| part, per view | now wall / CPU s | before wall / CPU s |\n|---|---:|---:|")
    for name, now, before in rows:
        print(f"| {name} | {now[0]:.4f} / {now[1]:.4f} | {before[0]:.4f} / {before[1]:.4f} |")
    print(f"\ntarget {a.target_s:g} s per view: {'met' if wall <= a.target_s else 'NOT met'} (wall, at this load)")


if __name__ == "__main__":
    main()
