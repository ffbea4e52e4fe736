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


def record_stage(net: Network, stage: str) -> None:
    """Keep the network's roads as they are after ``stage`` (scan_roads.json ``stages``: the length each check
    kept, and the axes with their carriageway width, from which a benchmark measures what each check dropped)."""
    net.stats.setdefault("stages", []).append({
        "stage": stage, "roads": len(net.arms), "length_m": round(network_length(net), 1),
        "arms": [{"width_m": round(float(a.width_m), 2), "axis": np.round(a.xy, 2).tolist()} for a in net.arms]})


def street_axis(v, f, labels, res: float = 0.25, min_half_m: float = 1.5, min_area_m2: float = 20.0,
                spur_m: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``res`` metre along the middle of the road-labelled ground seen from above: the skeleton of
    the road-labelled faces (gaps closed, holes filled, pieces under ``min_area_m2`` left out) without its spurs
    (a branch with a free end, shorter than the road's half width there plus ``spur_m``: a corner of the
    labels, once; the scan source's own pruning, repeated until stable, eats real street ends of ragged labels),
    where the road is at least ``2 * min_half_m`` wide. Returns (k, 2)
    site-frame x, y (each point stands for ``res`` metres of street) and (k, 2) unit directions along it."""
    from scipy import ndimage

    from ..mesh2d import Grid
    from .geometry import resample
    from .network import _degrees, _skeleton_edges

    grid = Grid.around(v[:, :2], res)
    road = rasterize_faces(v, f, np.flatnonzero((labels[f] == ROAD).sum(1) >= 2), grid)
    road = ndimage.binary_fill_holes(ndimage.binary_closing(road, np.ones((5, 5), bool)))
    lab, n = ndimage.label(road)
    if n:
        area = ndimage.sum(road, lab, np.arange(1, n + 1)) * res ** 2
        road = np.isin(lab, 1 + np.flatnonzero(area >= min_area_m2))
    node_xy, edges, _ = _skeleton_edges(road, grid)
    pts, dirs = [], []
    deg = _degrees(edges, len(node_xy))
    for a, b, xy, hw in edges:
        length = np.hypot(*np.diff(xy, axis=0).T).sum() if len(xy) > 1 else 0.0
        spur = (deg[a] == 1) != (deg[b] == 1) and max(deg[a], deg[b]) > 2 and length < float(hw.max()) + spur_m
        if spur or length < res:
            continue
        q = resample(xy, res)
        wide = np.interp(np.linspace(0, 1, len(q)), np.linspace(0, 1, len(hw)), hw) >= min_half_m
        if len(q) >= 2 and wide.any():
            pts.append(q[wide])
            dirs.append(directions(q, 1.5)[wide])
    if not pts:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return np.concatenate(pts), np.concatenate(dirs)


def directions(pts: np.ndarray, radius_m: float) -> np.ndarray:
    """(k, 2) unit direction of a line of points at each point: the main axis of its neighbours within
    ``radius_m``."""
    from scipy.spatial import cKDTree

    out = np.tile([1.0, 0.0], (len(pts), 1))
    tree = cKDTree(pts)
    for i, nb in enumerate(tree.query_ball_point(pts, radius_m)):
        q = pts[nb] - pts[nb].mean(0)
        if len(nb) >= 3:
            out[i] = np.linalg.eigh(q.T @ q)[1][:, -1]
    return out


def covered(points: np.ndarray, dirs: np.ndarray, arms: list[dict], tol_m: float,
            max_angle_deg: float = 30.0) -> np.ndarray:
    """Which of ``points`` ((k, 2), running along ``dirs``) lie on a road of ``arms`` (``{"axis": [[x, y], ...],
    "width_m": w}``, as in scan_roads.json ``stages``): within half the carriageway plus ``tol_m`` of its axis and
    no more than ``tol_m`` past either end of it, running the same way (within ``max_angle_deg``: a road across
    the street, or one wider than the street, does not cover it; nor does a wide road's end the street beyond it)."""
    from .geometry import on_polyline, unit

    out = np.zeros(len(points), bool)
    cos = np.cos(np.radians(max_angle_deg))
    for a in arms:
        xy = np.asarray(a["axis"], float)[:, :2]
        if len(xy) < 2 or not len(points):
            continue
        dist, s, j = on_polyline(points, xy)
        d = np.diff(xy, axis=0)[j]
        along = np.abs((d / np.maximum(np.hypot(*d.T), 1e-12)[:, None] * dirs).sum(1)) >= cos
        length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
        before = (points - xy[0]) @ unit(xy[1] - xy[0])  # < 0: before the axis's start
        after = (points - xy[-1]) @ unit(xy[-1] - xy[-2])  # > 0: past its end
        past = ((s <= 1e-9) & (before < -tol_m)) | ((s >= length - 1e-9) & (after > tol_m))
        out |= (dist <= a["width_m"] / 2 + tol_m) & along & ~past
    return out


def in_junctions(points: np.ndarray, xodr_text: str, raster_m: float = 0.25) -> np.ndarray:
    """Which of ``points`` ((k, 2), site frame) lie on a driving lane of one of the map's junctions (carla.Map): a
    street point there is served by the junction's connecting lanes whichever way the street runs through it."""
    from ..evidence import lane_polygons, lane_raster
    from ..mesh2d import Grid

    lanes = [ln for ln in lane_polygons(xodr_text, 0.5) if ln.type == "driving" and ln.junction]
    if not lanes or not len(points):
        return np.zeros(len(points), bool)
    for ln in lanes:
        ln.vote = 1
    grid = Grid.around(np.concatenate([np.concatenate([ln.left, ln.right]) for ln in lanes] + [points]), raster_m)
    vote, _ = lane_raster(lanes, grid)
    return grid.sample(vote, points) > 0
