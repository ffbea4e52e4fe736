"""Reading, cropping and writing OpenStreetMap data (.osm, .osm.bz2, .osm.pbf) with pyosmium."""
from __future__ import annotations

import bz2
import gzip
import xml.sax.saxutils as su
from dataclasses import dataclass, field
from pathlib import Path

from twinkit import InputError

SUFFIXES = (".osm", ".osm.bz2", ".osm.gz", ".osm.pbf", ".pbf", ".xml")


@dataclass
class OsmData:
    nodes: dict[int, tuple[float, float, dict]] = field(default_factory=dict)  # id -> (lon, lat, tags)
    ways: dict[int, tuple[list[int], dict]] = field(default_factory=dict)  # id -> (node refs, tags)
    relations: dict[int, tuple[list[tuple[str, int, str]], dict]] = field(default_factory=dict)  # (type, ref, role)

    def highway_ways(self) -> list[int]:
        return [w for w, (_, t) in self.ways.items() if "highway" in t]

    def count(self) -> dict:
        hw = self.highway_ways()
        return {"nodes": len(self.nodes), "ways": len(self.ways), "relations": len(self.relations),
                "highway_ways": len(hw),
                "traffic_signals": sum(1 for _, _, t in self.nodes.values() if t.get("highway") == "traffic_signals"),
                "ways_with_lanes": sum(1 for w in hw if "lanes" in self.ways[w][1])}

    def bounds(self) -> tuple[float, float, float, float] | None:
        """(south, west, north, east) of the nodes, or None."""
        if not self.nodes:
            return None
        lons = [v[0] for v in self.nodes.values()]
        lats = [v[1] for v in self.nodes.values()]
        return min(lats), min(lons), max(lats), max(lons)


def _kind(path: Path) -> str:
    name = path.name.lower()
    for suf in SUFFIXES:
        if name.endswith(suf):
            return suf
    return ""


def read_osm(path: Path) -> OsmData:
    """Read an OSM file (XML, XML.bz2, XML.gz or PBF); InputError naming the file on failure."""
    import osmium

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: OSM file not found")
    if not _kind(path):
        raise InputError(f"{path}: not an OSM file (expected one of {', '.join(SUFFIXES)})")
    data = OsmData()
    try:
        for o in osmium.FileProcessor(str(path)):
            if o.is_node():
                loc = o.location
                if loc.valid():
                    data.nodes[o.id] = (loc.lon, loc.lat, {t.k: t.v for t in o.tags})
            elif o.is_way():
                data.ways[o.id] = ([n.ref for n in o.nodes], {t.k: t.v for t in o.tags})
            elif o.is_relation():
                data.relations[o.id] = ([(m.type, m.ref, m.role) for m in o.members], {t.k: t.v for t in o.tags})
    except RuntimeError as exc:
        raise InputError(f"{path}: not a readable OSM file ({exc})") from None
    return data


def crop(data: OsmData, bbox: tuple[float, float, float, float]) -> OsmData:
    """Ways with at least one node inside (south, west, north, east), with all their nodes (like the OSM API)."""
    s, w, n, e = bbox
    inside = {i for i, (lon, lat, _) in data.nodes.items() if s <= lat <= n and w <= lon <= e}
    out = OsmData()
    for wid, (refs, tags) in data.ways.items():
        if any(r in inside for r in refs):
            known = [r for r in refs if r in data.nodes]  # extracts cut ways at their border
            if len(known) >= 2:
                out.ways[wid] = (known, tags)
    used = {r for refs, _ in out.ways.values() for r in refs} | inside
    out.nodes = {i: data.nodes[i] for i in used if i in data.nodes}
    for rid, (members, tags) in data.relations.items():
        keep = [m for m in members if (m[0] == "w" and m[1] in out.ways) or (m[0] == "n" and m[1] in out.nodes)]
        if keep and len(keep) == len(members):
            out.relations[rid] = (members, tags)
    return out


def _tags(tags: dict, indent: str) -> str:
    return "".join(f'{indent}<tag k={su.quoteattr(k)} v={su.quoteattr(v)}/>\n' for k, v in sorted(tags.items()))


def write_osm_xml(data: OsmData, path: Path, bounds: tuple[float, float, float, float] | None = None) -> None:
    """Write OSM XML 0.6 (what netconvert reads)."""
    parts = ['<?xml version="1.0" encoding="UTF-8"?>\n<osm version="0.6" generator="twinkit-roads">\n']
    b = bounds or data.bounds()
    if b:
        parts.append(f'  <bounds minlat="{b[0]:.7f}" minlon="{b[1]:.7f}" maxlat="{b[2]:.7f}" maxlon="{b[3]:.7f}"/>\n')
    for nid in sorted(data.nodes):
        lon, lat, tags = data.nodes[nid]
        head = f'  <node id="{nid}" version="1" visible="true" lat="{lat:.7f}" lon="{lon:.7f}"'
        parts.append(head + (">\n" + _tags(tags, "    ") + "  </node>\n" if tags else "/>\n"))
    for wid in sorted(data.ways):
        refs, tags = data.ways[wid]
        parts.append(f'  <way id="{wid}" version="1" visible="true">\n')
        parts.extend(f'    <nd ref="{r}"/>\n' for r in refs)
        parts.append(_tags(tags, "    ") + "  </way>\n")
    names = {"n": "node", "w": "way", "r": "relation"}
    for rid in sorted(data.relations):
        members, tags = data.relations[rid]
        parts.append(f'  <relation id="{rid}" version="1" visible="true">\n')
        parts.extend(f'    <member type="{names.get(t, t)}" ref="{r}" role={su.quoteattr(role)}/>\n'
                     for t, r, role in members)
        parts.append(_tags(tags, "    ") + "  </relation>\n")
    parts.append("</osm>\n")
    Path(path).write_text("".join(parts), encoding="utf-8")


def looks_like_osm_xml(raw: bytes) -> bool:
    """Whether bytes (possibly compressed) start an OSM XML document."""
    if raw[:3] == b"BZh":
        raw = bz2.decompress(raw)[:2048]
    elif raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)[:2048]
    head = raw[:2048].lstrip()
    return head.startswith(b"<?xml") and b"<osm" in head or head.startswith(b"<osm")
