"""OpenDRIVE under a similarity: ``new = scale * Rz(rotation) * old + translation`` (x, y and z), exactly.

Used by the CARLA package (twinkit-export: the site frame -> CARLA's frame, heights scaled too) and by
``road_source=opendrive`` (twinkit-roads: a map's own projection -> the site frame; ``scale_heights=False``:
a projection's scale factor is horizontal, heights keep their values; ``dz`` shifts them).

Every OpenDRIVE geometry survives a similarity: lines, arcs, spirals, poly3 and paramPoly3 keep
their form in the road's own (s, t) frame. Only the start point and heading of each plan-view
geometry move (rotation); with a scale, every length scales by ``scale`` and a polynomial
``f(u) = a + b u + c u^2 + d u^3`` in a length ``u`` takes ``a*q, b*q/scale, c*q/scale^2,
d*q/scale^3`` where ``q`` is the scale of its value (``scale`` for lengths and heights, 1 for
angles and slopes); curvature takes ``1/scale``. With ``scale_heights=False`` heights are not
lengths: height attributes (:data:`HEIGHTS`) keep their values and elevation / shape polynomials
take ``q = 1``.

The table :data:`LENGTHS` lists the attributes that are lengths, per element (OpenDRIVE 1.4-1.8,
what netconvert and RoadRunner write); :data:`POLYS` the polynomial records. Inertial positions
(``positionInertial``, ``cornerInertial``) move as points. An element with a numeric length-like
attribute the tables do not know is left unchanged only when ``scale == 1``; otherwise it is an error
naming the element (a silent half-scaled road would be worse).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

# attributes that are lengths (scale 1), per element tag
LENGTHS: dict[str, tuple[str, ...]] = {
    "road": ("length",),
    "type": ("s", "width"),  # road type: s; roadMark type: width
    "geometry": ("s", "length"),
    "laneSection": ("s",),
    "speed": ("sOffset",),  # lane speed; road type speed has only max/unit
    "material": ("sOffset",),
    "access": ("sOffset",),
    "rule": ("sOffset",),
    "visibility": ("sOffset", "forward", "back", "left", "right"),
    "height": ("sOffset", "inner", "outer"),
    "roadMark": ("sOffset", "width", "height"),
    "line": ("s", "length", "space", "tOffset", "sOffset", "width"),  # roadMark type/explicit lines
    "sway": ("ds",),
    "object": ("s", "t", "zOffset", "validLength", "length", "width", "radius", "height"),
    "repeat": ("s", "length", "distance", "tStart", "tEnd", "widthStart", "widthEnd", "heightStart", "heightEnd",
               "zOffsetStart", "zOffsetEnd", "lengthStart", "lengthEnd", "radiusStart", "radiusEnd"),
    "cornerRoad": ("s", "t", "dz", "height"),
    "cornerLocal": ("u", "v", "z", "height"),
    "cornerInertial": ("z", "height"),
    "cornerReference": (),
    "objectReference": ("s", "t", "zOffset", "validLength"),
    "tunnel": ("s", "length"),
    "bridge": ("s", "length"),
    "marking": ("width", "zOffset", "spaceLength", "lineLength", "startOffset", "stopOffset"),
    "border": ("width",),  # object border (outline) -- lane borders are polynomials, see POLYS
    "signal": ("s", "t", "zOffset", "height", "width", "length"),  # hOffset, pitch, roll: angles
    "positionRoad": ("s", "t", "zOffset"),
    "positionInertial": ("z",),
    "signalReference": ("s", "t"),
    "crossPath": ("s",),
    "crossfall": ("s",),
    "superelevation": ("s",),
    "shape": ("s", "t"),
    "elevation": ("s",),
    "laneOffset": ("s",),
    "width": ("sOffset",),
    "station": ("s",),
    "platform": (),
    "segment": ("sStart", "sEnd"),
    "neighbor": (),
    "CRG": ("sStart", "sEnd", "sOffset", "tOffset", "zOffset"),
    "predecessor": ("elementS",),
    "successor": ("elementS",),
    "priority": (),
}

# attributes that are heights (vertical lengths): not scaled when scale_heights is False
HEIGHTS = frozenset({"zOffset", "height", "dz", "z", "inner", "outer", "heightStart", "heightEnd", "zOffsetStart",
                     "zOffsetEnd"})
# polynomials whose value is a height
HEIGHT_POLYS = frozenset({"elevation", "shape"})

# polynomial records: tag -> (scale power of the value, coefficient names a..d)
#   value power 1: a length (elevation, width, offset); 0: an angle or slope
POLYS: dict[str, tuple[int, tuple[str, ...]]] = {
    "elevation": (1, ("a", "b", "c", "d")),
    "laneOffset": (1, ("a", "b", "c", "d")),
    "width": (1, ("a", "b", "c", "d")),
    "shape": (1, ("a", "b", "c", "d")),
    "sway": (1, ("a", "b", "c", "d")),
    "poly3": (1, ("a", "b", "c", "d")),
    "superelevation": (0, ("a", "b", "c", "d")),
    "crossfall": (0, ("a", "b", "c", "d")),
}
# lane borders are also tagged "border"; they have sOffset and a..d like width
LANE_BORDER_LENGTHS = ("sOffset",)

POINT_TAGS = ("positionInertial", "cornerInertial")
ANGLE_TAGS = ("positionInertial",)  # hdg in the inertial frame turns with the rotation


class XodrFrameError(ValueError):
    pass


def _num(v: str) -> float:
    return float(v)


def _fmt(v: float) -> str:
    return repr(float(v))


def _scale_attrs(el: ET.Element, names, factor: float) -> None:
    if factor == 1.0:
        return
    for n in names:
        if n in el.attrib:
            el.set(n, _fmt(_num(el.attrib[n]) * factor))


def _scale_poly(el: ET.Element, value_power: int, coeffs, scale: float) -> None:
    if scale == 1.0:
        return
    q = scale ** value_power
    for i, n in enumerate(coeffs):
        if n in el.attrib:
            el.set(n, _fmt(_num(el.attrib[n]) * q / scale ** i))


def _move_point(el: ET.Element, c: float, s: float, scale: float, rot: float, t=(0.0, 0.0)) -> None:
    x, y = _num(el.get("x", "0")), _num(el.get("y", "0"))
    el.set("x", _fmt(scale * (c * x - s * y) + t[0]))
    el.set("y", _fmt(scale * (s * x + c * y) + t[1]))
    if el.tag in ANGLE_TAGS and "hdg" in el.attrib and rot:
        el.set("hdg", _fmt(_num(el.attrib["hdg"]) + rot))


def transform_xodr(text: str, rotation_rad: float, scale: float, geo_reference: str | None = None, *,
                   name: str = "OpenDRIVE", keep_georeference_as: str = "twinkit_site_geoReference",
                   translation: tuple[float, float] = (0.0, 0.0), scale_heights: bool = True,
                   dz: float = 0.0) -> str:
    """``text`` (an OpenDRIVE document) moved by ``scale * Rz(rotation_rad) + translation``; its geoReference set
    to ``geo_reference`` (the old one kept in a header ``userData`` named ``keep_georeference_as``).

    ``scale_heights=False``: heights keep their values (see the module doc); ``dz`` is added to every road's
    elevation (a road without one gets a constant one) and to inertial heights. The identity (rotation 0,
    scale 1, no translation) leaves every coordinate as it is written."""
    root = _parse_opendrive(text, name)
    scale = float(scale)
    if not (scale > 0 and math.isfinite(scale)):
        raise XodrFrameError(f"{name}: scale must be positive, got {scale}")
    t = (float(translation[0]), float(translation[1]))
    mv = _Motion(name=name, c=math.cos(rotation_rad), s=math.sin(rotation_rad), rotation_rad=rotation_rad,
                 scale=scale, t=t, moves=not (rotation_rad == 0 and scale == 1.0 and t == (0.0, 0.0)),
                 scale_heights=scale_heights, hscale=scale if scale_heights else 1.0, dz=dz)
    header = root.find("header")
    if header is not None:
        off = header.find("offset")
        if off is not None and any(abs(_num(off.get(k, "0"))) > 0 for k in ("x", "y", "z", "hdg")):
            raise XodrFrameError(f"{name}: the header has an <offset> (x, y, z, hdg); twinkit writes the package "
                                 "frame without one: remove it (apply it to the geometry) and run again")
    _move_tree(root, mv)
    if dz:
        _shift_elevation(root, dz)
    if header is not None:
        if mv.moves:
            _bounds(header, mv.c, mv.s, scale, t)
        if geo_reference is not None:
            _set_georeference(header, geo_reference, keep_georeference_as)
    body = ET.tostring(root, encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"


def _parse_opendrive(text: str | bytes, name: str) -> ET.Element:
    """The document's <OpenDRIVE> root, comments kept; XodrFrameError when it is not well-formed or not OpenDRIVE."""
    try:
        root = ET.fromstring(text.encode() if isinstance(text, str) else text,
                             parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise XodrFrameError(f"{name}: not well-formed XML ({exc}); re-run the road alignment step") from None
    if root.tag != "OpenDRIVE":
        raise XodrFrameError(f"{name}: the root element is <{root.tag}>, not <OpenDRIVE>")
    return root


@dataclass(frozen=True)
class _Motion:
    """The move :func:`transform_xodr` applies: ``scale * Rz(rotation_rad) + t`` (c, s: its cosine and sine);
    ``moves``: not the identity; ``hscale``: the factor on heights; ``dz``: metres added to heights."""

    name: str
    c: float
    s: float
    rotation_rad: float
    scale: float
    t: tuple[float, float]
    moves: bool
    scale_heights: bool
    hscale: float
    dz: float


def _move_tree(parent: ET.Element, mv: _Motion) -> None:
    """Move every element under ``parent`` (a plan-view geometry's children are moved with it)."""
    for el in parent:
        if not isinstance(el.tag, str) or el.tag == "userData":
            continue  # comments; vendor data (RoadRunner's vector* records) are not road geometry
        _move_element(el, parent, mv)
        if not (el.tag == "geometry" and parent.tag == "planView"):
            _move_tree(el, mv)


def _move_element(el: ET.Element, parent: ET.Element, mv: _Motion) -> None:
    """Move one element's own attributes: points, lengths, polynomial coefficients; XodrFrameError for an
    element with length-like attributes twinkit does not know how to scale (when scaling)."""
    tag, scale = el.tag, mv.scale
    if tag == "geometry" and parent.tag == "planView":
        _move_plan_geometry(el, mv)
        return
    if tag == "border" and parent.tag == "lane":
        _scale_attrs(el, LANE_BORDER_LENGTHS, scale)
        _scale_poly(el, 1, ("a", "b", "c", "d"), scale)
        return
    if tag in POINT_TAGS:
        if mv.moves:
            _move_point(el, mv.c, mv.s, scale, mv.rotation_rad, mv.t)
        if mv.dz and "z" in el.attrib:
            el.set("z", _fmt(_num(el.attrib["z"]) * mv.hscale + mv.dz))
    if tag in LENGTHS:
        names = LENGTHS[tag]
        if not mv.scale_heights:
            _scale_attrs(el, [n for n in names if n not in HEIGHTS], scale)
        else:
            _scale_attrs(el, [n for n in names if not (mv.dz and tag in POINT_TAGS and n == "z")], scale)
    if tag in POLYS and tag != "poly3":
        power, coeffs = POLYS[tag]
        _scale_poly(el, 0 if (tag in HEIGHT_POLYS and not mv.scale_heights) else power, coeffs, scale)
    if scale != 1.0 and tag not in LENGTHS and tag not in POLYS and tag not in _NO_LENGTHS:
        suspicious = [k for k in el.attrib if k in _LENGTH_NAMES]
        if suspicious:
            raise XodrFrameError(f"{mv.name}: <{tag}> has {', '.join(suspicious)}, which twinkit does not know "
                                 f"how to scale; use the scale mode 'site' (no scale) or remove the element")


def _move_plan_geometry(el: ET.Element, mv: _Motion) -> None:
    """A plan-view <geometry>: its start point and heading moved, its s and length scaled, and its shape
    (arc, spiral, poly3, paramPoly3) scaled to match."""
    scale = mv.scale
    if mv.moves:
        _move_point(el, mv.c, mv.s, scale, 0.0, mv.t)
        if mv.rotation_rad:
            el.set("hdg", _fmt(_num(el.get("hdg", "0")) + mv.rotation_rad))
    _scale_attrs(el, ("s", "length"), scale)
    for g in el:
        if not isinstance(g.tag, str):
            continue
        if g.tag == "arc":
            _scale_attrs(g, ("curvature",), 1.0 / scale)
        elif g.tag == "spiral":
            _scale_attrs(g, ("curvStart", "curvEnd"), 1.0 / scale)
        elif g.tag == "poly3":
            _scale_poly(g, *POLYS["poly3"], scale)
        elif g.tag == "paramPoly3":
            if g.get("pRange", "normalized") == "arcLength":
                _scale_poly(g, 1, ("aU", "bU", "cU", "dU"), scale)
                _scale_poly(g, 1, ("aV", "bV", "cV", "dV"), scale)
            else:  # p in [0, 1]: every coefficient is a length
                _scale_attrs(g, ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV"), scale)


def _set_georeference(header: ET.Element, geo_reference: str, keep_georeference_as: str) -> None:
    """Set the header's <geoReference> (created first in the header when missing); the old one, when not empty,
    is kept in a ``userData`` named ``keep_georeference_as`` (when that is not empty either)."""
    geo = header.find("geoReference")
    old = (geo.text or "").strip() if geo is not None else ""
    if geo is None:
        geo = ET.Element("geoReference")
        header.insert(0, geo)
    geo.text = geo_reference
    if old and keep_georeference_as:
        ud = ET.SubElement(header, "userData", {"code": keep_georeference_as, "value": old})
        ud.tail = "\n    "


# elements without lengths, and the attribute names that would be lengths on an unknown element
_NO_LENGTHS = {"OpenDRIVE", "header", "geoReference", "offset", "userData", "include", "link", "predecessor",
               "successor", "neighbor", "planView", "line", "arc", "spiral", "paramPoly3", "elevationProfile",
               "lateralProfile", "lanes", "left", "center", "right", "lane", "objects", "signals", "outline",
               "outlines", "junction", "connection", "laneLink", "controller", "control", "validity", "dependency",
               "reference", "surface", "railroad", "switch", "mainTrack", "sideTrack", "partner", "junctionGroup",
               "junctionReference", "stations", "parkingSpace", "markings", "borders", "explicit", "dataQuality",
               "error", "rawData", "semantics", "vectorScene", "vectorRoad", "vectorLane", "vectorSignal",
               "vectorJunction", "vectorObject", "vectorController", "cornerReference", "priority", "platform"}
_LENGTH_NAMES = {"s", "t", "length", "width", "height", "radius", "sOffset", "tOffset", "zOffset", "ds", "x", "y",
                 "z", "distance", "u", "v"}


def _shift_elevation(root: ET.Element, dz: float) -> None:
    """``dz`` added to every road's elevation; a road without an elevation profile gets a constant one."""
    for road in root.findall("road"):
        prof = road.find("elevationProfile")
        if prof is None:
            prof = ET.Element("elevationProfile")
            pv = road.find("planView")
            road.insert(list(road).index(pv) + 1 if pv is not None else 0, prof)
        els = prof.findall("elevation")
        if not els:
            els = [ET.SubElement(prof, "elevation", {"s": "0", "a": "0", "b": "0", "c": "0", "d": "0"})]
        for e in els:
            e.set("a", _fmt(_num(e.get("a", "0")) + dz))


def _bounds(header: ET.Element, c: float, s: float, scale: float, t=(0.0, 0.0)) -> None:
    """The header's north/south/east/west: the box of the moved corners of the old box."""
    try:
        n, so, e, w = (_num(header.attrib[k]) for k in ("north", "south", "east", "west"))
    except (KeyError, ValueError):  # a header without its box, or not numbers
        return
    xs, ys = [], []
    for x, y in ((w, so), (w, n), (e, so), (e, n)):
        xs.append(scale * (c * x - s * y) + t[0])
        ys.append(scale * (s * x + c * y) + t[1])
    header.set("north", f"{max(ys):.3f}")
    header.set("south", f"{min(ys):.3f}")
    header.set("east", f"{max(xs):.3f}")
    header.set("west", f"{min(xs):.3f}")


# --------------------------------------------------------------------------- twinkit's own header tags

#: ``<userData code="twinkit_road_source" value="scan"/>``: the map was derived from the scan itself
#: (road_source=scan); ``<userData code="twinkit_roads" value="none"/>``: the scan holds no road, the map
#: has none (a twin without a road network). Read by the road steps and the exporters.
SCAN_TAG = '<userData code="twinkit_road_source" value="scan"/>'
NO_ROADS_TAG = '<userData code="twinkit_roads" value="none"/>'


def _has_user_data(text: str, code: str, value: str) -> bool:
    import re

    # the header comes first; an XML round trip may write ``value="scan" />``
    return re.search(rf'<userData\s+code="{code}"\s+value="{value}"\s*/?>', text[:4000]) is not None


def from_scan(text: str) -> bool:
    """The OpenDRIVE text was derived from the scan (road_source=scan)."""
    return _has_user_data(text, "twinkit_road_source", "scan")


def has_no_roads(text: str) -> bool:
    """The OpenDRIVE text is road_source=scan's map of a scan that holds no road."""
    return _has_user_data(text, "twinkit_roads", "none")


# --------------------------------------------------------------------------- where a network came from

#: the kinds :func:`source_kind` tells apart, with the words a message uses for each
SOURCE_NAMES = {
    "osm": "an OpenStreetMap extract (road_source=file / overpass / osm_api)",
    "opendrive": "an OpenDRIVE file (road_source=opendrive)",
    "scan": "the scan itself (road_source=scan)",
    "none": "no road network",
}

#: what to check, per source, when a network does not fit the scan: ``misfit`` (its lanes are not on the
#: scanned carriageway), ``no_overlap`` (the fit finds no road surface under it) and ``no_map`` (no map came
#: out: the CARLA package is props only)
SOURCE_HINTS = {
    "osm": {"misfit": "a wrong or outdated OSM, or a failed alignment? check the OSM extract and alignment.json",
            "no_overlap": "check the georeference (site.crs, site.base_point) and the OSM extract, or raise "
                          "steps.align_roads.search_m",
            "no_map": "give an OSM extract that holds the site's roads (site.inputs.osm)"},
    "opendrive": {"misfit": "a wrong geoReference or offset of the OpenDRIVE file (see reprojection.json), or a "
                            "failed alignment? check the file's geoReference and alignment.json",
                  "no_overlap": "check the OpenDRIVE file's geoReference and offset (reprojection.json), or raise "
                                "steps.align_roads.search_m",
                  "no_map": "give an OpenDRIVE file that holds the site's roads (site.inputs.xodr)"},
    "scan": {"misfit": "the scan's road labels or road class coverage are poor, or the scan is too sparse there "
                       "(see scan_roads.png); check the segmentation's labels, or give an OSM extract "
                       "(site.inputs.osm road_source=file)",
             "no_overlap": "the network was derived from this scan and needs no alignment: it is kept in place",
             "no_map": "the scan's road labels held no carriageway that held up (see scan_roads.png); check the "
                       "segmentation's road labels or the scan's density there, or give an OSM extract "
                       "(site.inputs.osm road_source=file)"},
    "none": {"misfit": "", "no_overlap": "",
             "no_map": "give an OSM extract (site.inputs.osm) or an OpenDRIVE file (road_source=opendrive) for a map"},
}

OPENDRIVE_TAG = '<userData code="twinkit_road_source" value="opendrive"/>'


def source_kind(text: str | None) -> str:
    """Where an OpenDRIVE map came from: 'scan' (road_source=scan, also its map without roads), 'opendrive'
    (road_source=opendrive, tagged by :func:`tag_source`), 'osm' (netconvert of an OSM extract: no tag) or
    'none' (``text`` None: no map)."""
    if text is None:
        return "none"
    if from_scan(text):
        return "scan"
    if _has_user_data(text, "twinkit_road_source", "opendrive"):
        return "opendrive"
    return "osm"


def source_hint(kind: str, concern: str) -> str:
    """The fix that fits ``concern`` (a key of :data:`SOURCE_HINTS`) for a network of source ``kind``."""
    return SOURCE_HINTS.get(kind, SOURCE_HINTS["osm"])[concern]


def tag_source(text: str, tag: str) -> str:
    """``text`` with ``tag`` (a ``<userData .../>`` of this section) in its header, once."""
    if tag in text[:4000]:
        return text
    i = text.find("<header")
    j = text.find(">", i)
    if i < 0 or j < 0:
        return text
    if text[j - 1] == "/":  # <header .../>
        return text[:j - 1] + ">" + tag + "</header>" + text[j + 1:]
    return text[:j + 1] + "\n        " + tag + text[j + 1:]
