"""Parking lanes (twinkit_roads.parking): inserted where OSM or the scanned cars ask, so the sidewalk lane
moves off the parking strip; lane ids and every reference to them follow; CARLA reads the result."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

pytest.importorskip("carla")

from twinkit.cityscapes import CAR, ROAD, SIDEWALK, WIDE_VEHICLES  # noqa: E402
from twinkit.street.lanes import LaneMap  # noqa: E402
from twinkit_roads import parking as P  # noqa: E402

LANE_M, STRIP_M = 3.25, 2.2


def _lanes(right: str) -> str:
    return f"""<lanes><laneSection s="0"><center><lane id="0" type="none" level="false"><link/></lane></center>
      <right>{right}</right></laneSection></lanes>"""


def _lane(lid: int, typ: str, w: float, pred: int | None = None, succ: int | None = None) -> str:
    link = "".join(f'<{k} id="{v}"/>' for k, v in (("predecessor", pred), ("successor", succ)) if v is not None)
    return f'<lane id="{lid}" type="{typ}" level="false"><link>{link}</link>' \
           f'<width sOffset="0" a="{w}" b="0" c="0" d="0"/></lane>'


def netconvert_like() -> str:
    """What netconvert writes for one direction of a street with a parking strip: two driving lanes and its
    2 m sidewalk at their edge (on the strip), road 1 from x = -40 to 0 (way 101 reversed), then a junction
    connecting road 2 to road 3 (x 10 .. 40), the sidewalks linked through it. y = 0 is the centre line."""
    dr = _lane(-1, "driving", LANE_M) + _lane(-2, "driving", LANE_M)
    road = """<road name="r" length="{L}" id="{id}" junction="{j}"><link>{link}</link>
      <planView><geometry s="0" x="{x}" y="0" hdg="0" length="{L}"><line/></geometry></planView>
      <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile><lateralProfile/>
      {lanes}<signals><signal id="s1" s="1" t="-8" zOffset="2" orientation="+" dynamic="no" type="-1" subtype="-1">
      <validity fromLane="-3" toLane="-1"/></signal></signals>{ud}</road>"""
    r1 = road.format(L=40, id=1, j=-1, x=-40, link='<successor elementType="junction" elementId="9"/>',
                     lanes=_lanes(dr + _lane(-3, "sidewalk", 2.0)),
                     ud='<userData code="sumoId" value="-101#0"/>')
    r2 = road.format(L=10, id=2, j=9, x=0, link='<predecessor elementType="road" elementId="1" contactPoint="end"/>'
                     '<successor elementType="road" elementId="3" contactPoint="start"/>',
                     lanes=_lanes(_lane(-1, "driving", LANE_M, -1, -1) + _lane(-2, "driving", LANE_M, -2, -2)
                                  + _lane(-3, "sidewalk", 2.0, -3, -3)), ud="")
    r3 = road.format(L=30, id=3, j=-1, x=10, link='<predecessor elementType="junction" elementId="9"/>',
                     lanes=_lanes(dr + _lane(-3, "sidewalk", 2.0)), ud='<userData code="sumoId" value="-101#1"/>')
    junction = """<junction id="9" name="j"><connection id="0" incomingRoad="1" connectingRoad="2" contactPoint="start">
      <laneLink from="-1" to="-1"/><laneLink from="-2" to="-2"/><laneLink from="-3" to="-3"/></connection></junction>"""
    return f"""<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4" name="t" version="1"/>
      {r1}{r2}{r3}{junction}</OpenDRIVE>"""


def street_mesh(cars_x=(-30.0, 20.0)):
    """A height field under road 1 and 3's right side: carriageway z = 0 out to the kerb at
    y = -(2 lanes + the strip), the pavement 0.12 m higher beyond; cars (1.4 m boxes) on the strip."""
    xs = np.arange(-45, 45.01, 0.1)
    ys = np.arange(-14, 0.01, 0.1)
    gx, gy = np.meshgrid(xs, ys)
    kerb = -(2 * LANE_M + STRIP_M)
    gz = np.where(gy < kerb, 0.12, 0.0)
    lab = np.where(gy < kerb, SIDEWALK, ROAD).astype(np.uint8)
    for cx in cars_x:
        car = (np.abs(gx - cx) < 2.2) & (np.abs(gy - (kerb + 1.1)) < 0.85)
        gz = np.where(car, 1.4, gz)
        lab = np.where(car, CAR, lab).astype(np.uint8)
    ny, nx = gx.shape
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]), faces, lab.ravel()


def _strip_point(x: float) -> list:
    return [x, -(2 * LANE_M + STRIP_M / 2), 0.0]  # the middle of the parking strip (a parked car's centre)


def test_netconvert_sidewalk_lies_on_the_strip_today():
    hits = LaneMap(netconvert_like()).lane_at([_strip_point(-30), _strip_point(20)], "Sidewalk")
    assert all(h is not None for h in hits)  # Map::GetWaypoint finds a sidewalk under the parked cars


def test_parking_lane_moves_the_sidewalk_onto_the_pavement():
    v, f, lab = street_mesh()
    res = P.add_parking(netconvert_like(), v, f, lab, osm_sides={}, vehicle_ids=WIDE_VEHICLES)
    sides = {(s.road, s.side): s for s in res.sides}
    assert sides[(1, "right")].vehicles == 1 and sides[(3, "right")].vehicles == 1
    assert sides[(1, "right")].kerb_m == pytest.approx(STRIP_M, abs=0.1)  # the kerb's foot, seen past the cars
    assert sides[(1, "right")].width_m == pytest.approx(STRIP_M, abs=0.1)
    lm = LaneMap(res.text)
    pts = [_strip_point(-30), _strip_point(20)]
    assert lm.lane_at(pts, "Sidewalk") == [None, None]
    assert [h[1] for h in lm.lane_at(pts, "Parking")] == ["Parking", "Parking"]
    pavement = [[-30, -(2 * LANE_M + STRIP_M + 1.0), 0.0], [20, -(2 * LANE_M + STRIP_M + 1.0), 0.0]]
    assert [h[0][2] for h in lm.lane_at(pavement, "Sidewalk")] == [-4, -4]
    # CARLA's waypoints and spawn entries keep to the driving lanes (Map.cpp ForEachDrivableLaneImpl)
    assert set(lm.waypoints(2.0).type.tolist()) == {"Driving"}


def test_renumbering_follows_every_reference():
    text, remap = P.insert_parking_lanes(netconvert_like(), {(1, "right"): 2.2, (3, "right"): 2.2})
    assert remap == {(1, -3): -4, (3, -3): -4}
    root = ET.fromstring(text)
    r2 = next(r for r in root.iter("road") if r.get("id") == "2")  # the junction road keeps its lanes ...
    sw = next(ln for ln in r2.iter("lane") if ln.get("type") == "sidewalk")
    assert sw.get("id") == "-3"
    assert sw.find("link/predecessor").get("id") == "-4" and sw.find("link/successor").get("id") == "-4"
    links = {(ll.get("from"), ll.get("to")) for ll in root.iter("laneLink")}
    assert ("-4", "-3") in links and ("-3", "-3") not in links
    r1 = next(r for r in root.iter("road") if r.get("id") == "1")
    assert r1.find(".//validity").get("fromLane") == "-4"
    assert [ln.get("id") for ln in r1.find(".//right").findall("lane")] == ["-1", "-2", "-3", "-4"]
    LaneMap(text)  # CARLA still reads it


def test_osm_tags_ask_for_parking(tmp_path):
    osm = tmp_path / "w.osm"
    osm.write_text("""<?xml version="1.0"?><osm version="0.6">
      <node id="1" lat="60.0" lon="24.0"/><node id="2" lat="60.001" lon="24.0"/>
      <way id="101"><nd ref="1"/><nd ref="2"/><tag k="highway" v="secondary"/><tag k="parking:both" v="lane"/></way>
      <way id="102"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/><tag k="parking:lane:right" v="parallel"/>
        <tag k="parking:left" v="no"/></way></osm>""")
    got = P.osm_parking(osm)
    assert got == {101: {"left": "lane", "right": "lane"}, 102: {"right": "parallel"}}
    v, f, lab = street_mesh(cars_x=())  # no car at all: the tag alone asks for the lane
    res = P.add_parking(netconvert_like(), v, f, lab, osm_sides=got, vehicle_ids=WIDE_VEHICLES)
    assert {(s.road, s.osm) for s in res.sides if s.width_m > 0} == {(1, "lane"), (3, "lane")}
    none = P.add_parking(netconvert_like(), v, f, lab, osm_sides={}, vehicle_ids=WIDE_VEHICLES)
    assert none.inserted == 0 and none.text == netconvert_like()


def test_step_writes_xodr_and_report(tmp_path):
    import json

    from twinkit.mesh import write_colored_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    v, f, lab = street_mesh()
    write_colored_ply(tmp_path / "textured_mesh.ply", v, f, np.full((len(v), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", lab)
    (tmp_path / "aligned.xodr").write_text(netconvert_like())
    out = run_step(plugin_from_module(roads, "step", "parking_lanes"), tmp_path / "run",
                   {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
                    "in_labels_npy": tmp_path / "labels.npy"})
    assert set(out) == {"aligned.xodr", "parking.json"}
    doc = json.loads(out["parking.json"].read_text())
    assert doc["parking_lanes"] == 2 and {s["road"] for s in doc["sides"] if s["width_m"]} == {1, 3}
    assert LaneMap(out["aligned.xodr"].read_text()).lane_at([_strip_point(-30)], "Sidewalk") == [None]


def test_no_parking_lane_where_the_kerb_is_at_the_driving_edge():
    """OSM asks for parking, but the scan's kerb stands at the driving lane's edge: no room for a lane."""
    xs = np.arange(-45, 45.01, 0.1)
    ys = np.arange(-14, 0.01, 0.1)
    gx, gy = np.meshgrid(xs, ys)
    kerb = -2 * LANE_M
    gz = np.where(gy < kerb, 0.12, 0.0)
    lab = np.where(gy < kerb, SIDEWALK, ROAD).astype(np.uint8).ravel()
    ny, nx = gx.shape
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    f = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    v = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    res = P.add_parking(netconvert_like(), v, f, lab, osm_sides={101: {"left": "lane", "right": "lane"}},
                        vehicle_ids=WIDE_VEHICLES)
    assert res.inserted == 0 and all("no room" in s.why for s in res.sides), [s.why for s in res.sides]
