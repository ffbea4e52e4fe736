"""What ``make import`` (and the package's editor script) places in the map level, emulated offline.

CARLA 0.9.16's import, read from its source (carla-simulator/carla; ``Commandlet/`` and ``Game/``
are under ``Unreal/CarlaUE4/Plugins/Carla/Source/Carla/``):

1. ``Util/BuildTools/Import.py`` ``generate_import_setting_file``: a map FBX is imported into
   ``/Game/<Pkg>/Maps/<Map>``, one static mesh per node (``bCombineMeshes 0``); a prop FBX into
   ``/Game/<Pkg>/Static/<tag>/<name>``, and ``generate_package_file`` registers it as
   ``/Game/<Pkg>/Static/<tag>/<name>/<stem>.<stem>`` and the map as ``path /Game/<Pkg>/Maps/<Map>``.
2. ``Commandlet/MoveAssetsCommandlet.cpp`` ``MoveAssetsFromMapForSemanticSegmentation``: each map
   mesh moves to ``/Game/<Pkg>/Static/<Folder>/<Map>``; the folders are Road, RoadLine, Terrain,
   SideWalk (by name, anything else Terrain): there is no destination for any other class.
3. ``Import.py`` ``import_assets_from_json_list`` runs ``PrepareAssetsForCooking`` with
   ``-OnlyPrepareMaps=1``; ``Commandlet/PrepareAssetsForCookingCommandlet.cpp``
   ``PrepareMapsForCooking`` loads ``/Game/Carla/Maps/BaseMap``, ``SpawnMeshesToWorld`` spawns a
   ``StaticMeshActor`` at the origin for every mesh under ``Maps/<Map>`` and
   ``Static/{Road,RoadLines,Terrain,SideWalk}/<Map>`` that passes ``ValidateStaticMesh`` (no
   "light"/"sign" in the asset or material name), sets its mesh's ``CollisionTraceFlag`` to
   ``CTF_UseComplexAsSimple``, and ``SaveWorld`` saves the level as ``<Map.Path>/<Map>``. Props are
   spawned only into ``Maps/PropsMap`` by ``PreparePropsForCooking``, which runs in ``make package``
   (``OnlyPrepareMaps=0``), not in the import. ``LoadAssetMaterialsCommandlet.cpp`` adds decals only.
4. ``Game/CarlaGameModeBase.cpp`` ``BeginPlay`` calls ``ATagger::TagActorsInLevel``: every
   static-mesh component of every actor in the level is tagged ``GetLabelByPath(mesh)`` =
   ``GetLabelByFolderName`` of the 5th ``/``-separated field (empty fields kept) of the mesh's
   path (``Game/Tagger.h``, ``Game/Tagger.cpp``).

So the import alone places only meshes tagged Roads, RoadLines, Terrain, Sidewalks (or None): a
building can be in the level with its own tag only if something else places its prop.
:func:`emulate_placement` models the project after steps 1-3 as an
:class:`unreal_stub.EditorState`, runs the package's ``place_in_map.py`` (if any) against the
``unreal`` stand-in, and reads the saved level: what ``reload_world`` brings back.
"""
from __future__ import annotations

import json
import runpy
import sys
from dataclasses import dataclass, field
from pathlib import Path

SRC_PLACE = ("Util/BuildTools/Import.py (generate_package_file, import_assets_from_json_list); "
             "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Commandlet/PrepareAssetsForCookingCommandlet.cpp "
             "(PrepareMapsForCooking, SpawnMeshesToWorld, SaveWorld); Game/Tagger.h (GetLabelByPath); "
             "Game/CarlaGameModeBase.cpp (BeginPlay -> ATagger::TagActorsInLevel)")
COMPLEX = "CTF_USE_COMPLEX_AS_SIMPLE"


def prop_object_path(package: str, prop: dict) -> str:
    """The object path ``Import.py``'s ``generate_package_file`` registers for a prop entry."""
    stem = Path(str(prop["source"])).name.split(".")[0]
    return f"/Game/{package}/Static/{prop['tag']}/{prop['name']}/{stem}.{stem}"


def map_object_path(package: str, map_name: str, folder: str, asset: str) -> str:
    """Where ``MoveAssets`` moves a map mesh (``/Game/<Pkg>/Static/<Folder>/<Map>/<asset>``)."""
    return f"/Game/{package}/Static/{folder}/{map_name}/{asset}.{asset}"


def level_path(package: str, map_name: str) -> str:
    """The level ``PrepareAssetsForCooking``'s ``SaveWorld`` writes: ``<Map.Path>/<Map>``."""
    return f"/Game/{package}/Maps/{map_name}/{map_name}"


def tagger_label_of_path(path: str) -> str:
    """``ATagger::GetLabelByPath``: the 5th ``/``-separated field (empty ones kept) through
    ``GetLabelByFolderName``; ``NONE`` when the path is shorter or the folder unknown."""
    from .carla_contract import tagger_label

    parts = path.split("/")
    return tagger_label(parts[4]) if len(parts) > 4 else "NONE"


@dataclass
class Placed:
    """One static mesh of the package and what the import flow left of it in the saved level."""

    asset: str
    kind: str  # "map" | "prop"
    class_id: int | None
    intended_tag: str | None
    faces: int
    actors: int = 0  # static-mesh actors showing it in the saved level
    tag: str = "NONE"  # the Tagger's label of its mesh path
    complex_collision: bool = False

    @property
    def ok(self) -> bool:
        return self.actors >= 1 and self.tag == (self.intended_tag or "NONE") and self.complex_collision


@dataclass
class Placement:
    """The emulated level after ``make import`` (+ the package's editor script, when ``script``)."""

    level: str
    script: str | None
    meshes: list[Placed] = field(default_factory=list)
    lifted_placed: list[str] = field(default_factory=list)  # lifted movable objects placed as props
    error: str | None = None

    def share(self, *, by_import_only: bool = False) -> float:
        """Share of the static faces in the saved level with their class's tag and their own collision."""
        ms = [m for m in self.meshes if not by_import_only or m.kind == "map"]
        total = sum(m.faces for m in self.meshes)
        return sum(m.faces for m in ms if m.ok) / total if total else 1.0

    def by_class(self) -> dict[str, dict]:
        """Per intended tag: static faces, faces placed right, and the tags they got."""
        out: dict[str, dict] = {}
        for m in self.meshes:
            e = out.setdefault(m.intended_tag or "NONE", {"faces": 0, "placed": 0, "tags": []})
            e["faces"] += m.faces
            e["placed"] += m.faces if m.ok else 0
            if m.actors and m.tag not in e["tags"]:
                e["tags"].append(m.tag)
        return out

    def summary(self) -> dict:
        return {"level": self.level, "script": self.script, "placed_share": round(self.share(), 4),
                "placed_share_import_only": round(self.share(by_import_only=True), 4),
                "by_class": self.by_class(), "lifted_placed": self.lifted_placed, "error": self.error,
                "not_placed": [m.asset for m in self.meshes if not m.ok]}


def _lifted(root: Path) -> set[str]:
    """Names of the lifted movable objects' props (``actors.json``: CARLA actors stand in for them)."""
    path = root / "actors.json"
    try:
        data = json.loads(path.read_text()) if path.is_file() else {}
    except ValueError:
        return set()
    return {str(a["scanned_prop_name"]) for a in data.get("actors", []) if isinstance(a, dict)
            and a.get("scanned_prop_name")}


def after_import(rep, package: str, map_name: str, props: list[dict]):
    """The project after ``make import`` (steps 1-3 of the module doc) as an EditorState, and the
    static meshes (Placed, by object path) it must end up showing."""
    from .carla_contract import SPAWNED_FOLDERS
    from .unreal_stub import EditorState, SavedActor

    state, want = EditorState(), {}
    level: list = []
    by_source = {Path(str(p.get("source"))).name: p for p in props if isinstance(p, dict)}
    for m in rep.meshes:
        if m.kind == "map":
            obj = map_object_path(package, map_name, m.folder, m.asset)
            # SpawnMeshesToWorld: CTF_UseComplexAsSimple on every mesh it spawns, saved with SaveDirtyPackages
            spawned = m.folder in SPAWNED_FOLDERS and not m.dropped
            state.meshes[obj] = COMPLEX if spawned else "CTF_USE_DEFAULT"
            if spawned:
                level.append(SavedActor(m.node, obj, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), "STATIC"))
        else:
            p = by_source.get(m.fbx) or {"name": Path(m.fbx).stem, "tag": m.folder, "source": m.fbx}
            obj = prop_object_path(package, p)
            state.meshes[obj] = "CTF_USE_DEFAULT"
        want[obj] = Placed(m.asset, m.kind, m.class_id, m.intended_tag, m.faces)
    state.levels[level_path(package, map_name)] = level
    return state, want


def run_editor_script(script: Path, state) -> str | None:
    """Run ``script`` with the ``unreal`` stand-in acting on ``state``; the error it raised, or None."""
    from .unreal_stub import make_module

    saved = sys.modules.get("unreal")
    sys.modules["unreal"] = make_module(state)
    try:
        runpy.run_path(str(script), run_name="__main__")
    except BaseException as exc:  # noqa: BLE001 - the script's failure is the finding
        return f"{script.name}: {type(exc).__name__}: {exc}"
    finally:
        if saved is None:
            sys.modules.pop("unreal", None)
        else:
            sys.modules["unreal"] = saved
    return None


def emulate_placement(rep, root: Path, package: str, map_name: str, props: list[dict],
                      script: Path | None) -> Placement:
    """The saved level after ``make import`` and, when ``script`` exists, the package's editor script."""
    state, want = after_import(rep, package, map_name, props)
    lifted = _lifted(root)
    res = Placement(level_path(package, map_name), script.name if script and script.is_file() else None)
    if script is not None and script.is_file():
        res.error = run_editor_script(script, state)
    for actor in state.levels.get(res.level, []):
        p = want.get(actor.mesh)
        if p is None:
            continue
        p.actors += 1
        p.tag = tagger_label_of_path(actor.mesh)
        p.complex_collision = state.meshes.get(actor.mesh) == COMPLEX
    for obj, p in want.items():
        if p.kind == "prop" and obj.split("/")[5] in lifted:
            if p.actors:
                res.lifted_placed.append(p.asset)
            continue
        res.meshes.append(p)
    return res


def check_import_placement(rep, root: Path, package: str, desc: dict, script: Path | None = None) -> Placement | None:
    """Rule ``import_placement``: every static mesh (map geometry and the props of static classes) ends
    in the saved map level, once, tagged as its class, with its own triangles as collision. None
    when the package has no map (nothing to place into)."""
    maps = [m for m in desc.get("maps", []) if isinstance(m, dict) and "name" in m]
    if not maps:
        return None
    root = Path(root)
    script = script if script is not None else root / "place_in_map.py"
    res = emulate_placement(rep, root, package, str(maps[0]["name"]), list(desc.get("props", [])), script)
    if res.error:
        rep.add("import_placement", f"the editor script failed against CARLA's editor API: {res.error}")
    bad = {k: v for k, v in res.by_class().items() if v["placed"] < v["faces"]}
    if bad:
        what = ", ".join(f"{k} ({100 * (1 - v['placed'] / v['faces']):.0f} % of {v['faces']} faces"
                         f"{'; tagged ' + '/'.join(v['tags']) if v['tags'] else ''})" for k, v in bad.items())
        rep.add("import_placement", f"{100 * res.share():.1f} % of the static faces end in the map level {res.level} "
                                    f"with their class's tag and own collision; not: {what}"
                                    + ("" if res.script else f"; nothing places the props (ship {script.name})"))
    dup = [m.asset for m in res.meshes if m.actors > 1]
    if dup:
        rep.add("import_placement", f"placed more than once in {res.level}: {', '.join(dup)}")
    if res.lifted_placed:
        rep.add("import_placement", f"lifted movable objects placed as static props (CARLA actors stand in for "
                                    f"them): {', '.join(res.lifted_placed)}")
    return res


def placement_summary(root: Path, package: str, rep=None) -> dict | None:
    """The import-placement emulation's summary for a written package (metrics, bench); ``rep``: the
    package's contract report when at hand (else it is made). None for a package without a map."""
    from .carla_contract import check_package

    root = Path(root)
    imp = root if root.name == "Import" else root / "Import"
    desc = json.loads((imp / package / f"{package}.json").read_text())
    maps = [m for m in desc.get("maps", []) if isinstance(m, dict) and "name" in m]
    if not maps:
        return None
    rep = rep if rep is not None else check_package(root, package)
    return emulate_placement(rep, imp.parent, package, str(maps[0]["name"]), list(desc.get("props", [])),
                             imp.parent / "place_in_map.py").summary()
