"""How CARLA 0.9.16 groups and cycles the traffic lights of an OpenDRIVE map, emulated offline.

The one place twinkit knows CARLA's traffic-light logic (the Unreal side cannot run here; it was read line
by line, carla-simulator/carla, release 0.9.16):

- ``LibCarla/source/carla/road/MapBuilder.cpp`` ``MapBuilder::SolveControllerAndJuntionReferences``: a
  controller learns its junctions, and a signal its controllers, only through ``<junction><controller id=..>``.
  A ``<controller>`` no junction names leaves its signals with no controller at all.
- ``Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/TrafficLightManager.cpp``
  ``ATrafficLightManager::SpawnTrafficLights``: spawns every signal a ``<controller>`` lists, plus every
  traffic light with no controller that is not on a junction road; ``RegisterLightComponent``: a light with
  controllers joins controller ``*GetControllers().begin()`` (the smallest id, a std::set of strings) in the
  group of that controller's smallest junction id (one ``ATrafficLightGroup`` per junction); a light without
  one gets a group and a controller of its own (``LoneTrafficLightsGroupControllerId``, red time 10 s).
- ``TrafficLightGroup.cpp`` ``ResetGroup`` / ``NextCycleStep`` / ``NextController`` and
  ``TrafficLightController.cpp`` ``NextState`` / ``IsCycleFinished`` with the stages of
  ``TrafficLightController.h`` (``LightStates``: green 10 s, yellow 3 s, red 2 s): in a group one controller
  at a time runs green, yellow, red, then the next; every other controller of the group stays red. All
  groups start together (``ResetGroup`` at registration), so lights in different groups are green at once.

An *approach* is the way a light's lanes enter its junction: the lanes of its ``<validity>`` and of every
``<signalReference>`` to it (lane 0 skipped, as ``GenerateTriggerBoxesForTrafficLights`` /
``UTrafficLightComponent::InitializeSign`` do), right-hand traffic (lanes < 0 drive along +s). Two approaches
of one junction *conflict* when their entry headings cross (between ``cross_deg`` apart); opposite and
same-direction approaches do not.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

#: SignalType::IsTrafficLight (LibCarla/source/carla/road/SignalType.cpp, carla 0.9.16)
LIGHT_TYPES = frozenset({"1000001", "1000002", "1000009", "1000010", "1000011", "1000007", "1000014", "1000015",
                         "1000016", "1000017", "1000018", "1000019", "1000013", "1000020", "1000008", "1000012",
                         "F", "W", "A"})
#: TrafficLightController.h LightStates: (state, seconds)
STAGES = (("green", 10.0), ("yellow", 3.0), ("red", 2.0))
#: the red time RegisterLightComponent gives a lone light's controller
LONE_RED_S = 10.0


@dataclass
class Approach:
    """Where a light's lanes enter a junction: junction id (None: no junction ahead), entry heading (rad,
    the file's frame, counter-clockwise from x), the incoming road ids."""
    junction: str | None
    heading: float | None
    roads: list[str] = field(default_factory=list)


@dataclass
class Light:
    """A traffic light CARLA spawns: its signal id, the group (junction id, or ``lone:<id>``) and controller
    RegisterLightComponent puts it in, and its approach."""
    id: str
    road: str
    group: str
    controller: str
    approach: Approach
    z_offset: float


def _end_heading(road: ET.Element) -> tuple[float, float]:
    """Heading (rad) of a road's reference line at s = 0 and s = length (plan view: line, arc, spiral,
    paramPoly3)."""
    geos = road.findall("planView/geometry")
    if not geos:
        return 0.0, 0.0
    h0 = float(geos[0].get("hdg", 0.0))
    g = geos[-1]
    h, ln = float(g.get("hdg", 0.0)), float(g.get("length", 0.0))
    kind = next(iter(g), None)
    if kind is not None and kind.tag == "arc":
        h += float(kind.get("curvature", 0.0)) * ln
    elif kind is not None and kind.tag == "spiral":
        h += 0.5 * (float(kind.get("curvStart", 0.0)) + float(kind.get("curvEnd", 0.0))) * ln
    elif kind is not None and kind.tag == "paramPoly3":
        p = 1.0 if kind.get("pRange", "normalized") == "normalized" else ln
        du = float(kind.get("bU", 0.0)) + 2 * float(kind.get("cU", 0.0)) * p + 3 * float(kind.get("dU", 0.0)) * p * p
        dv = float(kind.get("bV", 0.0)) + 2 * float(kind.get("cV", 0.0)) * p + 3 * float(kind.get("dV", 0.0)) * p * p
        h += math.atan2(dv, du)
    return h0, h


def _lanes(el: ET.Element) -> list[int]:
    out: list[int] = []
    for v in el.findall("validity"):
        a, b = int(v.get("fromLane", 0)), int(v.get("toLane", 0))
        out += [k for k in range(min(a, b), max(a, b) + 1) if k != 0]
    return out


class Wiring:
    """An OpenDRIVE map's signals, controllers and junctions as CARLA's MapBuilder reads them."""

    def __init__(self, xodr_text: str):
        root = ET.fromstring(xodr_text)
        self.roads = {r.get("id", ""): r for r in root.findall("road")}
        self.road_junction = {k: r.get("junction", "-1") for k, r in self.roads.items()}
        self.signals: dict[str, tuple[str, ET.Element]] = {}
        self.controls: dict[str, list[tuple[str, list[int], str]]] = {}  # signal -> (road, lanes, orientation)
        for rid, road in self.roads.items():
            for sig in road.findall("signals/signal"):
                sid = sig.get("id", "")
                self.signals[sid] = (rid, sig)
                self.controls.setdefault(sid, []).append((rid, _lanes(sig), sig.get("orientation", "+")))
            for ref in road.findall("signals/signalReference"):
                self.controls.setdefault(ref.get("id", ""), []).append((rid, _lanes(ref), ref.get("orientation", "+")))
        self.controllers = {c.get("id", ""): [x.get("signalId", "") for x in c.findall("control")]
                            for c in root.findall("controller")}
        self.junction_controllers = {j.get("id", ""): [c.get("id", "") for c in j.findall("controller")]
                                     for j in root.findall("junction")}
        self._heads = {k: _end_heading(r) for k, r in self.roads.items()}

    def _link(self, road: str, which: str) -> str | None:
        el = self.roads[road].find(f"link/{which}")
        if el is not None and el.get("elementType") == "junction":
            return el.get("elementId")
        return None

    def approach(self, signal_id: str) -> Approach:
        """The approach a signal controls (see the module doc); heading is the circular mean over its lanes."""
        js, hs, roads = [], [], []
        for road, lanes, orient in self.controls.get(signal_id, []):
            if road not in self.roads:
                continue
            if not lanes:  # GenerateDefaultValiditiesForSignalReferences: the lanes facing the orientation
                lanes = [-1] if orient != "-" else [1]
            h0, h1 = self._heads[road]
            jn = self.road_junction[road]
            for lane in lanes:
                if jn != "-1":  # a connecting road: the movement starts at its entry end
                    js.append(jn)
                    hs.append(h0 if lane < 0 else h1 + math.pi)
                else:
                    j = self._link(road, "successor" if lane < 0 else "predecessor")
                    if j is None:
                        continue
                    js.append(j)
                    hs.append(h1 if lane < 0 else h0 + math.pi)
                roads.append(road)
        if not js:
            return Approach(None, None, sorted(set(roads)))
        junction = max(set(js), key=js.count)
        hh = [h for j, h in zip(js, hs) if j == junction]
        return Approach(junction, math.atan2(sum(map(math.sin, hh)), sum(map(math.cos, hh))), sorted(set(roads)))

    def lights(self) -> list[Light]:
        """The lights SpawnTrafficLights spawns, each with the group and controller RegisterLightComponent gives
        it (module doc)."""
        sig_ctrls: dict[str, set[str]] = {}
        ctrl_junctions: dict[str, set[int]] = {}
        for jid, cids in self.junction_controllers.items():  # SolveControllerAndJuntionReferences
            for cid in cids:
                if cid not in self.controllers:
                    continue
                ctrl_junctions.setdefault(cid, set()).add(int(jid))
                for sid in self.controllers[cid]:
                    if sid in self.signals:
                        sig_ctrls.setdefault(sid, set()).add(cid)
        spawn = {sid for ids in self.controllers.values() for sid in ids if sid in self.signals}
        spawn |= {sid for sid, (road, el) in self.signals.items()
                  if not sig_ctrls.get(sid) and self.road_junction[road] == "-1" and el.get("type") in LIGHT_TYPES}
        out = []
        for sid in sorted(spawn):
            road, el = self.signals[sid]
            if sig_ctrls.get(sid):
                cid = min(sig_ctrls[sid])
                group, ctrl = str(min(ctrl_junctions[cid])), cid
            else:
                group, ctrl = f"lone:{sid}", f"lone:{sid}"
            out.append(Light(sid, road, group, ctrl, self.approach(sid), float(el.get("zOffset", 0.0))))
        return out


def crossing(h1: float | None, h2: float | None, cross_deg: tuple[float, float] = (30.0, 150.0)) -> bool:
    """Whether two entry headings (rad) cross: their angle between ``cross_deg`` (degrees)."""
    if h1 is None or h2 is None:
        return False
    d = abs(math.degrees((h1 - h2 + math.pi) % (2 * math.pi) - math.pi))
    return cross_deg[0] <= d <= cross_deg[1]


def _go_windows(lights: list[Light]) -> dict[str, tuple[float, float, float]]:
    """Per light: (start, end, period) of its non-red window in its group's cycle (TrafficLightGroup: controllers
    in turn, each green + yellow + red; registration order = the order lights were registered)."""
    order: dict[str, list[str]] = {}
    for lt in lights:
        ctrls = order.setdefault(lt.group, [])
        if lt.controller not in ctrls:
            ctrls.append(lt.controller)
    go = STAGES[0][1] + STAGES[1][1]
    out = {}
    for lt in lights:
        red = LONE_RED_S if lt.group.startswith("lone:") else STAGES[2][1]
        step = go + red
        k = order[lt.group].index(lt.controller)
        out[lt.id] = (k * step, k * step + go, step * len(order[lt.group]))
    return out


def green_together(a: tuple[float, float, float], b: tuple[float, float, float], horizon_s: float = 600.0) -> bool:
    """Whether two non-red windows (start, end, period; all groups start at t = 0) overlap within the horizon."""
    t = 0.0
    while t < horizon_s:
        ta = math.floor(t / a[2]) * a[2]
        tb = math.floor(t / b[2]) * b[2]
        if ta + a[0] <= t < ta + a[1] and tb + b[0] <= t < tb + b[1]:
            return True
        t += 0.5
    return False


def light_plan(xodr_text: str, cross_deg: tuple[float, float] = (30.0, 150.0)) -> dict:
    """The emulated CARLA light plan of a map, per junction with lights: its groups, controllers, lights, and
    the pairs of crossing approaches whose lights are green together at some moment of the cycle.

    Returns ``{"junctions": {jid: {"groups", "controllers", "lights", "conflicts": [[id, id], ...]}},
    "lights": [...], "no_junction": [ids of lights with no junction ahead]}``.
    """
    w = Wiring(xodr_text)
    lights = w.lights()
    win = _go_windows(lights)
    per: dict[str, list[Light]] = {}
    loose = []
    for lt in lights:
        if lt.approach.junction is None:
            loose.append(lt.id)
        else:
            per.setdefault(lt.approach.junction, []).append(lt)
    junctions = {}
    for jid, ls in sorted(per.items()):
        conflicts = []
        for i, a in enumerate(ls):
            for b in ls[i + 1:]:
                if crossing(a.approach.heading, b.approach.heading, cross_deg) and green_together(win[a.id], win[b.id]):
                    conflicts.append([a.id, b.id])
        junctions[jid] = {"groups": len({lt.group for lt in ls}), "controllers": len({lt.controller for lt in ls}),
                          "lights": len(ls), "approaches": len({round(lt.approach.heading or 0.0, 1) for lt in ls}),
                          "conflicts": conflicts}
    return {"junctions": junctions, "no_junction": loose,
            "lights": [{"id": lt.id, "road": lt.road, "group": lt.group, "controller": lt.controller,
                        "junction": lt.approach.junction, "zOffset": lt.z_offset,
                        "heading_deg": None if lt.approach.heading is None else round(math.degrees(lt.approach.heading), 1)}
                       for lt in lights]}
