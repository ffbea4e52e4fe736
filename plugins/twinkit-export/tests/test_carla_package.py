"""CARLA import package: layout, JSON, OpenDRIVE parsed offline with carla.Map, spawn points and frames."""
from __future__ import annotations

import json

import numpy as np
import pytest

from twinkit import InputError
from twinkit.testing import run_step

from conftest import HAS_BPY, SHARED, SITE, plugin

carla = pytest.importorskip("carla")
# the package's FBX files (map geometry + one prop per class) are written by Blender
needs_bpy = pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) is not installed")


def _package(tmp_path, fbx_out, class_dir, xodr, params=None, site=SITE):
    from twinkit_export.plugin import CarlaPackageParams

    return run_step(plugin("exporter", "carla_package"), tmp_path / "run",
                    {"in_twin_fbx": fbx_out, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr},
                    params or CarlaPackageParams(), site=site)


@pytest.fixture(scope="module")
def fake_fbx(tmp_path_factory, class_dir):
    """Without bpy the package code is still tested, with a stand-in FBX file."""
    if HAS_BPY:
        from twinkit.testing import run_step as rs

        return rs(plugin("exporter", "fbx"), tmp_path_factory.mktemp("fbx_pkg"), {"in_class_meshes_dir": class_dir},
                  site=SITE)["twin.fbx"]
    d = tmp_path_factory.mktemp("fakefbx")
    (d / "twin.fbx").write_bytes(b"Kaydara FBX Binary  \x00")
    return d / "twin.fbx"


@needs_bpy
def test_package_layout_and_json(tmp_path, fake_fbx, class_dir, xodr_file):
    out = _package(tmp_path, fake_fbx, class_dir, xodr_file)
    root = out["carla_import"]
    pkg = root / "Import" / "TeststreetTwin"
    desc = json.loads((pkg / "TeststreetTwin.json").read_text())
    assert desc["maps"] == [{"name": "Teststreet", "source": "./Teststreet.fbx", "use_carla_materials": False,
                             "xodr": "./Teststreet.xodr"}]
    # every class that MoveAssets cannot route to its own tag is a prop with its Tagger folder as tag
    props = {p["name"]: p for p in desc["props"]}
    classes = {c["name"] for c in json.loads((class_dir / "classes.json").read_text())["classes"] if c["faces"]}
    assert "Road_Road" in classes and "Building" in classes
    for name in classes - {"Road_Road", "Road_Sidewalk", "Terrain"}:
        pname = "Teststreet_" + {"TrafficLight": "TrafficLamp", "TrafficSign": "TrafficPlate"}.get(name, name)
        assert props[pname]["source"] == f"./{pname}.fbx" and (pkg / f"{pname}.fbx").exists()
        assert props[pname]["size"] in ("Tiny", "Small", "Medium", "Big", "Huge")
    assert props["Teststreet_Building"]["tag"] == "Building"
    for name in ("Teststreet.fbx", "Teststreet.xodr", "README.md"):
        assert (pkg / name).exists(), name
    # make import reads every .json under Import/ as a package, except roadpainter_decals.json
    assert sorted(p.name for p in (root / "Import").rglob("*.json")) == ["TeststreetTwin.json",
                                                                         "roadpainter_decals.json"]
    assert (root / "Import" / "roadpainter_decals.json").exists()
    assert (root / "spawn_points.json").exists() and (root / "spawn_props.py").exists()
    if HAS_BPY:
        assert (pkg / "twin.png").exists()  # the texture the FBX references by relative path
    # the packaged OpenDRIVE parses offline and has driving lanes
    m = carla.Map("Teststreet", (pkg / "Teststreet.xodr").read_text())
    assert len(m.generate_waypoints(5.0)) > 0
    readme = (pkg / "README.md").read_text()
    assert "make import" in readme and "Road_Road" in readme and "spawn_props.py" in readme


@needs_bpy
def test_spawn_points_on_driving_lanes_and_frames(tmp_path, fake_fbx, class_dir, xodr_file):
    out = _package(tmp_path, fake_fbx, class_dir, xodr_file)
    sp = json.loads(out["spawn_points.json"].read_text())
    pts = sp["spawn_points"]
    # the package is in the CARLA frame: the site frame turned by the meridian convergence (carla_frame.json)
    fr = json.loads((out["carla_import"] / "carla_frame.json").read_text())
    m = np.array(fr["matrix_site_to_package"])
    assert fr["rotation_deg"] == pytest.approx(1.7928, abs=1e-3) and fr["scale"] == 1.0
    # straight road along +x at y = 5 m (site frame), lanes 3.5 m wide, sidewalk not used
    assert {p["lane_id"] for p in pts} == {-1, 1}
    assert len(pts) == 2 * 2  # s = 0, 20 on each lane of the 36 m road
    for p in pts:
        site, c = p["site"], p["carla"]
        # right lane (-1) centre at y = 5 - 1.75, left lane (+1) at y = 5 + 1.75, in the site frame
        want_y = 5.0 - 1.75 if p["lane_id"] == -1 else 5.0 + 1.75
        assert site["y"] == pytest.approx(want_y, abs=1e-3)
        pkg = m @ [site["x"], site["y"], site["z"]]
        assert c["x"] == pytest.approx(pkg[0], abs=2e-3)
        assert c["y"] == pytest.approx(-pkg[1], abs=2e-3)  # CARLA/Unreal mirror y
        assert site["z"] == pytest.approx(0.5)
        # right lane drives along +x (heading 0), left lane against it
        assert site["heading_deg"] == pytest.approx(0.0 if p["lane_id"] == -1 else 180.0, abs=1e-3)
        assert -180 < c["yaw"] <= 180 and -180 < c["pitch"] <= 180


# without aligned.xodr (road_source=none) the package is props only: test_carla_no_map.py


def test_names_that_would_mislead_carla_are_refused(tmp_path, fake_fbx, class_dir, xodr_file):
    from twinkit_export.plugin import CarlaPackageParams

    with pytest.raises(InputError, match="Terrain"):
        _package(tmp_path, fake_fbx, class_dir, xodr_file, CarlaPackageParams(map_name="TerrainPark"))


def test_not_opendrive(tmp_path, fake_fbx, class_dir):
    bad = tmp_path / "aligned.xodr"
    bad.write_text("<html/>")
    with pytest.raises(InputError, match="OpenDRIVE"):
        _package(tmp_path, fake_fbx, class_dir, bad)


@needs_bpy
@pytest.mark.shared
def test_real_opendrive_fabriksgatan(tmp_path, fake_fbx, class_dir):
    xodr = SHARED / "data" / "opendrive" / "fabriksgatan.xodr"
    if not xodr.exists():
        pytest.skip(f"{xodr} not available")
    out = _package(tmp_path, fake_fbx, class_dir, xodr)
    sp = json.loads(out["spawn_points.json"].read_text())
    assert sp["count"] > 20
    pkg = next((out["carla_import"] / "Import").rglob("*.xodr"))
    m = carla.Map("x", pkg.read_text())
    # every spawn point lies on a driving lane of the package's map (CARLA frame), outside junctions
    for p in sp["spawn_points"][:40]:
        c = p["carla"]
        # (by road, lane and s: a point at a road's end also touches the junction's lanes, and which of the
        # two get_waypoint returns there is a matter of rounding)
        w = m.get_waypoint_xodr(p["road_id"], p["lane_id"], p["s"])
        assert w is not None and not w.is_junction and w.lane_type == carla.LaneType.Driving
        assert w.transform.location.distance(carla.Location(c["x"], c["y"], c["z"] - 0.5)) < 0.05


@needs_bpy
@pytest.mark.shared
def test_an_opendrive_map_from_road_source_opendrive_is_packaged(tmp_path, fake_fbx, class_dir):
    """A UTM map (soderleden.xodr, zone 32) moved into a site in the neighbouring UTM zone 31 by road_source=opendrive (twinkit-roads,
    reached through the registry), packaged: CARLA parses it, spawn points lie on its lanes, and CARLA's
    geolocation of its lane centres is where pyproj puts the source map's (within the package's 0.5 m)."""
    from pyproj import Transformer
    from scipy.spatial import cKDTree
    from twinkit.testing import need_plugin, run_plugin

    src = SHARED / "data" / "opendrive" / "soderleden.xodr"
    if not src.exists():
        pytest.skip(f"{src} not available")
    need_plugin("road_source", "opendrive")
    # the map's own geoReference puts it at lat 0, lon 4.5: a site CRS must be one whose area of use holds that
    # place (SWEREF 99 TM, Sweden's, is refused there)
    site = {"name": "teststreet", "crs": "EPSG:32631", "base_point": {"lat": -0.0000685, "lon": 4.5164, "alt": 0.0}}
    moved = run_plugin("road_source", "opendrive", tmp_path / "src", {"in_xodr": src}, site=site)["opendrive.xodr"]
    out = _package(tmp_path, fake_fbx, class_dir, moved, site=site)
    assert json.loads(out["spawn_points.json"].read_text())["count"] > 10
    pkg = carla.Map("p", next((out["carla_import"] / "Import").rglob("*.xodr")).read_text())
    a = carla.Map("a", src.read_text())
    ref = np.array([(w.transform.location.x, -w.transform.location.y) for w in a.generate_waypoints(0.1)])
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True)
    n = 0
    for w in pkg.generate_waypoints(2.0):
        if w.transform.location.length() > 150:
            continue
        loc = w.transform.location
        g = pkg.transform_to_geolocation(carla.Location(loc.x, -loc.y, 0.0))  # north-positive y (twinkit.geo.carla)
        e, nn = to_utm.transform(g.longitude, g.latitude)
        d, _ = cKDTree(ref).query([e, nn])
        assert d < 0.5, (w.road_id, w.lane_id, w.s, d)
        n += 1
    assert n > 50
