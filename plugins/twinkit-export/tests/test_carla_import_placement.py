"""What ``make import`` places in the CARLA map level (issue 45 item 3, rule ``import_placement``).

CARLA 0.9.16's import (``Util/BuildTools/Import.py``, ``PrepareAssetsForCookingCommandlet.cpp``
``PrepareMapsForCooking``) spawns into the level only the meshes of ``Maps/<Map>`` and
``Static/{Road,RoadLine,Terrain,SideWalk}/<Map>``; ``Tagger.h`` ``GetLabelByPath`` tags a mesh by
the folder at path segment 4. The package's ``place_in_map.py`` is run against the ``unreal``
stand-in (``twinkit_export.unreal_stub``) that models the editor after the import; only the
saved level counts (what ``reload_world`` loads).
"""
from __future__ import annotations

import ast
import json
import shutil
from pathlib import Path

import pytest

from twinkit_export import carla_contract as cc
from twinkit_export.carla_contract import ContractReport, MeshFate
from twinkit_export.carla_place import PLACE_SCRIPT, write_place_script
from twinkit_export.contract_import import (after_import, check_import_placement, emulate_placement, level_path,
                                            placement_summary, prop_object_path, run_editor_script,
                                            tagger_label_of_path)

from conftest import HAS_BPY, SITE, plugin

PKG, MAP = "DemoTwin", "Demo"


def test_tagger_reads_path_segment_4():
    """Tagger.h GetLabelByPath: ParseIntoArray(.., "/", false)[4] through GetLabelByFolderName."""
    assert tagger_label_of_path("/Game/DemoTwin/Static/Building/Demo_Building/Demo_Building.Demo_Building") == \
        "Buildings"
    assert tagger_label_of_path("/Game/DemoTwin/Static/Road/Demo/Demo_Road_Road.Demo_Road_Road") == "Roads"
    # a map mesh MoveAssets left in Maps/<Map> is tagged by the map's name: NONE
    assert tagger_label_of_path("/Game/DemoTwin/Maps/Demo/Demo_Building.Demo_Building") == "NONE"
    # Import.py generate_package_file: /Game/<Pkg>/Static/<tag>/<name>/<stem>.<stem>
    assert prop_object_path(PKG, {"name": "Demo_Wall", "tag": "Wall", "source": "./Demo_Wall.fbx"}) == \
        "/Game/DemoTwin/Static/Wall/Demo_Wall/Demo_Wall.Demo_Wall"
    assert level_path(PKG, MAP) == "/Game/DemoTwin/Maps/Demo/Demo"


def _street(tmp_path: Path, lifted: bool = True):
    """A package's contract report (map nodes + props as CARLA's import would see them), its props, its root."""
    rep = ContractReport(PKG)
    for node, folder, cid, tag, faces in (("Road_Road", "Road", 0, "Roads", 1000),
                                          ("Road_Sidewalk", "SideWalk", 1, "Sidewalks", 300),
                                          ("Terrain", "Terrain", 9, "Terrain", 200)):
        rep.meshes.append(MeshFate("map", "Demo.fbx", node, f"Demo_{node}", folder, tag, True, False, faces, cid, tag))
    props = []
    for name, folder, cid, tag, faces in (("Demo_Building", "Building", 2, "Buildings", 600),
                                          ("Demo_Pole", "Pole", 5, "Poles", 50),
                                          ("Demo_TrafficLamp", "TrafficLight", 6, "TrafficLight", 30),
                                          ("Demo_Vegetation", "Vegetation", 8, "Vegetation", 250),
                                          ("Demo_ScannedCar_000", "Car", 13, "Car", 80)):
        rep.meshes.append(MeshFate("prop", f"{name}.fbx", name, name, folder, tag, False, False, faces, cid, tag))
        props.append({"name": name, "source": f"./{name}.fbx", "tag": folder, "size": "Huge", "class": folder,
                      "faces": faces, **({"scanned": True} if "Scanned" in name else {})})
    root = tmp_path / "carla_import"
    root.mkdir()
    if lifted:
        (root / "actors.json").write_text(json.dumps({"actors": [{"scanned_prop_name": "Demo_ScannedCar_000"}]}))
    return rep, props, root


def test_bare_map_places_no_building(tmp_path):
    """Today's package (no editor script): the import places road, sidewalk, terrain; no building."""
    rep, props, root = _street(tmp_path)
    res = emulate_placement(rep, root, PKG, MAP, props, root / PLACE_SCRIPT)
    by = res.by_class()
    assert by["Buildings"]["placed"] == 0 and by["Vegetation"]["placed"] == 0 and by["Roads"]["placed"] == 1000
    assert res.share() == pytest.approx(1500 / 2430)  # the lifted car is an actor, not a static face
    cc_rep = ContractReport(PKG, meshes=list(rep.meshes))
    check_import_placement(cc_rep, root, PKG, {"maps": [{"name": MAP}], "props": props})
    assert [v.rule for v in cc_rep.violations] == ["import_placement"]
    assert "Buildings (100 %" in cc_rep.violations[0].message and "ship place_in_map.py" in cc_rep.violations[0].message


def test_editor_script_places_every_static_class_in_the_saved_level(tmp_path):
    rep, props, root = _street(tmp_path)
    script = write_place_script(root, PKG, MAP, props)
    ast.parse(script.read_text())  # the script parses
    res = emulate_placement(rep, root, PKG, MAP, props, script)
    assert res.error is None and res.share() == 1.0 and not res.lifted_placed
    for m in res.meshes:  # once each, tagged as its class, its own triangles as collision
        assert (m.actors, m.tag, m.complex_collision) == (1, m.intended_tag, True), m
    # running it again (a second import, a second run) adds nothing
    state_runs = []
    state, want = after_import(rep, PKG, MAP, props)
    for _ in range(2):
        assert run_editor_script(script, state) is None
        state_runs.append(len(state.levels[level_path(PKG, MAP)]))
    assert state_runs == [7, 7]  # 3 map meshes + 4 static props, the lifted car left to spawn_actors.py
    saved = state.levels[level_path(PKG, MAP)]
    assert {a.mesh for a in saved} == set(want) - {prop_object_path(PKG, props[-1])}
    assert all(a.location == (0.0, 0.0, 0.0) and a.mobility == "STATIC" for a in saved)
    # the API calls in order: the level first, the level saved last
    names = [c[0] for c in state.calls]
    assert names[0] == "load_level" and names[-1] == "save_current_level"


def test_only_the_saved_level_counts(tmp_path):
    """Actors spawned but never saved are gone on reload_world; so is a script aimed at another level."""
    rep, props, root = _street(tmp_path)
    script = write_place_script(root, PKG, MAP, props)
    text = script.read_text()
    script.write_text(text.replace("    if not unreal.EditorLevelLibrary.save_current_level():\n",
                                   "    if False:\n"))
    res = emulate_placement(rep, root, PKG, MAP, props, script)
    assert res.error is None and res.by_class()["Buildings"]["placed"] == 0
    script.write_text(text.replace(f"LEVEL = '{level_path(PKG, MAP)}'", "LEVEL = '/Game/DemoTwin/Maps/Other/Other'"))
    res = emulate_placement(rep, root, PKG, MAP, props, script)
    assert res.error and "not found" in res.error and res.share() < 1.0


def test_script_names_a_mesh_import_py_does_not_register(tmp_path):
    rep, props, root = _street(tmp_path)
    script = write_place_script(root, PKG, MAP, props)
    script.write_text(script.read_text().replace("/Static/Building/Demo_Building/", "/Static/Buildings/Demo_Building/"))
    res = emulate_placement(rep, root, PKG, MAP, props, script)
    assert res.error and "Demo_Building" in res.error
    assert res.by_class()["Buildings"]["placed"] == 0


def test_a_prop_in_a_folder_the_tagger_does_not_know_is_tagged_none(tmp_path):
    """GetLabelByFolderName: the exact folder names; 'Buildings' (plural) is NONE."""
    rep, props, root = _street(tmp_path)
    props[0]["tag"] = "Buildings"
    rep.meshes[3].folder = "Buildings"
    res = emulate_placement(rep, root, PKG, MAP, props, write_place_script(root, PKG, MAP, props))
    b = next(m for m in res.meshes if m.asset == "Demo_Building")
    assert (b.actors, b.tag, b.ok) == (1, "NONE", False)


# ----------------------------------------------------------------------------- the exporter's package

@pytest.fixture(scope="module")
def package(tmp_path_factory, class_dir, xodr_file, fbx_out):
    from twinkit.testing import run_step

    pytest.importorskip("carla")
    d = tmp_path_factory.mktemp("carla_pkg_place")
    out = run_step(plugin("exporter", "carla_package"), d / "run",
                   {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr_file},
                   site=SITE)
    return out["carla_import"]


@pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) writes the package's FBX files")
def test_package_places_the_whole_street_and_fails_without_its_script(package, tmp_path):
    rep = cc.check_package(package, "TeststreetTwin")
    assert rep.ok, [str(v) for v in rep.violations]
    desc = json.loads((package / "Import" / "TeststreetTwin" / "TeststreetTwin.json").read_text())
    script = package / PLACE_SCRIPT
    tree = ast.parse(script.read_text())
    place = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], "id", "") == "PLACE")
    # it names exactly the package's props (every one a static class here), at the path Import.py registers
    assert sorted(p["mesh"] for p in place) == sorted(prop_object_path("TeststreetTwin", p) for p in desc["props"])
    labels = {p["name"]: cc.tagger_label(p["tag"]) for p in desc["props"]}
    assert all(p["tag"] == tagger_label_of_path(p["mesh"]) == labels[p["name"]] for p in place)
    assert {"Buildings", "Poles", "TrafficSigns"} <= {p["tag"] for p in place}
    s = placement_summary(package, "TeststreetTwin")
    assert s["placed_share"] == 1.0 and s["placed_share_import_only"] < 1.0 and not s["error"]
    assert all(v["tags"] == [k] for k, v in s["by_class"].items())
    carla = pytest.importorskip("carla")  # the tags are carla.CityObjectLabel names of carla 0.9.16
    assert all(hasattr(carla.CityObjectLabel, k) for k in s["by_class"])
    # the package as it was before (no editor script): buildings not placed
    root = Path(shutil.copytree(package, tmp_path / "before"))
    (root / PLACE_SCRIPT).unlink()
    rep = cc.check_package(root, "TeststreetTwin")
    assert [v.rule for v in rep.violations] == ["import_placement"]
    assert "Buildings (100 %" in rep.violations[0].message
    readme = (package / "Import" / "TeststreetTwin" / "README.md").read_text()
    assert "-run=pythonscript" in readme and PLACE_SCRIPT in readme
