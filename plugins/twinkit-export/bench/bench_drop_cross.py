"""The drop test with the maps held fixed: the static mesh of each run of one capture against the map of each run.

On a capture whose roads come from the scan, any change to the mesh moves the map too (the rendered views, the
labels, the carriageway, the roads derived from it), so one run's drop test mixes the two effects. This scores
every run's final static mesh (``*_lift_movables/textured_mesh.obj``) under every run's final map
(``*_apply_alignment/aligned.xodr``) with the drop test's own check of the driving lanes (``check_lane``, the rays
inside the capture's footprint from ``*_read_cloud/points.ply``): the gate's figure (its share found off the kerb
line or on a continuous surface) and the rays that fail it. A mesh change that helps does so down a column.

Run: .venv/bin/python plugins/twinkit-export/bench/bench_drop_cross.py RUN_A RUN_B [...]
(each RUN a site's output folder of one capture: its numbered step folders, e.g. two ``engine.outputs_dir``)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _one(run: Path, pattern: str) -> Path:
    found = sorted(run.glob(pattern))
    if not found:
        sys.exit(f"{run}: no {pattern}; give a finished run's site folder (its numbered step folders)")
    return found[-1]


def cross(runs: list[Path]) -> list[dict]:
    """One row per (mesh run, map run): ``{"mesh", "map", "rays", "gate_pct", "failing", "widest_hole_m"}``."""
    import numpy as np

    from twinkit import artefacts as A
    from twinkit.surface.closest import Surface
    from twinkit.surface.watertight import Footprint, ground_share
    from twinkit_export.ground_check import DropTestParams, check_lane, lane_rays

    p = DropTestParams()
    fp = Footprint.from_points(A.read_points(_one(runs[0], "*_read_cloud/points.ply")).vertices,
                               fill_limit_m=p.fill_limit_m, margin_m=p.footprint_margin_m)
    rays = {}
    for run in runs:
        r = lane_rays(A.read_opendrive(_one(run, "*_apply_alignment/aligned.xodr")), p.spacing_m)["driving"]
        rays[run] = r[fp.inside(r)] if len(r) else r
    rows = []
    for mesh_run in runs:
        mesh = A.read_textured_obj(_one(mesh_run, "*_lift_movables/textured_mesh.obj"))
        scene = Surface(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)).scene
        for map_run in runs:
            lane, _, _ = check_lane("driving", rays[map_run], p.min_driving_pct, mesh, scene, p)
            rows.append({"mesh": str(mesh_run), "map": str(map_run), "rays": lane["rays"],
                         "gate_pct": ground_share(lane), "failing": lane["failing"]["rays"],
                         "widest_hole_m": lane["widest_hole_m"]})
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: a row per mesh, a column per map."""
    maps = list(dict.fromkeys(r["map"] for r in rows))
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    cell = {(r["mesh"], r["map"]): r for r in rows}
    out = ["| mesh \\ map | " + " | ".join(maps) + " |", "|---|" + "---:|" * len(maps)]
    for m in meshes:
        vals = []
        for mp in maps:
            r = cell[(m, mp)]
            g = "-" if r["gate_pct"] is None else f"{r['gate_pct']:.3f} %"
            vals.append(f"{g} ({r['failing']} of {r['rays']}, hole {r['widest_hole_m']:.2f} m)")
        out.append(f"| {m} | " + " | ".join(vals) + " |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="site output folders of runs of one capture")
    a = ap.parse_args(argv)
    if len(a.runs) < 2:
        ap.error("give two runs or more")
    print(table(cross(a.runs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
