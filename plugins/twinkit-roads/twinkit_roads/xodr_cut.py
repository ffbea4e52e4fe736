"""Cutting an OpenDRIVE road to a part of its length, and moving a road rigidly (ElementTree, in place).

:func:`cut_road` keeps ``[s0, s1]`` of a road: its plan view starts at the point and heading of ``s0`` and is
``s1 - s0`` long; every record placed along s (lane sections, lane widths and borders, road marks, speeds,
elevation, superelevation, crossfall, lane offset, road types) keeps its value at every kept s (polynomials are
re-expanded about their new start); signals and objects move with s and those beyond the new ends are put on
the nearest end (returned, so that the caller can say so). Plan-view geometries: ``line``, ``arc`` and
``paramPoly3`` are cut anywhere; a ``spiral`` or ``poly3`` only at its own end (:class:`CutError` otherwise).

:func:`narrow_lanes` gives single lanes of a road no width near one of its ends, the rest of the road as it was:
the lane section at each place a lane ends is split in two (:func:`split_section`: every lane record kept as it
was on each side, the lanes of the two parts linked by their ids) and the lane's width in the part towards the
end set to 0 (:func:`zero_lane`). The lane keeps its id in every section, so junction lane links into it still
hold (CARLA reads a lane of width 0 like any other; it carries nothing).

:func:`move_road` applies a rigid motion (a rotation about a point, then a translation) to a road's plan view:
the turnaround of a dead end follows the end of its road.
"""
from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET

import numpy as np


class CutError(ValueError):
    """The road cannot be cut there (a geometry type or a lane-section layout this module does not cut)."""


def _f(el: ET.Element, k: str, default: float = 0.0) -> float:
    return float(el.get(k, default))


def _fmt(v: float) -> str:
    return f"{float(v):.8f}"


def _shift_poly(c: tuple[float, float, float, float], t: float, k: float = 1.0) -> tuple[float, float, float, float]:
    """Coefficients of ``g(q) = f(t + k q)`` for ``f(u) = a + b u + c u^2 + d u^3``."""
    a, b, cc, d = c
    return (a + b * t + cc * t * t + d * t ** 3, k * (b + 2 * cc * t + 3 * d * t * t), k * k * (cc + 3 * d * t),
            k ** 3 * d)


def _poly(el: ET.Element, names=("a", "b", "c", "d")) -> tuple[float, float, float, float]:
    a, b, c, d = (_f(el, n) for n in names)
    return a, b, c, d


def _set_poly(el: ET.Element, c, names=("a", "b", "c", "d")) -> None:
    for n, v in zip(names, c):
        el.set(n, _fmt(v))


# ------------------------------------------------------------------------------------------------ plan view

def _pp3_arclength(g: ET.Element, el: ET.Element, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """(p, s): the parameter of a paramPoly3 and the arc length from its start, on ``n + 1`` samples."""
    hi = 1.0 if el.get("pRange", "normalized") != "arcLength" else _f(g, "length")
    p = np.linspace(0.0, hi, n + 1)
    du = np.polyval([3 * _f(el, "dU"), 2 * _f(el, "cU"), _f(el, "bU")], p)
    dv = np.polyval([3 * _f(el, "dV"), 2 * _f(el, "cV"), _f(el, "bV")], p)
    sp = np.hypot(du, dv)
    s = np.concatenate([[0.0], np.cumsum((sp[1:] + sp[:-1]) / 2 * np.diff(p))])
    return p, s


def _pp3_p(g: ET.Element, el: ET.Element, a: float) -> float:
    """The paramPoly3 parameter at arc length ``a`` from the geometry's start (scaled to its ``length``)."""
    p, s = _pp3_arclength(g, el)
    return float(np.interp(a * s[-1] / max(_f(g, "length"), 1e-12), s, p))


def pose_in(g: ET.Element, a: float) -> tuple[float, float, float]:
    """(x, y, heading rad) at ``a`` metres along the plan-view geometry ``g`` (line, arc, spiral at 0, paramPoly3)."""
    x0, y0, h0 = _f(g, "x"), _f(g, "y"), _f(g, "hdg")
    kind = next((c for c in g if isinstance(c.tag, str)), None)
    tag = kind.tag if kind is not None else "line"
    if tag == "line" or (a == 0.0 and tag != "paramPoly3"):
        return x0 + a * math.cos(h0), y0 + a * math.sin(h0), h0
    if tag == "arc":
        k = _f(kind, "curvature")
        if abs(k) < 1e-12:
            return x0 + a * math.cos(h0), y0 + a * math.sin(h0), h0
        return (x0 + (math.sin(h0 + k * a) - math.sin(h0)) / k, y0 - (math.cos(h0 + k * a) - math.cos(h0)) / k,
                h0 + k * a)
    if tag == "paramPoly3":
        p = _pp3_p(g, kind, a)
        u = np.polyval([_f(kind, "dU"), _f(kind, "cU"), _f(kind, "bU"), _f(kind, "aU")], p)
        v = np.polyval([_f(kind, "dV"), _f(kind, "cV"), _f(kind, "bV"), _f(kind, "aV")], p)
        du = np.polyval([3 * _f(kind, "dU"), 2 * _f(kind, "cU"), _f(kind, "bU")], p)
        dv = np.polyval([3 * _f(kind, "dV"), 2 * _f(kind, "cV"), _f(kind, "bV")], p)
        c, s = math.cos(h0), math.sin(h0)
        return x0 + c * u - s * v, y0 + s * u + c * v, h0 + math.atan2(dv, du)
    raise CutError(f"a <{tag}> geometry is cut only at its ends")


def road_pose(road: ET.Element, s: float) -> tuple[float, float, float]:
    """(x, y, heading rad) of the reference line of ``road`` at ``s`` (clamped to the road)."""
    geoms = road.find("planView").findall("geometry")
    s = min(max(s, 0.0), _f(road, "length"))
    g = next((g for g in reversed(geoms) if _f(g, "s") <= s + 1e-9), geoms[0])
    return pose_in(g, min(s - _f(g, "s"), _f(g, "length")))


def _cut_geometry(g: ET.Element, a: float, b: float) -> None:
    """Keep ``[a, b]`` metres of one plan-view geometry (its own s from 0); its s is left to the caller."""
    length = _f(g, "length")
    kind = next((c for c in g if isinstance(c.tag, str)), None)
    tag = kind.tag if kind is not None else "line"
    if tag in ("spiral", "poly3") and a > 1e-9:
        raise CutError(f"a <{tag}> geometry is cut only at its ends")
    if tag == "poly3" and b < length - 1e-9:
        raise CutError("a <poly3> geometry is cut only at its ends")
    x, y, h = pose_in(g, a)  # before the polynomials change
    if tag == "spiral" and b < length - 1e-9:
        k0, k1 = _f(kind, "curvStart"), _f(kind, "curvEnd")
        kind.set("curvEnd", _fmt(k0 + (k1 - k0) * b / length))
    if tag == "paramPoly3" and (a > 1e-9 or b < length - 1e-9):
        _cut_pp3(g, kind, a, b)
    if a > 1e-9:
        g.set("x", _fmt(x))
        g.set("y", _fmt(y))
        if tag != "paramPoly3":  # a paramPoly3 keeps its frame: its polynomials were moved in it
            g.set("hdg", _fmt(h))
    g.set("length", _fmt(b - a))


def _cut_pp3(g: ET.Element, el: ET.Element, a: float, b: float) -> None:
    """A paramPoly3 re-parametrised to its part from arc length ``a`` to ``b``, in the same local frame, its start
    moved to the frame's origin (the caller puts the geometry's x, y at the old point of ``a``)."""
    pa, pb = _pp3_p(g, el, a), _pp3_p(g, el, b)
    k = (pb - pa) if el.get("pRange", "normalized") != "arcLength" else 1.0
    for ax in ("U", "V"):
        names = tuple(n + ax for n in "abcd")
        c = list(_shift_poly(_poly(el, names), pa, k))
        c[0] = 0.0
        _set_poly(el, c, names)


def _cut_plan_view(road: ET.Element, s0: float, s1: float) -> None:
    pv = road.find("planView")
    for g in list(pv.findall("geometry")):
        gs, gl = _f(g, "s"), _f(g, "length")
        a, b = max(s0, gs) - gs, min(s1, gs + gl) - gs
        if b <= a + 1e-9:
            pv.remove(g)
            continue
        _cut_geometry(g, a, b)
        g.set("s", _fmt(max(gs, s0) - s0))
    if not pv.findall("geometry"):
        raise CutError("nothing of the plan view is left")


# ------------------------------------------------------------------------------------------------ records

def _cut_records(parent: ET.Element | None, tag: str, attr: str, lo: float, hi: float, poly: tuple | None) -> None:
    """Records ``tag`` under ``parent`` placed by ``attr``, each valid up to the next: keep those valid in
    ``[lo, hi)``, moved by ``-lo``; the one valid at ``lo`` starts there (a polynomial ``poly`` re-expanded)."""
    if parent is None:
        return
    recs = parent.findall(tag)
    if not recs:
        return
    pos = [_f(r, attr) for r in recs]
    first = max([i for i, p in enumerate(pos) if p <= lo + 1e-9], default=0)
    for i, r in enumerate(recs):
        if i < first or (i > first and pos[i] >= hi - 1e-9):
            parent.remove(r)
            continue
        if i == first and pos[i] < lo:
            if poly is not None:
                _set_poly(r, _shift_poly(_poly(r, poly), lo - pos[i]), poly)
            r.set(attr, _fmt(0.0))
        else:
            r.set(attr, _fmt(max(pos[i] - lo, 0.0)))


ABCD = ("a", "b", "c", "d")
#: records in a lane: tag -> polynomial coefficient names (None: a step function)
LANE_RECORDS = {"width": ABCD, "border": ABCD, "roadMark": None, "material": None, "speed": None, "access": None,
                "height": None, "rule": None, "visibility": None}


def _cut_sections(road: ET.Element, s0: float, s1: float) -> None:
    lanes = road.find("lanes")
    secs = lanes.findall("laneSection")
    pos = [_f(x, "s") for x in secs]
    first = max([i for i, p in enumerate(pos) if p <= s0 + 1e-9], default=0)
    for i, sec in enumerate(secs):
        if i < first or (i > first and pos[i] >= s1 - 1e-9):
            lanes.remove(sec)
            continue
        lo = max(s0 - pos[i], 0.0)
        hi = s1 - pos[i]
        for lane in sec.iter("lane"):
            for tag, poly in LANE_RECORDS.items():
                _cut_records(lane, tag, "sOffset", lo, hi, poly)
        sec.set("s", _fmt(max(pos[i] - s0, 0.0)))
    kept = lanes.findall("laneSection")
    if first > 0:  # the first section's lanes linked to a section that is gone
        _drop_lane_links(kept[0], "predecessor")
    if len(kept) < len(secs) - first:
        _drop_lane_links(kept[-1], "successor")


def _drop_lane_links(sec: ET.Element, which: str) -> None:
    for lane in sec.iter("lane"):
        link = lane.find("link")
        if link is not None:
            for el in link.findall(which):
                link.remove(el)


def _place(el: ET.Element, s0: float, new_len: float, what: str, notes: list[str]) -> None:
    s = _f(el, "s") - s0
    if s < -1e-6 or s > new_len + 1e-6:
        notes.append(f"{what} {el.get('id', '?')} at s {s + s0:.2f} m lay on the cut part: put at the road's "
                     f"{'start' if s < 0 else 'end'}")
    el.set("s", _fmt(min(max(s, 0.0), new_len)))


def cut_road(road: ET.Element, s0: float, s1: float) -> list[str]:
    """Keep ``[s0, s1]`` (metres along the road, 0 <= s0 < s1 <= length) of ``road``, in place. Returns notes
    (signals or objects moved onto a new end). :class:`CutError` when the plan view cannot be cut there."""
    length = _f(road, "length")
    s0, s1 = max(0.0, float(s0)), min(length, float(s1))
    if s1 - s0 < 0.5:
        raise CutError(f"road {road.get('id')}: less than 0.5 m would be left ({s0:.2f} .. {s1:.2f} m)")
    if s0 <= 1e-9 and s1 >= length - 1e-9:
        return []
    _cut_plan_view(road, s0, s1)
    _cut_records(road.find("elevationProfile"), "elevation", "s", s0, s1, ABCD)
    lat = road.find("lateralProfile")
    _cut_records(lat, "superelevation", "s", s0, s1, ABCD)
    _cut_records(lat, "crossfall", "s", s0, s1, ABCD)
    _cut_records(road.find("lanes"), "laneOffset", "s", s0, s1, ABCD)
    _cut_records(road, "type", "s", s0, s1, None)
    _cut_sections(road, s0, s1)
    new_len = s1 - s0
    notes: list[str] = []
    for tag, what in (("signal", "signal"), ("signalReference", "signal reference"), ("object", "object"),
                      ("objectReference", "object reference")):
        for el in road.iter(tag):
            _place(el, s0, new_len, what, notes)
    road.set("length", _fmt(new_len))
    return notes


def move_road(road: ET.Element, about: tuple[float, float], turn_rad: float, shift: tuple[float, float],
              dz: float = 0.0) -> None:
    """Rotate ``road``'s plan view by ``turn_rad`` about ``about`` (x, y), then move it by ``shift`` (x, y);
    ``dz`` metres added to its elevation (in place)."""
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    for g in road.find("planView").findall("geometry"):
        x, y = _f(g, "x") - about[0], _f(g, "y") - about[1]
        g.set("x", _fmt(about[0] + c * x - s * y + shift[0]))
        g.set("y", _fmt(about[1] + s * x + c * y + shift[1]))
        g.set("hdg", _fmt(_f(g, "hdg") + turn_rad))
    if dz:
        prof = road.find("elevationProfile")
        for e in prof.findall("elevation") if prof is not None else []:
            e.set("a", _fmt(_f(e, "a") + dz))


def elevation_at(road: ET.Element, s: float) -> float:
    """The road's elevation (m) at ``s``; 0 without an elevation profile."""
    prof = road.find("elevationProfile")
    recs = prof.findall("elevation") if prof is not None else []
    if not recs:
        return 0.0
    r = next((r for r in reversed(recs) if _f(r, "s") <= s + 1e-9), recs[0])
    a, b, c, d = _poly(r)
    u = s - _f(r, "s")
    return a + b * u + c * u * u + d * u ** 3


# ------------------------------------------------------------------------------------------------ lane sections

def _link_to_self(lane: ET.Element, which: str) -> None:
    """Point the lane's ``which`` link (predecessor | successor) at its own id (the lane of the same id in the
    neighbouring section of the road)."""
    link = lane.find("link")
    if link is None:
        link = ET.Element("link")
        lane.insert(0, link)
    for el in link.findall(which):
        link.remove(el)
    el = ET.Element(which, {"id": lane.get("id")})
    if which == "predecessor":
        link.insert(0, el)
    else:
        link.append(el)


def split_section(road: ET.Element, s: float) -> bool:
    """Split the lane section of ``road`` that holds ``s`` (metres along the road) in two at ``s``, in place:
    each lane record keeps its value at every s (polynomials re-expanded in the second part), and the lanes of the
    first part lead to those of the same id in the second. False (nothing done) when ``s`` lies within 1 mm of a
    section's start or of the road's ends."""
    lanes = road.find("lanes")
    secs = lanes.findall("laneSection")
    pos = [_f(x, "s") for x in secs]
    length = _f(road, "length")
    if s <= 1e-3 or s >= length - 1e-3 or any(abs(p - s) < 1e-3 for p in pos):
        return False
    i = max(j for j, p in enumerate(pos) if p <= s)
    first = secs[i]
    second = copy.deepcopy(first)
    a, hi = s - pos[i], (pos[i + 1] if i + 1 < len(pos) else length) - pos[i]
    for part, lo, up, which in ((first, 0.0, a, "successor"), (second, a, hi, "predecessor")):
        for lane in part.iter("lane"):
            for tag, poly in LANE_RECORDS.items():
                _cut_records(lane, tag, "sOffset", lo, up, poly)
            if lane.get("id") != "0":
                _link_to_self(lane, which)
    second.set("s", _fmt(s))
    lanes.insert(list(lanes).index(first) + 1, second)
    return True


def zero_lane(section: ET.Element, lane_id: int) -> bool:
    """Give lane ``lane_id`` of ``section`` no width (one width record of 0; its borders dropped), in place;
    False when the section has no such lane."""
    lane = next((ln for ln in section.iter("lane") if ln.get("id") == str(int(lane_id))), None)
    if lane is None:
        return False
    for tag in ("width", "border"):
        for el in lane.findall(tag):
            lane.remove(el)
    at = 1 if lane.find("link") is not None and list(lane)[0].tag == "link" else 0
    lane.insert(at, ET.Element("width", {"sOffset": _fmt(0.0), "a": _fmt(0.0), "b": _fmt(0.0), "c": _fmt(0.0),
                                         "d": _fmt(0.0)}))
    return True


def narrow_lanes(road: ET.Element, side: str, cuts: dict[int, float]) -> None:
    """Give each lane ``id -> d`` of ``cuts`` no width over the ``d`` metres next to the road's ``side`` end
    ("start" | "end"), in place: the lane sections split where a lane's width ends (:func:`split_section`),
    the lane zeroed in every section within its ``d`` (:func:`zero_lane`); ``d`` at or past the road's length
    zeroes the lane along the whole road."""
    length = _f(road, "length")
    for d in sorted(set(cuts.values())):
        split_section(road, d if side == "start" else length - d)
    secs = road.find("lanes").findall("laneSection")
    starts = [_f(x, "s") for x in secs]
    for sec, a, b in zip(secs, starts, starts[1:] + [length]):
        for lid, d in cuts.items():
            lo, hi = (0.0, d) if side == "start" else (length - d, length)
            if a >= lo - 1e-3 and b <= hi + 1e-3:
                zero_lane(sec, lid)
