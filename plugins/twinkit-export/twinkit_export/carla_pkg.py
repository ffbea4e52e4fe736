"""CARLA 0.9.16 import package and spawn points from the OpenDRIVE driving lanes.

Package layout (what ``make import`` reads; the rules are in ``carla_contract``)::

    Import/<Package>/<Package>.json   {"maps": [{name, source, use_carla_materials, xodr}],
                                       "props": [{name, source, tag, size}, ...]}
    Import/<Package>/<Map>.fbx        map geometry: the classes CARLA's MoveAssets routes to their own
                                      tag by name (Road_Road, Road_Sidewalk, Terrain)
    Import/<Package>/<Map>_<Class>.fbx  one prop per other class, imported into Static/<Tag>/ and so
                                      tagged by the folder (Tagger), blueprint static.prop.<map>_<class>
    Import/<Package>/<texture>.png    the texture every FBX references (relative path)
    Import/<Package>/<Map>.xodr       the aligned OpenDRIVE (site frame)
    Import/<Package>/README.md
    Import/roadpainter_decals.json    RoadPainter configuration for the map (no decals by default)
    place_in_map.py                   Unreal editor script: the static props into the map level (run once
                                      after ``make import``, which never places props; ``carla_place``)
    spawn_props.py                    places the props in a running map instead (gone on reload_world)
    spawn_points.json                 beside Import/, not in it: Import.py treats *every* .json file
                                      under Import/ as a package description
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

from .carla_place import PLACE_COMMAND, PLACE_SCRIPT, write_place_script
from .classes import CARLA_NAME_KEYS, ClassInfo


class PackageError(ValueError):
    pass


#: names of classes in the CARLA package where the class name itself would be dropped by
#: PrepareAssetsForCooking's ValidateStaticMesh ("light"/"sign" in the asset name); the tag still
#: comes from the folder (Static/TrafficLight, Static/TrafficSign)
PACKAGE_NAMES = {6: "TrafficLamp", 7: "TrafficPlate"}


def check_names(package: str, map_name: str) -> None:
    from .carla_contract import name_problems, suggest_name

    for what, name in (("package", package), ("map", map_name)):
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name or ""):
            raise PackageError(f"{what} name {name!r}: use letters, digits and '_' (starting with a letter)")
        for key in CARLA_NAME_KEYS:
            if key.lower() in name.lower():
                raise PackageError(f"{what} name {name!r} contains {key!r}, which CARLA's import uses to tag meshes; "
                                   f"choose another name, e.g. {what}_name={suggest_name(name)}")
    # every asset name of the map starts with the map name: a dropped word there drops the whole map
    probs = name_problems(map_name, what="map name")
    if probs:
        raise PackageError(f"{probs[0]}. Set carla_package's map_name to another name, e.g. "
                           f"map_name={suggest_name(map_name)}")


def package_mesh_name(ci: ClassInfo) -> str:
    """Name of a class's mesh in the CARLA package (free of the words CARLA's cooking filter drops)."""
    return PACKAGE_NAMES.get(ci.train_id, ci.carla_name)


def is_map_geometry(ci: ClassInfo) -> bool:
    """True when MoveAssets routes the class's mesh by name to the folder that carries its own tag."""
    from .carla_contract import move_assets_folder, tagger_label

    name = package_mesh_name(ci)
    return name in ("Road_Road", "Road_Sidewalk", "Road_Marking", "Terrain") and \
        tagger_label(move_assets_folder(name)) == ci.carla_tag


def prop_folder(ci: ClassInfo) -> str:
    """Static/<folder> (the prop's ``tag``) whose Tagger label is the class's CARLA tag."""
    from .carla_contract import TAGGER_FOLDERS

    return ci.carla_folder if ci.carla_folder in TAGGER_FOLDERS else "Unlabeled"  # unknown folder -> NONE


def prop_size(extent_m: float) -> str:
    """EPropSize by the largest bounding-box side: Tiny < mailbox < human < bus stop < house."""
    for limit, size in ((0.5, "Tiny"), (1.2, "Small"), (2.5, "Medium"), (6.0, "Big")):
        if extent_m < limit:
            return size
    return "Huge"


def lane_map(xodr_text: str, name: str):
    """The package's OpenDRIVE parsed offline (:class:`twinkit.street.lanes.LaneMap`); PackageError when it
    does not parse."""
    from twinkit.street.lanes import LaneMap, OpenDriveError

    try:
        return LaneMap(xodr_text, name)
    except OpenDriveError as exc:
        raise PackageError(str(exc)) from None


def spawn_points(lanes, spacing_m: float = 20.0, height_m: float = 0.5, skip_junctions: bool = True) -> list[dict]:
    """Spawn points on driving lanes of ``lanes`` (a LaneMap), every ``spacing_m`` along each lane, raised by
    ``height_m``.

    CARLA coordinates (``carla`` block) are what ``carla.Transform`` takes: metres, Unreal's
    left-handed frame (y = -north). ``site`` gives the same point in the site frame (y north) with
    the heading counter-clockwise from east.
    """
    from twinkit.street.lanes import to_carla, yaw_from_carla, yaw_to_carla

    wp = lanes.waypoints(float(spacing_m))
    keep = wp.is_type("driving")
    if skip_junctions:
        keep &= ~wp.in_junction
    wp = wp.take(keep).unique(2)
    out = []
    for i in range(len(wp)):
        x, y, z = wp.xyz[i].tolist()
        z += height_m
        cx, cy, _ = to_carla([x, y, z]).tolist()
        pitch, yaw, roll = (_wrap180(float(a)) for a in (wp.carla_pitch_deg[i], yaw_to_carla(wp.heading_deg[i]),
                                                          wp.carla_roll_deg[i]))
        out.append({
            "road_id": int(wp.road[i]), "section_id": int(wp.section[i]), "lane_id": int(wp.lane[i]),
            "s": round(float(wp.s[i]), 3),
            "carla": {"x": round(cx, 3), "y": round(cy, 3), "z": round(z, 3),
                      "pitch": round(pitch, 3), "yaw": round(yaw, 3), "roll": round(roll, 3)},
            "site": {"x": round(x, 3), "y": round(y, 3), "z": round(z, 3),
                     "heading_deg": round(_wrap180(yaw_from_carla(yaw)), 3)},
        })
    return out


def _wrap180(a: float) -> float:
    """Angle in degrees folded into (-180, 180]."""
    a = math.fmod(float(a), 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return 0.0 if abs(a) < 1e-9 else a


def xodr_georeference(xodr_text: str) -> str | None:
    m = re.search(r"<geoReference>\s*(?:<!\[CDATA\[)?(.*?)(?:\]\]>)?\s*</geoReference>", xodr_text, re.S)
    return m.group(1).strip() if m else None


README = """# CARLA import package `{package}`

Made by twinkit (`carla_package` exporter) for CARLA {carla_version} built from source.

Files: `{package}.json` (the package description `make import` reads), `{map}.fbx` (the map
geometry: {map_classes}), one FBX per other class (`{map}_<Class>.fbx`, imported as props),
`{texture}` (the texture every FBX references by relative path), `{map}.xodr` (the road network,
same local frame as the meshes). Beside this folder: `../roadpainter_decals.json` (road decals for
`{map}`: {decals}). Beside `Import/`: `place_in_map.py` (an editor script that puts the props
into the map level), `spawn_props.py` (spawns them in a running simulator instead) and
`spawn_points.json` ({n_spawn} spawn points on driving lanes for scripts; CARLA also makes its own
spawners from the OpenDRIVE during import). JSON files other than the package's and the decals
file must stay outside `Import/`: `make import` reads every `.json` there as a package.

## Import

1. Copy the contents of `carla_import/Import/` into `<carla>/Import/`: this folder and
   `roadpainter_decals.json` (if `<carla>/Import/roadpainter_decals.json` exists already, add our
   `{map}` entry to its `decals` list instead).
2. From the CARLA root: `make import ARGS="--package={package}"`. The package JSON names the map
   and the props; `--package` only tells `Import.py` where to copy `roadpainter_decals.json`
   (`Content/{package}/Config/`), where RoadPainter finds it.
3. Put the buildings, walls, poles, vegetation ... into the map level: copy `place_in_map.py`
   (beside `Import/`) to the CARLA root and, from there, run it with CARLA's editor:

       {place_command}

   (or, in the editor: File > Execute Python Script). It places each static prop at the origin,
   where its coordinates put it, with its own triangles as collision, and saves the level
   `Content/{package}/Maps/{map}/{map}`: the whole street is part of the map, tagged by class,
   and stays through `reload_world`. Running it again adds nothing.
4. `make launch` (or `make package ARGS="--packages={package}"`), open `Content/{package}/Maps/{map}`.
   Without step 3: with the simulator running the map, `python spawn_props.py` (beside `Import/`;
   `--help`) spawns the props as actors at the map origin; they are gone after `reload_world`.

## Semantic tags: what is automatic

- Map geometry ({map_classes}) is moved by name by CARLA's MoveAssets commandlet to the folder that
  carries its tag and is placed in the map by the import.
- Every other class is a prop: `make import` imports it into `Static/<Tag>/<prop>/`, so CARLA's
  Tagger gives it its class's tag, and registers it as blueprint `static.prop.<prop>`. Nothing in
  CARLA's import places props in a map (`PrepareAssetsForCooking` spawns only `Maps/<Map>` and
  `Static/{{Road,RoadLine,Terrain,SideWalk}}/<Map>`, and `MoveAssets` has no other destination);
  `place_in_map.py` (step 3) does, into the saved level.
- Traffic lights and signs are named `TrafficLamp` / `TrafficPlate` in this package: CARLA skips
  every mesh whose name contains "light" or "sign"; their tag still comes from the folder.

{table}
{movables}
Props are imported with CARLA's import settings: Unreal generates simple collision for them,
which for a whole-site class mesh is coarser than the mesh; `place_in_map.py` switches each to
its own triangles (complex as simple, as `PrepareAssetsForCooking` does for the map meshes). The
pedestrian navmesh is built from `{map}.fbx` alone (props are not obstacles in it).

## Frames

{frames}
"""

#: why a package has no map, per road source (twinkit.geo.xodr.source_kind): 'none' chosen, or the scan kept none
NO_MAP_WHY = {"none": "no road network (road_source=none)",
              "scan": "no road network: road_source=scan kept no road from the scan (see scan_roads.png)"}


def no_map_note(kind: str = "none") -> str:
    """The note of a package without a map (spawn_points.json, the step's metrics): why, per road source, and
    the fix that fits it."""
    from twinkit.geo.xodr import source_hint

    return (f"{NO_MAP_WHY.get(kind, NO_MAP_WHY['none'])}: the package has no map and no OpenDRIVE, so no spawn "
            f"points; the twin's meshes are props (README.md); {source_hint(kind, 'no_map')}")


NO_MAP_NOTE = no_map_note("none")

README_NO_MAP = """# CARLA import package `{package}`: props only, no map

Made by twinkit (`carla_package` exporter) for CARLA {carla_version} built from source, from a twin
made **without a road network**: {why}.

**There is no map and no OpenDRIVE (`.xodr`) in this package.** CARLA's `make import` needs an
OpenDRIVE file beside each map's FBX (`Import.py` builds the pedestrian navmesh and the traffic
manager's binary from it; a map entry without one fails), and a road network cannot be invented
from nothing. So `{package}.json` lists no map (`"maps": []`) and every class of the twin is a
prop: `{map}_<Class>.fbx`, imported into `Static/<Tag>/` so CARLA's Tagger gives it its class's
tag. Without OpenDRIVE there are no driving lanes, no spawn points (`spawn_points.json` is empty),
no traffic lights or signs from CARLA, and vehicles cannot drive on the twin. For a drivable map,
give the site an OSM extract (`site.inputs.osm`) or an OpenDRIVE (`road_source=opendrive`) and run
the recipe again.

Files: `{package}.json`, one FBX per class, `{texture}` (the texture every FBX references by
relative path). Beside this folder: `../roadpainter_decals.json` (empty: no map to paint). Beside
`Import/`: `spawn_props.py` (places the props in the running map, whichever it is).

## Import

1. Copy the contents of `carla_import/Import/` into `<carla>/Import/`.
2. From the CARLA root: `make import ARGS="--package={package}"`: the props become blueprints
   `static.prop.<prop>`.
3. `make launch`, open any map, and with the simulator running: `python spawn_props.py` (beside
   `Import/`). It spawns each prop at the map origin, where the twin's coordinates put it; or drag
   the prop assets into a level at (0, 0, 0) in the editor.

{table}
{movables}
## Frames

{frames}
"""

MOVABLES_README = """
## Movable objects ({n})

The scanned vehicles, riders and pedestrians were lifted out of the map (twinkit's `lift_movables`
step) and the ground beneath them closed. Beside `Import/`, `actors.json` lists each with a
suggested CARLA blueprint (by class and size) and its `carla.Transform`; with the map running,
`python spawn_actors.py` spawns them (`--list`, `--dry-run`, `--skip person`). The scanned meshes
are imported as props `<Map>_Scanned<Class>_NNN` (tagged by their class) but not spawned by
default: `spawn_actors.py --scanned` or `spawn_props.py --with-scanned` places them instead.
"""

SPAWN_SCRIPT = '''#!/usr/bin/env python3
"""Spawn the scanned objects of map {map!r} (package {package!r}) as props in a running CARLA.

Made by twinkit. `make import` imports the props of the package (into Static/<Tag>/, which gives
them their semantic tag) but never places them in a map; this script does, at the map origin,
where the meshes' coordinates put every object in its scanned place, for as long as the world
runs (reload_world drops them). place_in_map.py (CARLA's editor) puts them into the map level
itself instead; after it, this script would place them twice.

    python spawn_props.py [--host localhost] [--port 2000] [--skip car truck ...] [--list]
"""
import argparse
import sys

PROPS = {props}
MAP = {map_check!r}  # the map the props belong to; "": any map (a package without a map of its own)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--host", default="localhost")
    ap.add_argument("--port", type=int, default=2000)
    ap.add_argument("--skip", nargs="*", default=[], help="CityScapes classes to leave out (e.g. car person)")
    ap.add_argument("--list", action="store_true", help="print the props and exit")
    ap.add_argument("--with-scanned", action="store_true",
                    help="also the scanned movable objects (cars, ...), which spawn_actors.py replaces by actors")
    args = ap.parse_args()
    todo = [p for p in PROPS if p["class"] not in set(args.skip) and (args.with_scanned or not p.get("scanned"))]
    if args.list:
        for p in todo:
            print(p["blueprint"], p["class"], p["tag"], p["faces"])
        return 0
    import carla

    client = carla.Client(args.host, args.port)
    client.set_timeout(30.0)
    world = client.get_world()
    if MAP and not world.get_map().name.endswith(MAP):
        sys.exit(f"the running map is {{world.get_map().name}}, load {{MAP!r}} first "
                 f"(client.load_world({{MAP!r}}))")
    lib = world.get_blueprint_library()
    for p in todo:
        try:
            bp = lib.find(p["blueprint"])
        except IndexError:
            sys.exit(f"blueprint {{p['blueprint']}} not found: run make import for package {package!r} and restart "
                     f"the simulator")
        actor = world.spawn_actor(bp, carla.Transform())
        actor.set_simulate_physics(False)
        print(f"spawned {{p['blueprint']}} ({{p['class']}}, tag {{p['tag']}}) as actor {{actor.id}}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
'''


def _site_frames(georef: str) -> str:
    return (f"Mesh and OpenDRIVE share the site frame (x east, y north, z up, metres, origin at the base\n"
            f"point {georef}). Unreal mirrors y on import of both, so they stay aligned.")


def _prop_entry(name: str, ply: Path, ci, faces: int, mesh: str) -> dict:
    """A prop of the package: its name, class mesh file, class, tag folder, label, size and mesh name."""
    from .carla_contract import tagger_label
    from .classmesh import read_class_ply

    v = read_class_ply(ply).mesh.vertices
    extent = float((v.max(0) - v.min(0)).max()) if len(v) else 0.0
    return {"name": name, "ply": ply, "class": ci.name, "class_id": ci.train_id,
            "tag": prop_folder(ci), "label": tagger_label(prop_folder(ci)), "size": prop_size(extent),
            "faces": int(faces), "mesh": mesh}


def _map_and_props(present: list[dict], class_dir: Path, map_name: str, has_map: bool, scanned: list[dict] | None
                   ) -> tuple[list[Path], dict, list[dict]]:
    """Which class meshes go into the map FBX and which become props (plus the scanned ones):
    (map class mesh files, file -> FBX node name, prop entries)."""
    from .classes import info

    map_files, map_names, props = [], {}, []
    for c in present:
        ci = info(c["class_id"])
        ply = Path(class_dir) / c["file"]
        if has_map and is_map_geometry(ci):
            map_files.append(ply)
            map_names[ply] = package_mesh_name(ci)
            continue
        props.append(_prop_entry(f"{map_name}_{package_mesh_name(ci)}", ply, ci, c["faces"], package_mesh_name(ci)))
    for sp in scanned or []:
        ci = info(sp["class_id"])
        props.append({**_prop_entry(sp["name"], sp["ply"], ci, sp["faces"], sp["mesh"]), "scanned": True})
    if has_map and not map_files:
        raise PackageError("no road, sidewalk or terrain mesh: a CARLA map needs ground geometry")
    if not has_map and not props:
        raise PackageError("no class mesh with faces: nothing to put in the package")
    return map_files, map_names, props


def _write_spawn_files(folder: Path, package: str, map_name: str, has_map: bool, props: list[dict],
                       spawn: list[dict], note: str = NO_MAP_NOTE) -> None:
    """``spawn_props.py`` (every prop's blueprint) and ``spawn_points.json`` in ``folder``."""
    spawn_list = [{"blueprint": f"static.prop.{p['name'].lower()}", "class": p["class"], "tag": p["label"],
                   "faces": p["faces"], **({"scanned": 1} if p.get("scanned") else {})} for p in props]
    script = folder / "spawn_props.py"
    script.write_text(SPAWN_SCRIPT.format(map=map_name, package=package, map_check=map_name if has_map else "",
                                          props=json.dumps(spawn_list, indent=4)))
    script.chmod(0o755)
    (folder / "spawn_points.json").write_text(json.dumps(
        {"map": map_name if has_map else None, "count": len(spawn),
         "frames": {"carla": "carla.Transform arguments: metres, degrees, Unreal left-handed (y = -north)",
                    "site": "site frame: x east, y north, z up; heading counter-clockwise from east"},
         "spawn_points": spawn, **({} if has_map else {"note": note})}, indent=1) + "\n")


def _class_table(present: list[dict], props: list[dict], map_names: dict, class_dir: Path, map_name: str) -> list[str]:
    """The README's markdown table: where each class ends (map node or prop), its tag and who places it."""
    from .carla_contract import move_assets_folder
    from .classes import info

    rows = ["| class | in the package | ends in | tag | placed by |", "|---|---|---|---|---|"]
    for c in present:
        ci = info(c["class_id"])
        if ci.train_id in [p["class_id"] for p in props if not p.get("scanned")]:
            p = next(p for p in props if p["class_id"] == ci.train_id and not p.get("scanned"))
            rows.append(f"| {ci.name} | prop `{p['name']}` (`static.prop.{p['name'].lower()}`) | "
                        f"`Static/{p['tag']}/{p['name']}` | {p['label']} | "
                        f"{'`place_in_map.py` (editor, saved in the level)' if map_names else '`spawn_props.py`'} |")
        else:
            node = map_names[Path(class_dir) / c["file"]]
            rows.append(f"| {ci.name} | `{map_name}.fbx` node `{node}` | "
                        f"`Static/{move_assets_folder(f'{map_name}_{node}')}/{map_name}` | {ci.carla_tag} | "
                        f"`make import` |")
    for p in props:
        if p.get("scanned"):
            rows.append(f"| {p['class']} (scanned, lifted) | prop `{p['name']}` (`static.prop.{p['name'].lower()}`) | "
                        f"`Static/{p['tag']}/{p['name']}` | {p['label']} | `spawn_props.py --with-scanned` or "
                        f"`spawn_actors.py --scanned` (default: `spawn_actors.py` spawns CARLA actors instead) |")
    return rows


def write_package(folder: Path, *, package: str, map_name: str, class_dir: Path, classes: list[dict],
                  texture: Path | None, xodr_text: str | None, spawn: list[dict], use_carla_materials: bool, georef: dict,
                  decals: bool = False, python: str = "", log_path: Path | None = None,
                  carla_version: str = "0.9.16", frames=None, scanned: list[dict] | None = None,
                  no_map_source: str = "none") -> tuple[Path, dict]:
    """Write ``folder/Import/<package>/...``, ``Import/roadpainter_decals.json``, ``spawn_props.py``.

    ``classes``: the class-mesh manifest entries (``class_id``, ``file``, ``faces``). Returns the
    package folder and what went where (map classes, props). ``class_dir``'s meshes are in the
    package's frame already. ``frames(georef_text) -> str``: the README's frame section (default: the
    site frame). ``scanned``: the lifted movable objects as extra props (``carla_actors.scanned_props``:
    name, ply, class_id, faces, mesh), registered like the others but spawned only on request.
    ``xodr_text=None`` (no road network: ``road_source=none``, or ``no_map_source='scan'`` when the scan kept no
    road): no map at all, every class is a prop (``README_NO_MAP`` says why: CARLA's import needs an OpenDRIVE
    beside a map's FBX).
    """
    import shutil

    from .carla_contract import DECALS_FILE, decals_entry
    from .fbx import write_fbx_set

    folder = Path(folder)
    pkg = folder / "Import" / package
    pkg.mkdir(parents=True, exist_ok=True)
    tex = None
    if texture is not None and Path(texture).exists():
        tex = pkg / Path(texture).name
        shutil.copyfile(texture, tex)
    has_map = xodr_text is not None
    present = [c for c in classes if c["faces"] > 0]
    map_files, map_names, props = _map_and_props(present, class_dir, map_name, has_map, scanned)
    jobs = [(pkg / f"{map_name}.fbx", map_files, map_names)] if has_map else []
    jobs += [(pkg / f"{p['name']}.fbx", [p["ply"]], {p["ply"]: p["mesh"]}) for p in props]
    write_fbx_set(jobs, tex, georef=georef, python=python, log_path=log_path)
    if has_map:
        (pkg / f"{map_name}.xodr").write_text(xodr_text)
    desc = {"maps": [{"name": map_name, "source": f"./{map_name}.fbx",
                      "use_carla_materials": bool(use_carla_materials), "xodr": f"./{map_name}.xodr"}]
            if has_map else [],
            "props": [{"name": p["name"], "source": f"./{p['name']}.fbx", "tag": p["tag"], "size": p["size"]}
                      for p in props]}
    (pkg / f"{package}.json").write_text(json.dumps(desc, indent=2) + "\n")
    # no map: an empty decals list (without the file, Import.py would write one with random decals)
    (folder / "Import" / DECALS_FILE).write_text(json.dumps(
        {"decals": [decals_entry(map_name, decals)] if has_map else []}, indent=2) + "\n")
    _write_spawn_files(folder, package, map_name, has_map, props, spawn, no_map_note(no_map_source))
    if has_map:
        write_place_script(folder, package, map_name, props)
    rows = _class_table(present, props, map_names, class_dir, map_name)
    geo = ", ".join(f"{k} {v}" for k, v in georef.items() if k in ("crs", "lat", "lon", "alt"))
    (pkg / "README.md").write_text((README if has_map else README_NO_MAP).format(
        package=package, map=map_name, texture=tex.name if tex else "(no texture)", n_spawn=len(spawn),
        map_classes=", ".join(f"`{n}`" for n in map_names.values()),
        decals="none, `decals=true` for CARLA's default random decals" if not decals else "CARLA's default counts",
        movables=MOVABLES_README.format(n=len([p for p in props if p.get("scanned")]))
        if any(p.get("scanned") for p in props) else "",
        place_command=PLACE_COMMAND.format(script=PLACE_SCRIPT),
        why={"scan": "`road_source=scan` kept no road from the scan (see `scan_roads.png`)"}.get(
            no_map_source, "`road_source=none`, no OpenStreetMap or OpenDRIVE input"),
        table="\n".join(rows), frames=(frames or _site_frames)(f"({geo})" if geo else ""), carla_version=carla_version))
    return pkg, {"map_meshes": list(map_names.values()), "props": [p["name"] for p in props],
                 "prop_tags": {p["name"]: p["label"] for p in props}}
