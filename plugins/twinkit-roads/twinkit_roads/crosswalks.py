"""Crosswalks: OSM crossings and the scan's painted zebras, matched, merged and written as OpenDRIVE
crosswalk objects the way CARLA reads them.

CARLA 0.9.16 reads a crosswalk from ``<road><objects><object type="crosswalk" s t hdg ...><outline>
<cornerLocal u v z/>...`` only (LibCarla/source/carla/opendrive/parser/ObjectParser.cpp,
``ObjectParser::Parse``: cornerRoad and the other corner kinds are ignored; the road is the ``<road>``
holding the object) and reports its outline in ``carla.Map.get_crosswalks`` (Map::GetAllCrosswalkZones in
LibCarla/source/carla/road/Map.cpp: the reference-line point at ``s``, moved by ``t``, turned by ``hdg``;
each corner u along the road, v to its left). With ``t = 0`` and ``hdg = 0`` a site-frame corner p is
``u = (p - ref(s)) . tangent``, ``v = (p - ref(s)) . left normal`` (checked against the wheel in the tests).

All positions: site frame, metres (x east, y north); crossings as :class:`Crosswalk` polygons.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .zebras import Zebra

#: the id range of the crosswalk objects this module writes (CARLA keys nothing on it; unique in the file)
ID_BASE = 880000


@dataclass
class OsmCrossing:
    """A crossing OSM gives: ``xy`` (2,) site frame (after the road alignment); ``axis`` (2,) unit walking
    direction: along a ``footway=crossing`` way, across the road way through a ``highway=crossing`` node
    (None when no road way holds it: then across the nearest lane)."""

    osm: str
    xy: np.ndarray
    axis: np.ndarray | None = None
    tags: dict = field(default_factory=dict)


@dataclass
class Crosswalk:
    """One crosswalk: ``polygon`` (4, 2) site-frame corners (counter-clockwise), ``source`` one of
    ``osm+scan`` / ``osm`` / ``scan``, the OSM element and the zebra it came from."""

    polygon: np.ndarray
    source: str
    osm: str | None = None
    zebra: Zebra | None = None
    note: str = ""

    @property
    def centre(self) -> np.ndarray:
        return np.asarray(self.polygon, float).mean(0)

    def to_json(self) -> dict:
        return {"source": self.source, "osm": self.osm, "centre": [round(float(v), 3) for v in self.centre],
                "polygon": np.round(np.asarray(self.polygon, float), 3).tolist(),
                "zebra": self.zebra.to_json() if self.zebra is not None else None, "note": self.note}


def osm_crossings(data, to_site) -> list[OsmCrossing]:
    """The crossings of an :class:`twinkit_roads.osmio.OsmData`: ``highway=crossing`` nodes and
    ``footway=crossing`` (or ``path``/``cycleway=crossing``) ways; ``to_site`` maps (n, 2) lon, lat to the
    site frame (the projection and the road alignment). A node lying on a crossing way is that way's."""
    out: list[OsmCrossing] = []
    on_ways: set[int] = set()
    for wid, (refs, tags) in data.ways.items():
        if "crossing" not in (tags.get("footway"), tags.get("path"), tags.get("cycleway")):
            continue
        ll = [data.nodes[r][:2] for r in refs if r in data.nodes]
        if len(ll) < 2:
            continue
        xy = to_site(np.asarray(ll, float))
        d = xy[-1] - xy[0]
        if np.linalg.norm(d) < 0.5:
            continue
        on_ways.update(refs)
        out.append(OsmCrossing(f"way/{wid}", (xy[0] + xy[-1]) / 2, d / np.linalg.norm(d), dict(tags)))
    for nid, (lon, lat, tags) in data.nodes.items():
        if tags.get("highway") == "crossing" and nid not in on_ways:
            xy = to_site(np.array([[lon, lat]], float))[0]
            out.append(OsmCrossing(f"node/{nid}", xy, _across_road(data, nid, xy, to_site), dict(tags)))
    return out


_NOT_ROADS = ("footway", "path", "cycleway", "steps", "pedestrian", "crossing", "bridleway", "corridor")


def _across_road(data, nid: int, xy: np.ndarray, to_site) -> np.ndarray | None:
    """The walking direction at a crossing node: across the first road way (highway=*, not a footway) through
    it, from the way's neighbouring nodes; None when no road way holds the node."""
    for refs, tags in data.ways.values():
        if "highway" not in tags or tags["highway"] in _NOT_ROADS or nid not in refs:
            continue
        k = refs.index(nid)
        nb = [r for r in (refs[k - 1] if k > 0 else None, refs[k + 1] if k + 1 < len(refs) else None)
              if r is not None and r in data.nodes]
        if not nb:
            continue
        p = to_site(np.array([data.nodes[r][:2] for r in nb], float))
        d = (p[-1] - p[0]) if len(p) == 2 else (p[0] - xy) * (1 if refs.index(nb[0]) > k else -1)
        n = float(np.linalg.norm(d))
        if n > 1e-6:
            return np.array([-d[1], d[0]]) / n
    return None


@dataclass
class Carriageway:
    """The lanes of an OpenDRIVE map, as CARLA samples them: ``xy`` (n, 2) lane centres,
    ``tangent`` (n, 2) unit driving directions, ``halfw`` (n,) half widths, ``road`` (n,) ids; the lanes up
    to the sidewalk only (the carriageway, kerb to kerb)."""

    xy: np.ndarray
    tangent: np.ndarray
    halfw: np.ndarray
    road: np.ndarray
    junction: np.ndarray | None = None  # (n,) bool: the sample lies on a junction's lane

    @classmethod
    def of(cls, lane_map, step_m: float = 0.5) -> "Carriageway":
        """From a :class:`twinkit.street.lanes.LaneMap`: every lane but sidewalks (junctions' lanes too: a
        zebra often lies inside the junction netconvert draws)."""
        ls = lane_map.lanes(step_m)
        keep = ~ls.is_type("sidewalk")
        ls = ls.take(keep)
        h = np.radians(ls.heading_deg)
        return cls(ls.xyz[:, :2], np.stack([np.cos(h), np.sin(h)], 1), ls.width / 2, ls.road, ls.in_junction)

    def direction_at(self, xy: np.ndarray, reach_m: float = 12.0, outside_junctions: bool = False
                     ) -> np.ndarray | None:
        """The road's direction (unit, sign free) at the lane sample nearest ``xy`` (with ``outside_junctions``:
        of the lanes outside junctions, whose turning lanes run every way); None beyond ``reach_m``."""
        keep = ~self.junction if outside_junctions and self.junction is not None else np.ones(len(self.xy), bool)
        if not keep.any():
            return None
        d = np.where(keep, np.linalg.norm(self.xy - xy, axis=1), np.inf)
        i = int(np.argmin(d))
        return self.tangent[i] if d[i] <= reach_m else None

    def span(self, xy: np.ndarray, axis: np.ndarray, band_m: float, reach_m: float = 15.0) -> tuple[float, float] | None:
        """The carriageway's extent along ``axis`` (the walking direction) through ``xy``: (lo, hi) metres from
        ``xy``, the lanes within ``band_m`` of the walking line joined where they touch; None without lanes."""
        nrm = np.array([-axis[1], axis[0]])
        rel = self.xy - xy
        along, off = rel @ axis, rel @ nrm
        # a lane sample's extent across: its half width, seen along the axis (lanes across the walking line)
        cross = np.abs(self.tangent @ nrm)
        ok = (np.abs(off) <= band_m) & (np.abs(along) <= reach_m) & (cross >= 0.7)
        if not ok.any():
            return None
        iv = sorted(zip(along[ok] - self.halfw[ok] / cross[ok], along[ok] + self.halfw[ok] / cross[ok]))
        merged: list[list[float]] = []
        for a, b in iv:
            if merged and a <= merged[-1][1] + 0.3:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        best = min(merged, key=lambda ab: 0.0 if ab[0] <= 0 <= ab[1] else min(abs(ab[0]), abs(ab[1])))
        return float(best[0]), float(best[1])


def _box(centre: np.ndarray, axis: np.ndarray, lo: float, hi: float, width_m: float) -> np.ndarray:
    """(4, 2) corners: from ``lo`` to ``hi`` along ``axis`` through ``centre``, ``width_m`` wide across it."""
    nrm = np.array([-axis[1], axis[0]])
    hw = width_m / 2
    a, b = centre + axis * lo, centre + axis * hi
    return np.array([a - nrm * hw, b - nrm * hw, b + nrm * hw, a + nrm * hw])


def _zebra_box(z: Zebra, cw: Carriageway, band_m: float) -> tuple[np.ndarray, str]:
    """A zebra's crosswalk: the painted box, stretched along its walking axis to the kerbs of the carriageway
    it lies on (a zebra half hidden by a parked car still crosses the whole road)."""
    ax = np.asarray(z.axis, float)
    lo, hi = -z.length_m / 2, z.length_m / 2
    sp = cw.span(np.asarray(z.centre, float), ax, band_m)
    note = ""
    if sp is not None:
        lo2, hi2 = min(lo, sp[0]), max(hi, sp[1])
        if (hi2 - lo2) > (hi - lo) + 0.5:
            note = f"stretched from {hi - lo:.1f} m of paint to {hi2 - lo2:.1f} m kerb to kerb"
        lo, hi = lo2, hi2
    return _box(np.asarray(z.centre, float), ax, lo, hi, z.width_m), note


def _osm_box(c: OsmCrossing, cw: Carriageway, width_m: float) -> tuple[np.ndarray | None, str]:
    """An OSM crossing without paint: ``width_m`` wide, across the carriageway at its point."""
    ax = c.axis
    if ax is None:
        d = cw.direction_at(c.xy)
        if d is None:
            return None, "no lane within 12 m"
        ax = np.array([-d[1], d[0]])
    sp = cw.span(c.xy, ax, width_m / 2 + 0.5)
    if sp is None:
        return None, "no lane across its walking line"
    return _box(c.xy, ax, sp[0], sp[1], width_m), ""


def _match_cost(c: OsmCrossing, z: Zebra, match_m: float, reach_m: float) -> float | None:
    """Distance from the OSM crossing to the zebra's walking line (None when farther than ``match_m`` or more
    than ``reach_m`` along it, or when a way's walking direction disagrees with the zebra's by over 30 deg)."""
    ax = np.asarray(z.axis, float)
    rel = c.xy - np.asarray(z.centre, float)
    off, along = abs(float(rel @ np.array([-ax[1], ax[0]]))), abs(float(rel @ ax))
    if off > match_m or along > reach_m:
        return None
    if c.axis is not None and abs(float(np.dot(c.axis, ax))) < math.cos(math.radians(30)):
        return None
    return off


def _alone_why(z: Zebra, cw: Carriageway, min_bars_alone: int) -> str:
    """Why a zebra without OSM is not believed ('' when it is): too few bars, or walking along the lane it
    lies on (bars across the traffic: a misread of other paint)."""
    if z.bars < min_bars_alone:
        return f"{z.bars} bars, fewer than the {min_bars_alone} a zebra without OSM needs"
    d = cw.direction_at(np.asarray(z.centre, float), reach_m=4.0, outside_junctions=True)
    if d is not None and abs(float(np.dot(d, z.axis))) > math.cos(math.radians(30)):
        return "its walking direction runs along the lane it lies on"
    return ""


def merge(osm: list[OsmCrossing], zebras: list[Zebra], cw: Carriageway, *, match_m: float = 4.0,
          reach_m: float = 15.0, width_m: float = 3.0, min_bars_alone: int = 5) -> tuple[list[Crosswalk], list[str]]:
    """Match OSM crossings to zebras (nearest first, each used once) and build the crosswalks: a matched pair
    takes the zebra's place and extent (stretched kerb to kerb), an OSM crossing without paint gets
    ``width_m`` across its carriageway, a zebra without OSM counts on its own when :func:`_alone_why` has no
    objection. Returns (crosswalks, notes)."""
    pairs = []
    for i, c in enumerate(osm):
        for j, z in enumerate(zebras):
            cost = _match_cost(c, z, match_m, reach_m)
            if cost is not None:
                pairs.append((cost, i, j))
    used_o: dict[int, int] = {}
    used_z: set[int] = set()
    for _, i, j in sorted(pairs):
        if i not in used_o and j not in used_z:
            used_o[i] = j
            used_z.add(j)
    out, notes = [], []
    band = width_m / 2 + 0.5
    for i, c in enumerate(osm):
        if i in used_o:
            z = zebras[used_o[i]]
            poly, note = _zebra_box(z, cw, max(band, z.width_m / 2))
            out.append(Crosswalk(poly, "osm+scan", c.osm, z, note))
            continue
        poly, why = _osm_box(c, cw, width_m)
        if poly is None:
            notes.append(f"OSM crossing {c.osm} at ({c.xy[0]:.1f}, {c.xy[1]:.1f}) not written: {why}")
            continue
        out.append(Crosswalk(poly, "osm", c.osm, None, "no paint seen in the scan"))
    for j, z in enumerate(zebras):
        if j not in used_z:
            why = _alone_why(z, cw, min_bars_alone)
            if why:
                notes.append(f"painted stripes at ({z.centre[0]:.1f}, {z.centre[1]:.1f}) without an OSM crossing "
                             f"not written: {why}")
                continue
            poly, note = _zebra_box(z, cw, max(band, z.width_m / 2))
            out.append(Crosswalk(poly, "scan", None, z, note or "painted, not in OSM"))
    return out, notes


def _objects_el(road_el: ET.Element) -> ET.Element:
    """The road's <objects>, made after <lanes> (OpenDRIVE's order: lanes, objects, signals) when missing."""
    ob = road_el.find("objects")
    if ob is None:
        ob = ET.Element("objects")
        kids = list(road_el)
        at = kids.index(road_el.find("lanes")) + 1 if road_el.find("lanes") is not None else len(kids)
        road_el.insert(at, ob)
    return ob


def write_crosswalks(xodr_text: str, crosswalks: list[Crosswalk], reach_m: float = 2.0) -> tuple[str, list[dict]]:
    """``xodr_text`` with one crosswalk object per crosswalk on the road whose reference line is nearest its
    centre (outside junctions first), corners as cornerLocal (module docstring). Crosswalk objects already
    in the map are replaced. Returns (the map, one record per crosswalk: road, s, or why it was not written)."""
    from .reflines import reference_lines
    from .signals import _host

    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(xodr_text, parser=parser)
    for ob in root.iter("objects"):
        for o in [o for o in ob.findall("object") if o.get("type") == "crosswalk"]:
            ob.remove(o)
    refs = reference_lines(root)
    plain = {k: r for k, r in refs.items() if r.junction in ("-1", "", None)} or refs
    roads = {r.get("id"): r for r in root.iter("road")}
    records = []
    for k, cw in enumerate(crosswalks):
        c = cw.centre
        host = _host(plain, c, reach_m) or _host(refs, c, reach_m)
        if host is None:
            records.append({"written": False, "why": "no road reference line near its centre"})
            continue
        ref, s, _ = host
        s = min(max(s, 1e-3), ref.length - 1e-3)  # CARLA asserts 0 <= s <= length (Map::ComputeTransform)
        p0 = ref.point(s, 0.0)
        h = float(np.interp(s, ref.s, ref.hdg))
        tan, left = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
        rel = np.asarray(cw.polygon, float) - p0
        u, v = rel @ tan, rel @ left
        length = float(np.ptp(u))
        width = float(np.ptp(v))
        obj = ET.SubElement(_objects_el(roads[ref.road]), "object", {
            "id": str(ID_BASE + k), "name": f"Crosswalk_{cw.source.replace('+', '_')}", "s": f"{s:.6f}", "t": "0",
            "zOffset": "0", "hdg": "0", "roll": "0", "pitch": "0", "orientation": "none", "type": "crosswalk",
            "width": f"{width:.4f}", "length": f"{length:.4f}"})
        outline = ET.SubElement(obj, "outline")
        for i in list(range(len(u))) + [0]:  # closed, the way CARLA's own maps write it
            ET.SubElement(outline, "cornerLocal", {"u": f"{u[i]:.4f}", "v": f"{v[i]:.4f}", "z": "0"})
        records.append({"written": True, "road": ref.road, "s": round(float(s), 3), "id": str(ID_BASE + k)})
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n", records


def polygon_area(p: np.ndarray) -> float:
    """Area (m^2) of a simple polygon (k, 2+)."""
    x, y = np.asarray(p, float)[:, 0], np.asarray(p, float)[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def nearest_errors(found: list[np.ndarray], truth: list[np.ndarray]) -> list[float | None]:
    """For each truth polygon (k, 2+), the distance (m) from its centre to the nearest found polygon's centre
    (None without any found)."""
    cs = [np.asarray(f, float)[:, :2].mean(0) for f in found]
    out: list[float | None] = []
    for t in truth:
        tc = np.asarray(t, float)[:, :2].mean(0)
        out.append(min((float(np.linalg.norm(c - tc)) for c in cs), default=None))
    return out


def _to_site(site, alignment_json):
    """lon, lat (n, 2) -> site frame with the road alignment (alignment.json) applied, as the roads moved."""
    import json

    from twinkit.geo import SiteFrame

    from .align import _rot

    frame = SiteFrame.from_site(site)
    R, t = np.eye(2), np.zeros(2)
    if alignment_json is not None:
        a = json.loads(alignment_json.read_text())
        R, t = _rot(math.radians(float(a.get("yaw_deg", 0.0)))), np.array([float(a.get("tx_m", 0.0)),
                                                                          float(a.get("ty_m", 0.0))])
    return lambda ll: frame.lonlat_to_local(ll) @ R.T + t


def run_crosswalks(params, text: str, site, mesh_ply, labels_npy, osm_path, alignment_json, log
                   ) -> tuple[dict, str]:
    """The place_crosswalks step's work: OSM crossings (``osm_path``, moved by ``alignment_json``), zebras in
    the mesh (``mesh_ply`` with ``labels_npy``'s road class), merged and written into ``text``; CARLA's
    reading of the result. Returns (crosswalks.json document, the map)."""
    from twinkit import artefacts as A
    from twinkit.street.lanes import LaneMap

    from .osmio import read_osm
    from .zebras import find_zebras

    if not params.enabled:
        return {"enabled": False, "metrics": {"crosswalks": 0}, "crosswalks": []}, text
    osm = osm_crossings(read_osm(osm_path), _to_site(site, alignment_json)) \
        if params.from_osm and osm_path is not None else []
    zebras: list[Zebra] = []
    if params.from_scan:
        mesh = A.read_textured_mesh(mesh_ply)
        labels = A.read_labels(labels_npy) if labels_npy is not None else None
        if labels is not None and len(labels) != len(mesh.vertices):
            log.warning("crosswalks: %d labels for %d vertices: zebras looked for on all flat ground",
                        len(labels), len(mesh.vertices))
            labels = None
        if mesh.colors is None:
            log.warning("crosswalks: %s has no vertex colours: no painted zebra can be seen, OSM only", mesh_ply)
        zebras = find_zebras(mesh.vertices, mesh.faces, mesh.colors, labels, params.raster_m, params.min_bars)
    crosswalks, notes = merge(osm, zebras, Carriageway.of(LaneMap(text)), match_m=params.match_m,
                              width_m=params.width_m, min_bars_alone=params.min_bars_alone)
    moved, records = write_crosswalks(text, crosswalks)
    carla = LaneMap(moved, "crosswalks").crosswalks()
    for n in notes:
        log.warning("crosswalks: %s", n)
    painted = sum(1 for c in osm if "zebra" in (c.tags.get("crossing"), c.tags.get("crossing:markings")))
    if params.from_scan and painted > sum(1 for c in crosswalks if c.source == "osm+scan"):
        log.warning("crosswalks: OSM tags %d zebras, the scan shows paint at %d of them (occluded, worn, or the "
                    "colours too dark?)", painted, sum(1 for c in crosswalks if c.source == "osm+scan"))
    if len(carla) != sum(r["written"] for r in records):
        log.warning("crosswalks: %d written, CARLA reports %d", sum(r["written"] for r in records), len(carla))
    by = {k: sum(1 for c in crosswalks if c.source == k) for k in ("osm+scan", "osm", "scan")}
    log.info("crosswalks: %d OSM crossings, %d painted zebras in the scan -> %d crosswalks (%d both, %d OSM only, "
             "%d scan only); carla.Map reports %d", len(osm), len(zebras), len(crosswalks), by["osm+scan"],
             by["osm"], by["scan"], len(carla))
    metrics = {"crosswalks": len(crosswalks), "carla_crosswalks": len(carla), "osm_crossings": len(osm),
               "zebras": len(zebras), "osm_and_scan": by["osm+scan"], "osm_only": by["osm"], "scan_only": by["scan"]}
    doc = {"enabled": True, "metrics": metrics, "crosswalks": [dict(c.to_json(), **r) for c, r in zip(crosswalks, records)],
           "osm": [{"osm": c.osm, "xy": np.round(c.xy, 3).tolist(), "tags": c.tags} for c in osm],
           "zebras": [z.to_json() for z in zebras], "notes": notes,
           "carla": [np.round(p, 3).tolist() for p in carla],
           "params": {k: getattr(params, k) for k in params.__dataclass_fields__}}
    return doc, moved
