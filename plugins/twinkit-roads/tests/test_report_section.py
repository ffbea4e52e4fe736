"""twinkit-roads' report sections: the OpenDRIVE sampling behind the road network drawing."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit_roads.report import offset_polyline, read_opendrive

XODR = """<?xml version="1.0" standalone="yes"?>
<OpenDRIVE><header revMajor="1" revMinor="6" name="test"/>
<road id="1" length="60" junction="-1"><planView>
 <geometry s="0" x="-30" y="0" hdg="0" length="60"><line/></geometry></planView>
 <lanes><laneSection s="0">
  <left><lane id="2" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
        <lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none"/></center>
  <right><lane id="-1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-2" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
 </laneSection></lanes></road>
<road id="2" length="21" junction="-1"><planView>
 <geometry s="0" x="0" y="9" hdg="1.5707963" length="6"><line/></geometry>
 <geometry s="6" x="0" y="15" hdg="1.5707963" length="15"><arc curvature="0.03"/></geometry></planView>
 <lanes><laneSection s="0">
  <left><lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <right><lane id="-1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
 </laneSection></lanes></road>
</OpenDRIVE>
"""


def test_opendrive_geometry_sampling(tmp_path):
    p = tmp_path / "r.xodr"
    p.write_text(XODR)
    roads = read_opendrive(p)
    assert [r["id"] for r in roads] == ["1", "2"]
    assert roads[0]["width"] == pytest.approx(13.0)
    x, y = roads[0]["points"][-1]
    assert (x, y) == pytest.approx((30, 0), abs=1e-6)
    # arc of curvature 0.03 over 15 m from (0, 15) heading north: ends at x = -(1 - cos(0.45)) / 0.03
    x, y = roads[1]["points"][-1]
    assert x == pytest.approx(-(1 - np.cos(0.45)) / 0.03, abs=0.01)
    assert y == pytest.approx(15 + np.sin(0.45) / 0.03, abs=0.01)


def test_lane_bands_follow_each_side_of_the_reference_line():
    east = [(0.0, 0.0), (10.0, 0.0)]
    assert offset_polyline(east, 2.0) == [(0.0, 2.0), (10.0, 2.0)]  # left of eastward = north
    north = [(0.0, 0.0), (0.0, 10.0)]
    assert offset_polyline(north, 1.5) == [(-1.5, 0.0), (-1.5, 10.0)]


def test_the_sections_are_registered():
    from twinkit.plugins import load_registry

    import twinkit_roads.plugin as plugin

    reg = load_registry(extra=[("roads", plugin)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [
        ("roads", "Road network", 500.0), ("alignment", "Alignment", 900.0), ("signals", "Signals", 910.0),
        ("road_evidence", "Road network as evidence for the labels", 920.0)]
