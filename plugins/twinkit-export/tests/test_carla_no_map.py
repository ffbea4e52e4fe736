"""A twin without a road network (road_source=none): the CARLA package has no map and says so (issue 28).

CARLA's Import.py needs an OpenDRIVE beside a map's FBX (it copies it, builds the navmesh and the traffic
manager's binary from it), so the package lists no map and every class is a prop; the contract checks pass."""
from __future__ import annotations

import json

import pytest

from twinkit.testing import run_step

from conftest import HAS_BPY, SITE, plugin

pytestmark = pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) writes the package's FBX files")


def test_package_without_opendrive_is_props_only_and_says_so(tmp_path, class_dir, fbx_out):
    from twinkit_export.carla_contract import check_package

    out = run_step(plugin("exporter", "carla_package"), tmp_path / "run",
                   {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir}, site=SITE)
    root = out["carla_import"]
    pkg = root / "Import" / "TeststreetTwin"
    desc = json.loads((pkg / "TeststreetTwin.json").read_text())
    assert desc["maps"] == []
    classes = {c["name"] for c in json.loads((class_dir / "classes.json").read_text())["classes"] if c["faces"]}
    props = {p["name"]: p for p in desc["props"]}
    # every class is a prop, the ground classes too, each in the Tagger folder of its tag
    assert len(props) == len(classes) and props["Teststreet_Road_Road"]["tag"] == "Road"
    assert props["Teststreet_Building"]["tag"] == "Building"
    for p in desc["props"]:
        assert (pkg / p["source"]).is_file()
    assert not list(pkg.glob("*.xodr")) and not (pkg / "Teststreet.fbx").exists()
    readme = (pkg / "README.md").read_text()
    assert "no map and no OpenDRIVE" in readme and "road_source=none" in readme
    spawn = json.loads((root / "spawn_points.json").read_text())
    assert spawn["count"] == 0 and spawn["map"] is None and "no road network" in spawn["note"]
    assert json.loads((root / "Import" / "roadpainter_decals.json").read_text()) == {"decals": []}
    script = (root / "spawn_props.py").read_text()
    assert "MAP = ''" in script and all(f"static.prop.{n.lower()}" in script for n in props)
    assert check_package(root, "TeststreetTwin").ok
    # a props-only package without the README that says why it has no map breaks the contract
    (pkg / "README.md").unlink()
    assert not check_package(root, "TeststreetTwin").ok


def test_a_map_the_scan_found_no_roads_for_is_packaged_as_no_map(tmp_path, class_dir, fbx_out):
    """road_source=scan on a scan without roads writes an OpenDRIVE with none (userData twinkit_roads=none):
    the package treats it as no map (props only, the contract holds) instead of refusing it."""
    from twinkit_export.carla_contract import check_package

    xodr = tmp_path / "aligned.xodr"
    xodr.write_text('<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE>\n    <header revMajor="1" revMinor="4">\n'
                    '        <userData code="twinkit_road_source" value="scan" />\n'
                    '        <userData code="twinkit_roads" value="none" />\n    </header>\n</OpenDRIVE>\n')
    out = run_step(plugin("exporter", "carla_package"), tmp_path / "run",
                   {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr}, site=SITE)
    root = out["carla_import"]
    desc = json.loads((root / "Import" / "TeststreetTwin" / "TeststreetTwin.json").read_text())
    assert desc["maps"] == [] and desc["props"]
    spawn = json.loads((root / "spawn_points.json").read_text())
    assert spawn["count"] == 0
    assert check_package(root, "TeststreetTwin").ok
    # the note, the README and the step's metrics name the scan as the source, not road_source=none (issue 46)
    readme = (root / "Import" / "TeststreetTwin" / "README.md").read_text()
    for text in (spawn["note"], readme):
        assert "road_source=scan" in text and "road_source=none" not in text, text
    assert "scan_roads.png" in spawn["note"]
