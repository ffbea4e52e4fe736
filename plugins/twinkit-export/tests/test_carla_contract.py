"""The CARLA package against CARLA 0.9.16's import rules (twinkit_export.carla_contract).

Each test names the file of carla-simulator/carla the rule comes from. Unreal cannot run here,
so the rules are read from that source and applied to the package folder: what ``make import``
would import, move, tag, spawn into the map, drop, and paint.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from twinkit import InputError
from twinkit.testing import run_step

from conftest import HAS_BPY, SITE, plugin

carla = pytest.importorskip("carla")
pytestmark = pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) writes the package's FBX files")

from twinkit_export import carla_contract as cc  # noqa: E402
from twinkit_export import fbxbin  # noqa: E402


@pytest.fixture(scope="module")
def package(tmp_path_factory, class_dir, xodr_file, fbx_out):
    """The carla_package exporter's output for the synthetic street (it runs the contract itself)."""
    d = tmp_path_factory.mktemp("carla_pkg")
    out = run_step(plugin("exporter", "carla_package"), d / "run",
                   {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr_file},
                   site=SITE)
    return out["carla_import"]


def _copy(package: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(package, tmp_path / "carla_import"))


def _desc(root: Path) -> tuple[Path, dict]:
    p = root / "Import" / "TeststreetTwin" / "TeststreetTwin.json"
    return p, json.loads(p.read_text())


def _rules(rep) -> set[str]:
    return {v.rule for v in rep.violations}


# ----------------------------------------------------------------------------- the package passes

def test_package_passes_the_contract(package, class_dir):
    rep = cc.check_package(package, "TeststreetTwin", expect_decals=False)
    assert rep.ok, [str(v) for v in rep.violations]
    # MoveAssetsCommandlet.cpp + Tagger.cpp: every class ends in its own CARLA tag ...
    classes = [c for c in json.loads((class_dir / "classes.json").read_text())["classes"] if c["faces"]]
    got = {}
    for m in rep.meshes:
        got[m.class_id] = got.get(m.class_id, 0) + m.faces
        assert m.tag == m.intended_tag, (m.asset, m.folder, m.tag, m.intended_tag)
    assert got == {c["class_id"]: c["faces"] for c in classes}  # every face of every class, once
    # ... so no face is tagged Terrain unless its class is terrain
    assert rep.wrong_terrain_share() == 0.0
    # PrepareAssetsForCookingCommandlet.cpp (ValidateStaticMesh): nothing is dropped
    assert not any(m.dropped for m in rep.meshes)
    # the map geometry is spawned by the import; everything else is a prop the spawn script places
    assert {m.node for m in rep.meshes if m.kind == "map"} <= {"Road_Road", "Road_Sidewalk", "Terrain"}
    assert all(m.placed for m in rep.meshes if m.kind == "map")
    # FBX2OBJ.cpp: the sidewalk is walkable in the pedestrian navmesh
    assert rep.summary()["walkable_faces"] == next(c["faces"] for c in classes if c["name"] == "Road_Sidewalk")
    assert rep.decals is False


def test_traffic_lights_and_signs_keep_their_tag_under_names_carla_keeps(package):
    """PrepareAssetsForCookingCommandlet.cpp drops '*light*'/'*sign*'; Tagger.cpp tags by folder."""
    from twinkit_export.carla_pkg import package_mesh_name, prop_folder
    from twinkit_export.classes import info

    want = {6: ("Teststreet_TrafficLamp", "TrafficLight", carla.CityObjectLabel.TrafficLight.name),
            7: ("Teststreet_TrafficPlate", "TrafficSign", carla.CityObjectLabel.TrafficSigns.name)}
    for cid, (asset, folder, label) in want.items():
        assert f"Teststreet_{package_mesh_name(info(cid))}" == asset and prop_folder(info(cid)) == folder
        assert cc.tagger_label(folder) == label and not cc.dropped_words(asset)
    rep = cc.check_package(package, "TeststreetTwin")
    by_class = {m.class_id: m for m in rep.meshes}
    assert 7 in by_class  # the synthetic street has a traffic sign (no traffic light)
    for cid in set(want) & set(by_class):
        m = by_class[cid]
        assert (m.asset, m.folder, m.tag) == want[cid] and not m.dropped


def test_prop_fbx_files_hold_one_mesh_and_the_spawn_script_places_each(package):
    """Import.py registers a prop as /Game/<Pkg>/Static/<tag>/<name>/<stem>.<stem>; nothing places props."""
    _, desc = _desc(package)
    script = (package / "spawn_props.py").read_text()
    for p in desc["props"]:
        fs = fbxbin.summarize(package / "Import" / "TeststreetTwin" / p["source"])
        assert len(fs.meshes) == 1
        assert f"static.prop.{p['name'].lower()}" in script
    # the script runs without a simulator for --list
    res = subprocess.run([os.sys.executable, str(package / "spawn_props.py"), "--list", "--skip", "car"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    listed = [ln.split()[0] for ln in res.stdout.splitlines()]
    assert "static.prop.teststreet_building" in listed and "static.prop.teststreet_car" not in listed


def test_fbx_files_store_no_absolute_texture_path(package, fbx_out):
    """Issue item 9: FileName held the absolute path of a temporary build folder. Read with fbxbin and ufbx."""
    for fbx in [fbx_out, *sorted((package / "Import" / "TeststreetTwin").glob("*.fbx"))]:
        fs = fbxbin.summarize(fbx)
        names = [t.get(k) for t in fs.textures for k in ("FileName", "RelativeFilename") if t.get(k)]
        assert names and all(n == "twin.png" for n in names), (fbx.name, names)
        assert b"/.tmp/" not in fbx.read_bytes() and str(fbx.parent).encode() not in fbx.read_bytes()
    dump = fbx_out.with_suffix(".dump.json")
    proc = subprocess.run([os.sys.executable, str(Path(__file__).with_name("fbx_dump.py")), str(fbx_out), str(dump)],
                          capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    d = json.loads(dump.read_text())
    assert d["texture_files"] and all(f == ["twin.png", "twin.png"] for f in d["texture_files"])
    # fbxbin (the contract's reader) agrees with ufbx on objects and face counts
    ours = {m.name: m.faces for m in fbxbin.summarize(fbx_out).meshes}
    assert ours == {k: v["num_faces"] for k, v in d["nodes"].items()}


# ----------------------------------------------------------------------------- packages that fail

def test_mesh_named_traffic_light_fails(tmp_path, fbx_out, class_dir, xodr_file):
    """PrepareAssetsForCookingCommandlet.cpp ValidateStaticMesh: a map node '<Map>_TrafficLight' is dropped.

    First the package of before issue 23 (the whole per-class twin.fbx as the map), then a map FBX
    with a node named TrafficLight.
    """
    pkg = tmp_path / "Import" / "TeststreetTwin"
    pkg.mkdir(parents=True)
    shutil.copyfile(fbx_out, pkg / "Teststreet.fbx")
    shutil.copyfile(fbx_out.with_suffix(".png"), pkg / "twin.png")
    shutil.copyfile(xodr_file, pkg / "Teststreet.xodr")
    (pkg / "TeststreetTwin.json").write_text(json.dumps({"maps": [{
        "name": "Teststreet", "source": "./Teststreet.fbx", "use_carla_materials": False,
        "xodr": "./Teststreet.xodr"}], "props": []}))
    rep = cc.check_package(tmp_path, "TeststreetTwin")
    assert not rep.ok
    dropped = [str(v) for v in rep.violations if v.rule == "names_dropped"]
    assert any("Teststreet_TrafficSign" in v for v in dropped)
    assert all("PrepareAssetsForCookingCommandlet.cpp" in v for v in dropped)
    # MoveAssetsCommandlet.cpp: Building, Car, ... land in Static/Terrain
    assert "semantics" in _rules(rep) and rep.wrong_terrain_share() > 0.05
    # Import.py: no decals file -> default random decals
    assert "decals" in _rules(rep)
    # a map node named TrafficLight
    from twinkit_export.fbx import write_fbx_set

    classes = json.loads((class_dir / "classes.json").read_text())["classes"]
    road = class_dir / next(c["file"] for c in classes if c["name"] == "Road_Road")
    sign = class_dir / next(c["file"] for c in classes if c["class_id"] == 7)
    write_fbx_set([(pkg / "Teststreet.fbx", [road, sign], {sign: "TrafficLight"})], pkg / "twin.png")
    rep = cc.check_package(tmp_path, "TeststreetTwin")
    assert [m.asset for m in rep.meshes if m.dropped] == ["Teststreet_TrafficLight"]
    assert any("Teststreet_TrafficLight" in str(v) and v.rule == "names_dropped" for v in rep.violations)


def test_prop_named_traffic_light_fails(package, tmp_path):
    """ValidateStaticMesh checks the asset name, which for a prop is the FBX file name."""
    root = _copy(package, tmp_path)
    path, desc = _desc(root)
    prop = next(p for p in desc["props"] if p["tag"] == "TrafficSign")  # no traffic light in the street
    os.rename(path.parent / prop["source"], path.parent / "Teststreet_TrafficLight.fbx")
    prop["source"] = "./Teststreet_TrafficLight.fbx"
    path.write_text(json.dumps(desc))
    rep = cc.check_package(root, "TeststreetTwin")
    assert [v.rule for v in rep.violations if "Teststreet_TrafficLight" in v.message] == ["names_dropped"]


def test_map_named_signalhill_fails_in_the_package_and_in_the_exporter(package, tmp_path, fbx_out, class_dir,
                                                                        xodr_file):
    """Every map asset is named <Map>_<Node>: 'SignalHill' puts 'sign' in all of them."""
    root = _copy(package, tmp_path)
    path, desc = _desc(root)
    for ext in ("fbx", "xodr"):
        os.rename(path.parent / f"Teststreet.{ext}", path.parent / f"SignalHill.{ext}")
    desc["maps"][0].update(name="SignalHill", source="./SignalHill.fbx", xodr="./SignalHill.xodr")
    path.write_text(json.dumps(desc))
    rep = cc.check_package(root, "TeststreetTwin")
    dropped = {m.asset for m in rep.meshes if m.dropped}
    assert "SignalHill_Road_Road" in dropped and "names_dropped" in _rules(rep)
    # the exporter refuses such names up front, with a name that passes
    from twinkit_export.plugin import CarlaPackageParams

    for bad in ("SignalHill", "Lighthouse", "DesignDistrict"):
        with pytest.raises(InputError, match=r"'sign'|'light'") as exc:
            run_step(plugin("exporter", "carla_package"), tmp_path / f"run_{bad}",
                     {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr_file},
                     CarlaPackageParams(map_name=bad), site=SITE)
        suggested = str(exc.value).rsplit("map_name=", 1)[1].strip()
        assert not cc.name_problems(suggested), suggested
    assert cc.suggest_name("SignalHill") == "SynalHill" and cc.suggest_name("Lighthouse") == "Litehouse"


def test_decals_rules(package, tmp_path):
    """Import.py generates default decals when no roadpainter_decals.json is under Import/; RoadPainterWrapper.cpp
    reads the entry whose map_name is the map, with all its parameter fields."""
    root = _copy(package, tmp_path)
    decals = root / "Import" / cc.DECALS_FILE
    entry = json.loads(decals.read_text())["decals"][0]
    assert entry["map_name"] == "Teststreet" and not set(entry) & set(cc.DECAL_NAMES)
    assert set(cc.DECAL_FIELDS) <= set(entry)
    # asking for decals when the package has none is a violation; so is a missing file or a missing field
    assert "decals" in _rules(cc.check_package(root, "TeststreetTwin", expect_decals=True))
    entry.pop("random_offset")
    decals.write_text(json.dumps({"decals": [entry]}))
    assert any("random_offset" in v.message for v in cc.check_package(root, "TeststreetTwin").violations)
    decals.unlink()
    rep = cc.check_package(root, "TeststreetTwin")
    assert "decals" in _rules(rep) and rep.decals is True
    # the decals switch writes CARLA's default counts (those Import.py's generate_decals_file writes)
    on = cc.decals_entry("Teststreet", True)
    assert on["roadline1"] == 20 and on["gum"] == 30 and set(cc.DECAL_DEFAULT_COUNTS) <= set(cc.DECAL_NAMES)


def test_json_and_layout_rules(package, tmp_path):
    """Import.py: every *.json under Import/ is a package and a prop needs name/source/tag/size;
    CarlaBlueprintRegistry.cpp: size is an EPropSize name."""
    root = _copy(package, tmp_path)
    (root / "Import" / "TeststreetTwin" / "notes.json").write_text("{}")
    assert "layout" in _rules(cc.check_package(root, "TeststreetTwin"))
    (root / "Import" / "TeststreetTwin" / "notes.json").unlink()
    path, desc = _desc(root)
    desc["props"][0].pop("size")
    desc["props"][1]["size"] = "Enormous"
    desc["maps"][0]["use_carla_materials"] = "false"
    path.write_text(json.dumps(desc))
    rep = cc.check_package(root, "TeststreetTwin")
    msgs = [str(v) for v in rep.violations]
    assert any("lacks size" in m for m in msgs) and "prop_size" in _rules(rep)
    assert any("GetBoolField" in m for m in msgs)
    # placement: a prop that the spawn script does not place
    (root / "spawn_props.py").write_text("PROPS = []\n")
    assert "placement" in _rules(cc.check_package(root, "TeststreetTwin"))


# ----------------------------------------------------------------------------- the single rules

def test_move_assets_routing_and_tagger_folders():
    """MoveAssetsCommandlet.cpp (order of tests, FString::Contains ignores case) and Tagger.cpp
    (GetLabelByFolderName), with the label names of the installed carla==0.9.16."""
    assert cc.move_assets_folder("Demo_Road_Road") == "Road"
    assert cc.move_assets_folder("demo_road_road") == "Road"  # case-insensitive
    assert cc.move_assets_folder("Demo_Road_Marking") == "RoadLine"
    assert cc.move_assets_folder("Demo_Road_Sidewalk") == "SideWalk"
    assert cc.move_assets_folder("Demo_Road_Curb") == cc.move_assets_folder("Demo_Road_Gutter") == "SideWalk"
    assert cc.move_assets_folder("Demo_Terrain") == "Terrain"
    assert cc.move_assets_folder("Demo_Building") == "Terrain"  # anything else
    assert cc.move_assets_folder("Demo_Road_Grass") == "Terrain"  # declared in SSTags.h, never tested
    assert cc.move_assets_folder("TerrainTown_Road_Road") == "Road"  # Road_Road is tested first
    assert cc.move_assets_folder("TerrainTown_Road_Sidewalk") == "Terrain"  # Terrain before Sidewalk
    names = {n for n in dir(carla.CityObjectLabel) if not n.startswith("_")}
    assert set(cc.TAGGER_FOLDERS.values()) <= names
    assert cc.tagger_label("Unlabeled") == "NONE" and "NONE" in names
    assert cc.tagger_label("terrain") == "NONE"  # folder names compare exactly


def test_validate_static_mesh_filter_words():
    """PrepareAssetsForCookingCommandlet.cpp: 'light' or 'sign', any case, anywhere in the name."""
    for bad in ("Demo_TrafficLight", "Demo_TRAFFICSIGN", "Lighthouse_Road_Road", "DesignDistrict_Terrain",
                "Demo_Streetlights", "Demo_Signal"):
        assert cc.dropped_words(bad), bad
    for ok in ("Demo_TrafficLamp", "Demo_TrafficPlate", "Demo_Road_Road", "Demo_Building"):
        assert not cc.dropped_words(ok), ok


def test_navmesh_names_are_exact():
    """FBX2OBJ.cpp SetMaterials: its StartsWith compares whole names, so only 'Road_Sidewalk' is walkable."""
    assert cc.NAV_AREAS["Road_Sidewalk"] == "sidewalk"
    assert cc.NAV_AREAS.get("Road_Sidewalk_1", "block") == "block"
    assert cc.NAV_AREAS["Road_Road"] == "road"


# ----------------------------------------------------------------------------- walkers and parked cars

def test_parked_car_on_a_sidewalk_lane_is_reported(package, tmp_path):
    """Map.cpp Map::GetWaypoint (lane type Sidewalk): the synthetic street's map has a sidewalk lane right of
    its road (conftest.straight_xodr, y0 5 m: the lane from 1.5 to -0.5 m north); a car there is reported,
    one on the pavement beyond it is not. contract_sidewalks.py"""
    root = _copy(package, tmp_path)
    assert cc.check_package(root, "TeststreetTwin", expect_decals=False).ok
    pkg_xodr = (root / "Import" / "TeststreetTwin" / "Teststreet.xodr").read_text()
    from twinkit.street.lanes import LaneMap, to_carla

    lm = LaneMap(pkg_xodr)
    side = lm.lanes(1.0)
    sw = side.xyz[side.is_type("sidewalk")][len(side) // 4]  # a sidewalk-lane centre, package frame
    on = to_carla(sw)
    actors = [{"id": 0, "name": "Car_000", "class": "car", "blueprint": None,
               "transform": {"x": float(on[0]), "y": float(on[1]), "z": 0.2, "pitch": 0.0, "yaw": 0.0, "roll": 0.0}}]
    (root / "actors.json").write_text(json.dumps({"actors": actors}))
    (root / "spawn_actors.py").write_text("# spawns nothing\n")
    rep = cc.check_package(root, "TeststreetTwin", expect_decals=False)
    parked = [str(v) for v in rep.violations if v.rule == "parked_on_sidewalk"]
    assert len(parked) == 1 and "Car_000" in parked[0] and "Map.cpp" in parked[0], [str(v) for v in rep.violations]
    actors[0]["transform"]["y"] = float(on[1]) + 30.0  # 30 m south of the road: off every lane
    (root / "actors.json").write_text(json.dumps({"actors": actors}))
    assert "parked_on_sidewalk" not in _rules(cc.check_package(root, "TeststreetTwin", expect_decals=False))


# ----------------------------------------------------------------------------- lanes over the ground

def _lengthen(xodr: Path, to_m: float) -> None:
    """The package's one straight road made ``to_m`` long (its geometry with it)."""
    import re

    text = xodr.read_text()
    text = re.sub(r'length="36(\.0*)?"', f'length="{to_m}"', text)
    assert f'length="{to_m}"' in text
    xodr.write_text(text)


def test_lane_past_the_mesh_fails_lanes_over_ground(package, tmp_path):
    """trafficmanager/InMemoryMap.cpp SetUp + LocalizationStage.cpp Update: vehicles follow every waypoint of a
    lane to its end. The synthetic street's road (36 m, on the 40 m mesh) passes; made 40 m long it runs 2 m past
    the mesh's edge (as netconvert's turnarounds at the demo's map ends did), and fails."""
    rep = cc.check_package(package, "TeststreetTwin", expect_decals=False)
    assert "lanes_over_ground" not in _rules(rep)
    root = _copy(package, tmp_path)
    _lengthen(root / "Import" / "TeststreetTwin" / "Teststreet.xodr", 40.0)
    rep = cc.check_package(root, "TeststreetTwin", expect_decals=False)
    msgs = [str(v) for v in rep.violations if v.rule == "lanes_over_ground"]
    assert len(msgs) == 1 and "run past the edge of Teststreet.fbx" in msgs[0]
    assert "InMemoryMap.cpp" in msgs[0] and "LocalizationStage.cpp" in msgs[0]
    n = int(msgs[0].split(":")[1].split()[0])
    assert 2 <= n <= 8  # two lanes, 1-3 waypoints each past x = 20 m (the road's last 2 m)


def test_map_larger_than_the_scan_is_not_past_the_edge(package, tmp_path):
    """A road that runs on far beyond the mesh (a map larger than the scan: road_source=opendrive of a town) is
    counted as beyond the scan, not a lane past the mesh's edge."""
    from twinkit_export.contract_ground import check_lanes_over_ground

    root = _copy(package, tmp_path)
    _lengthen(root / "Import" / "TeststreetTwin" / "Teststreet.xodr", 200.0)
    rep = cc.ContractReport("TeststreetTwin")
    _, desc = _desc(root)
    (res,) = check_lanes_over_ground(rep, root / "Import" / "TeststreetTwin", desc["maps"])
    assert rep.ok and res["past_edge"] == 0 and res["beyond_scan"] > 300


def test_behaviour_rules_degrade_the_step_and_import_rules_fail_it(monkeypatch, tmp_path):
    """A package CARLA imports but in which the twin misbehaves (e.g. a sidewalk cut in two on a real scan) is
    written and the step is DEGRADED; a package that breaks the import itself fails the step."""
    import twinkit_export.carla_contract as ccm
    import twinkit_export.contract_import as ci
    from twinkit_export.plugin import _checked_summary

    class Ctx:
        def __init__(self):
            self.reasons = []

        def degraded(self, reason, hint=None):
            self.reasons.append(reason)

    def report(rules):
        rep = ccm.ContractReport("Pkg")
        for r in rules:
            rep.add(r, f"a {r} problem")
        return rep

    monkeypatch.setattr(ci, "placement_summary", lambda *a, **k: {})
    monkeypatch.setattr(ccm, "check_package", lambda *a, **k: report(["sidewalk_blocks", "conflicting_greens"]))
    ctx = Ctx()
    summ = _checked_summary(tmp_path, "Pkg", None, None, ctx)
    assert not summ["ok"] and len(ctx.reasons) == 2 and "sidewalk_blocks" in ctx.reasons[0]
    monkeypatch.setattr(ccm, "check_package", lambda *a, **k: report(["sidewalk_blocks", "names_dropped"]))
    with pytest.raises(RuntimeError, match="names_dropped"):
        _checked_summary(tmp_path, "Pkg", None, None, Ctx())
    assert ccm.BEHAVIOUR_RULES <= set(ccm.RULES)
