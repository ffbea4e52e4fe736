"""The lifted movable objects in the CARLA package: ``actors.json``, ``spawn_actors.py`` and the
scanned meshes as props.

- ``actors.json`` (beside ``Import/``: ``Import.py`` reads every ``.json`` under ``Import/`` as a
  package description) lists each object with its suggested blueprint and a ``carla.Transform`` in
  the package's map: metres, Unreal's left-handed frame (y = -north of the CARLA frame), yaw in
  degrees clockwise from +x seen from above -- the same conversion as the spawn points
  (``carla_pkg.spawn_points``: site heading = -yaw). Vehicles are spawned with their origin on the
  ground (a CARLA vehicle's origin is at its base; ``spawn_z_m`` above it keeps the wheels out of
  the road), walkers at half their height (a walker's origin is the centre of its capsule).
- ``spawn_actors.py`` spawns the suggested blueprints there (``--list``, ``--dry-run``,
  ``--skip``, ``--scanned`` for the scanned meshes instead).
- The scanned meshes become props ``<Map>_Scanned<Class>_NNN`` (tag by class: ``Static/Car`` ...),
  registered by ``make import`` but spawned only on request (``spawn_props.py --with-scanned`` or
  ``spawn_actors.py --scanned``): by default the simulator's own actors stand in for them.
"""
from __future__ import annotations

import dataclasses
import json
import math
import pprint
from pathlib import Path

import numpy as np

from .carla_pkg import _wrap180

ACTORS_FILE = "actors.json"
SPAWN_ACTORS = "spawn_actors.py"


def site_to_carla(xyz, yaw_site_deg: float, frame) -> tuple[dict, float]:
    """(carla location/rotation dict, package scale) of a site-frame point and heading (counter-clockwise
    from east). ``frame`` None: the package is in the site frame."""
    p = np.asarray(xyz, float).reshape(1, 3)
    rot, scale = 0.0, 1.0
    if frame is not None:
        p = frame.site_to_package(p)
        rot, scale = math.degrees(frame.rotation_rad), float(frame.scale)
    from twinkit.street.lanes import to_carla, yaw_to_carla

    x, y, z = (float(t) for t in to_carla(p)[0])
    return ({"x": round(x, 3), "y": round(y, 3), "z": round(z, 3), "pitch": 0.0,
             "yaw": round(_wrap180(yaw_to_carla(yaw_site_deg + rot)), 3), "roll": 0.0}, scale)


def carla_actors(actors: list[dict], frame, map_name: str, spawn_z_m: float = 0.2) -> list[dict]:
    """The ``actors.json`` entries of the package (see the module doc)."""
    out = []
    for a in actors:
        box = a["box"]
        cx, cy, _ = box["center"]
        size = box["size"]
        bp = a.get("blueprint")
        walker = bool(bp and bp["id"].startswith("walker."))
        z = a["ground_z"] + (size[2] / 2 + spawn_z_m if walker else spawn_z_m)
        tr, _ = site_to_carla([cx, cy, z], box["yaw_deg"], frame)
        prop = f"{map_name}_Scanned{a['name']}"
        out.append({"id": a["id"], "name": a["name"], "class": a["class"], "class_id": a["class_id"],
                    "blueprint": bp["id"] if bp else None, "blueprint_size_mismatch": bp["size_mismatch"] if bp else None,
                    "transform": tr, "size_m": size, "faces": a["faces"],
                    "scanned_prop": f"static.prop.{prop.lower()}", "scanned_prop_name": prop,
                    "site": {"center": box["center"], "yaw_deg": box["yaw_deg"], "ground_z": a["ground_z"]}})
    return out


def scanned_props(movables: list, map_name: str, frame, work: Path, texture_name: str | None) -> list[dict]:
    """The scanned meshes moved into the package frame and written to ``work`` as class PLYs; returns
    ``write_package``'s ``scanned`` entries (name, ply, class_id, faces, mesh)."""
    from .classmesh import write_class_ply

    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    out = []
    for cm in movables:
        if cm.mesh.n_faces == 0:
            continue
        moved = cm
        if frame is not None:
            rot = frame.matrix / frame.scale
            moved = dataclasses.replace(cm, mesh=dataclasses.replace(
                                        cm.mesh, vertices=frame.site_to_package(cm.mesh.vertices),
                                        attrs={**cm.mesh.attrs, "normals": (np.asarray(cm.mesh.normals, np.float64) @ rot.T).astype(np.float32)}))
        mesh = f"Scanned{cm.name}"
        ply = work / f"{mesh}.ply"
        write_class_ply(ply, moved, texture_name)
        out.append({"name": f"{map_name}_{mesh}", "ply": ply, "class_id": int(cm.class_id), "faces": cm.mesh.n_faces,
                    "mesh": mesh})
    return out


SCRIPT = '''#!/usr/bin/env python3
"""Spawn the movable objects scanned in map {map!r} (package {package!r}) as CARLA actors.

Made by twinkit. The scanned vehicles, riders and pedestrians were lifted out of the static map;
each is listed here with a suggested blueprint (by class and size) and its transform in the map
(carla.Transform: metres, Unreal's frame, y = -north). Vehicles are spawned with physics off
(parked); --scanned spawns the scanned meshes (props static.prop.{map_lower}_scanned*) instead.

    python spawn_actors.py [--host localhost] [--port 2000] [--list] [--dry-run] [--skip car ...] [--scanned]
"""
import argparse
import sys

ACTORS = {actors}
MAP = {map_check!r}  # the map the transforms belong to; "": any map (a package without a map of its own)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--host", default="localhost")
    ap.add_argument("--port", type=int, default=2000)
    ap.add_argument("--list", action="store_true", help="print the actors and exit")
    ap.add_argument("--dry-run", action="store_true", help="print what would be spawned, connect to nothing")
    ap.add_argument("--skip", nargs="*", default=[], help="CityScapes classes to leave out (e.g. person)")
    ap.add_argument("--scanned", action="store_true", help="spawn the scanned meshes (props) instead of blueprints")
    args = ap.parse_args()
    todo = [a for a in ACTORS if a["class"] not in set(args.skip)]
    if not args.scanned:
        todo = [a for a in todo if a["blueprint"]]
    if args.list or args.dry_run:
        for a in todo:
            t = a["transform"]
            bp = a["scanned_prop"] if args.scanned else a["blueprint"]
            where = "origin (mesh in map coordinates)" if args.scanned else \\
                f"x={{t['x']:.2f}} y={{t['y']:.2f}} z={{t['z']:.2f}} yaw={{t['yaw']:.1f}}"
            print(f"{{a['name']}}\\t{{a['class']}}\\t{{bp}}\\t{{where}}")
        return 0
    import carla

    client = carla.Client(args.host, args.port)
    client.set_timeout(30.0)
    world = client.get_world()
    if MAP and not world.get_map().name.endswith(MAP):
        sys.exit(f"the running map is {{world.get_map().name}}, load {{MAP!r}} first (client.load_world({{MAP!r}}))")
    lib = world.get_blueprint_library()
    for a in todo:
        bp_id = a["scanned_prop"] if args.scanned else a["blueprint"]
        try:
            bp = lib.find(bp_id)
        except IndexError:
            print(f"{{a['name']}}: blueprint {{bp_id}} not in this CARLA; skipped")
            continue
        if bp.has_attribute("role_name"):
            bp.set_attribute("role_name", a["name"])
        if args.scanned:
            tr = carla.Transform()
        else:
            t = a["transform"]
            tr = carla.Transform(carla.Location(x=t["x"], y=t["y"], z=t["z"]),
                                 carla.Rotation(pitch=t["pitch"], yaw=t["yaw"], roll=t["roll"]))
        actor = world.try_spawn_actor(bp, tr)
        if actor is None:
            print(f"{{a['name']}}: {{bp_id}} collides at its place; skipped")
            continue
        actor.set_simulate_physics(False)
        print(f"spawned {{a['name']}} as {{bp_id}} (actor {{actor.id}})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
'''


def write_actor_files(folder: Path, entries: list[dict], *, map_name: str, package: str, source: dict,
                      has_map: bool = True) -> None:
    """``folder/actors.json`` and ``folder/spawn_actors.py`` (folder = the package root beside ``Import/``).
    ``has_map=False``: the package has no map (no OpenDRIVE), the script spawns into whichever map runs."""
    folder = Path(folder)
    (folder / ACTORS_FILE).write_text(json.dumps({
        "map": map_name, "count": len(entries), "lifted": bool(source.get("lifted", True)),
        "frames": {"transform": "carla.Transform arguments: metres, degrees, Unreal left-handed (y = -north)",
                   "site": "site frame: x east, y north, z up; yaw counter-clockwise from east (long axis)"},
        "blueprints": "suggested by class and size among CARLA 0.9.16's blueprints (Docs/catalogue_vehicles.md, "
                      "Docs/bp_library.md); a box's front cannot be told from the scan: yaw may be off by 180 deg",
        "actors": entries}, indent=1) + "\n")
    script = folder / SPAWN_ACTORS
    script.write_text(SCRIPT.format(map=map_name, map_lower=map_name.lower(), package=package,
                                    map_check=map_name if has_map else "",
                                    actors=pprint.pformat(entries, indent=1, width=110, sort_dicts=False)))
    script.chmod(0o755)
