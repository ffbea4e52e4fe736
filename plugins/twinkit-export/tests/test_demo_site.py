"""Demo-site targets on a reduced mesh: the demo site's textured ground-truth mesh (~76k faces)
with its own per-vertex ground-truth labels, through split -> FBX -> USD -> CARLA package.

Targets: every class present in the labels is a correctly named sub-mesh in the FBX and the USD;
per-class vertex counts add up to the source mesh; the USD validates with 0 errors; the XODR in
the package parses with carla.Map.
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from twinkit.testing import need_plugin, run_step, shared_plugin_run

from twinkit_export.classes import BY_ID

from conftest import HAS_BPY, SHARED, plugin, straight_xodr

pytestmark = pytest.mark.slow

DEMO_SITE = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


@pytest.fixture(scope="module")
def demo_site(tmp_path_factory):
    """A folder with gt_mesh.obj/.mtl/.png, gt_mesh.ply and site.json of the small demo site."""
    given = os.environ.get("TWINKIT_DEMO_SITE_DIR")  # e.g. an existing outputs/demo/01_site (saves ~40 s)
    if given and (Path(given) / "gt_mesh.obj").exists():
        return Path(given)
    need_plugin("site_generator", "demo_intersection")  # the twinkit-demo-site package
    # the preset's photos too: the same site as the other sessions' (made once per make test run)
    out = shared_plugin_run("site_generator", "demo_intersection", tmp_path_factory.mktemp("demo_site"),
                            site=dict(DEMO_SITE), size="small", seed=0)
    return out["site.json"].parent


@pytest.fixture(scope="module")
def demo_split(demo_site, tmp_path_factory):
    from twinkit import artefacts as A

    obj = demo_site / "gt_mesh.obj"
    # the textured mesh is the ground-truth mesh itself: its labels are the per-vertex ground truth
    lab = tmp_path_factory.mktemp("demo_labels") / "labels.npy"
    A.write_labels(lab, A.read_gt_mesh(demo_site / "gt_mesh.ply").attrs["label"])
    out = run_step(plugin("step", "split_classes"), tmp_path_factory.mktemp("demo_split"),
                   {"in_labels_npy": lab, "in_textured_mesh_obj": obj}, site=DEMO_SITE)
    return obj, np.load(lab), out["class_meshes"]


def test_labels_and_counts_add_up(demo_site, demo_split):
    from twinkit.mesh import read_obj

    obj, labels, class_dir = demo_split
    man = json.loads((class_dir / "classes.json").read_text())
    n = len(read_obj(obj).vertices)
    assert len(labels) == n
    present = set(np.unique(labels).tolist())
    site = json.loads((demo_site / "site.json").read_text())
    assert present <= set(site["labels_present"]) | {255}
    assert {c["class_id"] for c in man["classes"]} == present
    for c in man["classes"]:
        assert c["name"] == BY_ID[c["class_id"]].carla_name
        assert c["own_vertices"] == c["label_count"] == int((labels == c["class_id"]).sum())
    assert sum(c["own_vertices"] for c in man["classes"]) == n
    assert man["stats"]["source_faces"] == sum(c["faces"] for c in man["classes"])


def test_usd_demo_validates(demo_site, demo_split, tmp_path):
    from pxr import Usd, UsdGeom

    _, labels, class_dir = demo_split
    out = run_step(plugin("exporter", "usd"), tmp_path / "usd", {"in_class_meshes_dir": class_dir,
                                                                  "in_site_json": demo_site / "site.json"},
                   site=DEMO_SITE)
    from twinkit_export.usd import validation_report

    rep = validation_report(out["twin.usd"])
    assert rep["errors"] == 0, rep["messages"]
    stage = Usd.Stage.Open(str(out["twin.usd"]))
    names = {p.GetName() for p in stage.GetDefaultPrim().GetChildren() if p.IsA(UsdGeom.Mesh)}
    assert names == {BY_ID[int(c)].carla_name for c in np.unique(labels)}
    geo = stage.GetRootLayer().customLayerData["twinkit:georeference"]
    assert geo["projected_x"] == pytest.approx(385346.25059729954)
    # colliders where Isaac Sim's vehicles and people stand: road, sidewalk, terrain, building
    from pxr import UsdPhysics

    collide = {p.GetName() for p in stage.GetDefaultPrim().GetChildren() if p.HasAPI(UsdPhysics.CollisionAPI)}
    assert {"Road_Road", "Road_Sidewalk", "Terrain", "Building"} <= collide
    assert not collide & {"Car", "Pedestrian", "Truck", "Bus", "Rider", "Motorcycle", "Bicycle"}


@pytest.mark.skipif(not HAS_BPY, reason="bpy not installed")
def test_fbx_and_carla_package_demo(demo_site, demo_split, tmp_path):
    import carla

    _, labels, class_dir = demo_split
    fbx = run_step(plugin("exporter", "fbx"), tmp_path / "fbx", {"in_class_meshes_dir": class_dir,
                                                                 "in_site_json": demo_site / "site.json"},
                   site=DEMO_SITE)["twin.fbx"]
    dump = tmp_path / "fbx.json"
    for _attempt in range(3):
        proc = subprocess.run([os.sys.executable, str(Path(__file__).with_name("fbx_dump.py")), str(fbx), str(dump)],
                              capture_output=True, timeout=300)
        if proc.returncode == 0:
            break
    assert proc.returncode == 0
    d = json.loads(dump.read_text())
    man = json.loads((class_dir / "classes.json").read_text())
    assert set(d["nodes"]) == {BY_ID[int(c)].carla_name for c in np.unique(labels)}
    for c in man["classes"]:
        node = d["nodes"][c["name"]]
        assert (node["num_vertices"], node["num_faces"]) == (c["vertices"], c["faces"])
        own = int((np.array(node["colors"]["class_id"])[:, 0] == c["class_id"]).sum())
        assert own == c["own_vertices"]
    assert sum(int((np.array(n["colors"]["class_id"])[:, 0] == BY_ID_rev(name)).sum())
               for name, n in d["nodes"].items()) == len(labels)
    xodr_src = SHARED / "data" / "opendrive" / "fabriksgatan.xodr"
    xodr = tmp_path / "aligned.xodr"
    xodr.write_text(xodr_src.read_text() if xodr_src.exists() else straight_xodr())
    out = run_step(plugin("exporter", "carla_package"), tmp_path / "pkg",
                   {"in_twin_fbx": fbx, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr,
                    "in_site_json": demo_site / "site.json"}, site=DEMO_SITE)
    pkg = out["carla_import"] / "Import" / "DemoTwin"
    # the package's FBX files (map geometry + one prop per other class) hold every class's faces once,
    # and CARLA's import rules give each its tag (carla_contract; the exporter already ran it)
    from twinkit_export.carla_contract import check_package

    rep = check_package(out["carla_import"], "DemoTwin", expect_decals=False)
    assert not rep.errors, [str(v) for v in rep.errors]
    # fabriksgatan is a real street laid over the demo mesh, not the demo's own roads: its lanes run off the mesh
    # and its blocks are not the demo's, which the behaviour rules report (the step is DEGRADED, the package written)
    assert {v.rule for v in rep.behaviour} <= {"lanes_over_ground", "sidewalk_blocks"}, [str(v) for v in rep.behaviour]
    assert {m.class_id: m.faces for m in rep.meshes} == {c["class_id"]: c["faces"] for c in man["classes"]}
    assert rep.wrong_terrain_share() == 0.0 and not any(m.dropped for m in rep.meshes)
    # the package's FBX files are made in the CARLA frame (a pure rotation on the demo: test_carla_frame.py)
    assert (pkg / "Demo.fbx").read_bytes()[:18] == b"Kaydara FBX Binary"
    fr = json.loads((out["carla_import"] / "carla_frame.json").read_text())
    assert fr["scale"] == 1.0 and fr["rotation_deg"] == pytest.approx(1.7928, abs=1e-3)
    m = carla.Map("Demo", (pkg / "Demo.xodr").read_text())
    assert len(m.generate_waypoints(10.0)) > 0
    assert json.loads((pkg / "DemoTwin.json").read_text())["maps"][0]["xodr"] == "./Demo.xodr"


def BY_ID_rev(name: str) -> int:
    return next(c.train_id for c in BY_ID.values() if c.carla_name == name)
