"""Road ends trimmed to the scanned ground: no lane of the aligned map runs past the mesh.

A road network from OSM is cut at the site's edge (the extract's box), and netconvert closes every dead end with
a turnaround: a junction whose one connecting road U-turns from the end of one direction's road into the start
of the other's, bulging a lane width beyond the node. At the map's edge both the road ends and the U-turns lie
past the scanned ground, so CARLA's traffic manager turns its vehicles around over the void.

:func:`trim_to_ground` finds the map's **ends**, each a node of the graph that leads nowhere else:

- a *free end*: a road end without a link (a one-way street entering the map);
- a *dead end*: a junction touching at most two ordinary road ends, every connecting road of which goes from
  one of them to another and turns back on itself (netconvert's turnaround; a junction without connecting roads
  too).

and, for each end whose lanes leave the ground (:func:`twinkit.street.lane_ground.on_ground`, every lane reached
from a driving lane, sampled every ``step_m``), cuts its roads back by the distance from the end to the farthest
lane sample off the ground within ``max_trim_m``, plus ``margin_m`` (:func:`twinkit_roads.xodr_cut.cut_road`);
a dead end's turnaround roads follow the cut rigidly (:func:`twinkit_roads.xodr_cut.move_road`), and the cut grows
by ``step_m`` until the moved U-turn lies on the ground too. The junction, its connections and the lane links are
kept as they were: the traffic manager still turns its vehicles at the dead end (a lane end without a successor
would remove the vehicle: ``LocalizationStage::Update`` in CARLA's ``LibCarla/source/carla/trafficmanager/
LocalizationStage.cpp``, ``marked_for_removal`` when ``GetNextWaypoint()`` is empty), now on the scanned ground.
Ends linked to a real junction are never cut; lanes off the ground there, or farther in than ``max_trim_m``,
are reported and left.
"""
from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .xodr_cut import CutError, cut_road, elevation_at, move_road, road_pose

#: the lane types of a turnaround that must lie on the ground (CARLA's drivable lanes; netconvert's sidewalk
#: around a U-turn sweeps a sidewalk's width farther out and would cost metres of road: reported, not cut for)
DRIVING = ("Driving", "Bidirectional", "Entry", "Exit", "OnRamp", "OffRamp")



@dataclass
class MapEnd:
    """One end of the map: ``ends`` the (road id, "start" | "end") it is made of, ``turnarounds`` the connecting
    roads of its junction (empty for a free end), ``junction`` its junction id (None for a free end)."""

    ends: list[tuple[str, str]]
    turnarounds: list[str] = field(default_factory=list)
    junction: str | None = None
    trim_m: float = 0.0
    note: str = ""

    def doc(self) -> dict:
        return {"junction": self.junction, "ends": [f"{r}:{e}" for r, e in self.ends], "turnarounds": self.turnarounds,
                "trim_m": round(self.trim_m, 3), **({"note": self.note} if self.note else {})}


def _links(road: ET.Element) -> dict[str, ET.Element | None]:
    link = road.find("link")
    return {"start": link.find("predecessor") if link is not None else None,
            "end": link.find("successor") if link is not None else None}


def map_ends(root: ET.Element) -> list[MapEnd]:
    """The free ends and the dead ends (turnaround junctions) of an OpenDRIVE document."""
    roads = {r.get("id"): r for r in root.findall("road")}
    normal = {i: r for i, r in roads.items() if r.get("junction", "-1") == "-1"}
    out: list[MapEnd] = []
    at_junction: dict[str, list[tuple[str, str]]] = {}
    for rid, r in normal.items():
        for side, el in _links(r).items():
            if el is None:
                out.append(MapEnd([(rid, side)]))
            elif el.get("elementType") == "junction":
                at_junction.setdefault(el.get("elementId"), []).append((rid, side))
    for j in root.findall("junction"):
        jid = j.get("id")
        ends = at_junction.get(jid, [])
        conn = [r for r in roads.values() if r.get("junction") == jid]
        if not ends or len({e[0] for e in ends}) > 2:
            continue
        touched = set()
        for c in conn:
            for side, el in _links(c).items():
                if el is not None and el.get("elementType") == "road":
                    touched.add(el.get("elementId"))
        if touched <= {e[0] for e in ends} and _same_side([(roads[r], side) for r, side in ends]):
            out.append(MapEnd(sorted(ends), sorted(r.get("id") for r in conn), jid))
    return out


def _same_side(ends: list[tuple[ET.Element, str]]) -> bool:
    """The road ends all come into their junction from one side (the directions into it within 30 degrees of
    each other): a dead end, not a junction that joins two roads one after the other."""
    into = []
    for road, side in ends:
        h = road_pose(road, float(road.get("length")) if side == "end" else 0.0)[2]
        into.append(h if side == "end" else h + math.pi)
    return all(abs(math.remainder(h - into[0], 2 * math.pi)) < math.radians(30) for h in into)


def _reach(samples, ground: np.ndarray, road: ET.Element, side: str, max_trim_m: float) -> float:
    """Metres from the road's ``side`` end to its first cross-section on the ground, walking in from that end (a
    cross-section: the road's lane samples at one s; off the ground when one of them is); 0 when the end's own
    cross-section is on the ground, ``max_trim_m + 1`` when none is within ``max_trim_m``. Holes farther in
    are not the end's (the drop test reports them)."""
    rid, length = int(road.get("id")), float(road.get("length"))
    k = samples.road == rid
    if not k.any():
        return 0.0
    s = np.round(samples.s[k], 3)
    dist = length - s if side == "end" else s
    off = {float(d) for d in np.unique(dist[~ground[k]])}
    for i, d in enumerate(np.unique(dist)):  # nearest first
        if float(d) not in off:
            return float(d) if i else 0.0  # the first cross-section on the ground; 0: the end's own
        if d > max_trim_m:
            break
    return float(max_trim_m) + 1.0  # off the ground as far as a cut may reach


def _motion(road: ET.Element, side: str, d: float) -> tuple[np.ndarray, float, np.ndarray, float]:
    """The rigid motion taking the ``side`` end of ``road`` to the point ``d`` metres in: (old point, turn rad,
    new point, height change)."""
    length = float(road.get("length"))
    s_old, s_new = (length, length - d) if side == "end" else (0.0, d)
    x0, y0, h0 = road_pose(road, s_old)
    x1, y1, h1 = road_pose(road, s_new)
    return np.array([x0, y0]), h1 - h0, np.array([x1, y1]), elevation_at(road, s_new) - elevation_at(road, s_old)


def _moved(xy: np.ndarray, about: np.ndarray, turn: float, to: np.ndarray) -> np.ndarray:
    c, s = np.cos(turn), np.sin(turn)
    d = xy - about
    return np.c_[c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]] + to


@dataclass
class TrimParams:
    """How far and how finely road ends are cut back (see the module doc)."""

    step_m: float = 0.25
    band_m: float = 0.5
    margin_m: float = 0.5
    max_trim_m: float = 10.0
    min_left_m: float = 2.0


def plan_end(end: MapEnd, roads: dict[str, ET.Element], samples, ground: np.ndarray, on_ground, p: TrimParams) -> None:
    """Set ``end.trim_m`` (0: nothing to cut) and ``end.note`` (why an end that leaves the ground is not cut)."""
    need = max(_reach(samples, ground, roads[r], side, p.max_trim_m) for r, side in end.ends)
    uturn = (np.isin(samples.road, [int(c) for c in end.turnarounds]) & samples.is_type(*DRIVING)
             if end.turnarounds else None)
    if need == 0.0 and (uturn is None or ground[uturn].all()):
        return
    d = need + p.margin_m if need > 0 else p.step_m
    while d <= p.max_trim_m + 1e-9:
        if any(float(roads[r].get("length")) - d < p.min_left_m for r, _ in end.ends):
            end.note = f"a road would be shorter than {p.min_left_m} m after a cut of {d:.2f} m: left as it is"
            return
        if uturn is None or not uturn.any():
            end.trim_m = d
            return
        about, turn, to, dz = _motion(roads[end.ends[0][0]], end.ends[0][1], d)
        xyz = samples.xyz[uturn].copy()
        xyz[:, :2] = _moved(xyz[:, :2], about, turn, to)
        xyz[:, 2] += dz
        if on_ground(xyz).all():
            end.trim_m = d
            return
        d += p.step_m
    end.note = f"its lanes leave the ground even after a cut of {p.max_trim_m} m (max_trim_m): left as it is"


def cut_end(end: MapEnd, roads: dict[str, ET.Element]) -> list[str]:
    """Cut the roads of ``end`` by ``end.trim_m`` and move its turnaround roads with them (in place); notes."""
    d = end.trim_m
    motion = _motion(roads[end.ends[0][0]], end.ends[0][1], d) if end.turnarounds else None
    notes: list[str] = []
    for rid, side in end.ends:
        r = roads[rid]
        length = float(r.get("length"))
        notes += cut_road(r, d, length) if side == "start" else cut_road(r, 0.0, length - d)
    if motion is not None:
        about, turn, to, dz = motion
        for c in end.turnarounds:
            move_road(roads[c], (float(about[0]), float(about[1])), turn,
                      (float(to[0] - about[0]), float(to[1] - about[1])), dz)
    return notes


def trim_to_ground(text: str, vertices: np.ndarray, faces: np.ndarray, p: TrimParams | None = None,
                   source: str = "aligned.xodr") -> tuple[str, dict]:
    """``text`` (OpenDRIVE, the mesh's frame) with its map ends cut back onto the mesh (``vertices`` (v, 3),
    ``faces`` (f, 3)), and the report: every end with its cut, notes, and the lane samples off the ground
    before and after."""
    from twinkit.street.lane_ground import on_ground
    from twinkit.street.lanes import LaneMap
    from twinkit.surface.closest import Surface

    p = p or TrimParams()
    scene = Surface(vertices, faces).scene

    def ground_of(xyz):
        return on_ground(xyz, vertices, faces, p.band_m, scene=scene)

    samples = LaneMap(text, source=source).lanes(p.step_m)
    ground = ground_of(samples.xyz)
    root = _parse(text)
    roads = {r.get("id"): r for r in root.findall("road")}
    ends = map_ends(root)
    for end in ends:  # every end planned on the map as it is, then cut
        plan_end(end, roads, samples, ground, ground_of, p)
    notes: list[str] = []
    for end in (e for e in ends if e.trim_m > 0):
        backup = copy.deepcopy(root)
        try:
            notes += cut_end(end, roads)
        except CutError as exc:  # this end stays as it was
            end.trim_m, end.note = 0.0, f"not cut: {exc}"
            root = backup
            roads = {r.get("id"): r for r in root.findall("road")}
    if not any(e.trim_m > 0 for e in ends):
        return text, _report(ends, samples, ground, samples, ground, notes)
    out = '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    after = LaneMap(out, source=source).lanes(p.step_m)
    return out, _report(ends, samples, ground, after, ground_of(after.xyz), notes)


def _parse(text: str) -> ET.Element:
    return ET.fromstring(text.encode(), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))


def _report(ends: list[MapEnd], s0, g0: np.ndarray, s1, g1: np.ndarray, notes: list[str]) -> dict:
    """The trim's report: the ends, and the lane samples off the ground before and after (driving lanes and all)."""
    d0, d1 = s0.is_type(*DRIVING), s1.is_type(*DRIVING)
    return {"ends": [e.doc() for e in ends], "cut_ends": sum(1 for e in ends if e.trim_m > 0),
            "max_trim_m": round(max((e.trim_m for e in ends), default=0.0), 3),
            "driving_off_ground_before": int((~g0 & d0).sum()), "driving_off_ground_after": int((~g1 & d1).sum()),
            "driving_samples_before": int(d0.sum()), "driving_samples_after": int(d1.sum()),
            "samples_off_ground_before": int((~g0).sum()), "samples_off_ground_after": int((~g1).sum()),
            "samples_before": int(len(g0)), "samples_after": int(len(g1)), "notes": notes}
