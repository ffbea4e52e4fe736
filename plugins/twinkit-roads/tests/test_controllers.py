"""Junction signal plans (controllers.py) and sign types (signtypes.py) as CARLA 0.9.16 reads them.

The light plan is judged with twinkit.street.lights (CARLA's grouping and cycle emulated offline: MapBuilder.cpp
SolveControllerAndJuntionReferences, TrafficLightManager.cpp RegisterLightComponent, TrafficLightGroup.cpp
NextController); sign types with SignalType.cpp (206 stop, 205 yield, 274 speed limit) and the blueprints
TrafficLightManager.cpp spawns for them.
"""
from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from twinkit.street.lights import light_plan
from twinkit_roads.controllers import merge_heads, phase_plan
from twinkit_roads.instances import Instance
from twinkit_roads.signals import place_signals
from twinkit_roads.signtypes import osm_kind, plate_look, road_speed_kmh, signal_type

ROOT = Path(__file__).resolve().parents[3]


def netconvert_junction() -> str:
    """netconvert's OpenDRIVE of the demo junction as the pipeline writes it today (tests/street/fixtures)."""
    return gzip.decompress((ROOT / "tests" / "street" / "fixtures" / "netconvert_junction.xodr.gz").read_bytes()).decode()


def test_today_conflicting_greens_and_stacked_heads_in_the_air_then_one_plan():
    text = netconvert_junction()
    # what netconvert's signals did: kept as written (the old place_signals)
    old, _, _ = place_signals(text, [], one_head=False, lights_on_ground=False, phase_plan="netconvert")
    j = light_plan(old)["junctions"]["1"]
    assert j["groups"] == 14 and len(j["conflicts"]) > 0 and j["lights"] == 14
    assert {lt["zOffset"] for lt in light_plan(old)["lights"]} == {5.0}
    # now: one head per approach on the ground, one controller per phase named from the junction
    new, placed, log = place_signals(text, [])
    plan = light_plan(new)
    j = plan["junctions"]["1"]
    assert j["groups"] == 1 and j["conflicts"] == [] and j["lights"] == 4 and j["approaches"] == 4
    assert j["controllers"] == 2  # a 4-way junction: two phases of opposite approaches
    assert {lt["zOffset"] for lt in plan["lights"]} == {0.0}
    root = ET.fromstring(new)
    assert len(root.find("junction[@id='1']").findall("controller")) == 2
    assert all(s.get("type") == "1000001" for s in root.iter("signal"))
    # a merged head keeps every lane of the signals it replaced: road 51's head covers lanes -2 and -1
    head = root.find(".//road[@id='51']/signals/signal")
    assert [(v.get("fromLane"), v.get("toLane")) for v in head.findall("validity")] == [("-2", "-1")]
    # carla.Map reads it: one landmark per head
    from twinkit.street.lanes import LaneMap
    assert len([lm for lm in LaneMap(new, "test").landmarks() if lm.type == "1000001"]) == 4


def test_each_approach_alone_when_asked():
    new, _, _ = place_signals(netconvert_junction(), [], phase_plan="approach")
    j = light_plan(new)["junctions"]["1"]
    assert j["groups"] == 1 and j["controllers"] == 4 and j["conflicts"] == []


def test_phase_plan_by_shape():
    import math
    four = {"n": -math.pi / 2, "s": math.pi / 2, "e": math.pi, "w": 0.0}
    assert sorted(map(sorted, phase_plan(four))) == [["e", "w"], ["n", "s"]]
    tee = {"w": 0.0, "e": math.pi, "s": math.pi / 2}
    assert sorted(map(sorted, phase_plan(tee))) == [["e", "w"], ["s"]]
    assert len(phase_plan(four, "approach")) == 4
    with pytest.raises(ValueError):
        phase_plan(four, "random")


def test_merge_heads_keeps_the_plain_head_with_all_lanes():
    sg = ET.fromstring('<signals><signal id="a" type="1000011"><validity fromLane="-2" toLane="-2"/></signal>'
                       '<signal id="b" type="1000001"><validity fromLane="-1" toLane="-1"/></signal>'
                       '<signal id="c" type="1000011"><validity fromLane="-4" toLane="-4"/></signal></signals>')
    keep, removed = merge_heads(sg, list(sg))
    assert keep.get("id") == "b" and removed == ["a", "c"] and len(sg) == 1
    assert [(v.get("fromLane"), v.get("toLane")) for v in keep.findall("validity")] == [("-4", "-4"), ("-2", "-1")]


def plate(rgb_counts):
    """(n, 3) uint8 colours: [(rgb, count), ...]."""
    return np.concatenate([np.tile(np.array(c, np.uint8), (n, 1)) for c, n in rgb_counts])


def test_plate_look():
    assert plate_look(plate([((200, 20, 20), 80), ((240, 240, 240), 10), ((150, 150, 150), 10)]))[0] == "stop"
    assert plate_look(plate([((200, 20, 20), 40), ((230, 200, 40), 40), ((150, 150, 150), 20)]))[0] == "yield"
    assert plate_look(plate([((200, 20, 20), 25), ((240, 240, 240), 60), ((20, 20, 20), 15)]))[0] == "speed"
    assert plate_look(plate([((20, 60, 170), 70), ((240, 240, 240), 30)]))[0] is None  # blue information plate
    assert plate_look(plate([((120, 120, 120), 100)]))[0] is None  # grey: no colour to read


def test_osm_kinds_and_types():
    assert osm_kind({"highway": "stop"}) == "stop" and osm_kind({"highway": "give_way"}) == "yield"
    assert osm_kind({"traffic_sign": "DE:206"}) == "stop" and osm_kind({"traffic_sign": "FI:C32[40]"}) == "speed"
    assert osm_kind({"traffic_sign": "FI:B5"}) == "yield" and osm_kind({"amenity": "bench"}) is None
    assert osm_kind({"traffic_sign": "FI:206"}) is None  # a code means what its country says
    assert signal_type("stop", None) == ("206", "-1", None) and signal_type("yield", None) == ("205", "-1", None)
    assert signal_type("speed", 40.0) == ("274", "40", "40") and signal_type("speed", None)[0] == "-1"
    road = ET.fromstring('<road><lanes><laneSection><right><lane><speed sOffset="0" max="11.11"/></lane></right>'
                         '</laneSection></lanes></road>')
    assert road_speed_kmh(road) == 40.0  # netconvert writes OSM's maxspeed in m/s


def test_scanned_stop_plate_is_typed_206_on_the_ground_today_it_was_minus_one():
    text = netconvert_junction()
    # a red plate beside road 52 (Testikuja from the south), 2.8 m up
    members = np.arange(100)
    inst = Instance("sign", np.array([3.7, -15.0, 2.8]), np.array([0.6, 0.05, 0.6]), 100, 2.8, 10, 7, id=0,
                    members=members)
    colors = plate([((200, 20, 20), 85), ((240, 240, 240), 15)])
    _, placed_old, _ = place_signals(text, [inst])  # no texture: the old generic type
    assert [p.type for p in placed_old if p.kind == "sign"] == ["-1"]
    new, placed, _ = place_signals(text, [inst], colors=colors)
    sign = next(p for p in placed if p.kind == "sign")
    assert sign.type == "206" and abs(sign.z_offset) < 0.1 and "look" in sign.note
    sig = next(s for s in ET.fromstring(new).iter("signal") if s.get("id") == sign.id)
    assert sig.get("type") == "206" and abs(float(sig.get("zOffset"))) < 0.1  # the ground under the plate
    # an OSM stop node beats the look; a speed plate takes the road's OSM maxspeed
    _, placed, _ = place_signals(text, [inst], colors=colors, osm_signs=[(3.5, -15.5, "yield")])
    assert next(p for p in placed if p.kind == "sign").type == "205"
    speed = plate([((200, 20, 20), 25), ((240, 240, 240), 75)])
    new, placed, _ = place_signals(text, [inst], colors=speed)
    sig = next(s for s in ET.fromstring(new).iter("signal") if s.get("id") == "scan_sign_0")
    assert sig.get("type") == "274" and sig.get("value") == sig.get("subtype") == "30"


def test_red_plate_facing_a_one_way_streets_wrong_way_is_no_entry_not_stop():
    # the demo's no-entry sign: east kerb of the one-way side street north of the junction
    inst = Instance("sign", np.array([3.7, 9.06, 2.55]), np.array([0.6, 0.05, 0.6]), 100, 2.5, 10, 7, id=0,
                    members=np.arange(100))
    _, placed, _ = place_signals(netconvert_junction(), [inst], colors=plate([((200, 20, 20), 85),
                                                                             ((240, 240, 240), 15)]))
    sign = next(p for p in placed if p.kind == "sign")
    assert sign.type == "-1" and "no-entry" in sign.note


def test_typed_plate_without_its_pole_is_kept():
    from twinkit_roads.signtypes import typed_plates
    red = plate([((200, 20, 20), 85), ((240, 240, 240), 15)])
    grey = plate([((128, 128, 128), 100)])
    a = Instance("sign", np.zeros(3), np.ones(3), 100, 2.5, 0, 7, rejected="0 pole vertices under it < 3",
                 members=np.arange(100))
    b = Instance("sign", np.zeros(3), np.ones(3), 100, 2.5, 0, 7, rejected="0 pole vertices under it < 3",
                 members=np.arange(100))
    c = Instance("sign", np.zeros(3), np.ones(3), 5, 2.5, 0, 7, rejected="5 vertices < 12; 0 pole vertices under it < 3",
                 members=np.arange(100))
    assert typed_plates([a], red) == [a] and a.evidence == "plate_look" and a.rejected == ""
    assert typed_plates([b], grey) == [] and typed_plates([c], red) == []


def test_one_plate_split_into_two_clusters_is_one_sign():
    yellow_red = plate([((200, 20, 20), 50), ((230, 200, 40), 50)])
    a = Instance("sign", np.array([-3.75, -15.69, 2.7]), np.array([0.6, 0.05, 0.6]), 100, 2.7, 10, 7, id=0,
                 members=np.arange(100))
    b = Instance("sign", np.array([-3.56, -15.67, 2.7]), np.array([0.6, 0.05, 0.6]), 100, 2.7, 10, 7, id=1,
                 members=np.arange(100))
    _, placed, log = place_signals(netconvert_junction(), [a, b], colors=yellow_red)
    assert [p.type for p in placed if p.kind == "sign"] == ["205"] and any("same plate" in ln for ln in log)


@pytest.mark.parametrize("town", ["Town10HD.xodr", "Town01.xodr"])
def test_carla_towns_keep_their_plan_and_their_signs_stand_on_the_ground(town):
    path = ROOT.parent / "shared" / "data" / "opendrive" / town
    if not path.is_file():
        pytest.skip(f"{path} not present")
    text = path.read_text()
    out, _, log = place_signals(text, [])
    before, after = light_plan(text), light_plan(out)
    assert out.count("<controller ") == text.count("<controller ")  # CARLA's own wiring stays
    assert [lt["controller"] for lt in after["lights"]] == [lt["controller"] for lt in before["lights"]]
    assert all(abs(float(s.get("zOffset"))) <= 1.0 for s in ET.fromstring(out).iter("signal")
               if s.get("type") in ("205", "206", "274"))


def test_user_phase_plan_by_compass_points():
    from twinkit_roads.controllers import compass_from
    import math
    assert compass_from(-math.pi / 2) == "N" and compass_from(0.0) == "W"  # heading south: comes from the north
    text = netconvert_junction()
    new, _, log = place_signals(text, [], phases={"default": [["N", "S"], ["E", "W"]]})
    j = light_plan(new)["junctions"]["1"]
    assert j["controllers"] == 2 and j["conflicts"] == [] and not log
    new, _, log = place_signals(text, [], phases={"1": [["N", "E"]]})  # a crossing pair, as the user asked
    j = light_plan(new)["junctions"]["1"]
    assert j["controllers"] == 3 and len(j["conflicts"]) == 1 and any("crossing" in ln for ln in log)


def test_osm_sign_nodes_in_the_aligned_frame(tmp_path):
    from twinkit_roads.signtypes import osm_sign_nodes
    (tmp_path / "a.osm").write_text(
        '<?xml version="1.0"?><osm version="0.6">'
        '<node id="1" lat="60.0" lon="25.0"><tag k="highway" v="stop"/></node>'
        '<node id="2" lat="60.0" lon="25.001"><tag k="traffic_sign" v="FI:361[40]"/></node>'
        '<node id="3" lat="60.0" lon="25.002"><tag k="amenity" v="bench"/></node></osm>')
    # a toy site frame: 1e-3 degrees = 100 m; the alignment turns 90 degrees and shifts 1 m in x
    nodes = osm_sign_nodes(tmp_path / "a.osm", lambda ll: (ll - [25.0, 60.0]) * 1e5,
                           {"yaw_deg": 90.0, "tx_m": 1.0, "ty_m": 0.0})
    assert [k for _, _, k in nodes] == ["stop", "speed"]
    assert nodes[1][0] == pytest.approx(1.0) and nodes[1][1] == pytest.approx(100.0)


def test_osm_stop_node_without_a_plate_is_written_on_its_approach():
    from twinkit_roads.reflines import reference_lines
    text = netconvert_junction()
    ref = reference_lines(ET.fromstring(text))["52"]  # Testikuja from the south, into junction 1
    x, y = ref.point(ref.length - 5.0, 0.0)
    far = ref.point(1.0, 0.0)  # a speed-limit node: never written from OSM alone (no plate, no value)
    new, placed, log = place_signals(text, [], osm_signs=[(x, y, "stop"), (x + 500, y, "yield"), (far[0], far[1], "speed")])
    osm = [p for p in placed if p.source == "osm"]
    assert [(p.id, p.type, p.road, p.orientation) for p in osm] == [("osm_stop_0", "206", "52", "+")]
    assert any("no approach" in ln for ln in log)  # the node far off the network
    from twinkit.street.lanes import LaneMap
    lm = next(m for m in LaneMap(new, "t").landmarks() if m.id == "osm_stop_0")
    assert lm.type == "206"
