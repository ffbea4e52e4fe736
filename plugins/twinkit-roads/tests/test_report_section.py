"""twinkit-roads' report sections: the lanes behind the road network drawing."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit_roads.report import network_items

XODR = """<?xml version="1.0" standalone="yes"?>
<OpenDRIVE><header revMajor="1" revMinor="6" name="test"/>
<road id="1" length="60" junction="-1"><planView>
 <geometry s="0" x="-30" y="0" hdg="0" length="60"><line/></geometry></planView>
 <lanes><laneSection s="0">
  <left><lane id="2" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
        <lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none"/></center>
  <right><lane id="-1" type="driving"><width sOffset="0" a="3.25" b="0.025" c="0" d="0"/></lane>
         <lane id="-2" type="sidewalk"><width sOffset="0" a="2" b="0" c="0" d="0"/></lane></right>
 </laneSection>
 <laneSection s="30">
  <left><lane id="1" type="driving"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none"/></center>
  <right><lane id="-1" type="driving"><width sOffset="0" a="4" b="0" c="0" d="0"/></lane></right>
 </laneSection></lanes></road>
</OpenDRIVE>
"""


def test_the_network_is_drawn_with_the_lane_widths_and_sections_carla_reads(tmp_path):
    """Paved bands follow each lane's width polynomial and every lane section; the sidewalk is no band."""
    p = tmp_path / "r.xodr"
    p.write_text(XODR)
    items = network_items(p)
    bands = [np.array(pts) for pts, cls in items if cls == "band"]
    lines = [np.array(pts) for pts, cls in items if cls == "xodr"]
    assert len(bands) == 5 and len(lines) == 5  # 3 driving lanes in the first section, 2 in the second
    lane_m1 = [b for b in bands if b[:, 1].max() <= 1e-3]  # right of the reference line (y = 0): lane -1
    assert len(lane_m1) == 2
    first, second = sorted(lane_m1, key=lambda b: b[:, 0].min())
    # a ring: the left border out, the right border back; its width where it starts and ends
    k = len(first) // 2
    assert np.hypot(*(first[0] - first[-1])) == pytest.approx(3.25, abs=1e-3)
    assert np.hypot(*(first[k - 1] - first[k])) == pytest.approx(3.25 + 0.025 * 29, abs=0.03)
    assert second[:, 1].min() == pytest.approx(-4.0, abs=1e-3)


def test_the_sections_are_registered():
    from twinkit.plugins import load_registry

    import twinkit_roads.plugin as plugin

    reg = load_registry(extra=[("roads", plugin)], entry_points=False)
    assert [(s.name, s.title, s.order) for s in reg.report_sections] == [
        ("roads", "Road network", 500.0), ("alignment", "Alignment", 900.0), ("signals", "Signals", 910.0),
        ("crosswalks", "Crosswalks", 915.0), ("road_evidence", "Road network as evidence for the labels", 920.0)]
