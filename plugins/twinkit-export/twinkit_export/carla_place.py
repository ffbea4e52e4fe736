"""The package's editor script ``place_in_map.py``: every static class in the imported map level.

CARLA 0.9.16's ``make import`` places in the map only the meshes of ``Maps/<Map>`` and
``Static/{Road,RoadLine(s),Terrain,SideWalk}/<Map>`` (``PrepareAssetsForCookingCommandlet.cpp``,
``PrepareMapsForCooking``), and ``MoveAssets`` routes map meshes to those four folders only, so a
mesh the import places can carry no tag but Roads, RoadLines, Terrain, Sidewalks or None
(``Tagger.h`` ``GetLabelByPath``: the folder at path segment 4). Props keep their class's tag
(``Import.py`` imports them into ``Static/<tag>/<name>``) but nothing in the import places them in
a level: ``contract_import`` holds the reasoning with its sources. ``place_in_map.py`` closes the
gap, run once after ``make import`` with CARLA's editor::

    "$UE4_ROOT/Engine/Binaries/Linux/UE4Editor-Cmd" "$CARLA_ROOT/Unreal/CarlaUE4/CarlaUE4.uproject" \
        -run=pythonscript -script="$CARLA_ROOT/place_in_map.py"

It opens the level ``/Game/<Pkg>/Maps/<Map>/<Map>`` that ``PrepareAssetsForCooking`` saved, sets
each static prop's mesh to use its own triangles as collision (``CTF_UseComplexAsSimple``, what
``PrepareAssetsForCooking`` sets on the map meshes), spawns one static-mesh actor per prop at the
origin (the meshes are in the map's frame) unless one is there already, and saves the level: the
actors are part of the map, tagged by CARLA's Tagger from their mesh's folder at every
``BeginPlay``, and ``reload_world`` loads them again. The lifted movable objects stay out (CARLA
actors replace them: ``spawn_actors.py``).
"""
from __future__ import annotations

import json
from pathlib import Path

PLACE_SCRIPT = "place_in_map.py"

#: the command README and docs give (run from the CARLA root after `make import`)
PLACE_COMMAND = ('"$UE4_ROOT/Engine/Binaries/Linux/UE4Editor-Cmd" "$PWD/Unreal/CarlaUE4/CarlaUE4.uproject" '
                 '-run=pythonscript -script="$PWD/{script}"')

SCRIPT = '''#!/usr/bin/env python3
"""Place the static props of package {package!r} in its map {map!r}: run by CARLA's Unreal editor.

Made by twinkit. `make import` places only the road, sidewalk and terrain meshes in the map; the
other classes are props in Static/<Tag>/ (their semantic tag) that it never places. This editor
script puts each in the level at the origin (the meshes are in the map's frame), with its own
triangles as collision, and saves the level, so they stay in the map through reload_world.
Run it once after `make import`, from the CARLA root (copy it there first):

    "$UE4_ROOT/Engine/Binaries/Linux/UE4Editor-Cmd" "$PWD/Unreal/CarlaUE4/CarlaUE4.uproject" \\
        -run=pythonscript -script="$PWD/place_in_map.py"

or in the editor (`make launch`): File > Execute Python Script. Running it again adds nothing.
"""
import unreal

LEVEL = {level!r}
PLACE = {place}


def complex_collision(mesh):
    """The mesh's own triangles as its collision (CTF_UseComplexAsSimple), saved with the asset."""
    body = mesh.get_editor_property("body_setup")
    if body is not None:
        body.set_editor_property("collision_trace_flag", unreal.CollisionTraceFlag.CTF_USE_COMPLEX_AS_SIMPLE)
        unreal.EditorAssetLibrary.save_loaded_asset(mesh, False)


def placed_meshes():
    """Object paths of the meshes the open level shows already."""
    out = set()
    for actor in unreal.EditorLevelLibrary.get_all_level_actors():
        if isinstance(actor, unreal.StaticMeshActor):
            mesh = actor.static_mesh_component.get_editor_property("static_mesh")
            if mesh is not None:
                out.add(mesh.get_path_name())
    return out


def main():
    if not unreal.EditorLevelLibrary.load_level(LEVEL):
        raise RuntimeError("level " + LEVEL + " not found: run make import for package {package} first")
    have = placed_meshes()
    added = 0
    for p in PLACE:
        mesh = unreal.EditorAssetLibrary.load_asset(p["mesh"])
        if mesh is None:
            raise RuntimeError("mesh " + p["mesh"] + " not found: run make import for package {package} first")
        complex_collision(mesh)
        if mesh.get_path_name() in have:
            continue
        actor = unreal.EditorLevelLibrary.spawn_actor_from_object(mesh, unreal.Vector(0.0, 0.0, 0.0),
                                                                  unreal.Rotator(0.0, 0.0, 0.0))
        actor.set_actor_label(p["name"])
        actor.static_mesh_component.set_mobility(unreal.ComponentMobility.STATIC)
        added += 1
    if not unreal.EditorLevelLibrary.save_current_level():
        raise RuntimeError("could not save " + LEVEL)
    unreal.log("place_in_map: %d of %d props placed in %s (%d there already)" % (added, len(PLACE), LEVEL,
                                                                                  len(PLACE) - added))


main()
'''


def place_entries(package: str, props: list[dict]) -> list[dict]:
    """What ``place_in_map.py`` places: every prop of ``props`` (``write_package``'s entries) that is a
    static class, i.e. not a lifted movable object. ``mesh`` is the object path ``Import.py``
    registers for the prop (``contract_import.prop_object_path``); ``tag`` the Tagger's label of it."""
    from .contract_import import prop_object_path, tagger_label_of_path

    out = []
    for p in props:
        if p.get("scanned"):
            continue
        mesh = prop_object_path(package, {"name": p["name"], "tag": p["tag"], "source": f"./{p['name']}.fbx"})
        out.append({"name": p["name"], "class": p["class"], "mesh": mesh, "tag": tagger_label_of_path(mesh),
                    "faces": int(p["faces"])})
    return out


def write_place_script(folder: Path, package: str, map_name: str, props: list[dict]) -> Path:
    """Write ``folder/place_in_map.py`` for the package's static props; returns its path."""
    from .contract_import import level_path

    entries = place_entries(package, props)
    body = "[\n" + "".join(f"    {json.dumps(e)},\n" for e in entries) + "]"
    path = Path(folder) / PLACE_SCRIPT
    path.write_text(SCRIPT.format(package=package, map=map_name, level=level_path(package, map_name), place=body))
    path.chmod(0o755)
    return path
