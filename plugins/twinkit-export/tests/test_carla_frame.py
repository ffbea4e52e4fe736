"""The CARLA package in the CARLA frame: OpenDRIVE moved exactly (carla.Map lane centres), FBX baked,
geolocation by the carla wheel.

Rules (CARLA 0.9.16): GeoReferenceParser.cpp keeps +lat_0/+lon_0 only; GeoLocation.cpp's spherical
transverse Mercator assumes x = east, y = north at that point; CARLA maps OpenDRIVE (x, y) to (x, -y)
(carla.Map, checked below); Util/DockerUtils/fbx/src/FBX2OBJ.cpp (the navmesh tool) reads raw FBX
vertex values, so the frame is baked into the vertices.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from twinkit import InputError
from twinkit.testing import run_step

from conftest import HAS_BPY, SHARED, SITE, plugin

carla = pytest.importorskip("carla")

from twinkit_export.xodr_frame import XodrFrameError, transform_xodr  # noqa: E402

GEO = "+proj=tmerc +lat_0=60.16945 +lon_0=24.93365 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m +no_defs"


def curvy_xodr() -> str:
    """One road of every plan-view geometry kind, with elevation, superelevation, lane offset and widths that vary."""
    return """<?xml version="1.0" standalone="yes"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="curvy" north="60" south="-10" east="80" west="-5">
    <geoReference><![CDATA[+proj=tmerc +lat_0=0 +lon_0=27 +k=0.9996 +x_0=114653.7 +y_0=-6672076.5 +ellps=GRS80]]></geoReference>
  </header>
  <road name="curvy" length="75" id="1" junction="-1">
    <link/>
    <type s="0" type="town"/>
    <planView>
      <geometry s="0" x="1.5" y="-2.0" hdg="0.3" length="10"><line/></geometry>
      <geometry s="10" x="11.05" y="0.96" hdg="0.3" length="20"><arc curvature="0.02"/></geometry>
      <geometry s="30" x="28.9" y="9.6" hdg="0.7" length="15"><spiral curvStart="0.02" curvEnd="-0.01"/></geometry>
      <geometry s="45" x="39.7" y="19.8" hdg="0.78" length="10"><poly3 a="0" b="0" c="0.01" d="-0.0005"/></geometry>
      <geometry s="55" x="46.8" y="27.0" hdg="0.8" length="10">
        <paramPoly3 aU="0" bU="10" cU="0.5" dU="-0.3" aV="0" bV="0" cV="0.8" dV="-0.4" pRange="normalized"/></geometry>
      <geometry s="65" x="53.9" y="34.1" hdg="0.85" length="10">
        <paramPoly3 aU="0" bU="1" cU="0.001" dU="0" aV="0" bV="0" cV="0.01" dV="-0.0004" pRange="arcLength"/></geometry>
    </planView>
    <elevationProfile><elevation s="0" a="0.5" b="0.02" c="0.0004" d="-0.000005"/></elevationProfile>
    <lateralProfile><superelevation s="0" a="0.01" b="0.001" c="-0.00001" d="0"/></lateralProfile>
    <lanes>
      <laneOffset s="0" a="0.2" b="0.01" c="-0.0001" d="0"/>
      <laneSection s="0">
        <left><lane id="1" type="driving" level="false"><link/>
          <width sOffset="0" a="3.5" b="0.01" c="-0.0002" d="0.000001"/></lane></left>
        <center><lane id="0" type="none" level="false"><link/></lane></center>
        <right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.2" b="0" c="0" d="0"/>
          <roadMark sOffset="0" type="solid" weight="standard" color="standard" width="0.13"/></lane></right>
      </laneSection>
      <laneSection s="40">
        <left><lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.9" b="0" c="0" d="0"/></lane></left>
        <center><lane id="0" type="none" level="false"><link/></lane></center>
        <right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.2" b="0.02" c="0" d="0"/></lane>
        </right>
      </laneSection>
    </lanes>
    <objects/>
    <signals>
      <signal s="20" t="-5" id="7" name="light" dynamic="yes" orientation="+" zOffset="2.5" type="1000001"
              subtype="-1" country="OpenDRIVE" value="-1" height="1.0" width="0.4" hOffset="0.1"/>
    </signals>
  </road>
</OpenDRIVE>
"""


def _centres(m, ds: float = 2.0) -> dict:
    return {(w.road_id, w.section_id, w.lane_id, round(w.s, 3)): w for w in m.generate_waypoints(ds)}


def _check_moved(text: str, rot: float, scale: float, tol: float = 0.01) -> int:
    """carla.Map lane centres of the moved OpenDRIVE == the moved lane centres of the original (by road, lane, s)."""
    m0 = carla.Map("a", text)
    m1 = carla.Map("b", transform_xodr(text, rot, scale, GEO))
    c, s = math.cos(rot), math.sin(rot)
    n = 0
    for w in m0.generate_waypoints(2.0):
        loc = w.transform.location
        x, y, z = loc.x, -loc.y, loc.z  # CARLA mirrors OpenDRIVE y
        want = np.array([scale * (c * x - s * y), scale * (s * x + c * y), scale * z])
        w1 = m1.get_waypoint_xodr(w.road_id, w.lane_id, w.s * scale)
        assert w1 is not None, (w.road_id, w.lane_id, w.s)
        if w1.section_id != w.section_id:  # s on a lane-section border: rounding picks either section
            continue
        l1 = w1.transform.location
        got = np.array([l1.x, -l1.y, l1.z])
        assert np.linalg.norm(got - want) < tol, (w.road_id, w.lane_id, w.s, got, want)
        # heading: CARLA's yaw is -hdg (mirror), so the rotation subtracts from it
        dyaw = (w1.transform.rotation.yaw - (w.transform.rotation.yaw - math.degrees(rot)) + 180) % 360 - 180
        assert abs(dyaw) < 0.01
        assert w1.lane_width == pytest.approx(scale * w.lane_width, abs=tol)
        n += 1
    return n


@pytest.mark.parametrize("rot_deg,scale", [(1.7928, 1.0), (-8.3494, 0.99835), (25.0, 1.00233)])
def test_lane_centres_survive_the_similarity(rot_deg, scale):
    assert _check_moved(curvy_xodr(), math.radians(rot_deg), scale) > 60


def test_moved_xodr_header_and_georeference():
    out = transform_xodr(curvy_xodr(), math.radians(90.0), 1.0, GEO)
    m = carla.Map("g", out)
    g = m.transform_to_geolocation(carla.Location(0, 0, 0))
    assert (g.latitude, g.longitude) == pytest.approx((60.16945, 24.93365), abs=1e-12)
    assert "twinkit_site_geoReference" in out and "+lon_0=27" in out  # the site string is kept in userData
    # the box turns with the roads: (east 80, north 60) turned 90 deg -> west -60, north 80
    assert 'north="80.000"' in out and 'west="-60.000"' in out
    # signals keep their road position; with a scale, their lengths scale, angles do not
    s2 = transform_xodr(curvy_xodr(), 0.0, 2.0, GEO)
    assert 'zOffset="5.0"' in s2 and 'hOffset="0.1"' in s2 and 'width="0.8"' in s2


def test_unknown_length_elements_refuse_a_scale():
    bad = curvy_xodr().replace("<objects/>", '<objects><gadget s="3" length="2"/></objects>')
    transform_xodr(bad, 0.1, 1.0, GEO)  # a pure rotation leaves it as it is
    with pytest.raises(XodrFrameError, match="gadget"):
        transform_xodr(bad, 0.1, 1.01, GEO)
    with pytest.raises(XodrFrameError, match="offset"):
        transform_xodr(curvy_xodr().replace("</geoReference>", '</geoReference><offset x="5" y="0" z="0" hdg="0"/>'),
                       0.1, 1.0, GEO)


@pytest.mark.shared
@pytest.mark.parametrize("name", ["Town01.xodr", "Town10HD.xodr", "fabriksgatan.xodr", "soderleden.xodr"])
def test_real_opendrive_survives(name):
    p = SHARED / "data" / "opendrive" / name
    if not p.exists():
        pytest.skip(f"{p} not available")
    assert _check_moved(p.read_text(), math.radians(-8.3494), 0.99835) > 50


def _package(tmp_path, fbx, class_dir, xodr, site=SITE, **kw):
    from twinkit_export.plugin import CarlaPackageParams

    return run_step(plugin("exporter", "carla_package"), tmp_path / "run",
                    {"in_twin_fbx": fbx, "in_class_meshes_dir": class_dir, "in_aligned_xodr": xodr},
                    CarlaPackageParams(**kw), site=site)


def _site_xodr(tmp_path, site) -> Path:
    """The conftest street with the exact site-frame geoReference (what the alignment step writes)."""
    from conftest import straight_xodr
    from twinkit.geo import SiteFrame

    p = tmp_path / "aligned.xodr"
    p.write_text(straight_xodr().replace(GEO.replace(" +no_defs", ""), SiteFrame.from_site(site).proj_string()))
    return p


@pytest.mark.parametrize("site", [SITE, {"name": "mex", "crs": "EPSG:32614",
                                         "base_point": {"lat": 19.4326, "lon": -99.1332, "alt": 2240.0}}])
def test_package_geolocates_in_carla(tmp_path, class_dir, site):
    """The package's spawn points: CARLA's formula within 0.5 m of pyproj's truth of the same site point."""
    from pyproj import Geod

    from twinkit.geo import SiteFrame

    fake = tmp_path / "twin.fbx"
    fake.write_bytes(b"Kaydara FBX Binary  \x00")
    xodr = _site_xodr(tmp_path, site)
    if not HAS_BPY:
        pytest.skip("the package's FBX is re-exported through bpy (Blender as a module)")
    out = _package(tmp_path, fake, class_dir, xodr, site=site)  # the FBX is made from the class meshes
    root = out["carla_import"]
    pkg_xodr = next((root / "Import").rglob("*.xodr")).read_text()
    m = carla.Map("p", pkg_xodr)
    sf = SiteFrame.from_site(site)
    fr = json.loads((root / "carla_frame.json").read_text())
    assert fr["geo_reference"] in pkg_xodr and fr["site_geo_reference"] == sf.proj_string()
    sp = json.loads(out["spawn_points.json"].read_text())["spawn_points"]
    geod = Geod(ellps="WGS84")
    for p in sp:
        c, s = p["carla"], p["site"]
        truth = sf.local_to_lonlat([[s["x"], s["y"]]])[0]
        g = m.transform_to_geolocation(carla.Location(c["x"], -c["y"], 0.0))  # north-positive y
        assert abs(geod.inv(truth[0], truth[1], g.longitude, g.latitude)[2]) < 0.5
        w = p["wgs84"]
        assert abs(geod.inv(truth[0], truth[1], w["lon"], w["lat"])[2]) < 0.01
    readme = next((root / "Import").rglob("README.md")).read_text()
    assert "CARLA frame" in readme and fr["geo_reference"] in readme


def test_site_frame_mode_keeps_the_old_package(tmp_path, class_dir):
    fake = tmp_path / "twin.fbx"
    fake.write_bytes(b"Kaydara FBX Binary  \x00")
    xodr = _site_xodr(tmp_path, SITE)
    out = _package(tmp_path, fake, class_dir, xodr, frame="site")
    pkg = out["carla_import"] / "Import" / "TeststreetTwin"
    assert (pkg / "Teststreet.xodr").read_text() == xodr.read_text()
    with pytest.raises(InputError, match="frame"):
        _package(tmp_path / "b", fake, class_dir, xodr, frame="north")


@pytest.mark.skipif(not HAS_BPY, reason="bpy (Blender as a module) is not installed")
def test_package_fbx_is_baked_in_the_carla_frame(tmp_path, class_dir, fbx_out):
    pytest.importorskip("ufbx")
    from twinkit_export.split import load_class_set

    out = _package(tmp_path, fbx_out, class_dir, _site_xodr(tmp_path, SITE))
    root = out["carla_import"]
    pkg = root / "Import" / "TeststreetTwin"
    m = np.array(json.loads((root / "carla_frame.json").read_text())["matrix_site_to_package"])
    dump = tmp_path / "fbx.json"
    for _attempt in range(3):  # ufbx 0.0.5's Python bindings crash now and then
        proc = subprocess.run([os.sys.executable, str(Path(__file__).with_name("fbx_dump.py")),
                               str(pkg / "Teststreet.fbx"), str(dump)], timeout=300, capture_output=True)
        if proc.returncode == 0:
            break
    assert proc.returncode == 0, proc.stderr[-2000:]
    d = json.loads(dump.read_text())
    assert ["DiffuseColor", "twin.png"] in d["materials"]["M_twinkit"] and (pkg / "twin.png").exists()
    matched = 0
    for cm in load_class_set(class_dir).meshes:
        n = d["nodes"].get(cm.name)  # the map FBX holds road, sidewalk and terrain; the rest are props
        if n is None:
            continue
        matched += 1
        assert n["scale"] == [1.0, 1.0, 1.0]  # baked: no node transform for the navmesh tool to miss
        np.testing.assert_allclose(np.array(n["positions"]), cm.mesh.vertices @ m.T, atol=1e-4)
    assert matched >= 1
    assert not list((tmp_path / "run").rglob("carla_frame_meshes"))  # the scratch FBX is not left in the result
