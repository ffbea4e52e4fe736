"""The package's OpenDRIVE signals as CARLA 0.9.16 runs them: light groups, the cycle, heights, sign types.

Rules (ids in ``RULES``, applied by :func:`check_signals`, called from ``carla_contract.check_package``):

- ``light_groups``: a junction's lights share one ``ATrafficLightGroup`` only when the junction names their
  controllers (``MapBuilder::SolveControllerAndJuntionReferences``; ``ATrafficLightManager::
  RegisterLightComponent`` gives a light without a junction-named controller a group of its own). Every
  junction with lights must come out with exactly one group (``twinkit.street.lights`` emulates both).
- ``conflicting_greens``: in a group one controller at a time runs green-yellow-red (``ATrafficLightGroup::
  NextCycleStep`` / ``NextController``), and all groups start together: no two crossing approaches of a
  junction may be green at one moment of the emulated cycle.
- ``signal_heights``: CARLA spawns a whole pole blueprint at road elevation + ``zOffset``
  (``MapBuilder::ComputeSignalTransform``, ``SpawnTrafficLights`` / ``SpawnSignals``; its ground fix runs only
  for Town15-like maps), so a light or a stop / yield / speed-limit sign stands on the ground only with
  ``|zOffset|`` <= ``max_z_offset_m``; and one pole per head: lights of one junction closer than
  ``stacked_m`` are stacked poles.
- ``sign_types``: ``SpawnSignals`` spawns sign actors by type ("206" stop, "205" yield; later releases
  ``BP_SpeedLimit<subtype>`` for "274"); a speed limit needs its value (``Landmark.value``) and the same
  number as subtype. Signs of the generic type "-1" spawn nothing; they are counted, not refused.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

SRC_BUILDER = "LibCarla/source/carla/road/MapBuilder.cpp (SolveControllerAndJuntionReferences, ComputeSignalTransform)"
SRC_MANAGER = ("Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/TrafficLightManager.cpp (SpawnTrafficLights, "
               "RegisterLightComponent, SpawnSignals)")
SRC_CYCLE = ("Unreal/CarlaUE4/Plugins/Carla/Source/Carla/Traffic/TrafficLightGroup.cpp (NextCycleStep, NextController), "
             "TrafficLightController.cpp/.h (NextState, LightStates)")
SRC_TYPES = "LibCarla/source/carla/road/SignalType.cpp; " + SRC_MANAGER

RULES: dict[str, tuple[str, str]] = {
    "light_groups": ("a junction's traffic lights form one light group only when the junction names their controllers "
                     "(<junction><controller id=..>); a light without one runs alone, green with all the others",
                     f"{SRC_BUILDER}; {SRC_MANAGER}"),
    "conflicting_greens": ("in a light group one controller at a time is green or yellow; groups run side by side: no "
                           "two crossing approaches of a junction may be green together", f"{SRC_MANAGER}; {SRC_CYCLE}"),
    "signal_heights": ("CARLA spawns a whole pole at road elevation + zOffset: lights and stop / yield / speed-limit "
                       "signs need zOffset near 0, and one pole per head", f"{SRC_BUILDER}; {SRC_MANAGER}"),
    "sign_types": ("sign actors are spawned by type: 206 stop, 205 yield (274 speed limit by its subtype, with its "
                   "value as the landmark's); -1 spawns nothing", SRC_TYPES),
}
#: the types CARLA spawns a sign blueprint for
TYPED_SIGNS = {"206": "stop", "205": "yield", "274": "speed limit"}


def _heights_and_types(text: str, max_z_offset_m: float) -> tuple[list[str], list[str], int]:
    """(signal_heights messages, sign_types messages, generic sign count) of one map."""
    from twinkit.street.lights import LIGHT_TYPES

    heights, types, generic = [], [], 0
    for sig in ET.fromstring(text).iter("signal"):
        sid, typ = sig.get("id"), sig.get("type", "-1")
        z = float(sig.get("zOffset", 0.0))
        if (typ in LIGHT_TYPES or typ in TYPED_SIGNS) and abs(z) > max_z_offset_m:
            what = "traffic light" if typ in LIGHT_TYPES else TYPED_SIGNS[typ] + " sign"
            heights.append(f"{what} {sid}: zOffset {z:.2f} m, its pole would stand {z:.2f} m off the road")
        if typ == "274":
            val, sub = sig.get("value"), sig.get("subtype")
            try:
                ok = val is not None and float(val) > 0 and sub is not None and float(sub) == float(val)
            except ValueError:
                ok = False
            if not ok:
                types.append(f"speed limit {sid}: value {val!r}, subtype {sub!r}; both must be the limit in km/h")
        elif typ in ("205", "206") and sig.get("subtype", "-1") != "-1":
            types.append(f"{TYPED_SIGNS[typ]} sign {sid}: subtype {sig.get('subtype')!r}, expected '-1'")
        elif typ == "-1" and sig.get("dynamic", "no") == "no":
            generic += 1
    return heights, types, generic


def _stacked(text: str, plan: dict, stacked_m: float) -> list[str]:
    """Lights of one junction standing closer than ``stacked_m`` (CARLA positions, ``LaneMap.landmarks``)."""
    try:
        from twinkit.street.lanes import LaneMap, OpenDriveError
    except ImportError:  # pragma: no cover - carla wheel missing
        return []
    try:
        pos = {lm.id: lm.xyz[:2] for lm in LaneMap(text, "signals").landmarks()}
    except OpenDriveError:
        return []
    by_j: dict[str, list[str]] = {}
    for lt in plan["lights"]:
        if lt["junction"] is not None and lt["id"] in pos:
            by_j.setdefault(lt["junction"], []).append(lt["id"])
    out = []
    for jid, ids in by_j.items():
        for i, a in enumerate(ids):
            for b in ids[i + 1:]:
                d = math.dist(pos[a], pos[b])
                if d < stacked_m:
                    out.append(f"junction {jid}: lights {a} and {b} {d:.2f} m apart (one pole each: stacked)")
    return out


def check_signals(rep, xodrs: list[Path], *, max_z_offset_m: float = 1.0, stacked_m: float = 0.5) -> dict:
    """Apply the signal rules to each map's OpenDRIVE; add violations to ``rep`` (``rep.add(rule, message)``).

    Returns per map: the emulated plan's junctions (groups, controllers, lights, conflicts), the counts of
    violations per rule and of generic signs."""
    from twinkit.street.lights import light_plan

    out = {}
    for x in xodrs:
        if not Path(x).is_file():
            continue
        text = Path(x).read_text()
        try:
            plan = light_plan(text)
        except (ET.ParseError, ValueError, KeyError) as exc:
            rep.add("light_groups", f"{Path(x).name}: cannot read its signals ({exc})")
            continue
        found: dict[str, list[str]] = {k: [] for k in RULES}
        for jid, j in plan["junctions"].items():
            if j["groups"] != 1:
                found["light_groups"].append(f"junction {jid}: its {j['lights']} lights fall into {j['groups']} light "
                                             "groups (its controllers are not named by the junction)")
            for a, b in j["conflicts"]:
                found["conflicting_greens"].append(f"junction {jid}: lights {a} and {b} guard crossing approaches "
                                                   "and are green together")
        heights, types, generic = _heights_and_types(text, max_z_offset_m)
        found["signal_heights"] = heights
        found["stacked"] = _stacked(text, plan, stacked_m)
        found["sign_types"] = types
        for key, msgs in found.items():
            if msgs:
                more = f" (and {len(msgs) - 3} more)" if len(msgs) > 3 else ""
                rep.add("signal_heights" if key == "stacked" else key,
                        f"{Path(x).name}: {len(msgs)} problem(s): " + "; ".join(msgs[:3]) + more)
        out[Path(x).name] = {"junctions": plan["junctions"], "problems": {k: len(v) for k, v in found.items()},
                             "generic_signs": generic}
    return out
