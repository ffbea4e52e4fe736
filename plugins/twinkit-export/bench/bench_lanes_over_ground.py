"""The package rule ``lanes_over_ground`` on finished CARLA packages; prints a Markdown table.

    .venv/bin/python plugins/twinkit-export/bench/bench_lanes_over_ground.py --run outputs/demo [--run ...]

For each run's package (``NN_carla/carla_import``): CARLA's driving waypoints every 1 m of the package's
OpenDRIVE against its map FBX (``contract_ground.check_lanes_over_ground``): how many have no ground beneath, how
many of those run past the mesh's edge (the rule's violations) and how many belong to a map larger than the scan.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from twinkit_export.carla_contract import ContractReport
from twinkit_export.contract_ground import check_lanes_over_ground

ROOT = Path(__file__).resolve().parents[3]
RUNS = [ROOT / "outputs" / "demo"]


def bench_run(run: Path) -> list[dict]:
    steps = sorted(run.glob("[0-9][0-9]_carla"))
    if not steps:
        raise SystemExit(f"{run}: no *_carla step folder (a finished pointcloud_site run?)")
    imp = steps[-1] / "carla_import" / "Import"
    out = []
    for pkg in sorted(p for p in imp.iterdir() if p.is_dir()):
        desc = json.loads((pkg / f"{pkg.name}.json").read_text())
        rep = ContractReport(pkg.name)
        for res in check_lanes_over_ground(rep, pkg, desc.get("maps", [])):
            out.append({"run": str(run), "package": pkg.name, **{k: res[k] for k in
                        ("map", "points", "off_ground", "past_edge", "beyond_scan")}, "violations": len(rep.violations)})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="append", type=Path, help="a finished run's folder (repeatable)")
    args = ap.parse_args(argv)
    runs = args.run or [r for r in RUNS if r.is_dir()]
    if not runs:
        print("no run found: give --run outputs/demo (a finished recipe=pointcloud_site site=demo run)")
        return 0
    rows = [r for run in runs for r in bench_run(run.resolve())]
    print("| run | map | waypoints | off the ground | past the mesh's edge (violations) | beyond the scan |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {Path(r['run']).parent.name}/{Path(r['run']).name} | {r['map']} | {r['points']} | {r['off_ground']} | "
              f"{r['past_edge']} | {r['beyond_scan']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
