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

:func:`trim_outer_lanes` does the same for the lanes outside a road end's outermost driving lane (sidewalk,
parking, shoulder, ...), once those lie where they will stay (after the parking lanes): at each map end, walking
from the outermost lane inwards, a lane whose ground ends before the road's end (a cross-section of it, rays every
``across_m`` from border to border, with a ray off the ground: :func:`twinkit.street.lane_ground.on_ground`) gets
no width from the road's end to ``margin_m`` past its first cross-section on the ground
(:func:`twinkit_roads.xodr_cut.narrow_lanes`: a new lane section there, the lane's width 0 in the part at the
end); an inner lane only as far as the lane outside it, and the walk stops at the first lane that keeps its
ground at the end. A dead end's turnaround roads lose, the same way outermost first, their outer lanes that
leave the ground anywhere. Only the map's ends: a sidewalk is never narrowed inside the map or at a real
junction, so each block keeps one sidewalk.
"""
from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .xodr_cut import CutError, cut_road, elevation_at, move_road, narrow_lanes, road_pose

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
    across_m: float = 0.1


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


# ------------------------------------------------------------------------------------------------ outer lanes

def _cross_ground(samples, which: np.ndarray, ground_of, across_m: float) -> np.ndarray:
    """(n,) bool: each of the ``which`` samples' lane cross-sections has ground under every ray across it (rays
    every ``across_m`` from border to border, half a step in from each; ``ground_of`` the ground test of
    (k, 3) points); True for the other samples."""
    idx = np.flatnonzero(which)
    ok = np.ones(len(samples), bool)
    if not len(idx):
        return ok
    w = samples.width[idx]
    n = np.maximum(1, np.ceil(w / across_m - 1e-9).astype(np.int64))
    owner = np.repeat(np.arange(len(idx)), n)
    j = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
    off = (j + 0.5) * (w[owner] / n[owner]) - w[owner] / 2
    pts = samples.xyz[idx][owner].copy()
    pts[:, :2] += off[:, None] * samples.normal[idx][owner]
    sub = np.ones(len(idx), bool)
    np.logical_and.at(sub, owner, ground_of(pts))
    ok[idx] = sub
    return ok


def _outer_lanes(road: ET.Element, side: str | None) -> list[list[tuple[int, str]]]:
    """Per side of the road (right, left): its lanes outward of the outermost driving lane, outermost first, as
    (id, type), in the lane section at the road's ``side`` end ("start" | "end"; None: every section's lanes)."""
    secs = road.find("lanes").findall("laneSection")
    pick = secs if side is None else [secs[0] if side == "start" else secs[-1]]
    drive = {t.lower() for t in DRIVING}
    out: list[list[tuple[int, str]]] = []
    for grp in ("right", "left"):
        row: list[tuple[int, str]] = []
        for sec in pick:
            el = sec.find(grp)
            for ln in sorted(el.findall("lane") if el is not None else [], key=lambda e: -abs(int(e.get("id")))):
                if ln.get("type", "").lower() in drive:
                    break
                if (int(ln.get("id")), ln.get("type", "")) not in row:
                    row.append((int(ln.get("id")), ln.get("type", "")))
        out.append(sorted(row, key=lambda t: -abs(t[0])))
    return out


def _plan_outer(rid: str, side: str, road: ET.Element, samples, ok: np.ndarray, p: TrimParams,
                notes: list[str]) -> dict[int, float]:
    """{lane id: metres from the road's ``side`` end to give no width} for the outer lanes of one road end."""
    length = float(road.get("length"))
    cuts: dict[int, float] = {}
    for row in _outer_lanes(road, side):
        limit = length
        for lid, kind in row:
            k = (samples.road == int(rid)) & (samples.lane == lid)
            reach = _reach(samples.take(k), ok[k], road, side, p.max_trim_m)
            if reach == 0.0:
                break
            if reach > p.max_trim_m:
                notes.append(f"road {rid} {side}: {kind} lane {lid} has no ground for more than {p.max_trim_m} m "
                             "(max_trim_m): left as it is")
                break
            if reach + p.margin_m > limit + 1e-9:
                notes.append(f"road {rid} {side}: {kind} lane {lid} leaves the ground {reach:.2f} m in, farther "
                             f"than the lane outside it is narrowed ({limit:.2f} m): narrowed as far as that")
            cuts[lid] = limit = min(reach + p.margin_m, limit)
    return cuts


def _off_outer(road: ET.Element, samples, ok: np.ndarray) -> list[tuple[int, str]]:
    """The outer lanes of a (turnaround) road that leave the ground anywhere, outermost first per side, up to
    the first that keeps it."""
    out = []
    for row in _outer_lanes(road, None):
        for lid, kind in row:
            k = (samples.road == int(road.get("id"))) & (samples.lane == lid)
            if not k.any() or ok[k].all():
                break
            out.append((lid, kind))
    return out


def trim_outer_lanes(text: str, vertices: np.ndarray, faces: np.ndarray, p: TrimParams | None = None,
                     source: str = "aligned.xodr") -> tuple[str, dict]:
    """``text`` (OpenDRIVE, the mesh's frame) with the outer lanes (sidewalk, parking, ...) of its map ends given
    no width where their ground ends before the road's end (see the module doc), and the report: every lane
    narrowed, notes, and the outer lanes' cross-sections off the ground before and after (lanes of width 0 left
    out)."""
    from twinkit.street.lane_ground import on_ground
    from twinkit.street.lanes import LaneMap
    from twinkit.surface.closest import Surface

    p = p or TrimParams()
    scene = Surface(vertices, faces).scene

    def cross_ok(smp):
        return _cross_ground(smp, ~smp.is_type(*DRIVING) & (smp.width > 1e-6),
                             lambda xyz: on_ground(xyz, vertices, faces, p.band_m, scene=scene), p.across_m)

    samples = LaneMap(text, source=source).lanes(p.step_m)
    ok = cross_ok(samples)
    root = _parse(text)
    roads = {r.get("id"): r for r in root.findall("road")}
    narrowed: list[dict] = []
    notes: list[str] = []
    for end in map_ends(root):
        for rid, side in end.ends:
            cuts = _plan_outer(rid, side, roads[rid], samples, ok, p, notes)
            types = dict(t for row in _outer_lanes(roads[rid], side) for t in row)
            narrowed += [{"road": rid, "end": side, "lane": lid, "type": types[lid], "metres": round(d, 3)}
                         for lid, d in cuts.items()]
            if cuts:
                narrow_lanes(roads[rid], side, cuts)
        for c in end.turnarounds:
            off = _off_outer(roads[c], samples, ok)
            length = float(roads[c].get("length"))
            narrowed += [{"road": c, "end": "turnaround", "lane": lid, "type": kind, "metres": round(length, 3)}
                         for lid, kind in off]
            if off:
                narrow_lanes(roads[c], "start", {lid: length for lid, _ in off})
    out = text if not narrowed else '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    after = LaneMap(out, source=source).lanes(p.step_m) if narrowed else samples
    ok1 = cross_ok(after) if narrowed else ok
    outer0 = ~samples.is_type(*DRIVING) & (samples.width > 1e-6)
    outer1 = ~after.is_type(*DRIVING) & (after.width > 1e-6)
    return out, {"narrowed": narrowed, "notes": notes, "outer_off_ground_before": int((~ok & outer0).sum()),
                 "outer_off_ground_after": int((~ok1 & outer1).sum()), "outer_samples_before": int(outer0.sum()),
                 "outer_samples_after": int(outer1.sum())}
