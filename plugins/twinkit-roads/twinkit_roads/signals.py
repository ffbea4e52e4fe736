"""OpenDRIVE signals where the scan has them.

netconvert guesses traffic lights from OSM nodes: it puts every signal of an approach at the
road's end, inside the lanes, 5 m up. This module finds the scanned traffic lights and signs in the
labelled mesh (CityScapes trainIds 5 pole, 6 traffic light, 7 traffic sign; instances.py), moves each
netconvert light group onto the scanned light that matches it and adds the scanned signs.

How CARLA reads a signal (carla 0.9.16, LibCarla/source/carla/road/MapBuilder.cpp,
``ComputeSignalTransform`` / ``SolveSignalReferencesAndTransforms``):

- position = the road's reference line at ``s`` (no lane offset), moved ``t`` to the left,
  ``z`` = road elevation + ``zOffset``;
- heading = road tangent + ``hOffset`` (the ``orientation`` attribute does not enter the transform);
- a traffic light (``SignalType::IsTrafficLight``: types 1000001 ... 1000020, F, W, A,
  LibCarla/source/carla/road/SignalType.cpp) is then moved 0.25 m along that heading.

So a signal written at (s, t) lands where we intend only if s, t are measured in that road's
reference-line frame and, for lights, the 0.25 m shift is taken off first (``carla_light_shift_m``).

``MapBuilder::CheckSignalsOnRoads`` then pushes every signal closer (3D) than 0.7 lane widths to the nearest
driving lane's centre outwards in steps of 0.2 lane widths, unless its name contains "STATIC". A pole on
the ground at the kerb is that close, so the signals placed on the scan are named ``SCAN_NAME``: the scan
says where the pole stands.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from .controllers import merge_heads, wire_junctions
from .instances import Instance
from .osmsigns import add_osm_signs
from .signal_bounds import clamp_to_roads
from .reflines import RefLine, reference_lines
from .signtypes import ground_typed_signs, plate_look, road_speed_kmh, signal_type

# SignalType::IsTrafficLight (LibCarla/source/carla/road/SignalType.cpp, carla 0.9.16)
CARLA_LIGHT_TYPES = {"1000001", "1000002", "1000009", "1000010", "1000011", "1000007", "1000014", "1000015",
                     "1000016", "1000017", "1000018", "1000019", "1000013", "1000020", "1000008", "1000012",
                     "F", "W", "A"}
#: the name of the signals placed on the scan ("STATIC": CheckSignalsOnRoads leaves them where they are)
SCAN_NAME = "twinkit_scan_STATIC"
UNKNOWN_SIGN_TYPE = "-1"  # OpenDRIVE: "-1" = no type; CARLA keeps it as a landmark and spawns no sign actor


# --------------------------------------------------------------------------- placing


@dataclass
class Placed:
    id: str
    kind: str
    road: str
    s: float
    t: float
    z_offset: float
    orientation: str
    source: str  # "scan" | "netconvert"
    moved_m: float = 0.0
    instance: int | None = None
    instance_position: list | None = None
    instance_size: list | None = None
    type: str = ""
    subtype: str = ""
    old_xy: list | None = None
    new_xy: list | None = None
    note: str = ""
    host_road: str | None = None

    def to_json(self) -> dict:
        d = {k: getattr(self, k) for k in ("id", "kind", "type", "subtype", "road", "orientation", "source",
                                            "instance", "instance_position", "instance_size", "note")}
        d["defined_on_road"] = self.host_road or self.road
        d.update({"s": round(self.s, 4), "t": round(self.t, 4), "zOffset": round(self.z_offset, 3),
                  "moved_m": round(self.moved_m, 3),
                  "position": [round(v, 3) for v in self.new_xy] if self.new_xy else None,
                  "netconvert_position": [round(v, 3) for v in self.old_xy] if self.old_xy else None})
        return d


def _f(x: float, nd: int = 8) -> str:
    return f"{x:.{nd}f}"


def _signal_xy(ref: RefLine, sig: ET.Element, shift_m: float) -> np.ndarray:
    """Where CARLA puts a signal (xy, site frame): reference line at s, t to the left, lights shifted."""
    s, t = float(sig.get("s")), float(sig.get("t", 0.0))
    p = ref.point(s, t)
    if sig.get("type") in CARLA_LIGHT_TYPES:
        s_c = min(max(s, 0.0), ref.length)
        i = int(np.clip(np.searchsorted(ref.s, s_c) - 1, 0, len(ref.s) - 1))
        h = ref.hdg[i] + float(sig.get("hOffset", 0.0))
        p = p + shift_m * np.array([math.cos(h), math.sin(h)])
    return p


def signal_positions(xodr_text: str, shift_m: float = 0.25) -> list[dict]:
    """Every signal's id, road, type and CARLA position (xy, site frame)."""
    root = ET.fromstring(xodr_text)
    refs = reference_lines(root)
    out = []
    for road in root.iter("road"):
        ref = refs.get(road.get("id"))
        for sig in road.iter("signal"):
            out.append({"id": sig.get("id"), "road": road.get("id"), "type": sig.get("type"),
                        "xy": _signal_xy(ref, sig, shift_m)})
    return out


def _host(refs: dict[str, RefLine], xy, reach_m: float, exclude: str | None = None
          ) -> tuple[RefLine, float, float] | None:
    """The road whose reference-line frame holds xy (not beyond either end), nearest first."""
    best = None
    for ref in refs.values():
        if ref.road == exclude:
            continue
        s, t, over = ref.project(xy)
        if over <= reach_m and (best is None or abs(t) < abs(best[2])):
            best = (ref, min(max(s, 0.0), ref.length), t)
    return best


def _signals_el(road_el: ET.Element) -> ET.Element:
    sg = road_el.find("signals")
    if sg is None:
        sg = ET.Element("signals")
        # <signals> follows <lanes> / <objects> in the OpenDRIVE schema
        kids = list(road_el)
        after = max((kids.index(e) for e in kids if e.tag in ("lanes", "objects")), default=len(kids) - 1)
        road_el.insert(after + 1, sg)
    return sg


def _move_signal(root: ET.Element, road_el: ET.Element, host_id: str, sig: ET.Element, h_offset: float) -> None:
    """Define ``sig`` on road ``host_id``; leave a <signalReference> with its lanes where it was.

    The defining copy gets validity lane 0 only, so CARLA builds no trigger box on the host road's
    lanes (UTrafficLightComponent::InitializeSign, Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/
    TrafficLightComponent.cpp, walks every reference to the signal and skips lane 0); the approach's
    reference carries the original validity, which is what the trigger boxes and waypoints read.
    """
    host_el = next(r for r in root.iter("road") if r.get("id") == host_id)
    parent = road_el.find("signals")
    ref_el = ET.Element("signalReference", {"id": sig.get("id"), "s": sig.get("s"), "t": sig.get("t", "0"),
                                            "orientation": sig.get("orientation", "+")})
    for v in sig.findall("validity"):
        ref_el.append(v)
        sig.remove(v)
    parent.remove(sig)
    parent.append(ref_el)  # <signalReference> entries follow the <signal> entries
    ET.SubElement(sig, "validity", {"fromLane": "0", "toLane": "0"})
    if abs(h_offset) > 1e-9:
        sig.set("hOffset", _f(h_offset))
    hs = _signals_el(host_el)
    n_sig = sum(1 for e in hs if e.tag == "signal")
    hs.insert(n_sig, sig)


def _light_groups(root: ET.Element, refs: dict[str, RefLine], group_m: float, shift_m: float
                  ) -> tuple[list[tuple[ET.Element, ET.Element, np.ndarray]], list[list[int]]]:
    """netconvert's traffic lights, (road element, signal element, CARLA xy), and their groups.

    A group is the lights of one road and orientation within ``group_m`` of each other along s
    (indices into the lights list, in document order).
    """
    sigs = []  # (road element, signal element, xy)
    for road in root.iter("road"):
        ref = refs[road.get("id")]
        for sig in road.iter("signal"):
            sigs.append((road, sig, _signal_xy(ref, sig, shift_m)))
    lights = [x for x in sigs if x[1].get("type") in CARLA_LIGHT_TYPES]
    groups: list[list[int]] = []
    for i, (road, sig, xy) in enumerate(lights):
        for g in groups:
            r0, s0 = lights[g[0]][0], lights[g[0]][1]
            if (r0 is road and abs(float(sig.get("s")) - float(s0.get("s"))) <= group_m
                    and sig.get("orientation", "+") == s0.get("orientation", "+")):
                g.append(i)
                break
        else:
            groups.append([i])
    return lights, groups


def _lane_sides(lights: list, groups: list[list[int]]) -> list[int]:
    """Per group, the side of the reference line its lanes are on: -1 right, +1 left, 0 both or none.

    A light stands at its lanes' kerb (right-hand traffic: right lanes, negative ids, and the right
    kerb; left-hand traffic mirrored).
    """
    side = []
    for g in groups:
        ids = [int(v.get(k)) for i in g for v in lights[i][1].findall("validity") for k in ("fromLane", "toLane")]
        side.append(-1 if ids and max(ids) < 0 else (1 if ids and min(ids) > 0 else 0))
    return side


def _pair_groups(lights: list, groups: list[list[int]], refs: dict[str, RefLine], scan_lights: list[Instance],
                 gate_m: float, wrong_side_m: float) -> dict[int, Instance]:
    """Group index -> the scanned light it moves onto (Hungarian method on horizontal distance).

    Labelled lights first; poles carrying an unlabelled head only for the groups still unpaired.
    Pairs farther than ``gate_m`` are refused; a light on the other side of the reference line than
    the group's lanes costs ``wrong_side_m`` more.
    """
    from scipy.optimize import linear_sum_assignment

    pairs: dict[int, Instance] = {}
    G = np.array([np.mean([lights[i][2] for i in g], 0) for g in groups]).reshape(-1, 2)
    side = _lane_sides(lights, groups)
    for evidence in ("label", "pole_head"):
        cand = [inst for inst in scan_lights if inst.evidence == evidence]
        free = [gi for gi in range(len(groups)) if gi not in pairs]
        if not cand or not free:
            continue
        L = np.array([inst.centre[:2] for inst in cand])
        D = np.hypot(G[free, None, 0] - L[None, :, 0], G[free, None, 1] - L[None, :, 1])
        C = D.copy()
        for r, gi in enumerate(free):
            ref = refs[lights[groups[gi][0]][0].get("id")]
            for c, inst in enumerate(cand):
                t = ref.project(inst.centre[:2])[1]
                if side[gi] and np.sign(t) != side[gi]:
                    C[r, c] += wrong_side_m
        rows, cols = linear_sum_assignment(np.where(D <= gate_m, C, 1e6))
        for r, c in zip(rows, cols):
            if D[r, c] <= gate_m:
                pairs[free[int(r)]] = cand[int(c)]
    return pairs


def _light_record(road: ET.Element, sig: ET.Element, xy: np.ndarray) -> Placed:
    """The record of a netconvert light as netconvert wrote it."""
    return Placed(sig.get("id"), "light", road.get("id"), float(sig.get("s")), float(sig.get("t", 0.0)),
                  float(sig.get("zOffset", 0.0)), sig.get("orientation", "+"), "netconvert",
                  type=sig.get("type", ""), subtype=sig.get("subtype", ""),
                  old_xy=[float(v) for v in xy], new_xy=[float(v) for v in xy])


def _move_light(root: ET.Element, refs: dict[str, RefLine], road: ET.Element, sig: ET.Element, xy: np.ndarray,
                inst: Instance, rec: Placed, shift_m: float, reach_m: float, ground: bool = True) -> None:
    """Rewrite ``sig`` (s, t, zOffset; its road if need be) so that CARLA puts it on ``inst``; fill ``rec``."""
    ref = refs[road.get("id")]
    s, t, over = ref.project(inst.centre[:2])
    # CARLA moves a light shift_m along its heading (road tangent + hOffset): write the point that far
    # back so that the light lands on the scanned head
    ho = float(sig.get("hOffset", 0.0))
    h_app = float(np.interp(s, ref.s, ref.hdg))
    s_w, t_w = s - shift_m * math.cos(ho), t - shift_m * math.sin(ho)
    host = ref
    if over > reach_m or not (0.0 <= s_w <= ref.length):
        # CARLA clamps s to the road (Road::GetDirectedPointInNoLaneOffset), so a light beyond the
        # approach's end cannot be written on it. Define the signal on the road whose frame holds
        # the light, and keep a <signalReference> with the lanes it controls on the approach.
        hb = _host(refs, inst.centre[:2], reach_m, exclude=ref.road)
        if hb is None:
            rec.note = f"scanned light {over:.2f} m beyond the road's end and on no other road: s clamped"
            s_w = min(max(s_w, 0.0), ref.length)
        else:
            host, hs, ht = hb
            hh = float(np.interp(hs, host.s, host.hdg))
            ho = float(sig.get("hOffset", 0.0))
            # keep the light's heading: the same direction measured from the host road's tangent
            ho_new = (h_app + ho - hh + math.pi) % (2 * math.pi) - math.pi
            s_w = hs - shift_m * math.cos(ho_new)
            t_w = ht - shift_m * math.sin(ho_new)
            _move_signal(root, road, host.road, sig, ho_new)
            rec.host_road = host.road
            rec.note = (f"scanned light {over:.2f} m beyond road {ref.road}'s end: signal defined on road "
                        f"{host.road}, referenced from road {ref.road} with its lanes (signalReference)")
    # the pole stands on the scanned ground under the head (kerb, sidewalk): CARLA's light blueprint carries its
    # heads at their own height
    zoff = float(inst.centre[2]) - host.z(s_w) - (inst.height_m if ground else 0.0)
    sig.set("name", SCAN_NAME)
    sig.set("s", _f(s_w))
    sig.set("t", _f(t_w))
    sig.set("zOffset", f"{zoff:.3f}")
    new_xy = _signal_xy(host, sig, shift_m)
    rec.s, rec.t, rec.z_offset, rec.source = s_w, t_w, zoff, "scan"
    rec.instance = inst.id
    if inst.evidence == "pole_head":
        rec.note = ((rec.note + "; ") if rec.note else "") + \
            "a pole carrying an unlabelled head (no traffic-light label there)"
    rec.instance_position = [round(float(v), 3) for v in inst.centre]
    rec.instance_size = [round(float(v), 3) for v in inst.size]
    rec.moved_m = float(np.hypot(*(new_xy - xy)))
    rec.new_xy = [float(v) for v in new_xy]


def _place_lights(root: ET.Element, refs: dict[str, RefLine], instances: list[Instance], log: list[str], *,
                  gate_m: float, group_m: float, shift_m: float, reach_m: float, wrong_side_m: float,
                  one_head: bool = True, ground: bool = True) -> list[Placed]:
    """Move netconvert's light groups onto the scanned lights (in place in ``root``); one record per signal.

    ``one_head``: a group's signals become one signal (``controllers.merge_heads``); ``ground``: a light's
    zOffset puts the pole's foot on the scanned ground under its head (``Instance.height_m`` below the head;
    netconvert's unpaired guesses: 0, the road's elevation)."""
    lights, groups = _light_groups(root, refs, group_m, shift_m)
    scan_lights = [inst for inst in instances if inst.kind == "light"]
    pairs = _pair_groups(lights, groups, refs, scan_lights, gate_m, wrong_side_m)
    placed: list[Placed] = []
    used = set()
    for gi, g in enumerate(groups):
        inst = pairs.get(gi)
        merged: list[str] = []
        if one_head and len(g) > 1 and np.ptp([float(lights[i][1].get("s")) for i in g]) < 0.01:
            # netconvert's pattern: a head's signals all at the road's end, one per lane and arrow
            keep, merged = merge_heads(lights[g[0]][0].find("signals"), [lights[i][1] for i in g])
            g = [i for i in g if lights[i][1] is keep]
        for i in g:
            road, sig, xy = lights[i]
            rec = _light_record(road, sig, xy)
            if inst is None:
                rec.note = "no scanned traffic light within the gate: netconvert's guess kept"
                if ground:
                    sig.set("zOffset", "0.000")
                    rec.z_offset = 0.0
            else:
                used.add(inst.id)
                _move_light(root, refs, road, sig, xy, inst, rec, shift_m, reach_m, ground)
            if merged:
                rec.note = ((rec.note + "; ") if rec.note else "") + \
                    f"one head for netconvert's signals {', '.join([sig.get('id')] + merged)} (their lanes in its validity)"
            placed.append(rec)
    for inst in scan_lights:
        if inst.id not in used and inst.evidence == "label":
            log.append(f"scanned traffic light {inst.id} at ({inst.centre[0]:.2f}, {inst.centre[1]:.2f}) matches no "
                       "netconvert light group (none left within the gate): not written")
    return placed


def _sign_kind(inst: Instance, colors, osm_signs, osm_match_m: float, used: set[int]) -> tuple[str | None, str]:
    """A scanned sign's kind and where it comes from: the nearest OSM sign node within ``osm_match_m`` (its index
    added to ``used``), else the plate's look (``signtypes``)."""
    if osm_signs:
        dist, i = min((math.hypot(x - inst.centre[0], y - inst.centre[1]), i) for i, (x, y, _) in enumerate(osm_signs))
        if dist <= osm_match_m:
            used.add(i)
            return osm_signs[i][2], f"OSM sign node {dist:.1f} m away"
    if colors is not None and inst.members is not None:
        kind, why = plate_look(colors[inst.members])
        pole = "; no pole found under it" if inst.evidence == "plate_look" else ""
        return kind, "the plate's look: " + why + pole
    return None, "no OSM sign near and no texture to read"


def _add_signs(root: ET.Element, refs: dict[str, RefLine], instances: list[Instance], log: list[str], *,
               sign_max_road_m: float, reach_m: float, colors=None, osm_signs=None,
               osm_match_m: float = 5.0, dedupe_m: float = 0.6) -> list[Placed]:
    """Add a signal per scanned sign on the road whose frame holds it, typed for CARLA where its kind is known
    (stop 206, yield 205, speed limit 274 with its value; ``signtypes``), else generic (-1); their records."""
    outside = {k: r for k, r in refs.items() if r.junction == "-1" and (r.lanes_right or r.lanes_left)}
    drivable = {k: r for k, r in refs.items() if r.lanes_right or r.lanes_left}
    placed: list[Placed] = []
    used: set[int] = set()
    n = 0
    for inst in (i for i in instances if i.kind == "sign"):
        # the road whose frame holds the sign (CARLA clamps s): outside junctions first
        best = _host(outside, inst.centre[:2], reach_m)
        if best is None or abs(best[2]) > sign_max_road_m:
            best = _host(drivable, inst.centre[:2], reach_m)
        if best is None or abs(best[2]) > sign_max_road_m:
            log.append(f"scanned sign {inst.id}: no road within {sign_max_road_m} m; not written")
            continue
        ref, s, t = best
        s = min(max(s, 0.0), ref.length)
        # right-hand traffic: a sign right of the reference line faces the lanes driving +s
        orient, lanes = ("+", ref.lanes_right) if t < 0 else ("-", ref.lanes_left)
        wrong_way = not lanes  # no lane drives towards it on its side: it faces a one-way street's wrong way
        if wrong_way:
            orient, lanes = ("-", ref.lanes_left) if t < 0 else ("+", ref.lanes_right)
        road_el = next(r for r in root.iter("road") if r.get("id") == ref.road)
        sg = _signals_el(road_el)
        kind, why = _sign_kind(inst, colors, osm_signs, osm_match_m, used)
        if kind == "stop" and wrong_way and not why.startswith("OSM"):
            # a red plate facing the wrong way of a one-way street is its no-entry sign, not a stop
            kind, why = None, why + "; it faces the wrong way of a one-way street: a no-entry sign"
        typ, sub, val = signal_type(kind, road_speed_kmh(road_el) if kind == "speed" else None)
        twin = next((p for p in placed if p.type == typ != UNKNOWN_SIGN_TYPE and p.instance_position and
                     math.dist(p.instance_position[:2], inst.centre[:2]) <= dedupe_m), None)
        if twin is not None:  # one plate split into two clusters: one CARLA sign
            log.append(f"scanned sign {inst.id}: a {kind} plate {math.dist(twin.instance_position[:2], inst.centre[:2]):.2f} m "
                       f"from {twin.id} of the same type: the same plate, not written again")
            continue
        sid = f"scan_sign_{n}"
        n += 1
        # a typed sign is a CARLA blueprint standing on the ground; a generic one stays a plate at its height
        zoff = float(inst.centre[2]) - ref.z(s) - (inst.height_m if typ != UNKNOWN_SIGN_TYPE else 0.0)
        attrs = {"id": sid, "name": SCAN_NAME, "s": _f(s), "t": _f(t), "zOffset": f"{zoff:.3f}",
                 "orientation": orient, "dynamic": "no", "country": "OpenDRIVE", "type": typ, "subtype": sub,
                 "height": f"{float(inst.size[2]):.3f}", "width": f"{float(inst.size[0]):.3f}"}
        if val is not None:
            attrs.update({"value": val, "unit": "km/h"})
        el = ET.SubElement(sg, "signal", attrs)
        if lanes:
            ET.SubElement(el, "validity", {"fromLane": str(min(lanes)), "toLane": str(max(lanes))})
        xy = ref.point(s, t)
        placed.append(Placed(sid, "sign", ref.road, s, t, zoff, orient, "scan", 0.0, inst.id,
                             [round(float(v), 3) for v in inst.centre], [round(float(v), 3) for v in inst.size],
                             typ, sub, None, [float(v) for v in xy],
                             (f"{kind} ({why})" if typ != UNKNOWN_SIGN_TYPE else
                              f"generic (-1): {kind or 'kind not known'} ({why})")))
    return placed + add_osm_signs(root, refs, osm_signs, used, log)


def place_signals(xodr_text: str, instances: list[Instance], *, gate_m: float = 15.0, group_m: float = 2.0,
                  carla_light_shift_m: float = 0.25, add_signs: bool = True,
                  sign_max_road_m: float = 12.0, reach_m: float = 0.05, wrong_side_m: float = 6.0,
                  one_head: bool = True, lights_on_ground: bool = True, phase_plan: str = "shape",
                  osm_signs: list | None = None, colors: np.ndarray | None = None, phases: dict | None = None
                  ) -> tuple[str, list[Placed], list[str]]:
    """Move netconvert's light groups onto the scanned lights; add the scanned signs.

    A *group* is the traffic-light signals of one road and orientation within ``group_m`` of each
    other along s (netconvert writes one per lane and turn arrow, all at the road's end): one head.
    Groups and scanned lights are paired by the Hungarian method on horizontal distance (labelled
    lights first, then poles carrying an unlabelled head), pairs farther than ``gate_m`` refused; a
    light on the other side of the reference line than the head's lanes costs ``wrong_side_m`` more
    (lights stand at their lanes' kerb; overhead or far-side lights still pair when nothing else fits).
    Each signal of a paired group gets the light's position in its own road's reference-line frame
    (s, t, zOffset = head centre above the road), or, past the road's end, in the frame of the road
    that holds it, with a signalReference left on its own road; its id, lanes (validity) and orientation
    stay. Unpaired groups keep netconvert's guess. ``one_head``: a group becomes one signal (type 1000001,
    its validity the group's lanes); ``lights_on_ground``: zOffset = the scanned ground under the head
    (CARLA's light blueprint is a whole pole); ``phase_plan`` (``shape`` | ``approach`` | ``netconvert``: left as written): one controller per
    phase of each junction, named from the junction (``controllers.wire_junctions``; ``phases``: a user plan by
    junction id or "default", lists of compass points traffic comes from). Signs: see
    ``_add_signs``; ``osm_signs``: OSM's sign nodes as (x, y, kind), site frame (``signtypes.osm_kind``);
    ``colors``: (n, 3) uint8 RGB of the mesh's vertices (``Instance.members`` index them) for the plate's look.
    """
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(xodr_text, parser=parser)
    refs = reference_lines(root)
    log: list[str] = []
    placed = _place_lights(root, refs, instances, log, gate_m=gate_m, group_m=group_m, shift_m=carla_light_shift_m,
                           reach_m=reach_m, wrong_side_m=wrong_side_m, one_head=one_head, ground=lights_on_ground)
    if phase_plan != "netconvert":
        _, wlog = wire_junctions(root, phase_plan, user=phases)
        log += wlog
    if add_signs:
        placed += _add_signs(root, refs, instances, log, sign_max_road_m=sign_max_road_m, reach_m=reach_m,
                             colors=colors, osm_signs=osm_signs)
    log += ground_typed_signs(root)
    log += clamp_to_roads(root, placed)  # carla.Map refuses s < 0 (signal_bounds.py)
    for sg in root.iter("signals"):  # tidy the blocks we edited (4-space indent, as netconvert writes)
        ET.indent(sg, space="    ", level=2)
    text = '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    return text, placed, log


# --------------------------------------------------------------------------- picture


def draw_signals(mesh_path, lines: list[dict], instances: list[Instance], rejected: list[Instance],
                 placed: list[Placed], out, px_per_m: float = 20.0, max_px: int = 4096, crop_m: float = 6.0) -> None:
    """Top view of the mesh with the lanes, the scanned instances (orange: lights, blue: signs, grey:
    rejected clusters), netconvert's signals (red crosses) and where they are now (green), arrows
    from old to new."""
    from PIL import Image, ImageDraw

    from twinkit.artefacts import read_textured_mesh

    from .mesh2d import picture_grid, rasterize

    mesh = read_textured_mesh(mesh_path)
    xy = mesh.vertices[:, :2]
    grid, res = picture_grid(xy, px_per_m, max_px)
    if mesh.colors is not None:
        cols = (mesh.colors[mesh.faces].mean(1) * 0.6).astype(np.uint8)  # darkened: the markers must stand out
    else:
        cols = np.full((len(mesh.faces), 3), 80, np.uint8)
    img = Image.fromarray(rasterize(mesh.vertices, mesh.faces, grid, colours=cols))
    d = ImageDraw.Draw(img)
    w = max(1, int(round(0.06 / res)))
    r = max(3, int(round(0.35 / res)))
    for ln in lines:
        for key in ("left", "right"):
            q = [tuple(v) for v in grid.to_px(ln[key])]
            if len(q) >= 2:
                d.line(q, fill=(200, 200, 200), width=max(1, w // 2))

    def px(p):
        return tuple(grid.to_px(np.asarray(p, float)[:2]))

    for inst in rejected:
        x, y = px(inst.centre)
        d.rectangle([x - r // 2, y - r // 2, x + r // 2, y + r // 2], outline=(150, 150, 150), width=w)
    for inst in instances:
        x, y = px(inst.centre)
        col = (255, 150, 0) if inst.kind == "light" else (60, 140, 255)
        d.rectangle([x - r, y - r, x + r, y + r], outline=col, width=2 * w)
        tag = " (pole+head)" if inst.evidence == "pole_head" else ""
        d.text((x + r + 2, y - r), f"{inst.kind} {inst.id}{tag}", fill=col)
    for p in placed:
        if p.old_xy is not None:
            x, y = px(p.old_xy)
            d.line([x - r, y - r, x + r, y + r], fill=(255, 40, 40), width=w)
            d.line([x - r, y + r, x + r, y - r], fill=(255, 40, 40), width=w)
        if p.new_xy is not None:
            x1, y1 = px(p.new_xy)
            if p.old_xy is not None and p.source == "scan":
                d.line([px(p.old_xy), (x1, y1)], fill=(120, 255, 120), width=max(1, w // 2))
            col = (40, 230, 40) if p.source == "scan" else (255, 40, 40)
            d.ellipse([x1 - r // 2, y1 - r // 2, x1 + r // 2, y1 + r // 2], outline=col, width=w)
    d.rectangle([8, 8, 420, 92], fill=(0, 0, 0))
    d.text((16, 14), "orange / blue squares: scanned traffic lights / signs", fill=(255, 150, 0))
    d.text((16, 30), "grey squares: clusters rejected (noise)", fill=(150, 150, 150))
    d.text((16, 46), "red crosses: netconvert's signals (red circle: kept)", fill=(255, 40, 40))
    d.text((16, 62), "green circles: signals placed from the scan", fill=(40, 230, 40))
    bar = 10.0 / res
    d.line([(16, 84), (16 + bar, 84)], fill=(255, 255, 255), width=3)
    d.text((22 + bar, 76), "10 m", fill=(255, 255, 255))
    img.save(out)


def carla_position_errors(moved_text: str, placed: list[Placed], source: str) -> dict[str, float]:
    """Per placed signal id: metres (horizontal, site frame) between where CARLA puts it in ``moved_text``
    (``twinkit.street.lanes.LaneMap``'s landmarks) and where it was meant to be (``Placed.new_xy``).
    ``source`` names the map in the error. An OpenDRIVE carla.Map cannot read is an ``OpenDriveError`` (an
    ``InputError``; its ``why`` says what carla.Map refused)."""
    from twinkit.street.lanes import LaneMap

    m = LaneMap(moved_text, "signals", source=source)
    want = {p.id: p.new_xy for p in placed}
    err = {}
    for lm in m.landmarks():
        w = want.get(lm.id)
        if w is not None:
            err[lm.id] = round(float(math.hypot(lm.xyz[0] - w[0], lm.xyz[1] - w[1])), 4)
    return err


def signals_report(placed: list[Placed], kept: list[Instance], rejected: list[Instance], notes: list[str],
                   carla_err: dict[str, float], params: dict, plan: dict | None = None) -> tuple[dict, dict]:
    """signals.json (the placed signals with CARLA's position error, the instances, the notes, CARLA's light
    plan as ``twinkit.street.lights.light_plan`` emulates it) and the place_signals step's metrics (counts,
    the median move of the scanned lights in m, groups per junction, conflicting greens, typed signs)."""
    lights = [p for p in placed if p.kind == "light"]
    n_scan = sum(p.source == "scan" for p in lights)
    doc = {
        "signals": [dict(p.to_json(), carla_position_error_m=carla_err.get(p.id)) for p in placed],
        "instances": [i.to_json() for i in kept], "rejected_clusters": [i.to_json() for i in rejected],
        "notes": notes,
        "definition": "position: where CARLA 0.9.16 puts the signal (x, y site frame, m); s, t, zOffset in the road's "
                      "reference-line frame of defined_on_road; road = the road whose lanes it controls (a "
                      "signalReference there when defined_on_road differs); source scan|netconvert; moved_m = "
                      "horizontal distance from netconvert's position",
        "params": params,
        "light_plan": plan,
    }
    moved_m = [p.moved_m for p in lights if p.source == "scan"]
    metrics = {"scanned_lights": sum(i.kind == "light" for i in kept),
               "scanned_signs": sum(i.kind == "sign" for i in kept),
               "pole_head_lights": sum(i.evidence == "pole_head" for i in kept),
               "rejected_clusters": len(rejected), "light_signals": len(lights), "light_signals_from_scan": n_scan,
               "light_signals_netconvert": len(lights) - n_scan, "signs_written": sum(p.kind == "sign" for p in placed),
               "median_moved_m": round(float(np.median(moved_m)), 3) if moved_m else 0.0,
               "max_carla_position_error_m": max(carla_err.values(), default=0.0)}
    js = (plan or {}).get("junctions", {})
    signs = [p for p in placed if p.kind == "sign"]
    metrics.update({"signalised_junctions": len(js),
                    "max_light_groups_per_junction": max((v["groups"] for v in js.values()), default=0),
                    "conflicting_greens": sum(len(v["conflicts"]) for v in js.values()),
                    "signs_typed": sum(p.type != UNKNOWN_SIGN_TYPE for p in signs),
                    "signs_generic": sum(p.type == UNKNOWN_SIGN_TYPE for p in signs)})
    return doc, metrics
