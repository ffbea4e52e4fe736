"""Walkers and parked cars in the CARLA package of finished site runs (issue 45, item 4).

    python plugins/twinkit-export/bench/bench_sidewalks.py outputs/demo [more runs ...] [--json out.json]

Per run (its last ``NN_carla/carla_import`` package), with the package checker's own functions
(``twinkit_export.contract_sidewalks``):

1. the ``Road_Sidewalk`` node of the map FBX (what CARLA's navmesh walks on): connected pieces in all, per
   block (the regions the OpenDRIVE's carriageway lanes enclose), blocks whose sidewalk is more than one
   surface, small pieces on the carriageway;
2. parked vehicles of ``actors.json`` standing on an OpenDRIVE sidewalk lane (``Map::GetWaypoint`` with lane
   type Sidewalk, through ``LaneMap.lane_at``);
3. the share of the OpenDRIVE's sidewalk-lane centre samples (every 0.5 m) that lie over the mesh's
   ``Road_Sidewalk`` (of the samples over the mesh), and over ``Road_Road``;
4. the parking lanes of the map (lane-type samples).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "plugins" / "twinkit-export"))


def package_of(run: Path) -> Path | None:
    """The carla_import folder of the run's last carla step."""
    c = sorted(p for p in Path(run).glob("[0-9][0-9]_carla/carla_import") if p.is_dir())
    return c[-1] if c else None


def measure(run: Path) -> dict:
    """The numbers of the module's doc for one run."""
    from twinkit.street.lanes import LaneMap
    from twinkit_export import contract_sidewalks as cs, fbxbin

    root = package_of(run)
    if root is None:
        return {"run": str(run), "error": "no NN_carla/carla_import"}
    pkg = next(p for p in (root / "Import").iterdir() if p.is_dir())
    desc = json.loads((pkg / f"{pkg.name}.json").read_text())["maps"][0]
    xodr = (pkg / desc["xodr"]).read_text(encoding="utf-8")
    geo = {n: (v, f) for n, v, f in fbxbin.mesh_arrays(pkg / desc["source"])}
    blocks = cs.sidewalk_blocks(*geo["Road_Sidewalk"], xodr) if "Road_Sidewalk" in geo else cs.BlockReport()
    actors = json.loads((root / "actors.json").read_text()).get("actors", []) if (root / "actors.json").is_file() \
        else []
    parked = cs.parked_on_sidewalk(actors, xodr)
    share = cs.sidewalk_lane_share(geo, xodr)
    lanes = LaneMap(xodr, "bench").lanes(0.5)
    return {"run": str(run), **blocks.summary(),
            "parked_vehicles": sum(1 for a in actors if str(a.get("class")) in cs.PARKED_CLASSES),
            "parked_on_sidewalk_lanes": len(parked), "parked_on_sidewalk": [p["name"] for p in parked],
            "sidewalk_lane_samples": share["samples"], "sidewalk_lane_samples_over_mesh": share["inside"],
            "share_over_sidewalk": share["share_by_node"].get("Road_Sidewalk", 0.0),
            "share_over_road": share["share_by_node"].get("Road_Road", 0.0),
            "parking_lane_samples": int(lanes.is_type("parking").sum())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="finished site runs (outputs/<site>)")
    ap.add_argument("--json", type=Path, help="write the rows here too")
    a = ap.parse_args()
    rows = [measure(r) for r in a.runs]
    cols = ("sidewalk_components", "blocks_with_sidewalk", "blocks_split", "stray_pieces", "parked_vehicles",
            "parked_on_sidewalk_lanes", "share_over_sidewalk", "share_over_road", "parking_lane_samples")
    print("| run | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for r in rows:
        print(f"| {r['run']} | " + " | ".join(str(r.get(c, r.get("error", ""))) for c in cols) + " |")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
