"""Parking lanes where the street has them, so the OpenDRIVE's sidewalk lanes lie on the sidewalk.

netconvert models no parking strip: its guessed sidewalk lane (``--sidewalks.guess``, 2 m) starts at the
outer edge of the outermost driving lane, i.e. on the parking strip, under the parked cars. Here a lane
of OpenDRIVE type ``parking`` is inserted between the outermost driving lane and whatever lies outward of
it (the sidewalk lane), on each side of a road (outside junctions) where

* OpenStreetMap says so: ``parking:<side>`` / ``parking:both`` (or the older ``parking:lane:<side>`` /
  ``parking:lane:both``) with a value of :data:`PARKING_VALUES`, on the way the road was converted from
  (netconvert's ``sumoId`` user data; a road with a ``-`` id runs against its way, so its right is the
  way's left), or
* the scan shows a parked vehicle there: a cluster of vehicle-labelled vertices whose centre lies beyond
  the outer edge of the outermost driving lane, within the strip.

The lane is as wide as the strip the scan shows: the median distance from the driving lane's outer edge
to the kerb's foot, plus ``kerb_top_m`` over the kerb's face to its top (:func:`twinkit_roads.kerbs.kerb_feet` on profiles cast outward from that edge, with
the vehicles taken out of the mesh so a car's flank is not read as a kerb); ``default_width_m`` where no
kerb is seen; no lane where the kerb stands at the driving lane's edge itself (kerb_feet's own profiles
there see it: cars parked half on the kerb, no strip). Lane ids outward of the new lane move out by one; every reference to them (lane links of
neighbouring roads, junction ``laneLink`` s, signal ``validity``) follows.

What CARLA does with it (carla-simulator/carla, ``LibCarla/source/carla/road/Map.cpp``):
``ForEachDrivableLaneImpl`` keeps only lanes with the ``Driving`` flag, so ``GenerateWaypoints``,
``GenerateTopology`` and ``GenerateWaypointsOnRoadEntries`` (the spawn points) never use a ``Parking``
lane (``Lane.h``: ``LaneType::Parking = 0x1 << 8``); ``Map::GetWaypoint`` with a lane-type filter finds
it. The traffic manager therefore never routes through it, and vehicles spawned there stand still.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: OSM parking values that mean "cars park on the carriageway beside the driving lanes"
PARKING_VALUES = ("lane", "parallel", "diagonal", "perpendicular", "marked", "street_side", "on_street", "yes")


@dataclass
class SideParking:
    """The evidence and the decision for one side of one road (site frame, metres)."""

    road: int
    side: str  # "right" (negative lane ids) or "left"
    osm: str  # the OSM value that asks for parking ("" when none)
    vehicles: int  # scanned vehicles standing in the strip
    kerb_m: float  # median distance from the driving lane's outer edge to the kerb foot (nan: none seen)
    kerb_samples: int
    width_m: float = 0.0  # the inserted lane's width (0: none inserted)
    why: str = ""

    def doc(self) -> dict:
        return {"road": self.road, "side": self.side, "osm": self.osm, "vehicles": self.vehicles,
                "kerb_m": None if not np.isfinite(self.kerb_m) else round(float(self.kerb_m), 3),
                "kerb_samples": self.kerb_samples, "width_m": round(float(self.width_m), 3), "why": self.why}


@dataclass
class ParkingResult:
    text: str
    sides: list[SideParking] = field(default_factory=list)

    @property
    def inserted(self) -> int:
        return sum(1 for s in self.sides if s.width_m > 0)


def osm_parking(osm_path: Path | None) -> dict[int, dict[str, str]]:
    """{way id: {"left"|"right": OSM value}} for the ways whose tags ask for parking on a side."""
    if osm_path is None:
        return {}
    from .osmio import read_osm

    out: dict[int, dict[str, str]] = {}
    for wid, (_, tags) in read_osm(Path(osm_path)).ways.items():
        sides = {}
        for side in ("left", "right"):
            for key in (f"parking:{side}", "parking:both", f"parking:lane:{side}", "parking:lane:both"):
                v = str(tags.get(key, "")).lower()
                if v in PARKING_VALUES:
                    sides[side] = v
                    break
        if sides:
            out[int(wid)] = sides
    return out


def road_way(road: ET.Element) -> tuple[int | None, bool]:
    """(OSM way id, reversed) of a netconvert road from its ``sumoId`` user data (``-101#0``: way 101,
    against its direction); (None, False) when it has none."""
    for ud in road.iter("userData"):
        if ud.get("code") == "sumoId":
            sid = str(ud.get("value", ""))
            rev = sid.startswith("-")
            head = sid.lstrip("-").split("#")[0]
            return (int(head), rev) if head.isdigit() else (None, False)
    return None, False


def vehicle_centres(vertices: np.ndarray, labels: np.ndarray, vehicle_ids, cell_m: float = 0.25,
                    min_area_m2: float = 1.5) -> np.ndarray:
    """(k, 2) site-frame centres of the vehicles in the labelled mesh: 8-connected clusters of the
    ``cell_m`` grid cells holding vehicle-labelled vertices, kept when they cover ``min_area_m2``."""
    from scipy import ndimage

    sel = np.isin(labels, np.asarray(vehicle_ids))
    if not sel.any():
        return np.zeros((0, 2))
    xy = vertices[sel, :2]
    lo = xy.min(0)
    ij = np.floor((xy - lo) / cell_m).astype(np.int64)
    grid = np.zeros(tuple(ij.max(0) + 1), bool)
    grid[ij[:, 0], ij[:, 1]] = True
    comp, n = ndimage.label(grid, structure=np.ones((3, 3)))
    out = []
    for k in range(1, n + 1):
        cells = np.argwhere(comp == k)
        if len(cells) * cell_m * cell_m >= min_area_m2:
            out.append(lo + (cells.mean(0) + 0.5) * cell_m)
    return np.asarray(out).reshape(-1, 2)


def outer_edges(xodr_text: str, step_m: float = 1.0) -> dict[tuple[int, str], tuple[np.ndarray, np.ndarray]]:
    """{(road, side): (points (k, 2), outward unit normals (k, 2))}: the outer edge of the outermost driving
    lane of each side of each road outside junctions (:class:`twinkit.street.lanes.LaneMap`, site frame)."""
    from twinkit.street.lanes import LaneMap

    best: dict[tuple[int, str], tuple[int, np.ndarray, np.ndarray]] = {}
    for ln in LaneMap(xodr_text, "parking").lanes(step_m).per_lane():
        if ln.in_junction[0] or not ln.is_type("driving")[0]:
            continue
        road, _, lane = ln.key
        key = (road, "right" if lane < 0 else "left")
        _, right = ln.borders()  # the right vector points away from the centre on both sides
        if key not in best or abs(lane) > best[key][0]:
            best[key] = (abs(lane), right, ln.normal)
        elif abs(lane) == best[key][0]:  # another lane section: the same lane further along
            best[key] = (abs(lane), np.concatenate([best[key][1], right]), np.concatenate([best[key][2], ln.normal]))
    return {k: (p, o) for k, (_, p, o) in best.items()}


def strip_kerb(points: np.ndarray, out: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
               centre_m: float = 2.2) -> np.ndarray:
    """(k,) distance (m) from each edge point outward to the kerb's foot, nan where no kerb is seen: kerb_feet's
    profiles centred ``centre_m`` outward of the edge, looking for the foot from 0.5 m to 2 ``centre_m`` - 0.5 m."""
    from .kerbs import kerb_feet

    d = kerb_feet(points + out * centre_m, out, vertices, faces, reach_m=centre_m + 0.6, search_m=centre_m - 0.5)
    return d + centre_m


def _side_lanes(section: ET.Element, side: str) -> list[ET.Element]:
    el = section.find(side)
    return [] if el is None else list(el.findall("lane"))


def insert_parking_lanes(xodr_text: str, widths: dict[tuple[int, str], float]) -> tuple[str, dict]:
    """``xodr_text`` with a ``parking`` lane of ``widths[(road, side)]`` metres (constant) beside the outermost
    driving lane of that side in every lane section of the road; lanes outward of it move out by one id and
    every reference to them follows. Returns the text and {(road, old lane id): new lane id}."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(xodr_text, parser=parser)
    roads = {int(r.get("id")): r for r in root.iter("road")}
    remap: dict[tuple[int, int], int] = {}
    for (rid, side), w in widths.items():
        road = roads.get(int(rid))
        if road is None or w <= 0:
            continue
        sign = -1 if side == "right" else 1
        for sec in road.iter("laneSection"):
            lanes = _side_lanes(sec, side)
            driving = [abs(int(ln.get("id"))) for ln in lanes if ln.get("type") == "driving"]
            if not driving:
                continue
            a = max(driving)
            for ln in lanes:
                lid = int(ln.get("id"))
                if abs(lid) > a:
                    remap[(int(rid), lid)] = lid + sign
                    ln.set("id", str(lid + sign))
            parent = sec.find(side)
            new = ET.Element("lane", {"id": str(sign * (a + 1)), "type": "parking", "level": "true"})
            ET.SubElement(new, "link")
            ET.SubElement(new, "width", {"sOffset": "0", "a": f"{w:.3f}", "b": "0", "c": "0", "d": "0"})
            ET.SubElement(new, "roadMark", {"sOffset": "0", "type": "none", "weight": "standard",
                                            "color": "standard", "width": "0"})
            at = [i for i, ln in enumerate(list(parent)) if ln.tag == "lane" and abs(int(ln.get("id"))) == a][0]
            parent.insert(at + 1 if side == "right" else at, new)
            # keep the XML order OpenDRIVE asks for: left lanes by descending id, right lanes by descending id
            ordered = sorted(parent.findall("lane"), key=lambda e: -int(e.get("id")))
            for ln in parent.findall("lane"):
                parent.remove(ln)
            for ln in ordered:
                parent.append(ln)
    _follow_remap(root, remap)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n", remap


def _follow_remap(root: ET.Element, remap: dict[tuple[int, int], int]) -> None:
    """Every reference to a renumbered lane: lane links (to the road's predecessor / successor road),
    junction laneLinks (``from`` on the incoming road, ``to`` on the connecting road), signal validity."""
    if not remap:
        return

    def new(road, lid):
        return remap.get((int(road), int(lid)), int(lid)) if road is not None else int(lid)

    for road in root.iter("road"):
        rid = int(road.get("id"))
        link = road.find("link")
        other = {}
        for kind in ("predecessor", "successor"):
            e = None if link is None else link.find(kind)
            other[kind] = int(e.get("elementId")) if e is not None and e.get("elementType", "road") == "road" else None
        for ln in road.iter("lane"):
            ll = ln.find("link")
            for kind in ("predecessor", "successor"):
                e = None if ll is None else ll.find(kind)
                if e is not None and e.get("id") is not None:
                    e.set("id", str(new(other[kind], e.get("id"))))
        for v in road.iter("validity"):
            for k in ("fromLane", "toLane"):
                if v.get(k) is not None:
                    v.set(k, str(new(rid, v.get(k))))
    for junc in root.iter("junction"):
        for con in junc.iter("connection"):
            inc, conn = con.get("incomingRoad"), con.get("connectingRoad")
            for ll in con.iter("laneLink"):
                ll.set("from", str(new(inc, ll.get("from"))))
                ll.set("to", str(new(conn, ll.get("to"))))


def plan_parking(xodr_text: str, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, *,
                 osm_sides: dict[int, dict[str, str]], vehicle_ids, default_width_m: float = 2.2,
                 min_width_m: float = 1.6, max_width_m: float = 3.2, min_kerb_samples: int = 5,
                 kerb_top_m: float = 0.0, step_m: float = 1.0) -> list[SideParking]:
    """The evidence and the parking width for each side of each road outside junctions (see the module).

    vertices (n, 3) / faces (m, 3) / labels (n,) trainIds: the labelled mesh (site frame, metres);
    osm_sides: :func:`osm_parking`; vehicle_ids: the trainIds of vehicles (the cars' clusters, and the
    faces taken out of the mesh before the kerb profiles); kerb_top_m: the lane runs this far past the kerb's
    foot, over its face and rounded edge, so the sidewalk lane starts on the pavement's top."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    roads = {int(r.get("id")): r for r in ET.fromstring(xodr_text, parser=parser).iter("road")}
    veh = np.isin(labels, np.asarray(vehicle_ids))
    still = faces[~veh[faces].any(axis=1)]  # the mesh without the vehicles: a car's flank is no kerb
    cars = vehicle_centres(vertices, labels, vehicle_ids)
    out = []
    for (rid, side), (pts, nrm) in sorted(outer_edges(xodr_text, step_m).items()):
        way, rev = road_way(roads[rid]) if rid in roads else (None, False)
        way_side = side if not rev else ("left" if side == "right" else "right")
        osm = osm_sides.get(way, {}).get(way_side, "") if way is not None else ""
        d = strip_kerb(pts, nrm, vertices, still)
        ok = np.isfinite(d) & (d >= min_width_m - 0.3) & (d <= max_width_m + 0.3)
        kerb = float(np.median(d[ok])) if ok.sum() >= min_kerb_samples else float("nan")
        if not np.isfinite(kerb):  # no strip's kerb: is the kerb at the driving lane's edge itself?
            from .kerbs import kerb_feet

            at_edge = kerb_feet(pts, nrm, vertices, still)
            if np.isfinite(at_edge).sum() >= min_kerb_samples:
                kerb = float(np.nanmedian(at_edge))
        reach = kerb if np.isfinite(kerb) else default_width_m
        n_cars = 0
        if len(cars):
            j = np.argmin(((cars[:, None, :] - pts[None, :, :]) ** 2).sum(-1), axis=1)
            rel = cars - pts[j]
            t = (rel * nrm[j]).sum(1)
            along = np.abs(rel[:, 0] * nrm[j, 1] - rel[:, 1] * nrm[j, 0])
            n_cars = int(np.count_nonzero((t > 0) & (t < reach + 0.3) & (along <= step_m)))
        sp = SideParking(rid, side, osm, n_cars, kerb, int(ok.sum()))
        if not osm and not n_cars:
            sp.why = "no OSM parking tag and no scanned vehicle in the strip"
        elif np.isfinite(kerb) and not (min_width_m <= kerb <= max_width_m):
            sp.why = f"the kerb is {kerb:.2f} m from the driving lane: no room for a parking lane"
        else:
            sp.width_m = kerb + kerb_top_m if np.isfinite(kerb) else default_width_m
            sp.why = ("kerb seen" if np.isfinite(kerb) else "no kerb seen: default width") + \
                f"; {'OSM ' + osm if osm else ''}{' and ' if osm and n_cars else ''}" + \
                (f"{n_cars} scanned vehicle(s)" if n_cars else "")
        out.append(sp)
    return out


def add_parking(xodr_text: str, vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, **kw) -> ParkingResult:
    """:func:`plan_parking`, then :func:`insert_parking_lanes` for the sides that get a lane."""
    sides = plan_parking(xodr_text, vertices, faces, labels, **kw)
    widths = {(s.road, s.side): s.width_m for s in sides if s.width_m > 0}
    text, _ = insert_parking_lanes(xodr_text, widths) if widths else (xodr_text, {})
    return ParkingResult(text, sides)
