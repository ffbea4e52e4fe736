"""Traffic-light heads and junction controllers CARLA cycles as a signal plan.

netconvert writes one ``<signal>`` per lane and turn arrow (3-4 stacked at one pole) and one ``<controller>``
holding all of a junction's signals that no ``<junction>`` names. CARLA then gives every light a group of its
own and all turn green together (``twinkit.street.lights``, which emulates CARLA 0.9.16's grouping and
cycle and cites its source). Here:

- :func:`merge_heads`: one signal per head (an approach's signals at one pole become one type-1000001 signal
  whose validity covers all their lanes, so CARLA still builds a trigger box on each lane);
- :func:`wire_junctions`: per junction, one ``<controller>`` per phase, each named from the junction
  (``<junction><controller id=.. type="0" sequence=k/>``, as CARLA's own maps do), so
  ``MapBuilder::SolveControllerAndJuntionReferences`` links them and ``TrafficLightManager`` puts the
  junction's lights in one group that runs the phases in turn.

The phase plan: ``approach`` (each approach alone, CARLA's Town maps and its OSM importer) or ``shape``
(the default: opposite approaches share a phase, so a 4-way junction has 2 phases and a T junction 2;
left turns across the opposite stream then yield, as at a permissive signal). Crossing approaches never
share a phase in either plan.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from twinkit.street.lights import LIGHT_TYPES, Wiring, crossing, light_plan

#: the signal type of a plain three-light head (SignalType.cpp: IsTrafficLight)
HEAD_TYPE = "1000001"


def _lane_ranges(lanes: list[int]) -> list[tuple[int, int]]:
    """Sorted lane ids -> contiguous (from, to) runs, never across lane 0."""
    runs: list[tuple[int, int]] = []
    for k in sorted(set(lanes)):
        if runs and k == runs[-1][1] + 1:
            runs[-1] = (runs[-1][0], k)
        else:
            runs.append((k, k))
    return runs


def merge_heads(signals_el: ET.Element, sigs: list[ET.Element]) -> tuple[ET.Element, list[str]]:
    """Merge one head's signals (elements of ``signals_el``) into one: the plain head (type 1000001) if there
    is one, else the first, typed 1000001, with validity covering every lane of the group. The others are
    removed. Returns the kept element and the removed signal ids."""
    keep = next((s for s in sigs if s.get("type") == HEAD_TYPE), sigs[0])
    lanes = [k for s in sigs for v in s.findall("validity")
             for k in range(min(int(v.get("fromLane", 0)), int(v.get("toLane", 0))),
                            max(int(v.get("fromLane", 0)), int(v.get("toLane", 0))) + 1) if k != 0]
    for v in keep.findall("validity"):
        keep.remove(v)
    for a, b in _lane_ranges(lanes):
        ET.SubElement(keep, "validity", {"fromLane": str(a), "toLane": str(b)})
    keep.set("type", HEAD_TYPE)
    keep.set("subtype", "-1")
    removed = []
    for s in sigs:
        if s is not keep:
            signals_el.remove(s)
            removed.append(s.get("id"))
    return keep, removed


def _approaches(heads: dict[str, float], tol_deg: float = 25.0) -> list[list[str]]:
    """Signals grouped by entry heading (within ``tol_deg``): one list per approach, ordered by heading."""
    out: list[tuple[float, list[str]]] = []
    for sid, h in sorted(heads.items(), key=lambda kv: kv[1]):
        for i, (h0, ids) in enumerate(out):
            if abs(math.degrees((h - h0 + math.pi) % (2 * math.pi) - math.pi)) <= tol_deg:
                ids.append(sid)
                break
        else:
            out.append((h, [sid]))
    return [ids for _, ids in out]


COMPASS = ("E", "NE", "N", "NW", "W", "SW", "S", "SE")


def compass_from(heading: float) -> str:
    """The compass point traffic with this entry heading (rad, x east, y north) comes from: E, NE, ... SE."""
    a = math.degrees(heading + math.pi) % 360.0
    return COMPASS[int(round(a / 45.0)) % 8]


def _user_phases(heads: dict[str, float], apps: list[list[str]], spec: list) -> list[list[str]]:
    """Phases from a user plan: lists of compass points traffic comes from (``[["N", "S"], ["E", "W"]]``);
    an approach takes the first phase naming its point; approaches named by none run alone."""
    phases: list[list[str]] = [[] for _ in spec]
    alone = []
    for a in apps:
        h = math.atan2(sum(math.sin(heads[s]) for s in a), sum(math.cos(heads[s]) for s in a))
        k = next((i for i, ph in enumerate(spec) if compass_from(h) in [str(x).upper() for x in ph]), None)
        if k is None:
            alone.append(a)
        else:
            phases[k] += a
    return [p for p in phases if p] + alone


def phase_plan(heads: dict[str, float], plan: str = "shape", cross_deg: tuple[float, float] = (30.0, 150.0),
               opposite_deg: float = 30.0, user: list | None = None) -> list[list[str]]:
    """Signal ids per phase for one junction from their approach headings (rad).

    ``user``: a plan as lists of compass points traffic comes from (``_user_phases``), used as given.
    ``approach``: one phase per approach. ``shape``: approaches whose headings are opposite (within
    ``opposite_deg`` of 180 degrees) and cross no other member share a phase; the rest run alone.
    """
    apps = _approaches(heads)
    if user:
        return _user_phases(heads, apps, user)
    if plan == "approach":
        return apps
    if plan != "shape":
        raise ValueError(f"phase plan {plan!r}: expected 'shape' or 'approach'")
    mean = [math.atan2(sum(math.sin(heads[s]) for s in a), sum(math.cos(heads[s]) for s in a)) for a in apps]
    used: set[int] = set()
    phases = []
    for i in range(len(apps)):
        if i in used:
            continue
        used.add(i)
        members = [i]
        for j in range(i + 1, len(apps)):
            d = abs(math.degrees((mean[i] - mean[j] + math.pi) % (2 * math.pi) - math.pi))
            if j not in used and abs(d - 180.0) <= opposite_deg and \
                    not any(crossing(mean[j], mean[m], cross_deg) for m in members):
                members.append(j)
                used.add(j)
                break
        phases.append([s for m in members for s in apps[m]])
    return phases


def wire_junctions(root: ET.Element, plan: str = "shape", cross_deg: tuple[float, float] = (30.0, 150.0),
                   user: dict | None = None) -> tuple[dict, list[str]]:
    """Give every junction whose lights CARLA would not run as one conflict-free group (``light_plan``) one
    controller per phase, named from the junction (in place in ``root``); junctions that already run right
    (CARLA's own maps) and their controllers stay as they are, unless ``user`` names them.

    ``user``: phase plans by junction id or ``"default"`` (``phase_plan``'s ``user``); a phase holding crossing
    approaches is kept as given and logged. Lights with no junction ahead keep no controller (CARLA runs each
    alone). Returns a summary
    (per junction: approaches, phases as lists of signal ids, controller ids) and log lines.
    """
    text = ET.tostring(root, encoding="unicode")
    w = Wiring(text)
    good = {j for j, v in light_plan(text, cross_deg)["junctions"].items() if v["groups"] == 1 and not v["conflicts"]
            and not (user and (j in user or "default" in user))}  # a plan the user gives is always applied
    keep_ctrl = {c for j in good for c in w.junction_controllers.get(j, [])}
    per: dict[str, dict[str, float]] = {}
    log: list[str] = []
    for sid, (road, el) in w.signals.items():
        if el.get("type") not in LIGHT_TYPES or any(sid in w.controllers.get(c, []) for c in keep_ctrl):
            continue
        ap = w.approach(sid)
        if ap.junction is None or ap.heading is None:
            log.append(f"traffic light {sid} on road {road}: no junction ahead of its lanes, left without a "
                       "controller (CARLA runs it alone)")
            continue
        if ap.junction not in good:
            per.setdefault(ap.junction, {})[sid] = ap.heading
    for c in root.findall("controller"):
        if c.get("id") not in keep_ctrl:
            root.remove(c)
    for j in root.findall("junction"):
        for c in j.findall("controller"):
            if c.get("id") not in keep_ctrl:
                j.remove(c)
    kids = list(root)
    at = next((i for i, e in enumerate(kids) if e.tag == "junction"), len(kids))
    junctions = {j.get("id"): j for j in root.findall("junction")}
    summary: dict = {}
    n = 0
    taken = {c.get("id") for c in root.findall("controller")}
    for jid in sorted(per, key=lambda x: (len(x), x)):
        spec = (user or {}).get(jid) or (user or {}).get("default")
        phases = phase_plan(per[jid], plan, cross_deg, user=spec)
        for ph in phases:
            if any(crossing(per[jid][a], per[jid][b], cross_deg) for a in ph for b in ph if a < b):
                log.append(f"junction {jid}: the given phase {sorted(ph)} lets crossing approaches go together")
        ids = []
        for k, sids in enumerate(phases):
            while f"{1000 + n}" in taken:
                n += 1
            cid = f"{1000 + n}"
            n += 1
            ctl = ET.Element("controller", {"id": cid, "name": f"junction{jid}_phase{k}", "sequence": str(k)})
            for sid in sorted(sids):
                ET.SubElement(ctl, "control", {"signalId": sid, "type": "0"})
            ET.indent(ctl, space="    ", level=1)
            ctl.tail = "\n    "
            root.insert(at, ctl)
            at += 1
            if jid in junctions:
                ref = ET.SubElement(junctions[jid], "controller", {"id": cid, "type": "0", "sequence": str(k)})
                ref.tail = "\n    "
            ids.append(cid)
        summary[jid] = {"approaches": len(_approaches(per[jid])), "phases": [sorted(p) for p in phases],
                        "controllers": ids, "plan": plan}
    return summary, log
