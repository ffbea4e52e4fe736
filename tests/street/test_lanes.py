"""twinkit.street.lanes: the lanes of an OpenDRIVE map in the site frame, read with carla.Map offline."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("carla")

from twinkit.errors import InputError  # noqa: E402
from twinkit.street.lanes import (LaneMap, OpenDriveError, from_carla, to_carla, yaw_from_carla,  # noqa: E402
                                  yaw_to_carla)

SHARED = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "opendrive"


def _lane(lid: int, kind: str, a: float, b: float = 0.0) -> str:
    return f'<lane id="{lid}" type="{kind}" level="false"><width sOffset="0" a="{a}" b="{b}" c="0" d="0"/></lane>'


def road_xodr(x0: float = 5.0, y0: float = 2.0, hdg: float = 0.0) -> str:
    """One straight road of 100 m from (x0, y0) along ``hdg``; two lane sections (s = 0 and 50). Right of the
    reference line: a driving lane whose width grows (3 + 0.02 s) in the first section and is 4 m in the
    second, then a 2 m sidewalk; left: a 3 m driving lane. A traffic light 10 m along, 8 m to the right."""
    sec0 = (f'<laneSection s="0"><left>{_lane(1, "driving", 3.0)}</left><center><lane id="0" type="none" '
            f'level="false"/></center><right>{_lane(-1, "driving", 3.0, 0.02)}{_lane(-2, "sidewalk", 2.0)}</right>'
            '</laneSection>')
    sec1 = (f'<laneSection s="50"><left>{_lane(1, "driving", 3.0)}</left><center><lane id="0" type="none" '
            f'level="false"/></center><right>{_lane(-1, "driving", 4.0)}{_lane(-2, "sidewalk", 2.0)}</right>'
            '</laneSection>')
    return ('<?xml version="1.0" standalone="yes"?>\n<OpenDRIVE><header revMajor="1" revMinor="4" name="t"/>'
            f'<road name="r" length="100" id="1" junction="-1"><link/><planView><geometry s="0" x="{x0}" y="{y0}" '
            f'hdg="{hdg}" length="100"><line/></geometry></planView><elevationProfile><elevation s="0" a="1.5" b="0" '
            f'c="0" d="0"/></elevationProfile><lanes>{sec0}{sec1}</lanes>'
            '<signals><signal s="10" t="-8" id="7" name="tl" dynamic="yes" orientation="-" zOffset="2" '
            'country="OpenDRIVE" type="1000001" subtype="-1" value="-1" height="1" width="0.5"/></signals>'
            '</road></OpenDRIVE>\n')


def test_the_y_flip_round_trips_and_negates_headings():
    p = np.array([[1.0, 2.0, 3.0], [-4.5, -0.25, 0.0]])
    assert np.array_equal(from_carla(to_carla(p)), p)
    assert np.array_equal(to_carla(p)[:, 1], -p[:, 1]) and np.array_equal(to_carla(p)[:, [0, 2]], p[:, [0, 2]])
    assert yaw_to_carla(yaw_from_carla(33.0)) == 33.0 and yaw_from_carla(90.0) == -90.0
    assert np.array_equal(yaw_from_carla(np.array([10.0, -170.0])), [-10.0, 170.0])


def test_lanes_lie_in_the_site_frame_right_lanes_to_the_right():
    """A road heading east: its right lanes (negative ids) lie south (y below the reference line), as in the
    OpenDRIVE file; heights from the elevation profile; a right lane's heading is its centre line's direction."""
    wp = LaneMap(road_xodr()).waypoints(1.0)
    right = wp.take(wp.lane == -1)
    assert len(right) > 50
    first = right.take(np.argsort(right.s)[:1])
    # 3 m wide at s = 0: its centre 1.5 m right of the reference line (y0 = 2)
    assert first.xyz[0] == pytest.approx([5.0, 2.0 - 1.5, 1.5], abs=1e-4)
    # the lane's centre line runs along the road and moves south by half the width's growth (0.01 / m)
    assert first.heading_deg[0] == pytest.approx(math.degrees(math.atan2(-0.01, 1.0)), abs=1e-4)
    assert np.allclose(right.normal, [0.0, -1.0], atol=0.011)  # the lane's right: south (turned by the widening)
    assert np.allclose(np.hypot(*right.normal.T), 1.0)
    left = wp.take(wp.lane == 1)  # driven westwards: its right is north
    assert np.all(left.xyz[:, 1] > 2.0) and np.allclose(left.normal, [0.0, 1.0], atol=1e-5)
    assert np.allclose(np.abs(left.heading_deg), 180.0, atol=1e-4)


def test_a_turned_road_turns_its_lanes_the_same_way():
    hdg = 0.7
    wp = LaneMap(road_xodr(0.0, 0.0, hdg)).waypoints(2.0)
    r = wp.take(wp.lane == -1)
    t = np.array([math.cos(hdg), math.sin(hdg)])
    n = np.array([t[1], -t[0]])  # right of the direction, site frame
    w = r.width
    # centre = reference point + n * (half the width), the reference point s along the direction
    expect = r.s[:, None] * t + n * (w / 2)[:, None]
    assert np.allclose(r.xyz[:, :2], expect, atol=1e-3)
    sec1 = r.s > 50.5  # the second section: constant width, the lane parallel to the road
    assert sec1.sum() > 10 and np.allclose(r.heading_deg[sec1], math.degrees(hdg), atol=1e-3)


def test_widths_follow_the_width_polynomial_and_the_lane_sections():
    wp = LaneMap(road_xodr()).waypoints(1.0)
    r = wp.take(wp.lane == -1)
    sec0, sec1 = r.take(r.s < 49.5), r.take(r.s > 50.5)
    assert len(sec0) > 40 and len(sec1) > 40
    assert np.allclose(sec0.width, 3.0 + 0.02 * sec0.s, atol=1e-4)  # a + b * ds
    assert np.allclose(sec1.width, 4.0, atol=1e-5)
    assert set(sec0.section.tolist()) != set(sec1.section.tolist())
    left, right = r.borders()
    assert np.allclose(np.hypot(*(right - left).T), r.width, atol=1e-5)
    # the left border of the right lane is the reference line (y0 = 2), its right border further south
    assert np.allclose(left[:, 1], 2.0, atol=1e-3) and np.allclose(right[:, 1], 2.0 - r.width, atol=1e-3)


def test_lanes_reach_the_sidewalks_and_group_per_lane():
    lm = LaneMap(road_xodr())
    assert set(lm.waypoints(1.0).type.tolist()) == {"Driving"}
    every = lm.lanes(1.0)
    side = every.take(every.is_type("sidewalk"))
    assert len(side) > 50
    # the sidewalk lies beyond the driving lane: its centre 1 m past the driving lane's right border
    assert np.allclose(side.xyz[:, 1], 2.0 - (3.0 + 0.02 * np.minimum(side.s, 50.0)) * (side.s < 50)
                       - 4.0 * (side.s >= 50) - 1.0, atol=2e-3)
    per = every.per_lane()
    keys = [ln.key for ln in per]
    assert len(keys) == len(set(keys)) == 6  # 3 lanes x 2 sections
    assert all(np.all(np.diff(ln.s) > 0) for ln in per)
    assert len(every.unique(3)) == len(every)


def test_landmarks_are_where_carla_puts_them_in_the_site_frame():
    (lm,) = LaneMap(road_xodr()).landmarks()
    assert (lm.id, lm.type, lm.road) == ("7", "1000001", 1)
    assert lm.xyz[1] == pytest.approx(2.0 - 8.0, abs=1e-3)  # 8 m right of a road heading east: south
    assert abs(lm.xyz[0] - (5.0 + 10.0)) <= 0.25 + 1e-3  # CARLA moves it along the road by half its width


def test_a_malformed_file_names_the_file_and_the_fix(tmp_path):
    bad = tmp_path / "broken.xodr"
    bad.write_text(road_xodr()[:300])
    with pytest.raises(OpenDriveError, match=r"broken\.xodr: carla\.Map cannot read it.*well-formed XML"):
        LaneMap.from_file(bad)
    with pytest.raises(InputError, match=r"roads\.json: not an OpenDRIVE file"):
        LaneMap('{"roads": []}', source="roads.json")
    # parses, but CARLA cannot walk a lane section without its centre lane
    no_centre = road_xodr().replace('<center><lane id="0" type="none" level="false"/></center>', "")
    with pytest.raises(OpenDriveError, match=r"m\.xodr: carla\.Map cannot walk its lanes.*<center>") as e:
        LaneMap(no_centre, source="m.xodr").lanes(1.0)
    assert e.value.source == "m.xodr" and e.value.why.startswith("carla.Map cannot walk")


@pytest.mark.shared
def test_site_frame_samples_are_carla_waypoints_flipped():
    """On a real map: every waypoint the LaneMap hands out is carla.Map's own, y negated, in CARLA's order."""
    import carla

    p = SHARED / "fabriksgatan.xodr"
    if not p.is_file():
        pytest.skip("needs ../shared/data/opendrive")
    text = p.read_text()
    raw = carla.Map("raw", text).generate_waypoints(1.0)
    wp = LaneMap(text).waypoints(1.0)
    assert len(wp) == len(raw) > 100
    loc = np.array([(w.transform.location.x, w.transform.location.y, w.transform.location.z) for w in raw])
    assert np.array_equal(wp.xyz, from_carla(loc))
    assert np.array_equal(wp.width, [w.lane_width for w in raw]) and np.array_equal(wp.s, [w.s for w in raw])
    assert np.array_equal(wp.heading_deg, [-w.transform.rotation.yaw for w in raw])
    assert len(LaneMap(text).topology()) == len(carla.Map("raw", text).get_topology()) > 0
