"""CARLA 0.9.16's import rules, read from its source, as checks on a package folder.

``make import`` cannot run here (no Unreal), so what it would do with a package is computed from
the rules below; each rule names the file of carla-simulator/carla it comes from (paths in that
repository; ``Commandlet/`` and ``Game/`` are under ``Unreal/CarlaUE4/Plugins/Carla/Source/Carla/``).
:func:`check_package` applies them to ``<root>/Import/<Package>/`` and returns a report; the
``carla_package`` exporter fails when the report has a violation.

What ``make import`` does, in order (``Util/BuildTools/Import.py``):

1. every ``*.json`` under ``Import/`` except ``roadpainter_decals.json`` is a package description;
   when no ``roadpainter_decals.json`` exists under ``Import/``, one with default random decals
   is generated for every ``.xodr``/``.fbx`` pair;
2. ``ImportAssets``: each map FBX goes to ``/Game/<Pkg>/Maps/<Map>`` (one static mesh per FBX
   node, named ``<FbxStem>_<Node>``); each prop FBX to ``/Game/<Pkg>/Static/<tag>/<name>`` (a
   single-mesh FBX becomes one asset named after the file, the path Import.py registers in
   ``<Pkg>.Package.json``: ``/Game/<Pkg>/Static/<tag>/<name>/<stem>.<stem>``);
3. ``MoveAssets`` moves the map's meshes by name into ``Static/{Road,RoadLine,Terrain,SideWalk}/<Map>``;
4. the pedestrian navmesh is built from the map FBX by node name (``FBX2OBJ``);
5. ``PrepareAssetsForCooking`` spawns the meshes of ``Maps/<Map>`` and those four folders into the
   map, skipping any mesh whose asset or material name contains "light" or "sign";
6. ``LoadAssetMaterials`` paints RoadPainter decals from ``roadpainter_decals.json``.

The semantic tag of a mesh is the folder at path segment 4 (``/Game/<Pkg>/Static/<Folder>/...``),
``Tagger.cpp``'s ``GetLabelByFolderName``. Props are never spawned into the map by the import.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from . import contract_walkers as _walkers
from .contract_actors import ACTORS_GEOMETRY_RULE, check_actor_geometry
from .contract_decals import (  # noqa: F401 (re-exported: carla_pkg and the tests read them here)
    DECAL_DEFAULT_COUNTS, DECAL_FIELDS, DECAL_NAMES, DECALS_FILE, check_decals, decals_entry)
from .contract_ground import RULE as GROUND_RULE
from .contract_ground import check_lanes_over_ground
from .contract_import import check_import_placement
from .contract_sidewalks import RULES as SIDEWALK_RULES, check_sidewalks
from .contract_signals import RULES as SIGNAL_RULES
from .contract_signals import check_signals

CARLA = "carla-simulator/carla"
SRC_IMPORT = "Util/BuildTools/Import.py"
SRC_MOVE = "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Commandlet/MoveAssetsCommandlet.cpp (SSTags.h)"
SRC_PREPARE = "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Commandlet/PrepareAssetsForCookingCommandlet.cpp"
SRC_TAGGER = "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Game/Tagger.cpp"
SRC_REGISTRY = "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Actor/CarlaBlueprintRegistry.cpp (PropParameters.h)"
SRC_NAV = "Util/DockerUtils/fbx/src/FBX2OBJ.cpp"
SRC_DECALS = ("Util/BuildTools/Import.py (generate_decals_file) + Unreal/CarlaUE4/Plugins/Carla/Source/Carla/"
              "Util/RoadPainterWrapper.cpp (ReadConfigFile)")
SRC_MATERIALS = "Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Commandlet/LoadAssetMaterialsCommandlet.cpp"
SRC_TWINKIT = "twinkit (not a CARLA rule)"

# -- MoveAssetsCommandlet.cpp: substrings tested in this order (FString::Contains, case-insensitive by default)
MOVE_ROUTES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("Road_Road", "Roads_Road"), "Road"),
    (("Road_Marking", "Roads_Marking"), "RoadLine"),
    (("Terrain",), "Terrain"),
    (("Road_Sidewalk", "Roads_Sidewalk"), "SideWalk"),
    (("Road_Curb", "Roads_Curb"), "SideWalk"),
    (("Road_Gutter", "Roads_Gutter"), "SideWalk"),
)
MOVE_DEFAULT = "Terrain"
MOVE_KEYS = tuple(k for keys, _ in MOVE_ROUTES for k in keys)

# -- PrepareAssetsForCookingCommandlet.cpp: folders whose meshes are spawned into the map
SPAWNED_FOLDERS = ("Road", "RoadLine", "Terrain", "SideWalk")
# ValidateStaticMesh: asset and material names containing these (case-insensitive) are never spawned
DROP_WORDS = ("light", "sign")
# IsMapInTiles / LoadAssetMaterials: an asset or map name containing this is handled as a tile of a large map
TILE_MARK = "_Tile_"

# -- Tagger.cpp GetLabelByFolderName: folder name -> carla.CityObjectLabel name (anything else: NONE)
TAGGER_FOLDERS = {
    "Building": "Buildings", "Fence": "Fences", "Pedestrian": "Pedestrians", "Pole": "Poles", "Other": "Other",
    "Road": "Roads", "RoadLine": "RoadLines", "SideWalk": "Sidewalks", "TrafficSign": "TrafficSigns",
    "Vegetation": "Vegetation", "Car": "Car", "Wall": "Walls", "Sky": "Sky", "Ground": "Ground", "Bridge": "Bridge",
    "RailTrack": "RailTrack", "GuardRail": "GuardRail", "TrafficLight": "TrafficLight", "Static": "Static",
    "Dynamic": "Dynamic", "Water": "Water", "Terrain": "Terrain", "Truck": "Truck", "Motorcycle": "Motorcycle",
    "Bicycle": "Bicycle", "Bus": "Bus", "Rider": "Rider", "Train": "Train",
}

# -- CarlaBlueprintRegistry.cpp / PropParameters.h: EPropSize names
PROP_SIZES = ("Tiny", "Small", "Medium", "Big", "Huge")

# -- FBX2OBJ.cpp SetMaterials: exact node names (its StartsWith compares whole names) -> navmesh area
NAV_AREAS = {"Road_Road": "road", "Road_Marking": "road", "Road_Curb": "road", "Road_Gutter": "road",
             "Road_Sidewalk": "sidewalk", "Road_Crosswalk": "crosswalk", "Road_Grass": "grass"}

#: every rule: id -> (what CARLA does, source file)
RULES: dict[str, tuple[str, str]] = {
    "layout": ("every *.json under Import/ except roadpainter_decals.json is a package description named after "
               "the file; source/xodr are joined to the JSON's folder", SRC_IMPORT),
    "json": ("maps: name, source, xodr, use_carla_materials (read with GetBoolField: a JSON boolean); props: "
             "name, source, tag, size (Import.py reads prop['size'])", f"{SRC_IMPORT}; {SRC_PREPARE}"),
    "prop_size": ("a prop's size must be an EPropSize name: " + ", ".join(PROP_SIZES), SRC_REGISTRY),
    "prop_single_mesh": ("a prop FBX holds one mesh, imported as the asset <stem> that Import.py registers as "
                         "/Game/<Pkg>/Static/<tag>/<name>/<stem>.<stem>", SRC_IMPORT),
    "names_dropped": ("meshes whose asset or material name contains 'light' or 'sign' (any case) are never "
                      "spawned (ValidateStaticMesh)", SRC_PREPARE),
    "names_tile": (f"an asset name containing '{TILE_MARK}' makes the map a tiled large map", SRC_PREPARE),
    "routing": ("map meshes are moved by (case-insensitive) substring of their asset name: Road_Road->Road, "
                "Road_Marking->RoadLine, Terrain->Terrain, Road_Sidewalk/Curb/Gutter->SideWalk, else Terrain",
                SRC_MOVE),
    "tag": ("the semantic tag is the folder at path segment 4 (/Game/<Pkg>/Static/<Folder>/...); unknown "
            "folders give NONE", SRC_TAGGER),
    "navmesh": ("pedestrian navmesh areas by exact map-FBX node name: Road_Sidewalk walkable, Road_Crosswalk, "
                "Road_Grass, Road_Road/Marking/Curb/Gutter road, anything else block", SRC_NAV),
    "decals": ("without Import/roadpainter_decals.json, make import generates default random decals (dirt, "
               "cracks, tyre marks, road lines) for every map; RoadPainter reads the entry whose map_name is the map",
               SRC_DECALS),
    "names_match": ("the .xodr is copied as <name>.xodr; the docs ask for <name>.fbx and <name>.xodr",
                    SRC_IMPORT),
    "texture_paths": ("the FBX references its texture by a path inside the package, never an absolute path "
                      "(Unreal falls back to <fbx folder>/RelativeFilename)", SRC_TWINKIT),
    "placement": ("props are imported but never placed in the map; the package must carry what places them",
                  f"{SRC_PREPARE}; {SRC_TWINKIT}"),
    "actors": ("the lifted movable objects: actors.json beside Import/ (every .json under Import/ is read as a "
               "package) with a vehicle.*/walker.* blueprint and a carla.Transform each, and spawn_actors.py that "
               "spawns them (nothing in the import spawns actors)", f"{SRC_IMPORT}; {SRC_TWINKIT}"),
    "crosswalks": _walkers.RULE[1],
    "semantics": ("every mesh ends in the CARLA tag of its class; 0 % of static faces tagged Terrain unless their "
                  "class is terrain", f"{SRC_MOVE}; {SRC_TAGGER}; {SRC_TWINKIT}"),
    "sidewalk_blocks": SIDEWALK_RULES["sidewalk_blocks"],  # contract_sidewalks.py
    "parked_on_sidewalk": SIDEWALK_RULES["parked_on_sidewalk"],
    "actors_geometry": ACTORS_GEOMETRY_RULE,
    "lanes_over_ground": GROUND_RULE,
    "import_placement": ("after make import (and the package's editor script place_in_map.py) every static mesh is in "
                         "the saved map level once, tagged by the folder of its mesh path, with complex-as-simple "
                         "collision; the import alone places only Maps/<Map> and Static/{Road,RoadLine,Terrain,"
                         "SideWalk}/<Map> (contract_import)", "Util/BuildTools/Import.py; " + SRC_PREPARE + "; "
                         + SRC_TAGGER),
    **SIGNAL_RULES,
}


#: rules about how the imported twin behaves (signals, walkers, lanes, actors), not about whether CARLA imports it:
#: their violations depend on what the capture shows, so the exporter writes the package and marks the run
#: DEGRADED (twinkit.quality) instead of failing; every other rule fails the export
BEHAVIOUR_RULES = frozenset({"light_groups", "conflicting_greens", "signal_heights", "sign_types", "sidewalk_blocks",
                             "parked_on_sidewalk", "actors_geometry", "lanes_over_ground"})


@dataclass
class Violation:
    rule: str
    message: str

    @property
    def source(self) -> str:
        return RULES[self.rule][1]

    def __str__(self) -> str:
        return f"[{self.rule}] {self.message} (CARLA rule from {self.source})"


@dataclass
class MeshFate:
    """What CARLA's import does with one mesh of the package."""

    kind: str  # "map" | "prop"
    fbx: str
    node: str
    asset: str  # Unreal asset name
    folder: str  # Static/<folder> it ends in
    tag: str  # carla.CityObjectLabel name given by the Tagger
    placed: bool  # spawned into the map by the import (maps only; props need the spawn script)
    dropped: bool  # ValidateStaticMesh refuses it
    faces: int
    class_id: int | None
    intended_tag: str | None
    nav_area: str | None = None


@dataclass
class ContractReport:
    package: str
    violations: list[Violation] = field(default_factory=list)
    meshes: list[MeshFate] = field(default_factory=list)
    decals: bool | None = None  # True when the package's decals configuration paints decals on its map
    crosswalks: dict = field(default_factory=dict)  # map name -> crosswalks the navmesh gets (contract_walkers)

    @property
    def ok(self) -> bool:
        return not self.violations

    @property
    def errors(self) -> list[Violation]:
        """The violations that break the import itself (every rule outside :data:`BEHAVIOUR_RULES`)."""
        return [v for v in self.violations if v.rule not in BEHAVIOUR_RULES]

    @property
    def behaviour(self) -> list[Violation]:
        """The violations of :data:`BEHAVIOUR_RULES`: CARLA imports the package, the twin misbehaves in it."""
        return [v for v in self.violations if v.rule in BEHAVIOUR_RULES]

    def add(self, rule: str, message: str) -> None:
        self.violations.append(Violation(rule, message))

    def faces_by_tag(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for m in self.meshes:
            if not m.dropped:
                out[m.tag] = out.get(m.tag, 0) + m.faces
        return out

    def wrong_terrain_share(self) -> float:
        """Share of static faces tagged Terrain whose class is not terrain (0.0 .. 1.0)."""
        total = sum(m.faces for m in self.meshes)
        wrong = sum(m.faces for m in self.meshes if m.tag == "Terrain" and m.intended_tag not in (None, "Terrain"))
        return wrong / total if total else 0.0

    def summary(self) -> dict:
        total = sum(m.faces for m in self.meshes)
        return {
            "package": self.package, "ok": self.ok, "violations": [str(v) for v in self.violations],
            "faces": total,
            "faces_by_tag": self.faces_by_tag(),
            "share_faces_by_tag": {k: round(v / total, 4) for k, v in self.faces_by_tag().items()} if total else {},
            "wrong_terrain_share": round(self.wrong_terrain_share(), 6),
            "dropped_assets": [m.asset for m in self.meshes if m.dropped],
            "walkable_faces": sum(m.faces for m in self.meshes if m.nav_area == "sidewalk"),
            "decals": self.decals,
            "crosswalks": self.crosswalks,
            "meshes": [{"asset": m.asset, "kind": m.kind, "folder": m.folder, "tag": m.tag, "faces": m.faces,
                        "placed": m.placed, "dropped": m.dropped, "intended_tag": m.intended_tag}
                       for m in self.meshes],
        }


# ----------------------------------------------------------------------------- single rules

def move_assets_folder(asset_name: str) -> str:
    """Static/<folder> the MoveAssets commandlet moves a map mesh with this asset name to."""
    low = asset_name.lower()
    for keys, folder in MOVE_ROUTES:
        if any(k.lower() in low for k in keys):
            return folder
    return MOVE_DEFAULT


def tagger_label(folder: str) -> str:
    """carla.CityObjectLabel name the Tagger gives a mesh stored in Static/<folder>/ (exact, case-sensitive)."""
    return TAGGER_FOLDERS.get(folder, "NONE")


def dropped_words(name: str) -> list[str]:
    """The words of ValidateStaticMesh's filter that ``name`` contains (case-insensitive)."""
    low = name.lower()
    return [w for w in DROP_WORDS if w in low]


def map_asset_name(fbx_stem: str, node: str) -> str:
    """Asset name Unreal gives a node of a multi-mesh FBX imported without combining meshes."""
    return f"{fbx_stem}_{node}"


def suggest_name(name: str) -> str:
    """A name close to ``name`` that passes the name rules (light/sign filter, routing keys, tiles)."""
    out = name
    for bad, good in (("light", "lite"), ("sign", "syn"), ("terrain", "terra"), ("_tile_", "tile")):
        out = re.sub(bad, lambda m, g=good: g.capitalize() if m.group(0)[0].isupper() else g, out, flags=re.I)
    for key in MOVE_KEYS:
        out = re.sub(re.escape(key), key.replace("_", ""), out, flags=re.I)
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", out) or name_problems(out):
        return "Site"
    return out


def name_problems(name: str, *, what: str = "name") -> list[str]:
    """Why CARLA's import would mishandle assets whose names contain ``name`` (empty list: fine)."""
    probs = []
    words = dropped_words(name)
    if words:
        probs.append(f"{what} {name!r} contains {' and '.join(repr(w) for w in words)}: PrepareAssetsForCooking "
                     f"skips every mesh whose name contains 'light' or 'sign' (any case), so every mesh of the "
                     f"map would be dropped")
    keys = [k for k in MOVE_KEYS if k.lower() in name.lower()]
    if keys:
        probs.append(f"{what} {name!r} contains {keys[0]!r}, which MoveAssets uses to route meshes (any case), so "
                     f"every mesh would be moved to one folder and tagged alike")
    if TILE_MARK.lower() in name.lower():
        probs.append(f"{what} {name!r} contains {TILE_MARK!r}: CARLA would treat the map as tiles of a large map")
    return probs


# ----------------------------------------------------------------------------- the package check

def _json(path: Path, rep: ContractReport, rule: str):
    try:
        return json.loads(path.read_text())
    except Exception as exc:
        rep.add(rule, f"{path}: not readable JSON ({exc})")
        return None


def _entry_ok(rep, desc_path: Path, where: str, entry, keys: tuple[str, ...]) -> bool:
    """Whether one ``maps[i]`` / ``props[i]`` entry of the package JSON is an object with every key Import.py
    reads; adds the violation when not."""
    if not isinstance(entry, dict):
        rep.add("json", f"{desc_path.name}: {where} is not an object")
        return False
    missing = [k for k in keys if k not in entry]
    if missing:
        rep.add("json", f"{desc_path.name}: {where} lacks {', '.join(missing)}")
        return False
    return True


def _intended(cid, class_tags: dict[int, str] | None) -> str | None:
    """The carla.CityObjectLabel name a trainId should end in (``class_tags`` first, then the class table)."""
    from .classes import info

    if cid is None:
        return None
    if class_tags and int(cid) in class_tags:
        return class_tags[int(cid)]
    return info(int(cid)).carla_tag


def _check_maps(rep: ContractReport, desc_path: Path, pkg: Path, maps: list, class_tags) -> list[str]:
    """The description's maps: entries, names, files, and each FBX mesh's fate; returns the map names."""
    from .classes import info

    map_names = []
    for i, m in enumerate(maps):
        if not _entry_ok(rep, desc_path, f"maps[{i}]", m, ("name", "source", "xodr", "use_carla_materials")):
            continue
        if not isinstance(m["use_carla_materials"], bool):
            rep.add("json", f"{desc_path.name}: maps[{i}].use_carla_materials must be a JSON boolean (GetBoolField)")
        name = str(m["name"])
        map_names.append(name)
        for p in name_problems(name, what="map name"):
            rep.add("names_dropped" if "light" in p or "'sign'" in p else "names_tile" if TILE_MARK in p
                    else "routing", f"{p}; rename it, e.g. {suggest_name(name)!r}")
        src, xodr = pkg / str(m["source"]), pkg / str(m["xodr"])
        if not src.is_file():
            rep.add("json", f"{desc_path.name}: maps[{i}].source {m['source']!r} does not exist in {pkg}")
            continue
        if not xodr.is_file():
            rep.add("json", f"{desc_path.name}: maps[{i}].xodr {m['xodr']!r} does not exist in {pkg}")
        if src.stem != name or xodr.stem != name:
            rep.add("names_match", f"map {name!r}: source {src.name} and xodr {xodr.name} should be {name}.fbx and "
                                   f"{name}.xodr")
        fs = _read_fbx(rep, src, pkg)
        if fs is None:
            continue
        for mesh in fs.meshes:
            asset = map_asset_name(src.stem, mesh.name)
            folder = move_assets_folder(asset)
            cid = mesh.properties.get("class_id")
            fate = MeshFate("map", src.name, mesh.name, asset, folder, tagger_label(folder), folder in SPAWNED_FOLDERS,
                            bool(dropped_words(asset) or any(dropped_words(mt) for mt in mesh.materials)),
                            mesh.faces, cid, _intended(cid, class_tags), NAV_AREAS.get(mesh.name, "block"))
            rep.meshes.append(fate)
            _check_mesh(rep, fate, mesh.materials)
            if cid is not None and info(int(cid)).carla_name == "Road_Sidewalk" and mesh.name != "Road_Sidewalk":
                rep.add("navmesh", f"{src.name}: sidewalk mesh {mesh.name!r} is not named exactly 'Road_Sidewalk': "
                                   f"the navmesh tool would not make it walkable")
    return map_names


def _check_props(rep: ContractReport, desc_path: Path, pkg: Path, props: list, class_tags) -> list[str]:
    """The description's props: entries, sizes, one mesh per FBX, each mesh's fate; returns the prop names."""
    prop_names = []
    for i, p in enumerate(props):
        if not _entry_ok(rep, desc_path, f"props[{i}]", p, ("name", "source", "tag", "size")):
            continue
        if p["size"] not in PROP_SIZES:
            rep.add("prop_size", f"{desc_path.name}: props[{i}].size {p['size']!r} is not one of {PROP_SIZES}")
        name, tag = str(p["name"]), str(p["tag"])
        prop_names.append(name)
        src = pkg / str(p["source"])
        if not src.is_file():
            rep.add("json", f"{desc_path.name}: props[{i}].source {p['source']!r} does not exist in {pkg}")
            continue
        fs = _read_fbx(rep, src, pkg)
        if fs is None:
            continue
        if len(fs.meshes) != 1:
            rep.add("prop_single_mesh", f"{src.name}: {len(fs.meshes)} meshes; a prop FBX must hold exactly one "
                                        f"(its asset is registered as {src.stem}.{src.stem})")
        for mesh in fs.meshes:
            asset = src.stem if len(fs.meshes) == 1 else map_asset_name(src.stem, mesh.name)
            cid = mesh.properties.get("class_id")
            fate = MeshFate("prop", src.name, mesh.name, asset, tag, tagger_label(tag), False,
                            bool(dropped_words(asset) or any(dropped_words(mt) for mt in mesh.materials)),
                            mesh.faces, cid, _intended(cid, class_tags))
            rep.meshes.append(fate)
            _check_mesh(rep, fate, mesh.materials)
    if len(set(prop_names)) != len(prop_names):
        rep.add("json", f"{desc_path.name}: prop names repeat; blueprint ids static.prop.<name> must be unique")
    return prop_names


def _check_placement(rep: ContractReport, prop_names: list[str], script: Path) -> None:
    """make import never places props: ``script`` must spawn every one (static.prop.<name>)."""
    text = script.read_text() if script.is_file() else ""
    missing = [n for n in prop_names if f"static.prop.{n.lower()}" not in text]
    if not text:
        rep.add("placement", f"{script.name} is missing: make import never places props in the map, so the "
                             f"package must carry the script that spawns them")
    elif missing:
        rep.add("placement", f"{script.name} does not spawn {', '.join(missing)}")


def check_package(root: Path, package: str | None = None, *, class_tags: dict[int, str] | None = None,
                  expect_decals: bool | None = None, spawn_script: Path | None = None,
                  expect_crosswalks: int | None = None) -> ContractReport:
    """Apply CARLA's import rules to ``root/Import/<package>/`` (``root`` may also be the Import folder).

    class_tags: trainId -> intended carla.CityObjectLabel name (from the FBX objects' ``class_id``);
    default: twinkit's class table. expect_decals: the decals setting the package must carry (None:
    only report it). spawn_script: the file that must place every prop (default ``root/spawn_props.py``).
    expect_crosswalks: how many crossings the scan and OSM show (place_crosswalks' crosswalks.json; None:
    only count what the navmesh gets).
    """
    root = Path(root)
    imp = root if root.name == "Import" else root / "Import"
    if not imp.is_dir():
        rep = ContractReport(package or "?")
        rep.add("layout", f"{imp}: no Import/ folder (copy the package as <carla>/Import/<Package>/)")
        return rep
    descs = sorted(p for p in imp.rglob("*.json") if p.name != DECALS_FILE)
    if package is None:
        package = descs[0].stem if descs else "?"
    rep = ContractReport(package)
    pkg = imp / package
    desc_path = pkg / f"{package}.json"
    # layout -------------------------------------------------------------------------------------
    if not desc_path.exists():
        rep.add("layout", f"{desc_path} is missing: Import.py takes the package name from <Package>.json")
        return rep
    others = [p for p in descs if p != desc_path]
    if others:
        rep.add("layout", f"{', '.join(str(p.relative_to(imp)) for p in others)}: every .json under Import/ is read "
                          f"as a package description; keep other JSON files outside Import/")
    desc = _json(desc_path, rep, "json")
    if not isinstance(desc, dict):
        return rep
    maps, props = desc.get("maps", []), desc.get("props", [])
    if not isinstance(maps, list) or not isinstance(props, list):
        rep.add("json", f"{desc_path.name}: 'maps' and 'props' must be lists")
        return rep
    if not maps and not props:
        rep.add("json", f"{desc_path.name}: no map and no prop ('maps' and 'props' are empty)")
    elif not maps and not (pkg / "README.md").is_file():
        # a props-only package is what CARLA imports without an OpenDRIVE; it must say that it has no map
        rep.add("json", f"{desc_path.name}: no map ('maps' is empty) and no README.md saying why")

    map_names = _check_maps(rep, desc_path, pkg, maps, class_tags)
    rep.crosswalks = _walkers.check_crosswalks(rep, pkg, maps, expect_crosswalks)
    check_lanes_over_ground(rep, pkg, maps)  # the lanes over the map's mesh (contract_ground.py)
    prop_names = _check_props(rep, desc_path, pkg, props, class_tags)
    # placement: nothing in the import places props ------------------------------------------------
    if prop_names:
        _check_placement(rep, prop_names, Path(spawn_script) if spawn_script else root / "spawn_props.py")
    # actors (twinkit's lifted movable objects): a transform and a spawn script ---------------------
    _check_actors(rep, root if root.name != "Import" else root.parent)
    # walkers and parked cars (contract_sidewalks.py): sidewalk per block, parked vehicles off sidewalk lanes
    check_sidewalks(rep, root if root.name != "Import" else root.parent, pkg, maps)
    check_actor_geometry(rep, root if root.name != "Import" else root.parent)
    check_import_placement(rep, root if root.name != "Import" else root.parent, package, desc)
    # decals --------------------------------------------------------------------------------------
    check_decals(rep, imp, map_names, expect_decals)
    # signals: light groups, the cycle, heights, sign types (contract_signals.py) ---------------------
    check_signals(rep, [pkg / f"{n}.xodr" for n in map_names])
    # semantics: every class ends in its tag -----------------------------------------------------------
    share = rep.wrong_terrain_share()
    if share > 0:
        rep.add("semantics", f"{100 * share:.1f} % of the static faces would be tagged Terrain although their class "
                             f"is not terrain")
    return rep


def _check_actors(rep: ContractReport, root: Path) -> None:
    """``actors.json`` beside Import/ (a .json inside it would be read as a package, Import.py): every
    actor has a blueprint id (or null) and a carla.Transform; ``spawn_actors.py`` places them."""
    path = root / "actors.json"
    if not path.exists():
        return
    data = _json(path, rep, "actors")
    if not isinstance(data, dict) or not isinstance(data.get("actors"), list):
        rep.add("actors", f"{path.name}: needs an 'actors' list")
        return
    script = root / "spawn_actors.py"
    text = script.read_text() if script.is_file() else ""
    if not text:
        rep.add("actors", f"{script.name} is missing: nothing spawns the actors of {path.name}")
    for i, a in enumerate(data["actors"]):
        t = a.get("transform") if isinstance(a, dict) else None
        if not isinstance(t, dict) or any(not isinstance(t.get(k), (int, float)) for k in ("x", "y", "z", "yaw")):
            rep.add("actors", f"{path.name}: actors[{i}] lacks a numeric transform x, y, z, yaw")
            continue
        bp = a.get("blueprint")
        if bp is not None and not (isinstance(bp, str) and bp.startswith(("vehicle.", "walker."))):
            rep.add("actors", f"{path.name}: actors[{i}].blueprint {bp!r} is not a vehicle.* or walker.* id")
        if text and bp and repr(bp) not in text:
            rep.add("actors", f"{script.name} does not spawn {a.get('name')} ({bp})")


def _check_mesh(rep: ContractReport, fate: MeshFate, materials: list[str]) -> None:
    where = f"{fate.fbx}: {'node' if fate.kind == 'map' else 'prop'} {fate.node!r} (asset {fate.asset!r})"
    words = dropped_words(fate.asset)
    if words:
        rep.add("names_dropped", f"{where} contains {' and '.join(repr(w) for w in words)}: never placed in the map; "
                                 f"rename it, e.g. {suggest_name(fate.asset)!r}")
    for mt in materials:
        if dropped_words(mt):
            rep.add("names_dropped", f"{where}: material {mt!r} contains 'light' or 'sign': the mesh is never placed; "
                                     f"rename it, e.g. {suggest_name(mt)!r}")
    if TILE_MARK.lower() in fate.asset.lower():
        rep.add("names_tile", f"{where} contains {TILE_MARK!r}")
    if fate.intended_tag is not None and fate.tag != fate.intended_tag and not (
            fate.intended_tag == "NONE" and fate.tag == "NONE"):
        if fate.tag != "Terrain":  # Terrain mis-tags are summed up in the 'semantics' rule
            rep.add("tag", f"{where} ends in Static/{fate.folder} and is tagged {fate.tag}, its class is "
                           f"{fate.intended_tag}")


def _read_fbx(rep, src: Path, pkg: Path):
    """The FBX's summary with its texture paths checked, or None (reported) when it does not parse."""
    from . import fbxbin

    try:
        fs = fbxbin.summarize(src)
    except Exception as exc:
        rep.add("json", f"{src}: not a readable binary FBX ({exc})")
        return None
    _check_textures(rep, src, fs, pkg)
    return fs


def _check_textures(rep: ContractReport, fbx: Path, fs, pkg: Path) -> None:
    for t in fs.textures:
        for key in ("FileName", "RelativeFilename"):
            v = t.get(key)
            if not v:
                continue
            if v.startswith("/") or re.match(r"^[A-Za-z]:[\\/]", v) or v.startswith("\\\\"):
                rep.add("texture_paths", f"{fbx.name}: {t['object']} {t['name']!r} stores the absolute path {v!r} "
                                         f"in {key}")
        rel = t.get("RelativeFilename")
        if rel and not (fbx.parent / rel).is_file() and not (pkg / Path(rel).name).is_file():
            rep.add("texture_paths", f"{fbx.name}: texture {rel!r} is not in the package")
