"""place_signals: netconvert's traffic lights moved onto the scanned ones, scanned signs added.

Small synthetic inputs: two straight roads in a row along +x (road 1: x 0..50, road 2: x 50..100),
two right lanes and one left lane, a netconvert-style traffic light at road 1's end controlling lane -1,
and a labelled point set (ground, a pole, a light head, a sign plate, noise). The rules checked come
from CARLA 0.9.16's source: a signal's position is the reference line at s moved t to the left,
z = elevation + zOffset, and lights move 0.25 m along their heading
(LibCarla/source/carla/road/MapBuilder.cpp ComputeSignalTransform / SolveSignalReferencesAndTransforms);
s is clamped to the road (so a light beyond the road's end needs another road); the traffic-light
types are SignalType::IsTrafficLight's (LibCarla/source/carla/road/SignalType.cpp).
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from twinkit_roads.instances import find_instances
from twinkit_roads.signals import place_signals

LANES = """<lanes><laneSection s="0">
  <left><lane id="1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></left>
  <center><lane id="0" type="none" level="false"/></center>
  <right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane>
         <lane id="-2" type="driving" level="false"><width sOffset="0" a="3.25" b="0" c="0" d="0"/></lane></right>
</laneSection></lanes>"""


def xodr(with_signal: bool = True, z: float = 0.0) -> str:
    sig = """<signals>
  <signal id="3_0" s="50.0" t="-1.625" orientation="+" dynamic="yes" zOffset="5" country="OpenDRIVE"
          type="1000011" subtype="10" height="0.78" width="0.26"><validity fromLane="-1" toLane="-1"/></signal>
</signals>""" if with_signal else ""
    ctrl = '<controller id="3"><control signalId="3_0"/></controller>' if with_signal else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE><header revMajor="1" revMinor="4" name="" version="1.00"/>
<road name="A" length="50.0" id="1" junction="-1">
  <link><successor elementType="road" elementId="2" contactPoint="start"/></link>
  <planView><geometry s="0" x="0" y="0" hdg="0" length="50.0"><line/></geometry></planView>
  <elevationProfile><elevation s="0" a="{z}" b="0" c="0" d="0"/></elevationProfile>
  {LANES}<objects/>{sig}
</road>
<road name="B" length="50.0" id="2" junction="-1">
  <link><predecessor elementType="road" elementId="1" contactPoint="end"/></link>
  <planView><geometry s="0" x="50" y="0" hdg="0" length="50.0"><line/></geometry></planView>
  <elevationProfile><elevation s="0" a="{z}" b="0" c="0" d="0"/></elevationProfile>
  {LANES}<objects/>
</road>
{ctrl}
</OpenDRIVE>
"""


def box(c, size, step=0.05):
    """Surface points of an axis-aligned box (a light head, a sign plate)."""
    c, size = np.asarray(c, float), np.asarray(size, float)
    g = [np.arange(-s / 2, s / 2 + 1e-9, step) if s > step else np.array([0.0]) for s in size]
    P = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)
    return P + c


def scene(light=(40.0, -8.0), sign=None, noise=True, ground_z=0.0):
    """(vertices, labels): ground (road, 0), a pole (5) under a light head (6), optional sign, noise."""
    V, L = [], []
    gx, gy = np.meshgrid(np.arange(-5, 105, 0.5), np.arange(-15, 15, 0.5))
    V.append(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, ground_z)], 1))
    L.append(np.zeros(gx.size, int))
    if light is not None:
        x, y = light
        pole = np.stack([np.full(40, x), np.full(40, y), ground_z + np.linspace(0.1, 3.5, 40)], 1)
        V += [pole, box((x + 0.2, y, ground_z + 2.9), (0.26, 0.34, 0.9))]
        L += [np.full(len(pole), 5), np.full(len(V[-1]), 6)]
    if sign is not None:
        x, y = sign
        pole = np.stack([np.full(30, x), np.full(30, y), ground_z + np.linspace(0.1, 2.2, 30)], 1)
        V += [pole, box((x, y, ground_z + 2.5), (0.02, 0.6, 0.6), step=0.04)]
        L += [np.full(len(pole), 5), np.full(len(V[-1]), 7)]
    if noise:  # label-6 speckle low on a car body, no pole under it
        V.append(box((20.0, 5.0, ground_z + 0.8), (0.3, 0.3, 0.3)))
        L.append(np.full(len(V[-1]), 6))
    return np.concatenate(V), np.concatenate(L)


def carla_landmarks(text):
    import carla

    m = carla.Map("t", text)
    return {lm.id: lm for lm in m.get_all_landmarks()}, m


def test_light_lands_on_scanned_head_with_road_lanes_and_orientation_kept():
    V, L = scene(light=(40.0, -8.0))
    kept, rejected = find_instances(V, L)
    lights = [i for i in kept if i.kind == "light"]
    assert len(lights) == 1 and abs(lights[0].centre[0] - 40.2) < 0.05
    assert any("pole" in r.rejected or "above ground" in r.rejected for r in rejected)  # the noise
    text, placed, _ = place_signals(xodr(), kept)
    rec = next(p for p in placed if p.id == "3_0")
    assert rec.source == "scan" and rec.road == "1" and rec.host_road is None
    sig = ET.fromstring(text).find(".//road[@id='1']/signals/signal[@id='3_0']")
    assert sig is not None and sig.get("orientation") == "+" and sig.get("type") == "1000011"
    assert [(v.get("fromLane"), v.get("toLane")) for v in sig.findall("validity")] == [("-1", "-1")]
    # the light head is at x 40.2, y -8 (left of the road is +y): s ~ 40.2 - 0.25 (CARLA's shift), t = -8
    assert float(sig.get("s")) == pytest.approx(40.2 - 0.25, abs=0.05)
    assert float(sig.get("t")) == pytest.approx(-8.0, abs=0.05)
    assert float(sig.get("zOffset")) == pytest.approx(0.0, abs=0.05)  # the pole on the ground under the head
    assert sig.get("name") == "twinkit_scan_STATIC"  # MapBuilder::CheckSignalsOnRoads leaves it on the scan
    lms, m = carla_landmarks(text)
    loc = lms["3_0"].transform.location
    assert math.hypot(loc.x - 40.2, -loc.y - (-8.0)) < 0.05  # CARLA is left-handed: y flipped
    assert loc.z == pytest.approx(0.0, abs=0.05)
    assert lms["3_0"].road_id == 1
    # no junction ahead of its lanes: netconvert's controller is gone and no junction names one
    assert '<control signalId="3_0"' not in text
    # the head at its scanned height when asked
    text, _, _ = place_signals(xodr(), kept, lights_on_ground=False)
    sig = ET.fromstring(text).find(".//road[@id='1']/signals/signal[@id='3_0']")
    assert float(sig.get("zOffset")) == pytest.approx(2.9, abs=0.1)


def test_no_scanned_light_keeps_netconvert_and_says_so():
    V, L = scene(light=None)
    kept, _ = find_instances(V, L)
    assert not [i for i in kept if i.kind == "light"]
    text, placed, _ = place_signals(xodr(), kept)
    rec = next(p for p in placed if p.id == "3_0")
    assert rec.source == "netconvert" and rec.moved_m == 0.0 and "netconvert" in rec.note
    sig = ET.fromstring(text).find(".//signal[@id='3_0']")
    assert float(sig.get("s")) == 50.0 and float(sig.get("t")) == -1.625 and sig.get("zOffset") == "0.000"


def test_light_beyond_the_gate_is_not_paired():
    V, L = scene(light=(10.0, -8.0))  # 40 m from netconvert's guess at the road's end
    kept, _ = find_instances(V, L)
    _, placed, notes = place_signals(xodr(), kept, gate_m=15.0)
    assert next(p for p in placed if p.id == "3_0").source == "netconvert"
    assert any("matches no netconvert light group" in n for n in notes)


def test_noise_clusters_rejected():
    V, L = scene(light=None, noise=True)
    # also a label-6 patch on a facade: big, with no pole
    wall = box((30.0, 12.0, 4.0), (3.0, 0.05, 3.0), step=0.1)
    V, L = np.concatenate([V, wall]), np.concatenate([L, np.full(len(wall), 6)])
    kept, rejected = find_instances(V, L)
    assert kept == []
    reasons = " | ".join(r.rejected for r in rejected)
    assert "above ground" in reasons and "across" in reasons


def test_flat_light_cluster_is_a_sign_and_signs_get_signals():
    # a sign plate mislabelled as traffic light (label 6) is flat: a sign
    V, L = scene(light=None, sign=(30.0, -8.0), noise=False)
    L = np.where(L == 7, 6, L)
    kept, _ = find_instances(V, L)
    assert [i.kind for i in kept] == ["sign"]
    text, placed, _ = place_signals(xodr(), kept)
    sg = [p for p in placed if p.kind == "sign"]
    assert len(sg) == 1 and sg[0].road == "1" and sg[0].orientation == "+"  # right of the road: faces +s traffic
    lms, _ = carla_landmarks(text)
    loc = lms[sg[0].id].transform.location
    assert math.hypot(loc.x - 30.0, -loc.y + 8.0) < 0.05  # signs are not shifted
    assert lms[sg[0].id].type == "-1"
    el = ET.fromstring(text).find(f".//signal[@id='{sg[0].id}']")
    assert [(v.get("fromLane"), v.get("toLane")) for v in el.findall("validity")] == [("-2", "-1")]


def test_light_beyond_road_end_defined_on_next_road_and_referenced():
    # CARLA clamps s to the road: a light 2 m past road 1's end is written on road 2, and road 1
    # keeps a signalReference carrying lane -1 (what CARLA's trigger boxes and waypoints read)
    V, L = scene(light=(51.8, -8.0))
    kept, _ = find_instances(V, L)
    text, placed, _ = place_signals(xodr(), kept)
    rec = next(p for p in placed if p.id == "3_0")
    assert rec.source == "scan" and rec.road == "1" and rec.host_road == "2"
    root = ET.fromstring(text)
    ref = root.find(".//road[@id='1']/signals/signalReference[@id='3_0']")
    assert ref is not None and [(v.get("fromLane"), v.get("toLane")) for v in ref] == [("-1", "-1")]
    assert root.find(".//road[@id='2']/signals/signal[@id='3_0']") is not None
    lms, m = carla_landmarks(text)
    loc = lms["3_0"].transform.location
    assert math.hypot(loc.x - 52.0, -loc.y + 8.0) < 0.05
    # road 1's lane -1 still sees the light ahead; road 2's lanes are not controlled by it
    w1 = m.get_waypoint_xodr(1, -1, 30.0)
    assert "3_0" in [lm.id for lm in w1.get_landmarks(30.0)]
    w2 = m.get_waypoint_xodr(2, -1, 1.0)
    assert "3_0" not in [lm.id for lm in w2.get_landmarks(10.0)]


def test_step_writes_xodr_json_png_and_checks_carla(tmp_path):
    from twinkit.mesh import write_colored_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    V, L = scene(light=(40.0, -8.0), sign=(30.0, 8.0), ground_z=12.0)
    faces = np.array([[0, 1, 2]])
    write_colored_ply(tmp_path / "textured_mesh.ply", V, faces, np.full((len(V), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", L.astype(np.uint8))
    (tmp_path / "aligned.xodr").write_text(xodr(z=12.0))
    out = run_step(plugin_from_module(roads, "step", "place_signals"), tmp_path / "run",
                   {"in_aligned_xodr": tmp_path / "aligned.xodr",
                    "in_textured_mesh_ply": tmp_path / "textured_mesh.ply", "in_labels_npy": tmp_path / "labels.npy"})
    assert set(out) == {"aligned.xodr", "signals.json", "signals.png"}
    doc = json.loads(out["signals.json"].read_text())
    by = {s["id"]: s for s in doc["signals"]}
    assert by["3_0"]["source"] == "scan" and by["3_0"]["carla_position_error_m"] < 0.05
    assert by["3_0"]["zOffset"] == pytest.approx(0.0, abs=0.05)  # on the ground (at 12 m), not at the site origin
    assert doc["light_plan"]["lights"][0]["zOffset"] == pytest.approx(0.0, abs=0.05)
    signs = [s for s in doc["signals"] if s["kind"] == "sign"]
    assert len(signs) == 1 and signs[0]["orientation"] == "-"  # left of the road: faces the -s lanes
    carla_landmarks(out["aligned.xodr"].read_text())


def test_step_rejects_labels_of_another_mesh(tmp_path):
    from twinkit import InputError
    from twinkit.mesh import write_colored_ply
    from twinkit.testing import plugin_from_module, run_step

    import twinkit_roads.plugin as roads

    V, L = scene()
    write_colored_ply(tmp_path / "textured_mesh.ply", V, np.array([[0, 1, 2]]), np.full((len(V), 3), 128, np.uint8))
    np.save(tmp_path / "labels.npy", L[:-5].astype(np.uint8))
    (tmp_path / "aligned.xodr").write_text(xodr())
    with pytest.raises(InputError, match="labels.npy"):
        run_step(plugin_from_module(roads, "step", "place_signals"), tmp_path / "run",
                 {"in_aligned_xodr": tmp_path / "aligned.xodr", "in_textured_mesh_ply": tmp_path / "textured_mesh.ply",
                  "in_labels_npy": tmp_path / "labels.npy"})


def test_reference_line_of_an_arc_and_projection_round_trip():
    from twinkit_roads.reflines import reference_lines

    road = """<OpenDRIVE><road id="2" length="21" junction="-1"><planView>
 <geometry s="0" x="0" y="9" hdg="1.5707963" length="6"><line/></geometry>
 <geometry s="6" x="0" y="15" hdg="1.5707963" length="15"><arc curvature="0.03"/></geometry></planView>
 </road></OpenDRIVE>"""
    ref = reference_lines(ET.fromstring(road))["2"]
    # arc of curvature 0.03 over 15 m from (0, 15) heading north
    assert ref.point(21.0, 0.0) == pytest.approx([-(1 - np.cos(0.45)) / 0.03, 15 + np.sin(0.45) / 0.03], abs=0.01)
    p = ref.point(12.0, -2.5)
    s, t, over = ref.project(p)
    assert (s, t, over) == pytest.approx((12.0, -2.5, 0.0), abs=0.01)
    assert ref.project([0.0, 5.0])[2] == pytest.approx(4.0, abs=0.01)  # 4 m before the start


def test_pole_with_an_unlabelled_head_fills_an_unpaired_light():
    from twinkit_roads.instances import find_pole_heads

    # the segmentation calls the head "building" (2): only the pole is labelled
    V, L = scene(light=(40.0, -8.0), noise=False)
    L = np.where(L == 6, 2, L)
    kept, _ = find_instances(V, L)
    assert kept == []
    heads = find_pole_heads(V, L, kept)
    assert len(heads) == 1 and heads[0].evidence == "pole_head"
    assert np.hypot(*(heads[0].centre[:2] - [40.1, -8.0])) < 0.15
    text, placed, _ = place_signals(xodr(), heads)
    rec = next(p for p in placed if p.id == "3_0")
    assert rec.source == "scan" and "unlabelled head" in rec.note
    lms, _ = carla_landmarks(text)
    loc = lms["3_0"].transform.location
    assert math.hypot(loc.x - 40.1, -loc.y + 8.0) < 0.15


def test_bare_poles_sign_posts_and_trees_are_not_heads():
    from twinkit_roads.instances import find_pole_heads

    V, L = scene(light=None, sign=(30.0, -8.0), noise=False)
    L = np.where(L == 7, 2, L)  # the plate unlabelled too: a thin plate is still no head
    lamp = np.stack([np.full(80, 60.0), np.full(80, -8.0), np.linspace(0.1, 7.0, 80)], 1)  # bare up to 7 m
    trunk = np.stack([np.full(40, 70.0), np.full(40, -8.0), np.linspace(0.1, 2.6, 40)], 1)
    g = np.random.default_rng(0).normal(size=(3000, 3))
    crown = g / np.linalg.norm(g, axis=1, keepdims=True) * [2.0, 2.0, 1.6] + [70.0, -8.0, 4.2]
    V = np.concatenate([V, lamp, trunk, crown])
    L = np.concatenate([L, np.full(len(lamp), 5), np.full(len(trunk), 5), np.full(len(crown), 8)])
    assert find_pole_heads(V, L, []) == []


def test_light_at_its_lanes_kerb_wins_over_a_nearer_one_across_the_road():
    # the head controls lane -1 (right of the reference line): a light 7.7 m away on the left kerb
    # loses to one 10.9 m away on the right kerb; without the side cost the nearer one would win
    V1, L1 = scene(light=(49.0, 6.0), noise=False)
    V2, L2 = scene(light=(42.0, -9.0), noise=False)
    kept, _ = find_instances(np.concatenate([V1, V2]), np.concatenate([L1, L2]))
    assert len([i for i in kept if i.kind == "light"]) == 2
    _, placed, _ = place_signals(xodr(), kept)
    assert next(p for p in placed if p.id == "3_0").instance_position[1] == pytest.approx(-9.0, abs=0.1)
    _, placed, _ = place_signals(xodr(), kept, wrong_side_m=0.0)
    assert next(p for p in placed if p.id == "3_0").instance_position[1] == pytest.approx(6.0, abs=0.1)


def test_network_without_lights_gets_only_the_scanned_signs():
    V, L = scene(light=(40.0, -8.0), sign=(30.0, -8.0), noise=False)
    kept, _ = find_instances(V, L)
    text, placed, notes = place_signals(xodr(with_signal=False), kept)
    assert [p.kind for p in placed] == ["sign"]
    assert any("matches no netconvert light group" in n for n in notes)  # the light is reported, not written
    lms, _ = carla_landmarks(text)
    assert list(lms) == [placed[0].id]
