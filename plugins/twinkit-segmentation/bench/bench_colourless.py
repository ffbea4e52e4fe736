"""Clouds without colour (issue 28): which rendering of a colourless mesh the real 2D model reads best.

    .venv/bin/python plugins/twinkit-segmentation/bench/bench_colourless.py --run outputs/demo [--every 3]
        [--modes colour,grey,shaded,height,intensity] [--texture-px 4096]

Takes a finished demo run (exact ground truth), removes the colours of its dense mesh, bakes the
simplified mesh's texture once per ``bake_texture.colourless`` mode (twinkit-pointcloud shading.py),
renders every ``--every``-th kept view of the run with render_views' defaults, and scores each set
through the whole vote with EfficientViT-B0 (bench_views.py: predict -> backproject with its
defaults -> mIoU against the ground truth). ``colour`` is the run's own texture (the reference).
Also prints each set's blank-view share and median grey-level spread (render_views' signal).
The run's over-segmentation (made with colours) is reused for every set.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))


def _step(run: Path, name: str) -> Path:
    hits = sorted(run.glob(f"[0-9][0-9]_{name}"))
    if not hits:
        sys.exit(f"{run}: no finished {name} step; run `twinkit recipe=segment_demo site=demo` first")
    return hits[-1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, default=Path("outputs/demo"))
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--modes", default="colour,grey,shaded,height,intensity")
    ap.add_argument("--texture-px", type=int, default=4096)
    ap.add_argument("--work", type=Path, default=Path("outputs/bench_colourless"))
    a = ap.parse_args(argv)

    import bench_views
    from twinkit.mesh import read_ply, write_ply
    from twinkit.testing import make_context
    from twinkit.plugins import get_registry

    from twinkit_segmentation import steps as S

    run = a.run
    index = json.loads((_step(run, "render_views") / "renders" / "index.json").read_text())
    kept = index["kept"][:: max(1, a.every)]
    a.work.mkdir(parents=True, exist_ok=True)
    (a.work / "views.json").write_text(json.dumps({"views": kept}))
    dense = read_ply(_step(run, "clean") / "clean_mesh.ply")
    dense.attrs.pop("colors", None)
    write_ply(a.work / "clean_mesh_nocolour.ply", dense)
    points = _step(run, "read_cloud") / "points.ply"
    summary = []
    for mode in a.modes.split(","):
        w = a.work / mode
        w.mkdir(exist_ok=True)
        ctx = make_context(w / "ctx", site={"name": "bench"})
        if mode == "colour":
            tex = _step(run, "texture") / "textured_mesh.ply"
        else:
            if mode == "intensity" and "intensity" not in read_ply(points).attrs:
                print("intensity: the run's cloud has none; skipped", flush=True)
                continue
            bake = get_registry().get("step", "bake_texture")  # the point-cloud plugin's step, by name
            bake.run(bake.params(texture_px=a.texture_px, colourless=mode), ctx,
                           in_mesh_ply=_step(run, "simplify") / "mesh.ply",
                           in_clean_mesh_ply=a.work / "clean_mesh_nocolour.ply",
                           out_textured_mesh_obj=w / "textured_mesh.obj", out_textured_mesh_ply=w / "textured_mesh.ply",
                           in_points_ply=points)
            tex = w / "textured_mesh.ply"
        rctx = make_context(w / "rctx", site={"name": "bench"})
        res = S.render_views(S.RenderParams(), rctx, in_textured_mesh_ply=tex, in_views_json=a.work / "views.json",
                             out_renders_dir=w / "renders")
        summary.append((mode, res.get("blank_share"), res.get("signal_std_median"), res["kept"]))
        bench_views.main(["--run", str(run), "--renders", str(w / "renders"), "--variants", "base",
                          "--label", mode, "--out", str(a.work / "table.md")])
    print("\n| mode | views | blank share | median grey-level std |\n|---|---:|---:|---:|")
    for mode, blank, std, n in summary:
        print(f"| {mode} | {n} | {blank} | {std} |")


if __name__ == "__main__":
    main()
