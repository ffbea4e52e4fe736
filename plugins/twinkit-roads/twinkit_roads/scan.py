"""Roads from the scan itself: lane centre lines, carriageway and sidewalk edges from the labelled mesh.

What a person does by hand in RoadRunner from lidar, as a road source (``road_source=scan``):

1. **Carriageway mask** (top view, ``raster_m``): faces labelled road (CityScapes 0) that lie on the
   carriageway level, i.e. below the curbs: up-facing faces within ``curb_tol_m`` of the local lowest
   ground (mesh2d.road_faces' ground fit, the same curb test align_roads uses). The labels say where
   the road roughly is; the curb step draws its edge. Curb-level faces a little beyond the labels
   (``label_margin_m``) are kept, so a label edge that wanders onto the carriageway does not move the
   road. Holes (cars, mislabelled markings) are filled.
2. **Axes and topology**: the mask is thinned to a one-pixel skeleton (Zhang-Suen); its pixels form a
   graph whose nodes are junctions (3+ arms) and ends. Short spurs (from mask corners) are pruned,
   nodes closer than a junction's size are merged.
3. **Each arm**: the skeleton path is smoothed; along it the distance to the carriageway edge is
   measured on both sides (rays along the normal). Parked cars and occlusions only ever *remove*
   road from the mask, so each side's edge is a high percentile over a window along the road. The
   axis is moved to the middle of the two edges; near a junction the axis is the straight
   continuation of the arm up to the junction point (the least-squares meeting point of the arms).
4. **Lanes**: per side ``floor(half width / lane_width_m)`` lanes of ``lane_width_m``; a remainder of
   at least ``min_strip_m`` is a parking strip at the curb (OpenDRIVE type none from netconvert,
   ``strip_type``), a smaller one widens the lanes. Roads narrower than two lanes are one lane, one way.
5. **Sidewalks**: beyond each curb, the run of sidewalk-labelled surface (else the raised level);
   its robust width becomes a sidewalk lane (``min_sidewalk_m``..``max_sidewalk_m``).
6. **OpenDRIVE**: a SUMO plain network (nodes at the junctions and ends, one edge per direction with
   its lanes: sidewalk, strip, driving lanes) goes through netconvert, which builds the junctions'
   connecting roads, as for OSM. A junction with traffic-light-labelled surface near it gets a
   signal plan (netconvert's signals, moved to the scanned heads later by place_signals).
"""
from __future__ import annotations

import dataclasses
import math
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from twinkit import InputError
from twinkit.ranges import param

ROAD, SIDEWALK, TRAFFIC_LIGHT = 0, 1, 6


class NoRoads(InputError):
    """The scan holds no road: no carriageway, or no derived road kept its lanes on the scan (``derived``:
    roads were derived and the checks dropped them all). ``scan_source`` writes a map without roads."""

    def __init__(self, message: str, derived: bool = False):
        super().__init__(message)
        self.derived = derived


@dataclass
class ScanSourceParams:
    labels: str = param("auto", choices=("auto", "predicted", "gt", "none"))  # auto: the segmentation's labels.npy when an earlier step wrote it, else the curbs alone; predicted: labels.npy (required); gt: gt_labels.npy (benchmarks); none: the curbs alone
    raster_m: float = param(0.25, gt=0, le=2)  # top-view resolution of the carriageway mask
    curb_tol_m: float = param(0.07, ge=0, le=1)  # height above the local lowest ground still on the carriageway (below the curb)
    use_curbs: bool = True  # false: the road labels alone draw the edges
    # the curb test needs a scan that resolves a 10-15 cm kerb: a cloud whose median point spacing
    # (points_meta.json) is coarser than this (aerial lidar) is read without curbs: the carriageway is the
    # road-labelled, up-facing, grey surface, and no sidewalk lanes are made (0: always the curbs)
    curb_max_spacing_m: float = param(0.10, ge=0, le=5)
    # without curbs: paved surface is grey; a face whose colour saturation ((max - min) / max of its
    # vertices' RGB) is above this is not carriageway (grass, gardens, roofs' tiles). 1: colour not used
    grey_max_saturation: float = param(0.10, gt=0, le=1)
    # without curbs, and with the cloud (points.ply): a carriageway is surface the scanner measured at its
    # usual density. Water and unscanned gaps return few lidar points and the mesh bridges them with
    # invented grey surface; a pixel whose 2 m neighbourhood holds less than this share of the cloud's
    # median density is not carriageway. 0: not used
    min_point_density: float = param(0.25, ge=0, le=1)
    # without curbs: a carriageway pixel has most of the pixels in a square this wide (half the narrowest
    # road) paved-looking; single grey specks (shadows, gravel, path stones) are not. 0: not used
    majority_m: float = param(1.5, ge=0, le=10)
    label_margin_m: float = param(1.5, ge=0, le=10)  # carriageway-level surface this far beyond the road labels is still road
    min_road_width_m: float = param(3.0, gt=0)  # narrower carriageway (driveways, gaps) is not a road
    min_road_length_m: float = param(8.0, gt=0)  # shorter arms (spurs of the mask's corners) are pruned
    edge_percentile: float = param(75.0, ge=50, le=100)  # per side: this percentile of the edge distance along a window (cars only remove road)
    edge_window_m: float = param(20.0, gt=0)  # ...over this length of road
    lane_width_m: float = param(3.25, gt=0, le=10)  # nominal lane width (the OSM route's default too)
    min_lane_width_m: float = param(2.5, gt=0, le=10)  # a road with less than this per direction has one lane, one way
    max_lane_width_m: float = param(4.5, gt=0, le=10)  # lanes are widened up to this before a strip is made
    min_strip_m: float = param(1.8, ge=0, le=10)  # remainder per side at least this wide: a parking strip at the curb
    curb_clearance_m: float = param(0.15, ge=0, le=2)  # widened lanes stop this short of the found curb (a no-traffic lane fills it)
    strip_type: str = param("parking", choices=("parking", "driving", "none"))  # parking -> lane type none (no traffic), driving -> another lane
    sidewalks: bool = True  # sidewalk lanes where the scan shows sidewalk beyond the curb
    min_sidewalk_m: float = param(1.0, ge=0, le=20)  # narrower sidewalk surface: no sidewalk lane
    max_sidewalk_m: float = param(6.0, gt=0, le=30)  # sidewalk lanes are at most this wide
    traffic_light_radius_m: float = param(12.0, ge=0)  # traffic-light labels within this of a junction's edge: a signalised junction
    min_traffic_light_vertices: int = param(20, ge=0)  # ...at least this many such vertices
    sample_m: float = param(2.0, gt=0, le=20)  # spacing of the road shape points
    # the map netconvert builds is checked against the scan (check_lanes): a driving-lane sample is on the
    # scan when the surface lies within lane_tol_m of the lane's height; a road's stretch, or a junction,
    # with less than min_lane_support of its samples on it (the lanes float over a bank or sink into a
    # slope) is cut out, or the junction taken apart, and netconvert runs again (up to lane_check_rounds)
    lane_tol_m: float = param(0.3, gt=0, le=2)
    min_lane_support: float = param(0.8, ge=0, le=1)
    lane_check_rounds: int = param(3, ge=0, le=10)
    # ...and a side of a road whose outermost edge_band_m is off the scan (more than 1 - min_lane_support of
    # its samples along the road) while the rest of that side is on is narrowed by it, per round (not below
    # min_road_width_m; sides with a sidewalk lane stay). 0: no narrowing
    edge_band_m: float = param(0.5, ge=0, le=3)
    # across a lane, the surface under neighbouring samples (a sixth of the lane's width apart) may differ
    # by at most lane_step_m: beyond a larger step (a low wall, a hedge's foot, a yard above the street) a
    # sample is off the scan even within lane_tol_m (a wheel catches on it). 0: no step test
    lane_step_m: float = param(0.1, ge=0, le=2)
    # ...and a sample with anything over it lower than lane_clear_m above the lane (a hedge, a wall's top, a
    # low roof) is off, whatever lies under it. 0: no such test
    lane_clear_m: float = param(2.0, ge=0, le=10)
    # when the checks (trim_unsupported, the lane check) keep less than this share of the road length first
    # derived, a warning says the map covers less of the streets than the scan shows
    min_kept_share: float = param(0.5, ge=0, le=1)
    timeout_s: float = param(300.0, gt=0)  # netconvert wall-clock limit


@dataclass
class Arm:
    """One road between two nodes of the network (a junction or an end)."""

    a: int
    b: int
    xy: np.ndarray  # (k, 2) axis, a -> b
    width_m: float  # carriageway, curb to curb
    sidewalk_left_m: float = 0.0  # left of a -> b
    sidewalk_right_m: float = 0.0
    z: np.ndarray | None = None
    # the heights of the right and left halves (a -> b): each direction's edge carries its own lanes' height,
    # so a cambered street's lanes sit on it (OpenDRIVE from netconvert has no cross slope)
    z_right: np.ndarray | None = None
    z_left: np.ndarray | None = None
    lanes: dict = field(default_factory=dict)


@dataclass
class Network:
    nodes: dict  # id -> {"xy": (x, y), "z": z, "kind": "junction" | "end", "signals": bool}
    arms: list
    mask: np.ndarray
    grid: object
    sidewalk_mask: np.ndarray | None
    stats: dict
    level_faces: np.ndarray | None = None  # faces on the carriageway level (below the curbs)


# --------------------------------------------------------------------------- masks

def _rasterize_faces(v, f, fidx, grid) -> np.ndarray:
    """Faces seen from above. PIL fills the pixels floor(a) .. floor(b) for a polygon from a to b: the mask
    is centred on the surface and on average half a pixel wider on each side (the widths take it off)."""
    from .mesh2d import Mesh, rasterize

    return rasterize(Mesh(v, f, None, None), grid, fidx) > 0


def _level_faces(v, f, curb_tol_m) -> np.ndarray:
    """Up-facing faces on the carriageway level, below the curbs (mesh2d.level_faces, the test align_roads'
    ground fallback uses too)."""
    from .mesh2d import level_faces

    return level_faces(v, f, curb_tol_m)


def _grey_ground(v, f, labels, rgb, p: ScanSourceParams) -> tuple[np.ndarray, str]:
    """Faces of the carriageway where the scan shows no curbs: paved-labelled (road or sidewalk: without a
    kerb the two are one surface, and a 2D model looking down at a street calls much of it sidewalk), facing
    up, grey."""
    from .mesh2d import Mesh, face_normals_z

    sel = np.flatnonzero(np.isin(labels[f], (ROAD, SIDEWALK)).sum(1) >= 2)
    sel = sel[face_normals_z(Mesh(v, f, None, None), sel) > 0.9]
    how = "road or sidewalk labels, facing up"
    if rgb is not None and p.grey_max_saturation < 1:
        c = rgb[f[sel]].astype(np.float64).mean(1)
        sat = (c.max(1) - c.min(1)) / np.maximum(c.max(1), 1.0)
        sel = sel[sat <= p.grey_max_saturation]
        how += f", grey (saturation <= {p.grey_max_saturation:g})"
    return sel, how


def measured(points_xy: np.ndarray, grid, share: float) -> tuple[np.ndarray, float]:
    """Pixels whose 2 m neighbourhood holds at least ``share`` of the cloud's median point density (points
    per m^2 over the pixels with any point near), and that median."""
    from scipy import ndimage

    px = np.floor(grid.to_px(points_xy)).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < grid.w) & (px[:, 1] >= 0) & (px[:, 1] < grid.h)
    cnt = np.zeros((grid.h, grid.w), np.float32)
    np.add.at(cnt, (px[ok, 1], px[ok, 0]), 1.0)
    k = max(3, int(round(2.0 / grid.res)) | 1)
    dens = ndimage.uniform_filter(cnt, size=k, mode="constant") / grid.res ** 2
    typical = float(np.median(dens[dens > 0])) if (dens > 0).any() else 0.0
    return dens >= share * typical, typical


def carriageway_mask(v, f, labels, grid, p: ScanSourceParams, level=None, *, curbs: bool = True,
                     rgb=None, points_xy: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Top-view mask of the carriageway. ``curbs`` false (a scan too sparse to show them; labels needed):
    the paved-labelled, up-facing, grey surface (``_grey_ground``) instead of the level below the curbs, where
    the cloud (``points_xy``, when given) was measured at its usual density."""
    from scipy import ndimage

    parts = []
    lab_mask = None
    if not curbs and labels is not None:
        sel, how = _grey_ground(v, f, labels, rgb, p)
        m = _rasterize_faces(v, f, sel, grid)
        if points_xy is not None and len(points_xy) and p.min_point_density > 0:
            ok, typical = measured(points_xy, grid, p.min_point_density)
            m &= ok
            how += (f", measured (>= {p.min_point_density:g} x the cloud's median {typical:.1f} points/m^2 "
                    "within 2 m)")
        if p.majority_m > 0:
            # seen from above, grey paved-looking specks lie everywhere (shadows, gravel, a garden's path
            # stones): a carriageway pixel has most of its neighbourhood paved-looking
            k = max(3, int(round(p.majority_m / grid.res)) | 1)
            m = ndimage.uniform_filter(m.astype(np.float32), size=k, mode="constant") > 0.5
            how += f", the majority of {k * grid.res:.2f} m around"
        return _clean_mask(m, grid, p, None, v, f, False), how + " (no curbs at this point spacing)"
    if labels is not None:
        lv = labels[f]
        road_f = np.flatnonzero((lv == ROAD).sum(1) >= 2)
        if len(road_f):
            lab_mask = _rasterize_faces(v, f, road_f, grid)
            parts.append("road labels")
    if p.use_curbs or lab_mask is None:
        low = _rasterize_faces(v, f, _level_faces(v, f, p.curb_tol_m) if level is None else level, grid)
        parts.append("curbs (carriageway level)")
        if lab_mask is not None:
            r = max(1, int(round(p.label_margin_m / grid.res)))
            near = ndimage.binary_dilation(ndimage.binary_closing(lab_mask, np.ones((5, 5), bool)),
                                           np.ones((2 * r + 1, 2 * r + 1), bool))
            m = low & near
        else:
            m = low
    else:
        m = lab_mask
    return _clean_mask(m, grid, p, level, v, f, p.use_curbs or lab_mask is None), " + ".join(parts)


def _clean_mask(m, grid, p: ScanSourceParams, level, v, f, by_level: bool) -> np.ndarray:
    """Gaps closed, holes filled, slivers opened away; components of a road's worth of surface kept, and
    with ``by_level`` only those on the lowest level (a yard or park is a curb above the carriageway)."""
    from scipy import ndimage

    r = max(1, int(round(0.75 / grid.res)))
    m = ndimage.binary_closing(m, np.ones((2 * r + 1, 2 * r + 1), bool), border_value=0)
    m = ndimage.binary_fill_holes(m)
    # away with slivers narrower than a lane half: what remains is carriageway
    k = max(1, int(round(0.5 * p.min_road_width_m / grid.res / 2)))
    m = ndimage.binary_opening(m, np.ones((2 * k + 1, 2 * k + 1), bool))
    lab, n = ndimage.label(m)
    if n > 1:  # keep components of at least a road's worth of surface...
        sizes = ndimage.sum(m, lab, range(1, n + 1)) * grid.res ** 2
        keep = np.flatnonzero(sizes >= p.min_road_width_m * p.min_road_length_m * 2) + 1
        if len(keep) > 1 and by_level:
            # ...on the lowest level: far from any road (a yard, a park) the raised ground is the local
            # lowest too, but it lies a curb above the carriageway's
            tri = v[f[level]] if level is not None else v[f]
            comp = grid.sample(lab, tri[:, :, :2].mean(1))
            cz = tri[:, :, 2].mean(1)
            med = {c: float(np.median(cz[comp == c])) for c in keep if (comp == c).any()}
            if med:
                low = min(med.values())
                keep = np.array([c for c in keep if med.get(c, low) <= low + 0.06])
        m = np.isin(lab, keep)
    return m


# --------------------------------------------------------------------------- skeleton

def thin(mask: np.ndarray) -> np.ndarray:
    """Zhang-Suen thinning (vectorised): a one-pixel, 8-connected skeleton of a boolean image."""
    img = np.pad(mask.astype(np.uint8), 1)
    while True:
        changed = False
        for step in (0, 1):
            p = img
            P2, P3, P4 = p[:-2, 1:-1], p[:-2, 2:], p[1:-1, 2:]
            P5, P6, P7 = p[2:, 2:], p[2:, 1:-1], p[2:, :-2]
            P8, P9 = p[1:-1, :-2], p[:-2, :-2]
            nb = [P2, P3, P4, P5, P6, P7, P8, P9]
            B = sum(x.astype(np.int32) for x in nb)
            seq = nb + [P2]
            A = sum(((seq[i] == 0) & (seq[i + 1] == 1)).astype(np.int32) for i in range(8))
            if step == 0:
                c = (P2 * P4 * P6 == 0) & (P4 * P6 * P8 == 0)
            else:
                c = (P2 * P4 * P8 == 0) & (P2 * P6 * P8 == 0)
            rm = (p[1:-1, 1:-1] == 1) & (B >= 2) & (B <= 6) & (A == 1) & c
            if rm.any():
                img = img.copy()
                img[1:-1, 1:-1][rm] = 0
                changed = True
        if not changed:
            break
    return img[1:-1, 1:-1].astype(bool)


_NB = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def skeleton_graph(skel: np.ndarray):
    """Nodes (clusters of pixels with != 2 neighbours) and the pixel paths between them.

    Returns (node_pixels: list of (k, 2) arrays of (row, col), edges: list of (na, nb, path (k, 2)))."""
    from scipy import ndimage

    s = skel.astype(np.uint8)
    cnt = ndimage.convolve(s, np.ones((3, 3), np.uint8), mode="constant") - s
    node = skel & (cnt != 2)
    lab, n = ndimage.label(node, np.ones((3, 3), bool))
    nodes = [np.argwhere(lab == i + 1) for i in range(n)]
    h, w = skel.shape
    visited = np.zeros_like(skel, bool)
    edges = []

    def nbrs(r, c):
        for dr, dc in _NB:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and skel[rr, cc]:
                yield rr, cc

    for ni, pix in enumerate(nodes):
        for r0, c0 in pix:
            for r, c in nbrs(r0, c0):
                if lab[r, c] or visited[r, c]:
                    continue
                path = [(r0, c0), (r, c)]
                visited[r, c] = True
                prev = (r0, c0)
                end = None
                while True:
                    cr, cc = path[-1]
                    nxt = None
                    for q in nbrs(cr, cc):
                        if q == prev or (q[0], q[1]) == (r0, c0) and len(path) <= 2:
                            continue
                        if lab[q]:
                            if lab[q] - 1 != ni or len(path) > 3:
                                end = lab[q] - 1
                                path.append(q)
                                break
                            continue
                        if not visited[q]:
                            nxt = q
                            break
                    if end is not None or nxt is None:
                        break
                    visited[nxt] = True
                    prev = (cr, cc)
                    path.append(nxt)
                if end is None:
                    continue  # a loop without nodes, or a dangling piece: ignored
                edges.append((ni, int(end), np.array(path)))
    # pure loops (no node) are not roads we can model: ignored
    # de-duplicate edges found from both ends
    seen, out = set(), []
    for a, b, p in edges:
        key = (min(a, b), max(a, b), tuple(p[len(p) // 2]))
        if key in seen:
            continue
        seen.add(key)
        out.append((a, b, p))
    return nodes, out


# --------------------------------------------------------------------------- geometry helpers

def _resample(xy: np.ndarray, step: float) -> np.ndarray:
    d = np.r_[0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    if d[-1] < 1e-9:
        return xy[:1]
    n = max(2, int(math.ceil(d[-1] / step)) + 1)
    t = np.linspace(0, d[-1], n)
    return np.stack([np.interp(t, d, xy[:, 0]), np.interp(t, d, xy[:, 1])], 1)


def _smooth(xy: np.ndarray, window: int) -> np.ndarray:
    """Moving average keeping the end points (reflected ends)."""
    if len(xy) < 3 or window < 2:
        return xy
    k = min(window, len(xy) - 1) | 1
    h = k // 2
    pad = np.concatenate([2 * xy[:1] - xy[h:0:-1], xy, 2 * xy[-1:] - xy[-2:-h - 2:-1]])
    ker = np.ones(k) / k
    return np.stack([np.convolve(pad[:, i], ker, mode="valid") for i in range(2)], 1)


def _fit_axis(xy: np.ndarray, window: int, huber_m: float = 0.3) -> np.ndarray:
    """A road's axis through noisy centre points: a robust (Huber, IRLS) quadratic in the road's own frame
    (its principal direction), when the road turns less than 30 degrees; a moving average otherwise.
    The per-point centres wobble where a car or an occlusion eats one edge; a street is straight or
    gently curved over the length of one arm between junctions."""
    if len(xy) < 6:
        return _smooth(xy, window)
    c = xy.mean(0)
    u, s_, vt = np.linalg.svd(xy - c, full_matrices=False)
    d = vt[0]
    n = np.array([-d[1], d[0]])
    t = (xy - c) @ d
    y = (xy - c) @ n
    tang = np.diff(_smooth(xy, window), axis=0)
    ang = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
    if len(ang) and float(np.ptp(ang)) > math.radians(30) or np.any(np.diff(t) <= 0) and np.any(np.diff(t) >= 0):
        return _smooth(xy, window)
    scale = max(float(np.abs(t).max()), 1.0)
    A = np.stack([np.ones_like(t), t / scale, (t / scale) ** 2], 1)
    w = np.ones(len(t))
    for _ in range(8):
        coef, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
        r = np.abs(y - A @ coef)
        w = np.sqrt(np.where(r <= huber_m, 1.0, huber_m / np.maximum(r, 1e-9)))
    yf = A @ coef
    return c + t[:, None] * d + yf[:, None] * n


def _normals(xy: np.ndarray) -> np.ndarray:
    t = np.gradient(xy, axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-9)
    return np.stack([-t[:, 1], t[:, 0]], 1)  # left normal


def _ray_lengths(mask, grid, xy, dirs, max_m, step) -> np.ndarray:
    """Distance from each point along its direction until the mask ends (first pixel off)."""
    ts = np.arange(0.0, max_m + step, step)
    pts = xy[:, None, :] + ts[None, :, None] * dirs[:, None, :]
    inside = grid.sample(mask.astype(np.uint8), pts) > 0
    off = ~inside
    off[:, -1] = True
    first = off.argmax(1)
    return ts[first]


def _junction_point(lines: list[tuple[np.ndarray, np.ndarray]], fallback: np.ndarray) -> np.ndarray:
    """Least-squares meeting point of lines (point, unit direction); the fallback when they are parallel."""
    A = np.zeros((2, 2))
    b = np.zeros(2)
    for p, d in lines:
        P = np.eye(2) - np.outer(d, d)
        A += P
        b += P @ p
    if len(lines) < 2 or abs(np.linalg.det(A)) < 1e-3 * len(lines):
        return fallback
    q = np.linalg.solve(A, b)
    return q if np.hypot(*(q - fallback)) < 30 else fallback


def lane_layout(width_m: float, p: ScanSourceParams) -> dict:
    """Lanes per direction, their width and a strip at the curb, for a carriageway ``width_m`` wide."""
    half = width_m / 2
    if half < p.min_lane_width_m:  # one lane, one way (spread about the axis: strip_m at each curb)
        lane = min(p.max_lane_width_m, max(width_m - 2 * p.curb_clearance_m, 0.5 * width_m))
        return {"two_way": False, "lanes": 1, "lane_m": round(lane, 3), "strip_m": round(max((width_m - lane) / 2, 0.0), 3)}
    n = max(1, int(math.floor(half / p.lane_width_m + 1e-6)))
    rem = half - n * p.lane_width_m
    if rem >= p.min_strip_m and p.strip_type != "driving":
        return {"two_way": True, "lanes": n, "lane_m": p.lane_width_m, "strip_m": round(rem, 3)}
    if p.strip_type == "driving" and rem >= p.min_strip_m:
        return {"two_way": True, "lanes": n + 1, "lane_m": round(half / (n + 1), 3), "strip_m": 0.0}
    # widen the lanes, but keep curb_clearance_m free at the curb: the found edge lies a little outside the
    # curb's foot (a reconstructed curb is a ramp), and a lane reaching onto the curb drops the drop test
    lane = min(p.max_lane_width_m, max(p.lane_width_m, (half - p.curb_clearance_m) / n))
    if n * p.lane_width_m > half:  # a carriageway narrower than two nominal lanes (5-6.5 m: a village street):
        # narrower lanes (not below min_lane_width_m), not nominal ones that reach over the edges (a 5.2 m
        # street had two 3.25 m lanes, 0.65 m beyond each edge, over verges and walls: IGN, Autzen)
        lane = max(p.min_lane_width_m, min(p.lane_width_m, half - p.curb_clearance_m))
    return {"two_way": True, "lanes": n, "lane_m": round(lane, 3), "strip_m": round(max(half - n * lane, 0.0), 3)}


# --------------------------------------------------------------------------- the network

def derive_network(v: np.ndarray, f: np.ndarray, labels: np.ndarray | None, p: ScanSourceParams,
                   log=None, *, curbs: bool = True, rgb: np.ndarray | None = None,
                   points_xy: np.ndarray | None = None) -> Network:
    """The road network of a labelled mesh (site frame): junctions, ends and the arms between them."""
    from scipy import ndimage

    from .mesh2d import Grid

    t0 = time.perf_counter()
    grid = Grid.around(v[:, :2], p.raster_m)
    if curbs or labels is None:
        level = _level_faces(v, f, p.curb_tol_m)
    else:  # no curbs: the carriageway's own faces give its heights (a lane on an embankment is no low level)
        level = _grey_ground(v, f, labels, rgb, p)[0]
    mask, how = carriageway_mask(v, f, labels, grid, p, level, curbs=curbs, rgb=rgb, points_xy=points_xy)
    if not (curbs or labels is None) and len(level):
        # the heights come from the carriageway's own faces: not from grey specks beside it
        inside = grid.sample(mask.astype(np.uint8), v[f[level]].mean(1)[:, :2]) > 0
        if inside.any():
            level = level[inside]
    if mask.sum() * grid.res ** 2 < p.min_road_width_m * p.min_road_length_m:
        raise NoRoads(f"no carriageway in the scan ({how}): {mask.sum() * grid.res ** 2:.0f} m^2 of road surface")
    dt = ndimage.distance_transform_edt(mask) * grid.res
    skel = thin(mask)
    node_pix, edges = skeleton_graph(skel)

    def px_to_xy(rc):
        rc = np.asarray(rc, float)
        return np.stack([grid.x0 + (rc[:, 1] + 0.5) * grid.res, grid.y0 - (rc[:, 0] + 0.5) * grid.res], 1)

    node_xy = [px_to_xy(pix).mean(0) for pix in node_pix]
    # --- prune spurs: an edge with a free end (degree-1 node) shorter than the half width where it leaves
    # the network, plus min_road_length_m; repeat until stable
    edges = [(a, b, px_to_xy(pth), dt[pth[:, 0], pth[:, 1]]) for a, b, pth in edges]
    for _ in range(10):
        deg = np.zeros(len(node_xy), int)
        for a, b, _, _ in edges:
            deg[a] += 1
            deg[b] += 1
        keep = []
        changed = False
        for e in edges:
            a, b, xy, hw = e
            length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
            free = (deg[a] == 1) != (deg[b] == 1)
            if free and length < float(hw.max()) + p.min_road_length_m and (deg[a] > 2 or deg[b] > 2):
                changed = True
                continue
            if a == b and length < 4 * float(hw.max()):  # tiny loops around a hole
                changed = True
                continue
            keep.append(e)
        edges = keep
        # merge through degree-2 nodes
        deg = np.zeros(len(node_xy), int)
        for a, b, _, _ in edges:
            deg[a] += 1
            deg[b] += 1
        for n in np.flatnonzero(deg == 2):
            ix = [i for i, e in enumerate(edges) if e[0] == n or e[1] == n]
            if len(ix) != 2 or ix[0] == ix[1]:
                continue
            e1, e2 = edges[ix[0]], edges[ix[1]]
            if e1[0] == e1[1] or e2[0] == e2[1]:
                continue
            x1 = e1 if e1[1] == n else (e1[1], e1[0], e1[2][::-1], e1[3][::-1])
            x2 = e2 if e2[0] == n else (e2[1], e2[0], e2[2][::-1], e2[3][::-1])
            merged = (x1[0], x2[1], np.concatenate([x1[2], x2[2][1:]]), np.concatenate([x1[3], x2[3][1:]]))
            edges = [e for i, e in enumerate(edges) if i not in ix] + [merged]
            changed = True
        if not changed:
            break
    if not edges:
        raise NoRoads(f"the carriageway ({how}, {mask.sum() * grid.res ** 2:.0f} m^2) has no road axis")
    # --- typical half width of each edge (middle part), junction sizes, merge close junctions
    half = []
    for a, b, xy, hw in edges:
        k = len(hw)
        mid = hw[k // 4: max(k // 4 + 1, 3 * k // 4)]
        half.append(float(np.median(mid)))
    deg = np.zeros(len(node_xy), int)
    for a, b, _, _ in edges:
        deg[a] += 1
        deg[b] += 1
    radius = np.zeros(len(node_xy))
    for (a, b, _, _), h in zip(edges, half):
        radius[a] = max(radius[a], h)
        radius[b] = max(radius[b], h)
    # union of junction nodes linked by an edge shorter than their size
    parent = list(range(len(node_xy)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    short = []
    for i, (a, b, xy, hw) in enumerate(edges):
        length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
        if a != b and deg[a] >= 3 and deg[b] >= 3 and length < 1.5 * (radius[a] + radius[b]):
            parent[find(a)] = find(b)
            short.append(i)
    edges = [e for i, e in enumerate(edges) if i not in short]
    half = [h for i, h in enumerate(half) if i not in short]
    groups: dict[int, list[int]] = {}
    for i in range(len(node_xy)):
        groups.setdefault(find(i), []).append(i)
    gid = {i: find(i) for i in range(len(node_xy))}
    node_r = {g: max(radius[i] for i in members) for g, members in groups.items()}
    node_c = {g: np.mean([node_xy[i] for i in members], 0) for g, members in groups.items()}
    deg2: dict[int, int] = {}
    for a, b, _, _ in edges:
        deg2[gid[a]] = deg2.get(gid[a], 0) + 1
        deg2[gid[b]] = deg2.get(gid[b], 0) + 1
    # --- each arm: smooth the axis away from junctions, centre it between the edges, measure widths
    step = 1.0
    raw_arms = []
    for (a, b, xy, hw), h in zip(edges, half):
        ga, gb = gid[a], gid[b]
        xy = _resample(xy, step)
        if len(xy) < 3:
            continue
        trim = np.ones(len(xy), bool)
        for g, at_start in ((ga, True), (gb, False)):
            if deg2.get(g, 0) >= 3:
                r = 1.15 * node_r[g] + 2.0
                trim &= np.hypot(*(xy - node_c[g]).T) > r
        if trim.sum() < max(3, int(p.min_road_length_m / 2 / step)):
            continue
        first, last = np.flatnonzero(trim)[[0, -1]]
        core = xy[first:last + 1]
        win = max(3, int(round(p.edge_window_m / 2 / step)))
        core = _smooth(core, win)
        # a skeleton stops about a half width before a free end (where the scan ends): measure the edges
        # on the straight continuation up to the end of the carriageway too
        for g, at_start in ((ga, True), (gb, False)):
            if deg2.get(g, 0) >= 3 or len(core) < 3:
                continue
            e = core[0] if at_start else core[-1]
            dv = _unit(core[0] - core[min(5, len(core) - 1)]) if at_start else _unit(core[-1] - core[max(-6, -len(core))])
            ln = float(_ray_lengths(mask, grid, e[None], dv[None], 60.0, grid.res / 2)[0]) - 1.0
            if ln > step:
                ext = e + dv * np.arange(step, ln, step)[:, None]
                core = np.concatenate([ext[::-1], core]) if at_start else np.concatenate([core, ext])
        nrm = _normals(core)
        left = _ray_lengths(mask, grid, core, nrm, 40.0, grid.res / 4)
        right = _ray_lengths(mask, grid, core, -nrm, 40.0, grid.res / 4)
        w = max(3, int(round(p.edge_window_m / step)))
        pad = w // 2
        lpad = np.pad(left, pad, mode="edge")
        rpad = np.pad(right, pad, mode="edge")
        lw = np.array([np.percentile(lpad[i:i + w], p.edge_percentile) for i in range(len(core))])
        rw = np.array([np.percentile(rpad[i:i + w], p.edge_percentile) for i in range(len(core))])
        centre = core + nrm * ((lw - rw) / 2)[:, None]
        centre = _fit_axis(centre, win)
        # the mask is on average half a pixel wider on each side (_rasterize_faces); the rays overshoot by
        # half their step: measured on the synthetic cross, half a pixel too wide in all
        width = float(np.median(lw + rw)) - grid.res / 2
        if width < p.min_road_width_m:
            continue
        raw_arms.append({"ga": ga, "gb": gb, "core": centre, "width": width, "nrm": _normals(centre)})
    if not raw_arms:
        raise NoRoads(f"the carriageway ({how}) holds no road at least {p.min_road_width_m} m wide and "
                      f"{p.min_road_length_m} m long")
    # --- junction points: where the arms' axes meet
    ends: dict[int, list] = {}
    for arm in raw_arms:
        c = arm["core"]
        ends.setdefault(arm["ga"], []).append((c[0], _unit(c[0] - c[min(5, len(c) - 1)])))
        ends.setdefault(arm["gb"], []).append((c[-1], _unit(c[-1] - c[max(-6, -len(c))])))
    jpos = {}
    for g, lines in ends.items():
        if len(lines) >= 3 or (len(lines) == 2 and deg2.get(g, 0) >= 3):
            jpos[g] = _junction_point(lines, node_c[g])
    # --- nodes and arms
    nodes: dict[int, dict] = {}
    arms: list[Arm] = []
    for arm in raw_arms:
        c = arm["core"]
        pts = [c]
        for g, at_start in ((arm["ga"], True), (arm["gb"], False)):
            if g in jpos:
                q = jpos[g]
                nodes.setdefault(g, {"xy": q, "kind": "junction"})
                seg = np.array([q, c[0]]) if at_start else np.array([c[-1], q])
                seg = _resample(seg, step)
                pts.insert(0, seg[:-1]) if at_start else pts.append(seg[1:])
            else:  # an end: continue straight to the mask's end, for the outer lanes too (at a road
                # that bends where the scan ends, the axis reaches farther than the lanes beside it)
                e = c[0] if at_start else c[-1]
                d = _unit(c[0] - c[min(5, len(c) - 1)]) if at_start else _unit(c[-1] - c[max(-6, -len(c))])
                side = np.array([-d[1], d[0]]) * max(arm["width"] / 2 - 0.5, 0.0)
                starts = np.stack([e, e + side, e - side])
                ln = float(_ray_lengths(mask, grid, starts, np.tile(d, (3, 1)), 60.0, grid.res / 2).min())
                q = e + d * ln
                seg = _resample(np.array([q, e]) if at_start else np.array([e, q]), step)
                pts.insert(0, seg[:-1]) if at_start else pts.append(seg[1:])
                key = ("end", len(nodes), at_start, id(arm))
                g_end = hash(key) & 0x7FFFFFFF
                nodes[g_end] = {"xy": q, "kind": "end"}
                if at_start:
                    arm["ga"] = g_end
                else:
                    arm["gb"] = g_end
        xy = np.concatenate([x for x in pts if len(x)])
        xy = _resample(xy, p.sample_m)
        arms.append(Arm(arm["ga"], arm["gb"], xy, arm["width"]))
    # renumber nodes 0..n-1
    ren = {g: i for i, g in enumerate(nodes)}
    nodes = {ren[g]: nd for g, nd in nodes.items()}
    for arm in arms:
        arm.a, arm.b = ren[arm.a], ren[arm.b]
    stats = {"carriageway_from": how, "carriageway_m2": round(float(mask.sum() * grid.res ** 2), 1),
             "skeleton_nodes": len(node_pix), "derive_s": round(time.perf_counter() - t0, 3)}
    net = Network(nodes, arms, mask, grid, None, stats)
    net.level_faces = level
    return net


def _unit(d) -> np.ndarray:
    d = np.asarray(d, float)
    n = float(np.hypot(*d))
    return d / n if n > 1e-9 else np.array([1.0, 0.0])


#: sidewalk surface more than this above the carriageway level beside it is not a sidewalk (a roof, a wall)
WALK_MAX_M = 0.5


def add_sidewalks(net: Network, v, f, labels, p: ScanSourceParams) -> None:
    """Sidewalk width beyond each curb: the run of sidewalk-labelled surface (else the raised level)."""
    from scipy import ndimage

    grid = net.grid
    if labels is not None and (labels == SIDEWALK).any():
        lv = labels[f]
        sw_f = np.flatnonzero((lv == SIDEWALK).sum(1) >= 2)
        # a sidewalk one can step onto from the road: within WALK_MAX_M of the carriageway level beside it
        # (an aerial scan's flat roofs and walls can take the sidewalk label too)
        zr = _level_raster(v, f, net.level_faces, grid)
        cz = v[f[sw_f], 2].mean(1)
        dz = cz - grid.sample(zr, v[f[sw_f], :2].mean(1))
        sw_f = sw_f[(dz > -0.1) & (dz < WALK_MAX_M)]
        sw = _rasterize_faces(v, f, sw_f, grid)
        sw = ndimage.binary_closing(sw, np.ones((5, 5), bool))
        src = "sidewalk labels"
    else:  # the raised level: up-facing faces 6-35 cm above the carriageway level, just beyond the curb
        from .mesh2d import Mesh, face_normals_z

        nz = face_normals_z(Mesh(v, f, None, None))
        up = np.flatnonzero(nz > 0.9)
        zr = _level_raster(v, f, net.level_faces, grid)
        cz = v[f[up], 2].mean(1)
        lvl = grid.sample(zr, v[f[up], :2].mean(1))
        raised = up[(cz - lvl > 0.06) & (cz - lvl < 0.35) & np.isfinite(lvl)]
        sw = _rasterize_faces(v, f, raised, grid) & ~net.mask
        src = "raised level beside the curb"
    net.sidewalk_mask = sw
    net.stats["sidewalks_from"] = src
    for arm in net.arms:
        nrm = _normals(arm.xy)
        for side, sgn in (("left", 1.0), ("right", -1.0)):
            edge = arm.xy + sgn * nrm * (arm.width_m / 2 + 0.3)  # past the curb stone (its own label varies)
            run = _ray_lengths(sw, grid, edge, sgn * nrm, 15.0, grid.res / 2) - grid.res / 2
            # only away from the junctions (the cross street's carriageway crosses the sidewalk there)
            ok = np.ones(len(run), bool)
            for nid in (arm.a, arm.b):
                nd = net.nodes[nid]
                if nd["kind"] == "junction":
                    ok &= np.hypot(*(arm.xy - nd["xy"]).T) > arm.width_m + 6.0
            vals = run[ok] if ok.sum() >= 3 else run
            wv = float(np.percentile(vals, 60)) + 0.3 if len(vals) else 0.0  # + the curb stone the ray started past
            wv = min(wv, p.max_sidewalk_m)
            if wv >= p.min_sidewalk_m and float(np.mean(vals > 0.5)) >= 0.3:
                setattr(arm, f"sidewalk_{side}_m", round(wv, 2))


def _level_raster(v, f, fidx, grid) -> np.ndarray:
    """Height of the carriageway level per pixel (nan where none); nearest filled."""
    from scipy import ndimage

    c = v[f[fidx]].mean(1)
    px = np.floor(grid.to_px(c[:, :2])).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < grid.w) & (px[:, 1] >= 0) & (px[:, 1] < grid.h)
    z = np.full((grid.h, grid.w), np.nan)
    z[px[ok, 1], px[ok, 0]] = c[ok, 2]
    if np.isnan(z).all():
        return np.zeros_like(z)
    idx = ndimage.distance_transform_edt(np.isnan(z), return_distances=False, return_indices=True)
    return z[idx[0], idx[1]]


def add_heights_and_signals(net: Network, v, f, labels, p: ScanSourceParams) -> None:
    zr = _level_raster(v, f, net.level_faces, net.grid)
    for arm in net.arms:
        # the carriageway's height at each shape point: the median of its level across the road (a lane
        # off the axis of a cambered or sloping street is as far above as the other is below), lightly
        # smoothed along the road (3 points)
        nrm = _normals(arm.xy)
        across = np.linspace(-0.4, 0.4, 9) * arm.width_m
        zz = net.grid.sample(zr, arm.xy[:, None, :] + across[None, :, None] * nrm[:, None, :]).astype(float)

        def smooth(a):
            return np.convolve(np.pad(a, 1, mode="edge"), np.ones(3) / 3, mode="valid")

        arm.z = smooth(np.median(zz, axis=1))
        # each direction's driving lanes lie from the axis outwards (netconvert spreads them to the right of
        # the edge's shape), over lanes x lane_m: its height is the surface's across that band
        lay = lane_layout(arm.width_m, p)
        band = lay["lanes"] * lay["lane_m"]
        off = np.linspace(0.1, 0.9, 5) * band
        for side, sgn in (("z_right", -1.0), ("z_left", 1.0)):  # the normal points left
            q = arm.xy[:, None, :] + (sgn * off)[None, :, None] * nrm[:, None, :]
            setattr(arm, side, smooth(np.median(net.grid.sample(zr, q).astype(float), axis=1)))
    # a node's height is where its roads meet it (their ends' heights), not the level raster at its point:
    # a junction point can lie off the carriageway, where the nearest carriageway face is another one
    # (IGN: a three-way junction 0.7 m under the ground)
    ends: dict[int, list[float]] = {}
    for arm in net.arms:
        ends.setdefault(arm.a, []).append(float(arm.z[0]))
        ends.setdefault(arm.b, []).append(float(arm.z[-1]))
    for nid, nd in net.nodes.items():
        nd["z"] = (float(np.median(ends[nid])) if nid in ends
                   else float(net.grid.sample(zr, np.asarray(nd["xy"])[None])[0]))
        nd["signals"] = False
    if labels is None or p.min_traffic_light_vertices <= 0:
        return
    tl = v[labels == TRAFFIC_LIGHT, :2]
    for nid, nd in net.nodes.items():
        if nd["kind"] != "junction" or not len(tl):
            continue
        r = max(a.width_m / 2 for a in net.arms if nid in (a.a, a.b)) + p.traffic_light_radius_m
        near = int((np.hypot(*(tl - nd["xy"]).T) < r).sum())
        nd["signals"] = near >= p.min_traffic_light_vertices
        nd["traffic_light_vertices"] = near


def _true_runs(b: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of each run of True in a 1-D bool array."""
    d = np.diff(np.r_[0, b.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def trim_unsupported(net: Network, v, f, p: ScanSourceParams, tol_m: float = 0.3, min_support: float = 0.8,
                     scene=None) -> dict:
    """A derived lane must lie on scanned ground. Along each road, the share of its carriageway's cross
    section (7 samples, 0.3 m in from each edge) where a vertical ray meets the surface within ``tol_m`` of
    the road's height there; from a road's free end (not a junction) the road is cut back while that share is under
    ``min_support`` (a road that bends where the scan ends and runs on into a wall, Lille); inside a road, 2 or
    more unsupported shape points in a row (a few metres under a roof or over a gap, IGN) split it into two
    roads with new ends; a piece shorter than ``min_road_length_m`` is dropped, and so are the nodes it leaves
    alone. Returns what was cut."""
    import open3d as o3d

    from twinkit.surface.closest import Surface

    if scene is None:
        scene = Surface(np.asarray(v, np.float64), np.asarray(f)).scene
    bad: dict[int, np.ndarray] = {}
    for k, arm in enumerate(net.arms):
        if arm.z is None or len(arm.xy) < 3:
            continue
        nrm = _normals(arm.xy)
        half = max(arm.width_m / 2 - 0.3, 0.0)
        across = np.linspace(-half, half, 7)
        q = arm.xy[:, None, :] + across[None, :, None] * nrm[:, None, :]
        rays = np.zeros((q.shape[0] * q.shape[1], 6), np.float32)
        rays[:, :2] = q.reshape(-1, 2)
        rays[:, 2] = np.repeat(arm.z, q.shape[1]) + tol_m
        rays[:, 5] = -1.0
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # the surface within tol_m of the road's height
        frac = (t <= 2 * tol_m).reshape(q.shape[:2]).mean(axis=1)
        bad[k] = frac < min_support
    out = cut_arms(net, bad, p)
    net.stats["unsupported"] = out
    if not net.arms:
        raise NoRoads("none of the roads derived from the scan lies on scanned ground (their lanes run over walls, "
                      "roofs or gaps)", derived=True)
    return out


def cut_arms(net: Network, bad: dict[int, np.ndarray], p: ScanSourceParams, keep_junction_ends: bool = True) -> dict:
    """Cut the arms (index -> per-shape-point bool, True where the road is not on the scan): from a free end
    the road is cut back over its bad points (from a junction too unless ``keep_junction_ends``: the road
    then leaves the junction and ends where it is on the scan again); inside, 2 or more bad points in a row
    split it into two roads with new ends; a piece shorter than ``min_road_length_m`` is dropped, and so are
    the nodes left alone."""
    cut_m, dropped = 0.0, 0
    keep = []
    for k, arm in enumerate(net.arms):
        b = bad.get(k)
        if b is None or not b.any():
            keep.append(arm)
            continue
        n = len(b)
        keep_pt = np.ones(n, bool)
        for i, j in _true_runs(b):  # runs of unsupported shape points
            at_a, at_b = i == 0, j == n
            if at_a and at_b:
                keep_pt[:] = False
            elif at_a:  # a junction end stays (the junction needs it) when keep_junction_ends
                keep_pt[i:j] = keep_junction_ends and net.nodes[arm.a]["kind"] != "end"
            elif at_b:
                keep_pt[i:j] = keep_junction_ends and net.nodes[arm.b]["kind"] != "end"
            elif j - i >= 2:  # inside the road: 2+ points (a few metres) under a roof or over a gap split it
                keep_pt[i:j] = False
        if keep_pt.all():
            keep.append(arm)
            continue
        full = float(np.hypot(*np.diff(arm.xy, axis=0).T).sum())
        kept_len = 0.0
        for i, j in _true_runs(keep_pt):
            seg = arm.xy[i:j]
            length = float(np.hypot(*np.diff(seg, axis=0).T).sum()) if len(seg) > 1 else 0.0
            if length >= p.min_road_length_m and len(seg) >= 3:
                piece = dataclasses.replace(arm, xy=seg, **{k: getattr(arm, k)[i:j] for k in ("z", "z_left", "z_right")
                                                            if getattr(arm, k) is not None})
                for end_idx, attr in ((i, "a"), (j - 1, "b")):
                    if (attr == "a" and i == 0) or (attr == "b" and j == n):
                        continue  # the road's own node
                    nid = max(net.nodes) + 1
                    net.nodes[nid] = {"xy": arm.xy[end_idx], "z": float(arm.z[end_idx]) if arm.z is not None else 0.0,
                                      "kind": "end"}
                    setattr(piece, attr, nid)
                keep.append(piece)
                kept_len += length
            else:
                dropped += 1 if (i == 0 and j == n) else 0
        if kept_len == 0.0:
            dropped += 1
        cut_m += full - kept_len
    net.arms = keep
    used = {n for arm in keep for n in (arm.a, arm.b)}
    net.nodes = {k: nd for k, nd in net.nodes.items() if k in used}
    return {"cut_m": round(cut_m, 1), "dropped_roads": dropped}


def lane_heights(xodr_text: str, v, f, tol_m: float = 0.3, spacing_m: float = 1.0, above_m: float = 1.0,
                 below_m: float = 3.0, covered_m: float = 15.0, scene=None, step_m: float = 0.0,
                 edge_in_m: float = 0.05, clear_m: float = 0.0) -> dict:
    """Do the driving lanes carla.Map reads from the OpenDRIVE lie on the scanned surface at their heights?
    Samples every ``spacing_m`` along each driving lane, 7 across it (the outermost ``edge_in_m`` inside its
    borders). A sample is **on** when the surface
    lies within ``tol_m`` of the lane's height; **off** when it lies elsewhere: up to ``below_m`` under the
    lane (the lane floats over a bank or a yard), up to ``above_m`` over it (the lane is buried in a
    slope), or not at all under a roof up to ``covered_m`` over the lane (it runs into a house); an open
    hole in the mesh is left to the drop test. With ``step_m`` > 0, a sample is also off when the surface
    between it and the lane's middle steps by more than ``step_m`` from one sample to the next (the lane's
    edge over a low wall or a yard above the street: within ``tol_m``, yet no road). With ``clear_m`` > 0, a
    sample with any surface over it less than ``clear_m`` above the lane is off too, ground or not (a hedge,
    a wall's top, a low roof: a car drives into it). Returns the samples' x, y, whether on and
    off, and the junction (its OpenDRIVE name, netconvert's node id) of those inside one ('' elsewhere)."""
    import re

    import carla
    import open3d as o3d

    from twinkit.surface.closest import Surface

    m = carla.Map("scan_lane_heights", xodr_text)
    names = {int(i): nm for nm, i in re.findall(r'<junction\s+name="([^"]*)"\s+id="(-?\d+)"', xodr_text)}
    names.update({int(i): nm for i, nm in re.findall(r'<junction\s+id="(-?\d+)"\s+name="([^"]*)"', xodr_text)})
    pts, junc = [], []
    across = np.linspace(-0.5, 0.5, 7)  # border to border, the outermost edge_in_m in (where a tyre's edge runs)
    for w in m.generate_waypoints(spacing_m):
        if w.lane_type != carla.LaneType.Driving:
            continue
        loc = w.transform.location
        rv = w.transform.get_right_vector()
        nx, ny = rv.x, -rv.y  # CARLA's y points south
        off = across * max(float(w.lane_width) - 2 * edge_in_m, 0.0)
        pts.append(np.c_[loc.x + off * nx, -loc.y + off * ny, np.full(len(off), loc.z)])
        junc += [names.get(w.get_junction().id, str(w.get_junction().id)) if w.is_junction else ""] * len(off)
    if not pts:
        return {"xy": np.zeros((0, 2)), "on": np.zeros(0, bool), "off": np.zeros(0, bool), "junction": np.zeros(0, str)}
    r = np.vstack(pts)
    if scene is None:
        scene = Surface(np.asarray(v, np.float64), np.asarray(f)).scene

    def down(z0):  # distance to the first surface under z0 (inf: none)
        q = np.zeros((len(r), 6), np.float32)
        q[:, :2] = r[:, :2]
        q[:, 2] = z0
        q[:, 5] = -1.0
        return scene.cast_rays(o3d.core.Tensor(q))["t_hit"].numpy()

    t_mid = down(r[:, 2] + tol_m)
    on = t_mid <= 2 * tol_m
    below = t_mid <= tol_m + below_m
    t_top = down(r[:, 2] + above_m)  # the top surface, from above_m over the lane
    above = t_top <= above_m - tol_m
    q = np.zeros((len(r), 6), np.float32)  # a roof over a lane with no ground under it: the lane runs into a house
    q[:, :2] = r[:, :2]
    q[:, 2] = r[:, 2] + tol_m
    q[:, 5] = 1.0
    t_up = scene.cast_rays(o3d.core.Tensor(q))["t_hit"].numpy()
    covered = t_up <= covered_m
    off = ~on & (below | above | covered)
    if clear_m > 0:
        low = t_up <= clear_m - tol_m
        off |= low
        on &= ~low
    if step_m > 0:
        top = np.where(t_top <= above_m + below_m, r[:, 2] + above_m - t_top, np.nan)
        stepped = steps_across(top, len(across), step_m)
        off |= stepped
        on &= ~stepped
    return {"xy": r[:, :2], "on": on, "off": off, "junction": np.array(junc)}


def steps_across(top: np.ndarray, k: int, step_m: float) -> np.ndarray:
    """(n,) bool for lane samples laid out ``k`` across per cross-section (consecutive entries of ``top``, the
    height of the top surface under each, nan where there is none): the surface changes by more than
    ``step_m`` from one sample to the next between this sample and the lane's middle one. Where a sample has
    no surface (an open hole, left to the drop test), no step is counted on either side of it."""
    z = top.reshape(-1, k)
    mid = k // 2
    out = np.zeros(z.shape, bool)
    with np.errstate(invalid="ignore"):
        right = np.abs(np.diff(z[:, mid:], axis=1)) > step_m  # mid -> k-1
        left = np.abs(np.diff(z[:, mid::-1], axis=1)) > step_m  # mid -> 0
    out[:, mid + 1:] = np.logical_or.accumulate(right, axis=1)
    out[:, mid - 1::-1] = np.logical_or.accumulate(left, axis=1)
    return out.ravel()


def check_lanes(net: Network, xodr_text: str, v, f, p: ScanSourceParams, scene=None) -> dict:
    """The map netconvert built from the derived network, against the scan (``lane_heights``): per road,
    the shape points whose driving lanes are off the surface on more than ``1 - min_lane_support`` of their
    samples; per junction, the same share over its connecting lanes. Returns ``{"bad_points": {arm index:
    bool array}, "bad_junctions": {node id: share on}, "on_share": share of all samples on}``."""
    from scipy.spatial import cKDTree

    lh = lane_heights(xodr_text, v, f, tol_m=p.lane_tol_m, scene=scene, step_m=p.lane_step_m, clear_m=p.lane_clear_m)
    on, off, jn, xy = lh["on"], lh["off"], lh["junction"], lh["xy"]
    res = {"bad_points": {}, "bad_junctions": {}, "narrow": {}, "samples": int(len(on)),
           "on_share": round(float(on.sum() / max((on | off).sum(), 1)), 4)}
    judged = on | off
    for nid in net.nodes:
        s = (jn == f"n{nid}") & judged
        if s.sum() >= 10:
            share = float(on[s].mean())
            if share < p.min_lane_support:
                res["bad_junctions"][nid] = round(share, 3)
    road = (jn == "") & judged
    if not road.any() or not net.arms:
        return res
    axis = np.concatenate([a.xy for a in net.arms])
    owner = np.concatenate([np.full(len(a.xy), k) for k, a in enumerate(net.arms)])
    index = np.concatenate([np.arange(len(a.xy)) for a in net.arms])
    half = np.concatenate([np.full(len(a.xy), a.width_m / 2 + 1.0) for a in net.arms])
    d, i = cKDTree(axis).query(xy[road])
    near = d <= half[i]
    src = np.flatnonzero(road)[near]
    i = i[near]
    n_on = np.bincount(i, weights=on[src].astype(float), minlength=len(axis))
    n_all = np.bincount(i, minlength=len(axis)).astype(float)
    bad_pt = (n_all >= 5) & (n_on < p.min_lane_support * n_all)
    for k in range(len(net.arms)):
        b = bad_pt[owner == k][np.argsort(index[owner == k])]
        if b.any():
            res["bad_points"][k] = b
    # each side's outermost edge_band_m: off the scan along the road while the rest of that side is on (the
    # lanes wider than the paved band: a path between grass, a lane edge on a wall's foot) -> narrower
    if p.edge_band_m <= 0:
        return res
    nrm = np.concatenate([_normals(a.xy) for a in net.arms])
    lateral = ((xy[src] - axis[i]) * nrm[i]).sum(axis=1)  # + left of the road's direction
    off_s, arm_s = off[src], owner[i]
    bad_share = 1.0 - p.min_lane_support
    for k, arm in enumerate(net.arms):
        reach = _lanes_reach(arm, p)
        sides = []
        for sgn, walk in ((1, arm.sidewalk_left_m), (-1, arm.sidewalk_right_m)):
            if walk > 0:  # a sidewalk lane lies beyond: that edge is a kerb, drawn from the scan's curbs
                continue
            side = (arm_s == k) & (sgn * lateral > 0)
            outer = side & (sgn * lateral > reach - p.edge_band_m)
            inner = side & ~outer
            if (outer.sum() >= 10 and off_s[outer].mean() > bad_share
                    and (inner.sum() < 10 or off_s[inner].mean() <= bad_share)):
                sides.append(sgn)
        if sides:
            res["narrow"][k] = sides
    # ...and where only a stretch of one side is off (a hedge, a wall's corner beside the road for a few
    # metres) while the other side's edge there is on: that stretch of the road moves away from it
    res["nudge"] = {}
    start = np.cumsum([0] + [len(a.xy) for a in net.arms])
    for k, arm in enumerate(net.arms):
        if k in res["narrow"] or arm.sidewalk_left_m > 0 or arm.sidewalk_right_m > 0:
            continue
        reach = _lanes_reach(arm, p)
        n = len(arm.xy)
        share = {}
        for sgn in (1, -1):
            sel = (arm_s == k) & (sgn * lateral > reach - p.edge_band_m)
            j = i[sel] - start[k]
            win = np.ones(5)  # about 10 m of road (shape points every sample_m)
            tot = np.convolve(np.bincount(j, minlength=n).astype(float), win, "same")
            bad = np.convolve(np.bincount(j, weights=off_s[sel].astype(float), minlength=n), win, "same")
            share[sgn] = np.where(tot >= 4, bad / np.maximum(tot, 1.0), 0.0) > bad_share
        move = share[-1].astype(float) - share[1].astype(float)  # +1: to the left (the right edge is off)
        if move.any():
            res["nudge"][k] = move
    return res


def _lanes_reach(arm: Arm, p: ScanSourceParams) -> float:
    """How far from the axis a road's outermost lane edge lies (lane_layout; a one-way road's lane is centred)."""
    lay = lane_layout(arm.width_m, p)
    return lay["lanes"] * lay["lane_m"] + lay["strip_m"] if lay["two_way"] else lay["lane_m"] / 2 + lay["strip_m"]


def nudge_arms(net: Network, nudge: dict[int, np.ndarray], p: ScanSourceParams) -> int:
    """Move stretches of roads sideways by half ``edge_band_m`` (per shape point: +1 to the left of the road's
    direction, -1 to the right), tapered over the neighbouring points; ends at a junction stay. Returns
    how many roads moved."""
    moved = 0
    for k, mv in nudge.items():
        arm = net.arms[k]
        m = np.clip(np.convolve(mv, [0.5, 1.0, 0.5], "same"), -1.0, 1.0)
        for end, nid in ((0, arm.a), (-1, arm.b)):
            if net.nodes.get(nid, {}).get("kind") == "junction":
                m[end] = 0.0
        if not m.any():
            continue
        arm.xy = arm.xy + 0.5 * p.edge_band_m * m[:, None] * _normals(arm.xy)
        moved += 1
    return moved


def narrow_arms(net: Network, narrow: dict[int, list[int]], p: ScanSourceParams) -> int:
    """Take ``edge_band_m`` off the given sides (+1 left, -1 right) of the arms: the carriageway width shrinks
    and the axis moves half that away from each trimmed side (not below ``min_road_width_m``). Returns
    how many roads changed."""
    changed = 0
    for k, sides in narrow.items():
        arm = net.arms[k]
        width = arm.width_m - p.edge_band_m * len(sides)
        if width < p.min_road_width_m:
            continue
        arm.xy = arm.xy - 0.5 * p.edge_band_m * sum(sides) * _normals(arm.xy)
        arm.width_m = width
        changed += 1
    return changed


def detach_junctions(net: Network, nodes: list[int], p: ScanSourceParams) -> int:
    """Take junctions out of the network: each road that met one is cut back to outside it (the junction's
    reach: its widest road's width plus 2 m from its point) and ends there. Returns the roads dropped."""
    dropped = 0
    for nid in nodes:
        nd = net.nodes.get(nid)
        if nd is None:
            continue
        mine = [a for a in net.arms if nid in (a.a, a.b)]
        reach = max((a.width_m for a in mine), default=0.0) + 2.0
        out = []
        for arm in net.arms:  # (arms compared by identity: a dataclass of arrays has no usable ==)
            if nid not in (arm.a, arm.b):
                out.append(arm)
                continue
            far = np.flatnonzero(np.hypot(*(arm.xy - np.asarray(nd["xy"])).T) > reach)
            if arm.a == arm.b or not len(far):
                dropped += 1
                continue
            i, j = (far[0], len(arm.xy)) if arm.a == nid else (0, far[-1] + 1)
            seg = arm.xy[i:j]
            if len(seg) < 3 or float(np.hypot(*np.diff(seg, axis=0).T).sum()) < p.min_road_length_m:
                dropped += 1
                continue
            piece = dataclasses.replace(arm, xy=seg, **{a: getattr(arm, a)[i:j] for a in ("z", "z_left", "z_right")
                                                        if getattr(arm, a) is not None})
            new = max(net.nodes) + 1
            end_i = 0 if arm.a == nid else len(seg) - 1
            net.nodes[new] = {"xy": seg[end_i], "z": float(piece.z[end_i]) if piece.z is not None else 0.0,
                              "kind": "end", "signals": False}
            setattr(piece, "a" if arm.a == nid else "b", new)
            out.append(piece)
        net.arms = out
        net.nodes.pop(nid, None)
    used = {n for arm in net.arms for n in (arm.a, arm.b)}
    net.nodes = {k: nd for k, nd in net.nodes.items() if k in used}
    return dropped


# --------------------------------------------------------------------------- OpenDRIVE through netconvert

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
    from .convert import _env, finish_netconvert, netconvert_output, netconvert_path

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
    from twinkit.geo.xodr import SCAN_TAG as tag, from_scan

    if from_scan(xodr_text):
        return xodr_text
    i = xodr_text.find("<header")
    j = xodr_text.find(">", i)
    if i < 0 or j < 0:
        return xodr_text
    if xodr_text[j - 1] == "/":  # <header .../>
        return xodr_text[:j - 1] + ">" + tag + "</header>" + xodr_text[j + 1:]
    return xodr_text[:j + 1] + "\n        " + tag + xodr_text[j + 1:]


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


# --------------------------------------------------------------------------- the picture

def draw_scan_roads(v, f, labels, net: Network, xodr_text: str, out: Path, px_per_m: float = 8.0,
                    max_px: int = 3000, truth: list | None = None, note: str | None = None) -> dict:
    """Top view of the labelled mesh (CityScapes colours, dimmed) with the derived network: the
    carriageway edges found (yellow), the lanes carla.Map reads from the OpenDRIVE (driving borders
    white, centre lines red, sidewalk lanes orange), the true centre lines if known (cyan)."""
    from PIL import Image, ImageDraw

    from twinkit.cityscapes import colorize

    from .evidence import lane_polygons
    from .mesh2d import Mesh, picture_grid, rasterize

    grid, res = picture_grid(v[:, :2], px_per_m, max_px)
    if labels is not None:
        cols = (colorize(labels[f[:, 0]]).astype(float) * 0.6).astype(np.uint8)
    else:
        z = v[f, 2].mean(1)
        g = np.clip((z - np.percentile(z, 2)) / max(float(np.ptp(z)), 1e-6) * 150 + 40, 0, 255).astype(np.uint8)
        cols = np.stack([g, g, g], 1)
    img = Image.fromarray(rasterize(Mesh(v, f, None, None), grid, colours=cols, mode="RGB"))
    d = ImageDraw.Draw(img)
    w = max(1, int(round(0.1 / res)))

    def line(p, fill, width):
        q = [tuple(map(float, x)) for x in grid.to_px(np.asarray(p)[:, :2])]
        if len(q) >= 2:
            d.line(q, fill=fill, width=width)

    lanes = lane_polygons(xodr_text, 0.5)
    for ln in lanes:
        if ln.type == "sidewalk" and len(ln.left) >= 2:
            ring = np.concatenate([ln.left, ln.right[::-1]])
            d.polygon([tuple(map(float, x)) for x in grid.to_px(ring)], outline=(255, 150, 40))
    from .align import lane_lines

    lines = lane_lines(xodr_text, 1.0, junctions=True)
    for ln in lines:
        line(ln["left"], (255, 255, 255), max(1, w // 2))
        line(ln["right"], (255, 255, 255), max(1, w // 2))
    for t in truth or []:
        line(np.asarray(t), (0, 220, 255), w)
    for ln in lines:
        line(ln["centre"], (230, 20, 20), w)
    for arm in net.arms:
        nrm = _normals(arm.xy)
        for sgn in (1, -1):
            line(arm.xy + sgn * nrm * arm.width_m / 2, (255, 230, 0), max(1, w // 2))
    for nd in net.nodes.values():
        x, y = grid.to_px(np.asarray(nd["xy"]))
        r = 4
        d.ellipse([x - r, y - r, x + r, y + r], outline=(255, 0, 255), width=2)
    from .qa import legend

    legend(d, [("roads from the scan (road_source=scan)", (255, 255, 255)),
               ("yellow: carriageway edges (labels + curbs)", (255, 230, 0)),
               ("white / red: lane borders / centre lines", (230, 20, 20)),
               ("orange: sidewalk lanes; magenta: nodes", (255, 150, 40))]
           + ([("cyan: true lane centre lines", (0, 220, 255))] if truth else []), res, width=360, slots=5)
    if note:  # why there is nothing to draw
        d.rectangle([8, img.size[1] - 30, min(img.size[0] - 8, 16 + 6 * len(note)), img.size[1] - 8], fill=(0, 0, 0))
        d.text((16, img.size[1] - 24), note, fill=(255, 80, 80))
    img.save(out)
    return {"px": list(img.size), "m_per_px": res, "lane_segments": len(lines)}


# --------------------------------------------------------------------------- measures

def lanes_on_road(xodr_text: str, v, f, labels, step_m: float = 0.5, raster_m: float = 0.1,
                  junctions: bool = False) -> dict:
    """Share of the driving lanes' area (carla.Map, outside junctions unless ``junctions``) that lies on
    road-labelled surface of the mesh (seen from above); and of their centre points."""
    from scipy import ndimage

    from .align import lane_lines
    from .evidence import lane_polygons, lane_raster
    from .mesh2d import Grid

    grid = Grid.around(v[:, :2], raster_m)
    lv = labels[f]
    road = _rasterize_faces(v, f, np.flatnonzero((lv == ROAD).sum(1) >= 2), grid)
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


# --------------------------------------------------------------------------- the road source

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


def _no_roads(exc: "NoRoads", ctx, mesh, labels, which, frame, out_xodr: Path, out_json: Path, out_png: Path,
              t0: float) -> dict:
    """No road in the scan: a map without roads, so the twin goes on without a road network (the exports and
    the CARLA package without a map, as with road_source=none). Roads derived and then all dropped by the
    checks (the scan shows carriageway, none of it held up) make the run degraded; a scan with no carriageway
    at all (a park, a yard) is a twin without roads, said in a warning."""
    import json

    out_xodr.write_text(empty_map(frame.proj_string()), encoding="utf-8")
    why = str(exc)
    net = Network({}, [], np.zeros((1, 1), bool), None, None, {})
    draw_scan_roads(mesh.v, mesh.f, labels, net, out_xodr.read_text(encoding="utf-8"), out_png,
                    note=f"no roads: {why}")
    doc = {"roads": [], "nodes": [], "no_roads": why, "derived_then_dropped": bool(exc.derived), "labels": which,
           "definition": "no road in the scan: opendrive.xodr holds no road (userData twinkit_roads=none); the twin "
                         "has no road network", "total_s": round(time.perf_counter() - t0, 3)}
    out_json.write_text(json.dumps(doc, indent=1))
    ctx.log.warning("road_source=scan: no roads: %s. The twin has no road network (the CARLA package has no map); "
                    "give an OSM extract (site.inputs.osm) for one", why)
    if exc.derived:
        ctx.degraded(f"roads from the scan: none kept ({why})",
                     "see scan_roads.png; give an OSM extract (site.inputs.osm) for the map")
    return {"roads": 0, "junctions": 0, "driving_lanes": 0, "labels": which, "no_roads": True,
            "total_s": doc["total_s"]}


def scan_source(params: ScanSourceParams, ctx, *, in_textured_mesh_ply: Path, out_opendrive_xodr: Path,
                out_scan_roads_json: Path, out_scan_roads_png: Path, in_labels_npy: Path | None = None,
                in_gt_labels_npy: Path | None = None, in_roads_truth_json: Path | None = None,
                in_points_meta_json: Path | None = None, in_points_ply: Path | None = None) -> dict:
    """Roads from the scan itself (no OSM): the labelled mesh's carriageway, curbs and sidewalks ->
    lanes -> OpenDRIVE in the site frame (``opendrive.xodr``, checked by osm_to_opendrive like a map)."""
    import json

    from twinkit.geo import SiteFrame

    from .mesh2d import read_mesh

    params = params or ScanSourceParams()
    t0 = time.perf_counter()
    mesh = read_mesh(in_textured_mesh_ply)
    which = params.labels
    if which == "auto":
        which = "predicted" if in_labels_npy is not None else "none"
        if in_labels_npy is None:
            ctx.log.info("road_source=scan: no labels.npy before this step; the curbs alone draw the roads")
    src = {"predicted": in_labels_npy, "gt": in_gt_labels_npy, "none": None}[which]
    labels = None
    if which != "none":
        if src is None:
            what = ("the segmentation's labels.npy (the steps before fetch_roads)" if which == "predicted"
                    else "gt_labels.npy (a site with ground truth: the demo)")
            raise InputError(f"road_source=scan with labels={which} needs {what}; none was written before this "
                             "step. Use road_source.labels=none for the curbs alone")
        try:
            labels = np.load(src).astype(np.int64).reshape(-1)
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"{src}: not a readable .npy label array ({exc}); re-run the segmentation") from None
        if len(labels) != len(mesh.v):
            raise InputError(f"{src}: {len(labels)} labels for the {len(mesh.v)} vertices of "
                             f"{in_textured_mesh_ply.name}; give the per-vertex labels of this mesh")
    spacing = None
    if in_points_meta_json is not None:
        try:
            spacing = (json.loads(Path(in_points_meta_json).read_text()).get("density") or {}).get("spacing_m")
        except (OSError, ValueError):
            spacing = None
    # a cloud coarser than curb_max_spacing_m shows no curbs: with labels, the paved-labelled grey ground
    # is the carriageway (no road or sidewalk label at all: no carriageway, no roads)
    coarse = spacing is not None and params.curb_max_spacing_m > 0 and float(spacing) > params.curb_max_spacing_m
    labels_for_mask = None
    if labels is not None:
        if coarse:
            labels_for_mask = labels
        elif not (labels == ROAD).any():
            ctx.log.warning("road_source=scan: no vertex is labelled road in %s; the curbs alone draw the roads",
                            src.name)
        else:
            labels_for_mask = labels
    curbs = not (labels_for_mask is not None and coarse)
    if not curbs:
        ctx.log.info("road_source=scan: point spacing %.3f m is coarser than curb_max_spacing_m=%g: no curbs to "
                     "see; the carriageway is the paved-labelled grey ground the scanner measured, and no sidewalk "
                     "lanes are made",
                     float(spacing), params.curb_max_spacing_m)
    points_xy = None
    if not curbs and in_points_ply is not None and params.min_point_density > 0:
        from twinkit.mesh import read_ply

        try:
            points_xy = np.asarray(read_ply(Path(in_points_ply)).vertices, np.float64)[:, :2]
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"{in_points_ply}: not a readable PLY ({exc}); re-run read_cloud") from None
    frame = SiteFrame.from_site(ctx.site)
    try:
        net = derive_network(mesh.v, mesh.f, labels_for_mask, params, ctx.log, curbs=curbs, rgb=mesh.rgb,
                             points_xy=points_xy)
        net.stats["curbs"] = curbs
        net.stats["point_spacing_m"] = spacing
        derived_m = network_length(net)
        if params.sidewalks and curbs:
            add_sidewalks(net, mesh.v, mesh.f, labels, params)
        add_heights_and_signals(net, mesh.v, mesh.f, labels, params)
        from twinkit.surface.closest import Surface

        scene = Surface(np.asarray(mesh.v, np.float64), np.asarray(mesh.f)).scene  # one BVH for both checks
        cut = trim_unsupported(net, mesh.v, mesh.f, params, scene=scene)
        if cut["cut_m"] or cut["dropped_roads"]:
            ctx.log.info("road_source=scan: %.1f m of road ends cut back and %d roads dropped where their lanes left the "
                         "scanned ground", cut["cut_m"], cut["dropped_roads"])
        work = out_opendrive_xodr.parent / "scan_plain"
        rounds = []
        for rnd in range(params.lane_check_rounds + 1):
            nod, edg = write_plain(net, params, frame.proj_string(), work)
            info = netconvert_plain(nod, edg, out_opendrive_xodr, params, ctx.log)
            if rnd == params.lane_check_rounds:
                break
            # the lanes netconvert built (junctions included) must lie on the scan at their heights
            chk = check_lanes(net, out_opendrive_xodr.read_text(encoding="utf-8"), mesh.v, mesh.f, params, scene)
            row = {"round": rnd + 1, "samples": chk["samples"], "on_share": chk["on_share"],
                   "junctions_off": {f"n{k}": v for k, v in chk["bad_junctions"].items()},
                   "roads_off": len(chk["bad_points"])}
            rounds.append(row)
            if not chk["bad_points"] and not chk["bad_junctions"] and not chk["narrow"] and not chk["nudge"]:
                break
            before = (len(net.arms), sum(len(a.xy) for a in net.arms), len(net.nodes))
            row["roads_narrowed"] = narrow_arms(net, chk["narrow"], params)  # in place: the indices stay
            row["roads_moved"] = nudge_arms(net, chk["nudge"], params)
            cut2 = cut_arms(net, chk["bad_points"], params, keep_junction_ends=False)
            gone = detach_junctions(net, [k for k in chk["bad_junctions"] if k in net.nodes], params)
            row.update({"cut_m": cut2["cut_m"], "dropped_roads": cut2["dropped_roads"] + gone})
            if not row["roads_narrowed"] and not row["roads_moved"] and (len(net.arms), sum(len(a.xy) for a in net.arms), len(net.nodes)) == before:
                break  # what is off cannot be cut (single shape points): the drop test reports it
            ctx.log.info("road_source=scan: check %d: %.1f %% of the driving-lane samples on the scanned surface; %d "
                         "road(s) off it in places (%.1f m cut), %d narrowed, %d junction(s) taken apart (%s), %d road(s) "
                         "dropped; netconvert again", rnd + 1, 100 * chk["on_share"], len(chk["bad_points"]), cut2["cut_m"],
                         row["roads_narrowed"],
                         len(chk["bad_junctions"]), ", ".join(f"n{k}: {100 * v:.0f} % on" for k, v in
                                                             chk["bad_junctions"].items()) or "-",
                         row["dropped_roads"])
            if not net.arms:
                raise NoRoads("none of the roads derived from the scan keeps its lanes on the scanned surface (they "
                              "float over banks or sink into slopes)", derived=True)
        net.stats["lane_check"] = rounds
        kept_m = network_length(net)
        net.stats.update({"derived_m": round(derived_m, 1), "kept_m": round(kept_m, 1),
                          "kept_share": round(kept_m / derived_m, 3) if derived_m else None})
    except NoRoads as exc:
        return _no_roads(exc, ctx, mesh, labels, which, frame, out_opendrive_xodr, out_scan_roads_json,
                         out_scan_roads_png, t0)
    text = mark_source(out_opendrive_xodr.read_text(encoding="utf-8"))
    out_opendrive_xodr.write_text(text, encoding="utf-8")
    doc = describe(net)
    doc.update({"labels": which, "labels_file": str(src) if src else None, **info,
                "definition": "roads derived from the scan: carriageway = road-labelled surface on the level below "
                              "the curbs; axes = its skeleton, centred between the edges; lanes of lane_width_m per "
                              "direction, a remainder >= min_strip_m a parking strip at the curb; sidewalk lanes "
                              "where sidewalk surface lies beyond the curb; junctions by netconvert",
                "params": {k: getattr(params, k) for k in params.__dataclass_fields__}})
    truth = None
    if in_roads_truth_json is not None:
        tj = json.loads(Path(in_roads_truth_json).read_text())
        truth = [np.asarray(ln["points"], float)[:, :2] for ln in tj.get("lanes", [])] or None
    if labels is not None:
        doc["lanes_on_road"] = lanes_on_road(text, mesh.v, mesh.f, labels)
    if truth:
        from .align import centreline_rmse

        allp = np.concatenate(truth)
        lo, hi = allp.min(0) + 2.0, allp.max(0) - 2.0
        rmse, n = centreline_rmse(text, truth, (lo[0], lo[1], hi[0], hi[1]))
        doc["centreline_rmse_m"] = round(rmse, 4)
        doc["centreline_points"] = n
    draw_scan_roads(mesh.v, mesh.f, labels, net, text, out_scan_roads_png, truth=truth)
    doc["total_s"] = round(time.perf_counter() - t0, 3)
    out_scan_roads_json.write_text(json.dumps(doc, indent=1))
    n_roads, n_j = len(net.arms), sum(nd["kind"] == "junction" for nd in net.nodes.values())
    n_lanes = sum(a.lanes["lanes"] * (2 if a.lanes["two_way"] else 1) for a in net.arms)
    ctx.log.info("roads from the scan (%s; labels: %s): %d roads, %d junctions, %d driving lanes, %d sidewalk lanes; "
                 "%.1f s", net.stats["carriageway_from"], which, n_roads, n_j, n_lanes,
                 sum((a.sidewalk_left_m > 0) + (a.sidewalk_right_m > 0) for a in net.arms), doc["total_s"])
    metrics = {"roads": n_roads, "junctions": n_j, "driving_lanes": n_lanes, "labels": which,
               "carriageway_m2": net.stats["carriageway_m2"], "total_s": doc["total_s"]}
    if "lanes_on_road" in doc:
        metrics["lanes_on_road_share"] = doc["lanes_on_road"]["on_road_share"]
        if doc["lanes_on_road"]["on_road_share"] < 0.9:
            ctx.log.warning("only %.0f %% of the derived driving lanes lie on road-labelled surface: check "
                            "scan_roads.png", 100 * doc["lanes_on_road"]["on_road_share"])
    if net.stats.get("kept_share") is not None:
        metrics["kept_share"] = net.stats["kept_share"]
        if net.stats["kept_share"] < params.min_kept_share:
            ctx.log.warning("the checks against the scan kept only %.0f %% of the %.0f m of road derived from it (lanes "
                            "over walls, hedges, banks or roofs were cut; scan_roads.json lane_check): the map covers "
                            "less of the streets than the scan shows, see scan_roads.png; an OSM extract "
                            "(site.inputs.osm) gives the whole network", 100 * net.stats["kept_share"],
                            net.stats["derived_m"])
    if "centreline_rmse_m" in doc:
        metrics["centreline_rmse_m"] = doc["centreline_rmse_m"]
        ctx.log.info("derived lane centre lines vs truth: RMSE %.3f m (%d points), lanes on road %.1f %%",
                     doc["centreline_rmse_m"], doc["centreline_points"],
                     100 * doc.get("lanes_on_road", {}).get("on_road_share", float("nan")))
    return metrics
