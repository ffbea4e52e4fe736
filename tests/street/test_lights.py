"""twinkit.street.lights: CARLA 0.9.16's traffic-light grouping and cycle, emulated offline.

What is emulated, and where CARLA does it (carla-simulator/carla 0.9.16):
- LibCarla/source/carla/road/MapBuilder.cpp, MapBuilder::SolveControllerAndJuntionReferences: a signal gets a
  controller only through <junction><controller id=..>;
- Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/TrafficLightManager.cpp, RegisterLightComponent: one
  ATrafficLightGroup per junction, its controllers in turn; a light without a controller alone
  (LoneTrafficLightsGroupControllerId); SpawnTrafficLights: which lights are spawned;
- TrafficLightGroup.cpp NextCycleStep / NextController, TrafficLightController.h LightStates (10 / 3 / 2 s).

The fixture is netconvert's OpenDRIVE of the demo junction as today's pipeline writes it (one <controller>
with all 14 signals, no junction naming it).
"""
from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from twinkit.street.lights import Wiring, crossing, green_together, light_plan

HERE = Path(__file__).parent
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opendrive"


def netconvert_junction() -> str:
    return gzip.decompress((HERE / "fixtures" / "netconvert_junction.xodr.gz").read_bytes()).decode()


def test_netconvert_controller_without_junction_gives_every_light_its_own_group():
    plan = light_plan(netconvert_junction())
    j = plan["junctions"]["1"]
    assert j["lights"] == 14 and j["groups"] == 14  # RegisterLightComponent's lone branch, one per light
    assert j["approaches"] == 4
    assert len(j["conflicts"]) > 0  # every light green in the first 13 s: crossing approaches together
    assert all(lt["zOffset"] == 5.0 for lt in plan["lights"])  # netconvert's heads 5 m up


def test_junction_named_controllers_make_one_group_that_takes_turns():
    text = netconvert_junction()
    # name netconvert's controller from the junction: one group, one controller -> all green together
    text1 = text.replace('<junction name="3" id="1">', '<junction name="3" id="1"><controller id="3" type="0"/>')
    j = light_plan(text1)["junctions"]["1"]
    assert j["groups"] == 1 and j["controllers"] == 1 and len(j["conflicts"]) > 0


def test_cycle_windows_of_one_group_never_overlap_and_lone_groups_do():
    # two controllers of one group: (0, 13, 30) and (15, 28, 30); lone lights: both (0, 13, 25)
    assert not green_together((0.0, 13.0, 30.0), (15.0, 28.0, 30.0))
    assert green_together((0.0, 13.0, 25.0), (0.0, 13.0, 25.0))


def test_crossing_is_between_30_and_150_degrees():
    import math
    assert crossing(0.0, math.pi / 2) and not crossing(0.0, math.pi) and not crossing(0.0, 0.1)
    assert not crossing(None, 0.0)


def test_approach_of_a_netconvert_light_is_its_road_entering_the_junction():
    w = Wiring(netconvert_junction())
    ap = w.approach("3_0")  # road 55 (Testikuja from the north) lane -2 into junction 1
    assert ap.junction == "1" and ap.roads == ["55"]


@pytest.mark.parametrize("town", ["Town10HD.xodr", "Town01.xodr"])
def test_carla_towns_come_out_with_one_group_per_junction_and_no_conflict(town):
    path = SHARED / town
    if not path.is_file():
        pytest.skip(f"{path} not present")
    plan = light_plan(path.read_text())
    assert plan["junctions"], "CARLA's town has signalised junctions"
    for jid, j in plan["junctions"].items():
        assert j["groups"] == 1, (jid, j)
        assert j["conflicts"] == [], (jid, j)
    assert not plan["no_junction"]
