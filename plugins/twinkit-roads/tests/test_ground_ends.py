"""The map's ends cut back onto the scanned ground (ground_ends.py, xodr_cut.py), on the demo street."""
import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from twinkit.testing import plugin_from_module, run_step

import twinkit_roads.plugin as roads
from twinkit_roads.ground_ends import map_ends, trim_to_ground
from twinkit_roads.xodr_cut import cut_road

from conftest import DEMO_SITE

carla = pytest.importorskip("carla")


def _apply(demo_site, xodr, tmp_path, name, **params):
    """apply_alignment with the demo generator's exact inverse (no fit: the test is about the ends)."""
    site = json.loads(demo_site["site.json"].read_text())["osm_transform"]
    th = -math.radians(site["rotation_deg"])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    t = -R @ np.array([site["dx_m"], site["dy_m"]])
    f = tmp_path / f"{name}.json"
    f.write_text(json.dumps({"yaw_deg": math.degrees(th), "tx_m": t[0], "ty_m": t[1]}))
    return run_step(plugin_from_module(roads, "step", "apply_alignment"), tmp_path / name,
                    {"in_roads_xodr": xodr, "in_alignment_json": f, "in_textured_mesh_ply": demo_site["gt_mesh.ply"]},
                    roads.ApplyParams(qa_px_per_m=4, **params), site=DEMO_SITE)


@pytest.fixture(scope="module")
def demo_maps(demo_site, tmp_path_factory):
    """(aligned map as before this change, the same map trimmed to the ground, the trim's report, mesh)."""
    from twinkit.mesh import read_ply

    tmp = tmp_path_factory.mktemp("ground_ends")
    conv = run_step(plugin_from_module(roads, "step", "osm_to_opendrive"), tmp / "conv",
                    {"in_osm_osm": demo_site["roads.osm"]}, roads.ConvertParams(), site=DEMO_SITE)
    before = _apply(demo_site, conv["roads.xodr"], tmp, "before", trim_to_ground=False)
    after = _apply(demo_site, conv["roads.xodr"], tmp, "after")
    mesh = read_ply(demo_site["gt_mesh.ply"])
    text = before["aligned.xodr"].read_text()
    again, report = trim_to_ground(text, mesh.vertices, mesh.faces)
    assert again == after["aligned.xodr"].read_text()  # what the step wrote
    return text, again, report, mesh


def _off(text, mesh):
    from twinkit.street.lane_ground import lanes_over_ground
    from twinkit.street.lanes import LaneMap

    return lanes_over_ground(LaneMap(text), mesh.vertices, mesh.faces, step_m=1.0)


def _graph(text):
    """Roads, junction connections, lanes per road and CARLA's topology (lane to lane, without a lane's
    segment to itself, which CARLA lists for some lanes that end nowhere)."""
    from twinkit.street.lanes import LaneMap

    root = ET.fromstring(text)
    lanes = {r.get("id"): sorted((ln.get("id"), ln.get("type")) for ln in r.iter("lane")) for r in root.findall("road")}
    conns = sorted((j.get("id"), c.get("incomingRoad"), c.get("connectingRoad"))
                   for j in root.findall("junction") for c in j.findall("connection"))
    topo = {(a[0], a[2], b[0], b[2]) for a, b in LaneMap(text).topology() if (a[0], a[2]) != (b[0], b[2])}
    return lanes, conns, topo


def test_demo_map_ends_are_cut_back_onto_the_ground(demo_maps):
    """Today netconvert's turnarounds at the demo's three dead ends run past the mesh; after the trim no driving
    waypoint leaves it, and the network is the same graph."""
    before, after, report, mesh = demo_maps
    ends = map_ends(ET.fromstring(before))
    assert sum(1 for e in ends if e.turnarounds) == 3  # west, east and south dead ends
    off0, off1 = _off(before, mesh), _off(after, mesh)
    assert off0.off.sum() >= 10 and any(r in {int(t) for e in ends for t in e.turnarounds}
                                         for r in off0.road[off0.off])
    assert off1.off.sum() == 0, off1.summary()["off_ground_at"]
    assert report["cut_ends"] >= 3 and 0 < report["max_trim_m"] < 3.0
    assert report["driving_off_ground_after"] == 0 < report["driving_off_ground_before"]
    assert _graph(after) == _graph(before)
    # the traffic manager's end: the dead end still turns its vehicles round (LocalizationStage.cpp removes a
    # vehicle whose lane has no next waypoint), now on the ground
    m = carla.Map("t", after)
    for e in (e for e in ends if e.turnarounds):
        rid = next(r for r, side in e.ends if side == "end")  # the road into the dead end (its lane -1)
        road = next(r for r in ET.fromstring(after).findall("road") if r.get("id") == rid)
        nxt = m.get_waypoint_xodr(int(rid), -1, float(road.get("length")) - 0.5).next(2.0)
        assert nxt and {w.road_id for w in nxt} <= {int(t) for t in e.turnarounds}


def test_trim_is_a_no_op_on_a_map_inside_its_ground(demo_maps):
    before, _, _, mesh = demo_maps
    v = mesh.vertices.copy()
    v[:, :2] *= 2.0  # the same street, its ground reaching twice as far
    out, rep = trim_to_ground(before, v, mesh.faces)
    assert out == before and rep["cut_ends"] == 0 and rep["driving_off_ground_before"] == 0


ROAD = """<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE><header revMajor="1" revMinor="4" name="t"/>
<road name="r" length="{L}" id="7" junction="-1"><link/>
 <planView>
  <geometry s="0" x="1" y="2" hdg="0.3" length="10"><line/></geometry>
  <geometry s="10" x="{x1}" y="{y1}" hdg="0.3" length="10"><arc curvature="0.05"/></geometry>
  <geometry s="20" x="{x2}" y="{y2}" hdg="0.8" length="{L3}">
   <paramPoly3 aU="0" bU="10" cU="0" dU="0" aV="0" bV="0" cV="2" dV="-1" pRange="normalized"/></geometry>
 </planView>
 <elevationProfile><elevation s="0" a="1" b="0.02" c="0" d="0"/><elevation s="15" a="1.3" b="0.02" c="0.001" d="0"/>
 </elevationProfile>
 <lanes><laneSection s="0">
  <center><lane id="0" type="none"><link/></lane></center>
  <right><lane id="-1" type="driving"><link/><width sOffset="0" a="3" b="0.02" c="0" d="0"/></lane></right>
 </laneSection><laneSection s="12">
  <center><lane id="0" type="none"><link/></lane></center>
  <right><lane id="-1" type="driving"><link/><width sOffset="0" a="3.2" b="0" c="0.001" d="0"/>
   <width sOffset="8" a="3.264" b="0.016" c="0" d="0"/></lane></right>
 </laneSection></lanes>
 <signals><signal s="2" t="-3" id="s1" type="206" dynamic="no" orientation="+"/>
  <signal s="25" t="-3" id="s2" type="205" dynamic="no" orientation="+"/></signals>
</road></OpenDRIVE>
"""


def _road_text():
    x1, y1 = 1 + 10 * math.cos(0.3), 2 + 10 * math.sin(0.3)
    k, h = 0.05, 0.3
    x2, y2 = x1 + (math.sin(h + k * 10) - math.sin(h)) / k, y1 - (math.cos(h + k * 10) - math.cos(h)) / k
    p = np.linspace(0, 1, 20001)  # the paramPoly3's arc length
    L3 = float(np.trapezoid(np.hypot(np.full_like(p, 10.0), 2 * 2 * p - 3 * p * p), p))
    return ROAD.format(L=20 + L3, x1=x1, y1=y1, x2=x2, y2=y2, L3=L3), 20 + L3


@pytest.mark.parametrize("s0,s1", [(3.0, 26.0), (0.0, 17.0), (14.5, 29.0)])
def test_cut_road_keeps_every_kept_point_where_it_was(s0, s1):
    """A cut inside a line, an arc and a paramPoly3 and across lane sections: CARLA puts the lane centre, its
    width and height at new s where they were at s + s0; signals on the cut part go to the nearest end."""
    text, length = _road_text()
    s1 = min(s1, length)
    root = ET.fromstring(text)
    notes = cut_road(root.find("road"), s0, s1)
    cut = ET.tostring(root, encoding="unicode")
    a, b = carla.Map("a", text), carla.Map("b", cut)
    assert float(root.find("road").get("length")) == pytest.approx(s1 - s0)
    for s in np.linspace(0.05, s1 - s0 - 0.05, 25):
        wa, wb = a.get_waypoint_xodr(7, -1, float(s + s0)), b.get_waypoint_xodr(7, -1, float(s))
        la, lb = wa.transform.location, wb.transform.location
        assert math.dist((la.x, la.y, la.z), (lb.x, lb.y, lb.z)) < 0.02, (s, la, lb)
        assert wb.lane_width == pytest.approx(wa.lane_width, abs=0.005)
    sig = {s.get("id"): float(s.get("s")) for s in root.iter("signal")}
    for sid, s_old in (("s1", 2.0), ("s2", 25.0)):
        assert sig[sid] == pytest.approx(min(max(s_old - s0, 0.0), s1 - s0))
    assert len(notes) == sum(1 for s_old in (2.0, 25.0) if not s0 <= s_old <= s1)
