"""OpenDRIVE through netconvert: SUMO plain files of the derived network, netconvert, the scan's header tag,
and the map without roads."""
from __future__ import annotations

import subprocess
import time
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from twinkit import InputError

from .geometry import lane_layout, on_polyline
from .model import Network, ScanSourceParams


def write_plain(net: Network, p: ScanSourceParams, proj: str, folder: Path) -> tuple[Path, Path]:
    """SUMO plain network files (nodes, edges with their lanes) of the derived network."""
    folder.mkdir(parents=True, exist_ok=True)
    allxy = np.concatenate([a.xy for a in net.arms])
    lo, hi = allxy.min(0) - 50, allxy.max(0) + 50
    bnd = f"{lo[0]:.2f},{lo[1]:.2f},{hi[0]:.2f},{hi[1]:.2f}"
    nl = ['<?xml version="1.0" encoding="UTF-8"?>', "<nodes>",
          f'  <location netOffset="0.00,0.00" convBoundary="{bnd}" origBoundary="{bnd}" projParameter={quoteattr(proj)}/>']
    for nid, nd in net.nodes.items():
        kind = "traffic_light" if nd.get("signals") else ("priority" if nd["kind"] == "junction" else "dead_end")
        x, y = nd["xy"]
        nl.append(f'  <node id="n{nid}" x="{x:.3f}" y="{y:.3f}" z="{nd.get("z", 0.0):.3f}" type="{kind}"/>')
    nl.append("</nodes>")
    el = ['<?xml version="1.0" encoding="UTF-8"?>', "<edges>"]
    for i, arm in enumerate(net.arms):
        lay = lane_layout(arm.width_m, p)
        arm.lanes = lay
        z = arm.z if arm.z is not None else np.zeros(len(arm.xy))
        zr = arm.z_right if lay["two_way"] and arm.z_right is not None else z
        zl = arm.z_left if lay["two_way"] and arm.z_left is not None else z
        dirs = [("f", arm.a, arm.b, arm.xy, zr, arm.sidewalk_right_m)]
        if lay["two_way"]:
            dirs.append(("b", arm.b, arm.a, arm.xy[::-1], zl[::-1], arm.sidewalk_left_m))
        for tag, a, b, xy, zz, sw in dirs:
            lanes = []
            if p.sidewalks and sw > 0:
                lanes.append(("pedestrian", None, sw))
            if lay["strip_m"] > 0.05:
                lanes.append((None, "all", lay["strip_m"]))
            for _ in range(lay["lanes"]):
                lanes.append((None, "pedestrian", lay["lane_m"]))
            if not lay["two_way"]:  # one edge centred on the axis: the same strip and sidewalk on its left
                if lay["strip_m"] > 0.05:
                    lanes.append((None, "all", lay["strip_m"]))
                both = min(arm.sidewalk_left_m, arm.sidewalk_right_m) if p.sidewalks else 0.0
                lanes = [ln for ln in lanes if ln[0] != "pedestrian"]
                if both > 0:
                    lanes = [("pedestrian", None, both)] + lanes + [("pedestrian", None, both)]
            shape = " ".join(f"{x:.3f},{y:.3f},{h:.3f}" for (x, y), h in zip(xy, zz))
            spread = "right" if lay["two_way"] else "center"
            el.append(f'  <edge id="scan{i}{tag}" from="n{a}" to="n{b}" priority="{lay["lanes"]}" '
                      f'numLanes="{len(lanes)}" speed="13.89" spreadType="{spread}" shape="{shape}">')
            for k, (allow, disallow, wd) in enumerate(lanes):
                attr = f' allow="{allow}"' if allow else ""
                attr += f' disallow="{disallow}"' if disallow else ""
                el.append(f'    <lane index="{k}"{attr} width="{wd:.3f}"/>')
            el.append("  </edge>")
    el.append("</edges>")
    nod, edg = folder / "scan.nod.xml", folder / "scan.edg.xml"
    nod.write_text("\n".join(nl) + "\n", encoding="utf-8")
    edg.write_text("\n".join(el) + "\n", encoding="utf-8")
    return nod, edg


def write_turns(net: Network, edg: Path, folder: Path) -> Path | None:
    """A SUMO plain connection file deleting the turns the lane check dropped (``net.no_turns``: node id, where
    the turn starts, where it ends): at that node, the incoming edge of ``edg`` nearest the start to the outgoing
    edge nearest the end. None (and no file) when there are none."""
    con = folder / "scan.con.xml"
    con.unlink(missing_ok=True)
    if not net.no_turns:
        return None
    edges = [e for e in _plain_edges(edg) if len(e[3]) >= 2]
    pairs: list[tuple[str, str]] = []
    for nid, a, b in net.no_turns:
        inc = [(float(on_polyline(np.asarray([a]), sh)[0][0]), eid) for eid, _, to, sh in edges if to == f"n{nid}"]
        out = [(float(on_polyline(np.asarray([b]), sh)[0][0]), eid) for eid, fr, _, sh in edges if fr == f"n{nid}"]
        if inc and out and (min(inc)[1], min(out)[1]) not in pairs:
            pairs.append((min(inc)[1], min(out)[1]))
    if not pairs:
        return None
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<connections>"]
    lines += [f'  <delete from="{a}" to="{b}"/>' for a, b in pairs]
    con.write_text("\n".join(lines + ["</connections>"]) + "\n", encoding="utf-8")
    return con


def netconvert_plain(nod: Path, edg: Path, xodr: Path, p: ScanSourceParams, log=None, surface=None,
                     con: Path | None = None) -> dict:
    """netconvert on the plain network -> OpenDRIVE (the junctions' connecting roads are netconvert's, less the
    connections ``con`` deletes), with the edges' heights (``scan_elevations``; ``surface``: the carriageway's
    height at (k, 2) points, for the junctions' connecting roads)."""
    from ..convert import _env, finish_netconvert, netconvert_output, netconvert_path

    args = [str(netconvert_path()), "--node-files", str(nod), "--edge-files", str(edg),
            "--opendrive-output", str(xodr), "--offset.disable-normalization", "--no-turnarounds",
            "--junctions.corner-detail", "5", "--tls.discard-simple", "--no-warnings", "false", "--verbose", "false"]
    if con is not None:
        args += ["--connection-files", str(con)]
    t0 = time.perf_counter()
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=p.timeout_s, env=_env())
    except subprocess.TimeoutExpired:
        raise InputError(f"netconvert did not finish in {p.timeout_s:g} s on the scan's road network "
                         f"({edg}); raise road_source.timeout_s") from None
    lines, errors = netconvert_output(r)
    info = finish_netconvert(r, lines, errors, xodr, args, f"the scan's road network {edg}",
                             time.perf_counter() - t0, log)
    text, heights = scan_elevations(xodr.read_text(encoding="utf-8"), edg, surface=surface)
    xodr.write_text(text, encoding="utf-8")
    return {**info, **heights}


def scan_elevations(xodr_text: str, edg: Path, step_m: float = 1.0, surface=None) -> tuple[str, dict]:
    """netconvert's map with the heights the plain edges were given. netconvert keeps a junction flat at its
    node's height and cuts each road at the junction's border, gives the road there the junction's height and
    smooths the jump along the road (its max-grade fix); on a street that slopes away from a junction whose
    shape reaches far along it (an acute corner, wide roads) the first lanes past the border then float or
    sink. Each road's elevation is rewritten, every ``step_m`` and piecewise linear: the carriageway's surface
    under its driving lanes (``surface``, a function of (k, 2) points; :func:`_surface_under_lanes`) where it
    is known, else its edge's shape (the nearest point of the edge running its way: the edge's z, linear
    between its points); each connecting road in a junction runs from its predecessor's height at their contact
    to its successor's: over the surface under its lanes, tilted linearly to meet both ends, or straight
    without it.
    Returns the map and ``{"elevations_rewritten": roads, "elevation_moved_max_m": largest change}``."""
    import xml.etree.ElementTree as ET

    from ..reflines import reference_lines

    shapes = _edge_shapes(edg)
    root = ET.fromstring(xodr_text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    refs = reference_lines(root, 0.1)
    roads = {r.get("id"): r for r in root.iter("road")}
    profiles: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for rid, ref in refs.items():
        if ref.junction == "-1" and ref.length > 0 and shapes:
            prof = _road_profile(ref, shapes, _stations(ref.length, step_m))
            if prof is not None:
                profiles[rid] = _on_surface(roads[rid], ref, prof, surface)
    for rid, ref in refs.items():
        if ref.junction != "-1" and ref.length > 0:
            prof = _connecting_profile(roads[rid], ref, profiles, surface, step_m)
            if prof is not None:
                profiles[rid] = prof
    moved = 0.0
    for rid, (s, z) in profiles.items():
        moved = max(moved, float(np.abs(z - np.array([refs[rid].z(si) for si in s])).max()))
        _write_profile(roads[rid], s, z)
    text = '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    return text, {"elevations_rewritten": len(profiles), "elevation_moved_max_m": round(moved, 3)}


def mark_source(xodr_text: str) -> str:
    """Tag the header so later steps (and people) know the map came from the scan."""
    from twinkit.geo.xodr import SCAN_TAG, from_scan, tag_source

    return xodr_text if from_scan(xodr_text) else tag_source(xodr_text, SCAN_TAG)


def empty_map(proj: str) -> str:
    """An OpenDRIVE map with no roads (carla.Map reads it: no waypoints), tagged as the scan's and as empty."""
    from xml.sax.saxutils import escape

    from twinkit.geo.xodr import NO_ROADS_TAG, SCAN_TAG

    return ('<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE>\n    <header revMajor="1" revMinor="4" name="" '
            'version="1.00" north="0" south="0" east="0" west="0">\n'
            f"        <geoReference><![CDATA[{escape(proj)}]]></geoReference>\n"
            f"        {SCAN_TAG}\n        {NO_ROADS_TAG}\n    </header>\n</OpenDRIVE>\n")


def is_empty_map(xodr_text: str) -> bool:
    """The map ``scan_source`` writes when the scan holds no road."""
    from twinkit.geo.xodr import has_no_roads

    return has_no_roads(xodr_text)


def _runs_along(hdg: np.ndarray, shape: np.ndarray, seg: np.ndarray) -> bool:
    """Do points with headings ``hdg`` run the way of the polyline ``shape`` at its segments ``seg`` (mean cosine
    over 0.7)?"""
    d = np.diff(shape[:, :2], axis=0)[seg]
    return bool(((np.cos(hdg) * d[:, 0] + np.sin(hdg) * d[:, 1]) / np.maximum(np.hypot(*d.T), 1e-12)).mean() > 0.7)


def _stations(length: float, step_m: float) -> np.ndarray:
    return np.unique(np.r_[np.arange(0.0, length, step_m), length])


def _plain_edges(edg: Path) -> list[tuple[str, str, str, np.ndarray]]:
    """The edges of a SUMO plain edge file: (id, from node, to node, shape (k, 2 or 3))."""
    import xml.etree.ElementTree as ET

    out = []
    for e in ET.parse(edg).getroot().iter("edge"):
        pts = np.array([[float(c) for c in pt.split(",")] for pt in (e.get("shape") or "").split()])
        out.append((e.get("id"), e.get("from"), e.get("to"), pts))
    return out


def _edge_shapes(edg: Path) -> dict[str, np.ndarray]:
    """Edge id -> its shape (k, 3: x, y, z) in a SUMO plain edge file; edges without a 3D shape left out."""
    return {eid: pts for eid, _, _, pts in _plain_edges(edg) if len(pts) >= 2 and pts.shape[1] == 3}


def _road_profile(ref, shapes: dict, s: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(s, z) of a road from the edge it was built from (the nearest shape running its way: its z, linear between
    its points); None when no edge runs there (a road netconvert added)."""
    from .geometry import on_polyline

    xy = np.array([ref.point(si, 0.0) for si in s])
    hdg = np.interp(s, ref.s, np.unwrap(ref.hdg))
    fit = [(on_polyline(xy, sh), sh) for sh in shapes.values()]
    fit = [(d, al, sh) for (d, al, j), sh in fit if _runs_along(hdg, sh, j)]
    if not fit:
        return None
    dist, along, sh = min(fit, key=lambda t: t[0].mean())
    if dist.mean() > 5.0:
        return None
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(sh[:, :2], axis=0).T))]
    return s, np.interp(along, cum, sh[:, 2])


def _connecting_profile(road, ref, profiles: dict, surface, step_m: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(s, z) of a junction's connecting road: from its predecessor's height at their contact to its successor's,
    over ``surface`` under its lane's middle (tilted linearly to meet both) or straight; None when either road has
    no profile."""
    link = road.find("link")
    ends = []
    for tag in ("predecessor", "successor"):
        el = link.find(tag) if link is not None else None
        if el is None or el.get("elementType") != "road" or el.get("elementId") not in profiles:
            return None
        _, pz = profiles[el.get("elementId")]
        ends.append(float(pz[0] if el.get("contactPoint") == "start" else pz[-1]))
    if surface is None or ref.length <= 2 * step_m:
        return np.array([0.0, ref.length]), np.array(ends)
    s = _stations(ref.length, step_m)
    under = _surface_under_lanes(road, ref, s, surface)
    if under is None:
        return np.array([0.0, ref.length]), np.array(ends)
    zs = under[0]
    w = s / ref.length
    return s, zs + (ends[0] - zs[0]) * (1 - w) + (ends[1] - zs[-1]) * w


def _driving_offsets(road) -> list[float]:
    """Lateral offsets (m, + left of the reference line) across a road's right driving lanes, five per lane from
    border to border (the first lane section's widths; netconvert's roads carry their lanes on the right), or
    the middle of its first right lane when none is driving."""
    sec = road.find("lanes/laneSection/right")
    out, first, edge = [], None, 0.0
    lanes = sorted(sec.findall("lane"), key=lambda ln: -int(ln.get("id"))) if sec is not None else []
    for ln in lanes:  # -1, -2, ...: outwards from the reference line
        wd = ln.find("width")
        w = float(wd.get("a", 0.0)) if wd is not None else 0.0
        if first is None:
            first = -(edge + w / 2)
        if ln.get("type") == "driving":
            out.extend(-(edge + w * f) for f in (0.1, 0.3, 0.5, 0.7, 0.9))
        edge += w
    return out or ([first] if first is not None else [-1.6])


def _surface_under_lanes(road, ref, s: np.ndarray, surface) -> tuple[np.ndarray, np.ndarray] | None:
    """The carriageway's height under a road's driving lanes at stations ``s``: per station the median of
    ``surface`` across them (:func:`_driving_offsets`), filled linearly where it has none and smoothed over three
    stations; with the stations where it had some. None when the surface is unknown under the whole road."""
    offs = _driving_offsets(road)
    z = np.asarray(surface(np.array([ref.point(si, t) for si in s for t in offs])), float).reshape(len(s), len(offs))
    known = np.isfinite(z).any(axis=1)
    if not known.any():
        return None
    with np.errstate(all="ignore"):
        zs = np.nanmedian(z[known], axis=1)
    zs = np.interp(s, s[known], zs)
    return np.convolve(np.pad(zs, 1, mode="edge"), np.ones(3) / 3, mode="valid"), known


def _on_surface(road, ref, prof: tuple[np.ndarray, np.ndarray], surface) -> tuple[np.ndarray, np.ndarray]:
    """A road's profile from its edge's shape, moved onto the carriageway under its driving lanes where the surface
    is known (``surface`` None: unchanged). The edge's heights are that surface too, but sampled every
    ``sample_m``, smoothed over three shape points and ending at the junction point's height, so a road's last
    metres lean towards the junction's middle, and so do the connecting roads that start there (docs/roads.md)."""
    under = _surface_under_lanes(road, ref, prof[0], surface) if surface is not None else None
    if under is None:
        return prof
    zs, known = under
    return prof[0], np.where(known, zs, prof[1])


def _write_profile(road, s: np.ndarray, z: np.ndarray) -> None:
    """Replace a road's elevation profile by the piecewise linear one through (s, z)."""
    import xml.etree.ElementTree as ET

    prof = road.find("elevationProfile")
    if prof is None:
        prof = ET.Element("elevationProfile")
        road.insert(list(road).index(road.find("planView")) + 1, prof)
    for e in list(prof):
        prof.remove(e)
    slope = np.diff(z) / np.maximum(np.diff(s), 1e-9)
    for si, zi, bi in zip(s[:-1], z[:-1], slope):
        ET.SubElement(prof, "elevation", {"s": f"{si:.8f}", "a": f"{zi:.6f}", "b": f"{bi:.8f}", "c": "0", "d": "0"})
