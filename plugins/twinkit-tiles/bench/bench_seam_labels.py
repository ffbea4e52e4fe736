"""Do the tile seams show in the semantic labels? ``recipe=tiled_segment`` on the small demo site, tiled
(3 x 3 tiles of 20 m) and untiled (one tile, same code), with the real 2D model when its weights are
in ../shared/models (else the oracle, which only exercises the wiring). The untiled run checks the same
lines as the tiled run's seams (``evaluate_seam_labels.planes``), so the two rows compare the same
places: label changes along edges crossing those lines, the changes the ground truth does not have, and
vertex accuracy within 1 m of them vs. elsewhere. Prints a markdown table and writes JSON.

    .venv/bin/python plugins/twinkit-tiles/bench/bench_seam_labels.py [--json out.json] [--out /tmp/seamlab]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
WEIGHTS = REPO.parent / "shared" / "models"


def run(out: Path, *args: str) -> float:
    cmd = [sys.executable, "-m", "twinkit", "recipe=tiled_segment", "site=demo", "site.size=small",
           "steps.plan_tiles.voxel_m=0.03", "steps.plan_tiles.target_faces=500000", "executor.workers=2",
           f"engine.outputs_dir={out}", *args]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=str(REPO))
    if r.returncode:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr[-4000:]}")
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/twinkit-bench-seam-labels")
    ap.add_argument("--json", default="")
    ap.add_argument("--tile-m", type=float, default=20.0)
    a = ap.parse_args()
    model = [] if any(WEIGHTS.glob("**/*.pt")) else ["image_model=oracle"]
    out = Path(a.out)
    secs = {"tiled": run(out / "tiled", f"steps.plan_tiles.tile_m={a.tile_m}", *model)}
    tiles = json.loads((out / "tiled" / "demo" / "03_plan_tiles" / "tiles.json").read_text())["items"]
    from twinkit_tiles.edges import seam_planes

    lines = [f"{'xyz'[ax]}={v:.4f}" for ax, v in seam_planes(tiles)]
    secs["untiled"] = run(out / "untiled", "steps.plan_tiles.tile_m=100000", *model,
                          "steps.evaluate_seam_labels.planes=[" + ",".join(f'"{x}"' for x in lines) + "]")
    rows = {}
    for name in ("tiled", "untiled"):
        ws = out / name / "demo"
        lab = json.loads(next(ws.glob("*_seam_labels/seam_labels.json")).read_text())
        seg = json.loads(next(ws.glob("*_evaluate_segmentation/seg_metrics.json")).read_text())["scores"]
        rows[name] = {"seconds": round(secs[name], 1), "miou": round(seg["miou"], 2),
                      "accuracy": round(seg["accuracy"], 2)} | {k: v for k, v in lab.items() if not isinstance(v, list)}
    print(f"model: {'oracle (no weights found)' if model else 'EfficientViT-B0 (../shared/models)'}; "
          f"lines checked: {', '.join(lines)}\n")
    print("| run | mIoU | accuracy % | label changes at the lines % | not in GT % | at control planes % "
          "| not in GT % | accuracy within 1 m of the lines % | elsewhere % | s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in rows.items():
        print(f"| {name} | {r['miou']} | {r['accuracy']} | {r['seam_change_pct']} | {r.get('seam_changes_not_in_gt_pct')} "
              f"| {r['control_change_pct']} | {r.get('control_changes_not_in_gt_pct')} "
              f"| {r.get('accuracy_near_seams_pct')} | {r.get('accuracy_elsewhere_pct')} | {r['seconds']} |")
    if a.json:
        Path(a.json).write_text(json.dumps({"lines": lines, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
