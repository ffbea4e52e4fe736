"""OpenDRIVE through netconvert: SUMO plain files of the derived network, netconvert, the scan's header tag,
and the map without roads."""
from __future__ import annotations

import subprocess
import time
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from twinkit import InputError

from .geometry import lane_layout
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


def netconvert_plain(nod: Path, edg: Path, xodr: Path, p: ScanSourceParams, log=None) -> dict:
    """netconvert on the plain network -> OpenDRIVE (the junctions' connecting roads are netconvert's)."""
    from ..convert import _env, finish_netconvert, netconvert_output, netconvert_path

    args = [str(netconvert_path()), "--node-files", str(nod), "--edge-files", str(edg),
            "--opendrive-output", str(xodr), "--offset.disable-normalization", "--no-turnarounds",
            "--junctions.corner-detail", "5", "--tls.discard-simple", "--no-warnings", "false", "--verbose", "false"]
    t0 = time.perf_counter()
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=p.timeout_s, env=_env())
    except subprocess.TimeoutExpired:
        raise InputError(f"netconvert did not finish in {p.timeout_s:g} s on the scan's road network "
                         f"({edg}); raise road_source.timeout_s") from None
    lines, errors = netconvert_output(r)
    return finish_netconvert(r, lines, errors, xodr, args, f"the scan's road network {edg}",
                             time.perf_counter() - t0, log)


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
