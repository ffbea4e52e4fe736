"""OSM's stop and give-way nodes the scan has no plate for, written as OpenDRIVE signals CARLA spawns.

netconvert keeps no sign in its OpenDRIVE, so an unsignalised junction loses OSM's ``highway=stop`` /
``highway=give_way`` (and ``traffic_sign=*`` stop / give-way codes). Each such node (``signtypes.osm_kind``, in the
aligned frame, ``signtypes.osm_sign_nodes``) with no scanned sign within ``osm_match_m`` becomes a signal of type
206 / 205 on the approach it guards: the road outside junctions whose lanes carry traffic from the node into a
junction within ``reach_m`` ahead. OSM draws the node on the way's centre line, so the signal is written there,
on the ground, named ``osm_<kind>``: ``MapBuilder::CheckSignalsOnRoads`` (LibCarla/source/carla/road/
MapBuilder.cpp) moves a signal that close to a driving lane out of the road, which is where CARLA's sign actor
should stand.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from .reflines import RefLine
from .signtypes import signal_type


def _junction_ends(root: ET.Element) -> dict[str, dict[str, str]]:
    """Road id -> {"successor"|"predecessor": junction id} for the road ends that meet a junction."""
    out: dict[str, dict[str, str]] = {}
    for r in root.iter("road"):
        for which in ("successor", "predecessor"):
            el = r.find(f"link/{which}")
            if el is not None and el.get("elementType") == "junction":
                out.setdefault(r.get("id", ""), {})[which] = el.get("elementId", "")
    return out


def _approach(refs: dict[str, RefLine], ends: dict[str, dict[str, str]], xy, reach_m: float, max_t_m: float = 6.0):
    """(road, s, t, orientation, lanes) of the approach a node guards, or None: lanes driving towards a junction
    end of a road outside junctions, the node within ``max_t_m`` of its line and at most ``reach_m`` before that end."""
    best = None
    for ref in refs.values():
        if ref.junction != "-1":
            continue
        s, t, over = ref.project(xy)
        if over > 0.5 or abs(t) > max_t_m:
            continue
        for orient, lanes, to_end, link in (("+", ref.lanes_right, ref.length - s, "successor"),
                                            ("-", ref.lanes_left, s, "predecessor")):
            if lanes and link in ends.get(ref.road, {}) and 0.0 <= to_end <= reach_m:
                if best is None or to_end < best[0]:
                    best = (to_end, (ref.road, s, t, orient, lanes))
    return None if best is None else best[1]


def add_osm_signs(root: ET.Element, refs: dict[str, RefLine], osm_signs: list, used: set[int], log: list[str], *,
                  reach_m: float = 30.0) -> list:
    """Write the stop / give-way nodes of ``osm_signs`` ((x, y, kind), aligned frame) not in ``used`` (indices a
    scanned sign took); in place in ``root``. Returns their ``signals.Placed`` records."""
    from .signals import Placed, _f, _signals_el

    placed: list = []
    roads = {r.get("id"): r for r in root.iter("road")}
    ends = _junction_ends(root)
    for i, (x, y, kind) in enumerate(osm_signs or []):
        if i in used or kind not in ("stop", "yield"):
            continue
        ap = _approach(refs, ends, (x, y), reach_m)
        if ap is None:
            log.append(f"OSM {kind} node at ({x:.1f}, {y:.1f}): no approach to a junction within {reach_m:g} m; "
                       "not written")
            continue
        road, s, t, orient, lanes = ap
        typ, sub, _ = signal_type(kind, None)
        sid = f"osm_{kind}_{i}"
        el = ET.SubElement(_signals_el(roads[road]), "signal", {
            "id": sid, "name": f"osm_{kind}", "s": _f(s), "t": _f(t), "zOffset": "0.000", "orientation": orient,
            "dynamic": "no", "country": "OpenDRIVE", "type": typ, "subtype": sub, "height": "0.900", "width": "0.900"})
        ET.SubElement(el, "validity", {"fromLane": str(min(lanes)), "toLane": str(max(lanes))})
        placed.append(Placed(sid, "sign", road, s, t, 0.0, orient, "osm", type=typ, subtype=sub,
                             new_xy=[float(x), float(y)],
                             note=f"{kind} from OSM (no scanned plate within reach); CARLA moves it off the lanes"))
    return placed
