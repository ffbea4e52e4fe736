"""Figures of a derived network: its length, its description (scan_roads.json), its lanes on road."""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import ROAD

from .masks import rasterize_faces
from .model import Network


def network_length(net: Network) -> float:
    """Metres of road axis in the network."""
    return float(sum(np.hypot(*np.diff(a.xy, axis=0).T).sum() for a in net.arms))


def describe(net: Network) -> dict:
    return {
        "nodes": [{"id": nid, "kind": nd["kind"], "xy": [round(float(c), 3) for c in nd["xy"]],
                   "z": round(float(nd.get("z", 0.0)), 3), "signals": bool(nd.get("signals")),
                   **({"traffic_light_vertices": nd["traffic_light_vertices"]} if "traffic_light_vertices" in nd else {})}
                  for nid, nd in net.nodes.items()],
        "roads": [{"from": a.a, "to": a.b, "length_m": round(float(np.hypot(*np.diff(a.xy, axis=0).T).sum()), 2),
                   "carriageway_m": round(a.width_m, 3), "sidewalk_left_m": a.sidewalk_left_m,
                   "sidewalk_right_m": a.sidewalk_right_m, **a.lanes,
                   "axis": [[round(float(x), 3), round(float(y), 3)] for x, y in a.xy]} for a in net.arms],
        **net.stats,
    }


def lanes_on_road(xodr_text: str, v, f, labels, step_m: float = 0.5, raster_m: float = 0.1,
                  junctions: bool = False) -> dict:
    """Share of the driving lanes' area (carla.Map, outside junctions unless ``junctions``) that lies on
    road-labelled surface of the mesh (seen from above); and of their centre points."""
    from scipy import ndimage

    from ..align import lane_lines
    from ..evidence import lane_polygons, lane_raster
    from ..mesh2d import Grid

    grid = Grid.around(v[:, :2], raster_m)
    lv = labels[f]
    road = rasterize_faces(v, f, np.flatnonzero((lv == ROAD).sum(1) >= 2), grid)
    road = ndimage.binary_closing(road, np.ones((3, 3), bool))
    lanes = [ln for ln in lane_polygons(xodr_text, step_m) if ln.type == "driving" and (junctions or not ln.junction)]
    if not lanes:
        return {"lane_area_m2": 0.0, "on_road_share": 0.0, "centre_on_road_share": 0.0}
    for ln in lanes:
        ln.vote = 1
    vote, _ = lane_raster(lanes, grid)
    inl = vote > 0
    share = float((inl & road).sum() / max(inl.sum(), 1))
    cen = np.concatenate([ln["centre"] for ln in lane_lines(xodr_text, 1.0, junctions=junctions)])
    cshare = float(np.mean(grid.sample(road.astype(np.uint8), cen) > 0)) if len(cen) else 0.0
    return {"lane_area_m2": round(float(inl.sum() * raster_m ** 2), 1), "on_road_share": round(share, 4),
            "centre_on_road_share": round(cshare, 4)}
