"""Movable objects out of the static map: find the scanned vehicles, riders and pedestrians in the
labelled textured mesh, cut them out, close the ground beneath them, and describe each as an actor.

Why: a parked car in the static map is collidable geometry nobody can move; a car parked on a
driving lane puts a solid block over lane waypoints. Simulators want such objects as actors
(CARLA: a ``vehicle.*`` / ``walker.*`` blueprint; Isaac: a separate prim without a static
collider).

The labels are noisy (on the demo the predicted "car" covers the ground around the cars too), so
the class alone does not make an object; 3D cues decide (all in the site frame, metres, z up):

1. **Ground height** on a grid (``cell_m``): the up-facing vertices (normal z >= ``up_normal_z``)
   no higher than ``ground_tol_m`` above the lowest up-facing vertex within ``ground_window_m``
   are ground; a cell's ground height is their mean; cells without ground (under a car's roof)
   take the nearest ground cell's height. The window is wider than any vehicle is wide, so a roof
   never counts as ground. Every vertex gets ``h`` = height above that ground.
2. **Candidates**: vertices with a movable label (person 11, rider 12, car 13, truck 14, bus 15,
   train 16, motorcycle 17, bicycle 18) and ``h > min_height_m``; movable-labelled vertices below
   that are ground, whatever the label says.
3. **Instances**: candidates clustered in 3D (``cluster_gap_m``); a cluster is an object when it
   stands up (its top at least the class's minimum height, at most its maximum), has a footprint
   no longer than the class allows, and has walls (at least ``min_vertical_share`` of its
   vertices with a near-horizontal normal). Flat patches (a painted bay, a ramp labelled car) fail
   the first or the last test; a building wall labelled car fails the size test. The class is the
   votes' first that the shape fits; a cluster with a vehicle's width and walls that fits no voted
   class is a car or truck by size (``choose_class``), and one longer than a car is first cut where its
   height dips (cars parked bumper to bumper, ``split_along``).
4. **Faces of an instance**: grown over the mesh from the cluster's faces through faces whose
   corners all lie above ``cut_height_m``, inside the cluster's oriented footprint widened by
   ``margin_m`` and below its top + ``margin_m``, whatever their label (wheels and windows are
   often labelled something else). Bits of surface left inside the footprint with no connection
   to the ground outside it (the reconstructed underside) go with the object.
5. **Fill**: every boundary loop the cut opened is closed with a patch at the ring's height (the
   local ground): a fan around the centroid where the loop is star-shaped seen from above, else
   ear clipping of the loop's outline. Each patch face copies the texture coordinates of the
   nearest ground face of the ring (a plausible piece of the surrounding ground), and its vertices
   take the ring's majority ground class (road, sidewalk, terrain). No open border is left unless
   a loop cannot be closed safely (it runs off the footprint: the object stood at the scan's edge;
   reported).
6. **Labels left**: movable labels that stay in the static mesh (flat ground voted car, rejected
   clusters) take the label of the nearest non-movable vertex (a ground class when the vertex is
   at ground height), so the static map carries no movable class.
"""
from __future__ import annotations

import dataclasses

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from twinkit.mesh import Mesh
from twinkit.mesh.core import compact, vertex_normals
from twinkit.surface.groundfill import fill_loop_on_ground

#: CityScapes trainIds of movable objects
MOVABLE = (11, 12, 13, 14, 15, 16, 17, 18)
#: ground classes a filled patch can take (road, sidewalk, terrain)
GROUND = (0, 1, 9)
#: per class: (min top above ground m, max top m, max footprint length m, min vertices)
CLASS_LIMITS = {
    11: (0.9, 2.4, 1.6, 20),  # person
    12: (0.9, 2.5, 2.6, 20),  # rider
    13: (0.7, 2.6, 7.0, 40),  # car
    14: (1.2, 4.6, 14.0, 40),  # truck
    15: (1.8, 4.6, 20.0, 40),  # bus
    16: (1.8, 5.0, 40.0, 40),  # train
    17: (0.5, 2.0, 3.0, 20),  # motorcycle
    18: (0.5, 1.9, 2.5, 20),  # bicycle
}
NAMES = {11: "Person", 12: "Rider", 13: "Car", 14: "Truck", 15: "Bus", 16: "Train", 17: "Motorcycle",
         18: "Bicycle"}


@dataclass
class LiftOptions:
    cell_m: float = 0.25  # ground grid cell
    ground_window_m: float = 4.0  # wider than the widest vehicle (a bus is 2.55 m)
    ground_tol_m: float = 0.25  # up-facing vertices this far above the local lowest are not ground (curbs are)
    up_normal_z: float = 0.85
    min_height_m: float = 0.25  # movable-labelled vertices at most this above the ground are ground
    cut_height_m: float = 0.10  # faces with every corner above this (inside the footprint) belong to the object
    cluster_gap_m: float = 0.5  # candidate vertices closer than this are one object
    min_vertical_share: float = 0.15  # share of an object's vertices with |normal z| < 0.5 (walls)
    margin_m: float = 0.3  # footprint widening for the face growth
    max_fill_extent_m: float = 3.0  # a hole reaching farther than this beyond the footprint is not filled
    debris_margin_m: float = 0.5  # small pieces left within the footprint + this go with the object
    debris_max_faces: int = 200
    patch_cell_m: float = 0.2  # grid of the ground patch where a footprint stays uncovered; 0 = no patch
    fill_cell_m: float = 0.1  # a closed hole under an object is filled on this grid at the ground's height
    flatten_feet_m: float = 0.5  # ... and its border inside the footprint, up to this high, lowered onto the ground
    #                           (0: a fan / ear clipping of the border, which spans it at the border's heights)
    gap_max_m: float = 1.0  # smaller spots a ray at the ground falls through, surface all round, get a patch; 0 = off
    gap_cell_m: float = 0.05  # ... found and patched on this grid
    small_loop_m: float = 1.0  # a loop of open border this short at an object's foot is closed even when it is no
    #                             hole seen from above (a fold of the cut-off feet); 0 = off
    fin_min_m: float = 0.2  # open pieces left standing at an object's foot higher than this (a kerb) go with it
    #                         (_peel_fins); 0 = off
    ground_hole_max_m: float = 8.0  # any other hole of the ground up to this wide is closed at the ground's height
    #                           (the ground fill's limit: wider is an unscanned area); 0 = off


@dataclass
class Instance:
    id: int
    class_id: int
    faces: np.ndarray  # indices into the input mesh's faces
    center: np.ndarray  # (3,) box centre, site frame
    size: np.ndarray  # (3,) length >= width, height (ground to top)
    yaw_deg: float  # long axis, counter-clockwise from east, in (-90, 90]
    ground_z: float
    label_share: float  # share of the cluster's vertices with the instance's class
    vertices: int = 0
    class_by: str = "labels"  # "labels": the votes' class fits its shape; "size": the votes named a class the
    #                            shape rules out, and the shape is a vehicle's (see choose_class)

    @property
    def name(self) -> str:
        return f"{NAMES.get(self.class_id, f'Class{self.class_id}')}_{self.id:03d}"


@dataclass
class LiftResult:
    mesh: Mesh  # the static mesh (objects cut out, holes filled), unreferenced vertices dropped
    labels: np.ndarray  # its per-vertex labels
    instances: list[Instance]
    source: Mesh  # the input mesh (instances' faces index it)
    source_labels: np.ndarray
    report: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- ground

class GroundGrid:
    """Ground height on a regular grid (see the module doc, step 1)."""

    def __init__(self, vertices: np.ndarray, normals: np.ndarray, opt: LiftOptions):
        from scipy.ndimage import distance_transform_edt, minimum_filter

        c = float(opt.cell_m)
        self.c = c
        self.lo = vertices[:, :2].min(axis=0) - c
        ij = self._ij(vertices[:, :2])
        self.nx, self.ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2
        flat = ij[:, 1] * self.nx + ij[:, 0]
        up = normals[:, 2] >= opt.up_normal_z
        zmin = np.full(self.nx * self.ny, np.inf)
        np.minimum.at(zmin, flat[up], vertices[up, 2])
        w = max(3, int(round(opt.ground_window_m / c)) | 1)
        zloc = minimum_filter(zmin.reshape(self.ny, self.nx), size=w, mode="nearest").ravel()
        g = up & (vertices[:, 2] <= zloc[flat] + opt.ground_tol_m)
        s = np.zeros(self.nx * self.ny)
        n = np.zeros(self.nx * self.ny)
        np.add.at(s, flat[g], vertices[g, 2])
        np.add.at(n, flat[g], 1)
        gz = np.where(n > 0, s / np.maximum(n, 1), np.nan).reshape(self.ny, self.nx)
        self.has_ground = n.reshape(self.ny, self.nx) > 0
        if not self.has_ground.any():
            gz[:] = float(np.min(vertices[:, 2])) if len(vertices) else 0.0
        else:
            _, (iy, ix) = distance_transform_edt(~self.has_ground, return_indices=True)
            gz = gz[iy, ix]
        self.z = gz

    def _ij(self, xy: np.ndarray) -> np.ndarray:
        return np.floor((xy - self.lo) / self.c).astype(np.int64)

    def at(self, xy: np.ndarray) -> np.ndarray:
        ij = self._ij(np.asarray(xy, float).reshape(-1, 2))
        i = np.clip(ij[:, 0], 0, self.nx - 1)
        j = np.clip(ij[:, 1], 0, self.ny - 1)
        return self.z[j, i]


# ----------------------------------------------------------------------------- geometry helpers

def oriented_box(xy: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Minimum-area rectangle around ``xy`` (n, 2): (centre (2,), length, width, yaw of the long
    axis in degrees counter-clockwise from +x, folded into (-90, 90])."""
    xy = np.asarray(xy, float)
    pts = xy
    if len(xy) >= 3:
        try:
            from scipy.spatial import ConvexHull

            pts = xy[ConvexHull(xy).vertices]
        except Exception:  # collinear / too few distinct points
            pts = xy
    best = None
    cand = [0.0]
    if len(pts) >= 2:
        e = np.diff(np.vstack([pts, pts[:1]]), axis=0)
        cand = list(np.arctan2(e[:, 1], e[:, 0]) % (np.pi / 2))
    for a in cand:
        ca, sa = np.cos(a), np.sin(a)
        u = xy @ np.array([ca, sa])
        v = xy @ np.array([-sa, ca])
        area = (u.max() - u.min()) * (v.max() - v.min())
        if best is None or area < best[0] - 1e-12:
            best = (area, a, u.min(), u.max(), v.min(), v.max())
    _, a, u0, u1, v0, v1 = best
    ca, sa = np.cos(a), np.sin(a)
    cu, cv = (u0 + u1) / 2, (v0 + v1) / 2
    centre = np.array([cu * ca - cv * sa, cu * sa + cv * ca])
    lu, lv = u1 - u0, v1 - v0
    yaw = np.degrees(a)
    if lv > lu:
        lu, lv = lv, lu
        yaw += 90.0
    yaw = (yaw + 90.0) % 180.0 - 90.0  # [-90, 90)
    if yaw <= -90.0 + 1e-9:
        yaw += 180.0  # (-90, 90]
    return centre, float(lu), float(lv), float(yaw)


def _in_box(xy: np.ndarray, centre, length, width, yaw_deg, margin) -> np.ndarray:
    a = np.radians(yaw_deg)
    d = xy - centre
    u = d @ np.array([np.cos(a), np.sin(a)])
    v = d @ np.array([-np.sin(a), np.cos(a)])
    return (np.abs(u) <= length / 2 + margin) & (np.abs(v) <= width / 2 + margin)


def _signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _ear_clip(p: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray | None:
    """Triangles (k, 3) of indices into ``p`` (n, 2), a counter-clockwise simple polygon; None when
    the outline is not simple enough to clip."""
    n = len(p)
    idx = list(range(n))
    tris = []
    ids = np.arange(n) if ids is None else np.asarray(ids)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(idx) > 3 and guard < 4 * n * n:
        m = len(idx)
        clipped = False
        pts = p[idx]
        for k in range(m):
            guard += 1
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % m]
            a, b, c = p[i0], p[i1], p[i2]
            if cross(a, b, c) <= 1e-12:
                continue  # reflex or flat corner
            # no other outline vertex inside the ear (vectorised)
            q = pts
            d1 = (b[0] - a[0]) * (q[:, 1] - a[1]) - (b[1] - a[1]) * (q[:, 0] - a[0])
            d2 = (c[0] - b[0]) * (q[:, 1] - b[1]) - (c[1] - b[1]) * (q[:, 0] - b[0])
            d3 = (a[0] - c[0]) * (q[:, 1] - c[1]) - (a[1] - c[1]) * (q[:, 0] - c[0])
            inside = (d1 > -1e-12) & (d2 > -1e-12) & (d3 > -1e-12)
            inside[[(k - 1) % m, k, (k + 1) % m]] = False
            # the ear's own vertices met again on the outline (a pinch) and coincident points do not block
            own = ids[np.asarray(idx)]
            inside &= (own != ids[i0]) & (own != ids[i1]) & (own != ids[i2])
            inside &= np.linalg.norm(q - b, axis=1) > 1e-9
            if inside.any():
                continue
            tris.append((i0, i1, i2))
            del idx[k]
            clipped = True
            break
        if not clipped:
            return None
    if len(idx) == 3:
        tris.append(tuple(idx))
    return np.asarray(tris, np.int64)


def _fill_loop(vertices: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Close a hole's boundary loop (vertex ids in the order :func:`boundary_loops` gives, i.e. the
    hole on the left seen from above... reversed to counter-clockwise here). Returns (faces (k, 3)
    with new-vertex ids >= len(vertices) meaning the appended centroid, centroid (3,) or None)."""
    ccw = loop[::-1]
    p = vertices[ccw, :2]
    if _signed_area(p) <= 0:
        return None  # not a hole in an up-facing surface (an island's outline, the scan's outer edge)
    c = vertices[ccw].mean(axis=0)
    nb = np.roll(np.arange(len(ccw)), -1)
    # fan: every triangle (c, ccw[i], ccw[i+1]) counter-clockwise seen from above
    e0 = p - c[:2]
    e1 = p[nb] - c[:2]
    crs = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
    if (crs > 1e-9).all():
        n = len(vertices)
        faces = np.stack([np.full(len(ccw), n), ccw, ccw[nb]], axis=1)
        return faces, c
    tri = _ear_clip(p, ccw)
    if tri is not None and len(tri):
        return ccw[tri], None
    # an outline that crosses itself seen from above: the fan still closes the border (some of its
    # triangles overlap, at the ring's height)
    n = len(vertices)
    return np.stack([np.full(len(ccw), n), ccw, ccw[nb]], axis=1), c


def refine_class(cid: int, votes: np.ndarray, length: float, width: float) -> int:
    """The class by label votes, unless the size rules it out: a car, truck, bus or train narrower than
    1 m and shorter than 2.8 m is a two-wheeler (labels confuse them; a scan sees a motorcycle's side):
    motorcycle or bicycle by their votes, else by length (a motorcycle is 1.9 m or longer)."""
    if cid in (13, 14, 15, 16) and width < 1.0 and length < 2.8:
        if votes[17] or votes[18]:
            return 17 if votes[17] >= votes[18] else 18
        return 17 if length >= 1.9 else 18
    return cid


def why_not(cid: int, n: int, top: float, length: float, vert_share: float, opt: LiftOptions) -> str | None:
    """Why a cluster of ``n`` vertices, ``top`` m high, ``length`` m long, is no object of class ``cid``
    (None: it is one)."""
    lo_top, hi_top, max_len, min_n = CLASS_LIMITS[cid]
    if n < min_n:
        return "too_few_vertices"
    if top < lo_top:
        return "too_low"
    if top > hi_top:
        return "too_high"
    if length > max_len:
        return "too_long"
    if vert_share < opt.min_vertical_share:
        return "no_walls"
    return None


#: a vehicle the scanner saw is at least this wide (a side and the roof)
VEHICLE_MIN_WIDTH_M = 1.2
#: a truck by size alone is at least this high (lower and longer than a car: a row of cars, a wall)
TRUCK_MIN_TOP_M = 2.2
#: a second class by votes is tried when it has at least this share of the cluster's vertices
SECOND_VOTE_SHARE = 0.1


def choose_class(votes: np.ndarray, n: int, top: float, length: float, width: float, vert_share: float,
                 opt: LiftOptions, split_tried: bool = False) -> tuple[int, str | None, str]:
    """The class of a cluster: (class id, why it is no object or None, "labels" | "size").

    The class with the most votes, if the shape fits it (``CLASS_LIMITS``); else the next class by votes
    that has at least ``SECOND_VOTE_SHARE`` of them and fits; else, for a cluster with a vehicle's width,
    car or truck by size. The 2D model names a parked car "person" or "motorcycle" on uncoloured or
    oblique views (a real mobile scan without colour; the demo's seed 7), and a 4.5 x 1.9 x 1.5 m
    object with walls is a car whatever the votes say. A vehicle-wide cluster longer than a car is
    "too_long" until ``split_tried`` (it may be cars parked bumper to bumper, ``split_along``); then a
    truck by size if it is at least ``TRUCK_MIN_TOP_M`` high. Nothing is made of a cluster no class fits."""
    mv = np.asarray(votes)[list(MOVABLE)]
    order = [MOVABLE[i] for i in np.argsort(-mv, kind="stable") if mv[i] > 0] or [MOVABLE[0]]
    first = order[0]
    why = why_not(first, n, top, length, vert_share, opt)
    if why is None:
        return first, None, "labels"
    for c in order[1:]:
        if votes[c] >= SECOND_VOTE_SHARE * n and why_not(c, n, top, length, vert_share, opt) is None:
            return c, None, "labels"
    if width >= VEHICLE_MIN_WIDTH_M:
        if why_not(13, n, top, length, vert_share, opt) is None:
            return 13, None, "size"
        if not split_tried and why_not(13, n, top, 0.0, vert_share, opt) is None:
            return first, "too_long", "labels"  # a car's height and width, longer: maybe several (split_along)
        if top >= TRUCK_MIN_TOP_M and why_not(14, n, top, length, vert_share, opt) is None:
            return 14, None, "size"
    return first, why, "labels"


def split_along(xy: np.ndarray, h: np.ndarray, yaw_deg: float, min_piece_m: float = 2.0, bin_m: float = 0.1,
                dip: float = 0.7) -> list[np.ndarray] | None:
    """Cut a cluster in two where its height profile along the long axis dips deepest: the gap between
    two cars parked bumper to bumper. (mask, mask) over the points, or None when no bin at least
    ``min_piece_m`` from either end is lower than ``dip`` times the lower of the peaks on its two sides."""
    from scipy.ndimage import maximum_filter1d

    a = np.radians(yaw_deg)
    t = np.asarray(xy, float) @ np.array([np.cos(a), np.sin(a)])
    b = ((t - t.min()) / bin_m).astype(np.int64)
    prof = np.zeros(int(b.max()) + 1)
    np.maximum.at(prof, b, np.asarray(h, float))
    prof = maximum_filter1d(prof, 3)  # a bin the points' spacing skips is no gap
    lo = int(round(min_piece_m / bin_m))
    hi = len(prof) - lo
    if hi <= lo:
        return None
    k = lo + int(np.argmin(prof[lo:hi]))
    if prof[k] > dip * min(prof[:k].max(), prof[k + 1:].max()):
        return None
    # the middle of the run of lowest bins around k (two bumpers side by side are one low run)
    low = prof <= prof[k] + 0.05
    a, e = k, k
    while a - 1 >= lo and low[a - 1]:
        a -= 1
    while e + 1 < hi and low[e + 1]:
        e += 1
    k = (a + e) // 2
    return [b <= k, b > k]


# ----------------------------------------------------------------------------- the lift

def _covered(pts: np.ndarray, tri_xy: np.ndarray) -> np.ndarray:
    """(k,) bool: the 2D points lie in at least one of the triangles (m, 3, 2)."""
    out = np.zeros(len(pts), bool)
    if len(tri_xy) == 0 or len(pts) == 0:
        return out
    a, b, c = tri_xy[:, 0], tri_xy[:, 1], tri_xy[:, 2]
    for s in range(0, len(tri_xy), 2000):
        A, B, C = a[s:s + 2000, None], b[s:s + 2000, None], c[s:s + 2000, None]
        P = pts[None]

        def side(p, q, r):
            return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

        d1, d2, d3 = side(A, B, P), side(B, C, P), side(C, A, P)
        neg = (d1 < -1e-12) | (d2 < -1e-12) | (d3 < -1e-12)
        pos = (d1 > 1e-12) | (d2 > 1e-12) | (d3 > 1e-12)
        out |= (~(neg & pos)).any(axis=0)
    return out


def _ground_gaps(v: np.ndarray, f: np.ndarray, grid: GroundGrid, cell_m: float, max_extent_m: float) -> list:
    """Small places where a vertical ray at the ground finds no surface within 0.5 m of the ground (a wheel
    or a foot would drop in) with surface all round them: the remains of a hole whose border is no
    simple loop (it runs up an object's foot, or crosses itself seen from above). Each as a box
    (``center``, ``size``, ``yaw_deg`` 0) for :func:`_patch_footprints`."""
    from types import SimpleNamespace

    from scipy import ndimage as ndi

    from twinkit.surface.closest import Surface
    from twinkit.surface.watertight import drop_test

    if len(f) == 0:
        return []
    lo = v[:, :2].min(axis=0)
    hi = v[:, :2].max(axis=0)
    xs = np.arange(lo[0] + cell_m / 2, hi[0], cell_m)
    ys = np.arange(lo[1] + cell_m / 2, hi[1], cell_m)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.c_[gx.ravel(), gy.ravel()]
    covered = drop_test(v, f, np.c_[xy, grid.at(xy)], 0.5, scene=Surface(v, f).scene).reshape(gx.shape)
    lab, n = ndi.label(~covered)
    out = []
    if n == 0:
        return out
    for k, sl in enumerate(ndi.find_objects(lab), start=1):
        if sl is None:
            continue
        ext = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) * cell_m
        if ext > max_extent_m:
            continue
        if sl[0].start == 0 or sl[1].start == 0 or sl[0].stop == lab.shape[0] or sl[1].stop == lab.shape[1]:
            continue  # touches the mesh's box: the site's edge, not enclosed
        win = (slice(sl[0].start - 1, sl[0].stop + 1), slice(sl[1].start - 1, sl[1].stop + 1))
        comp = lab[win] == k
        ring = ndi.binary_dilation(comp) & ~comp
        if not covered[win][ring].all():
            continue
        j, i = np.nonzero(comp)
        cx = xs[win[1].start + i]
        cy = ys[win[0].start + j]
        out.append(SimpleNamespace(center=np.array([(cx.min() + cx.max()) / 2, (cy.min() + cy.max()) / 2]),
                                   size=np.array([np.ptp(cx) + cell_m, np.ptp(cy) + cell_m, 0.0]), yaw_deg=0.0))
    return out


def _patch_footprints(v, f, lab, tc, grid: GroundGrid, instances, opt: LiftOptions, max_edge_m: float | None = None):
    """Ground patches where a footprint is still uncovered: a 2D Delaunay triangulation of the static
    mesh's border vertices there (so the patch shares them: joined to the ground where the border's
    edges are Delaunay edges) and grid points at the ground height, keeping the triangles over
    uncovered ground inside the footprint. Returns (new vertices, faces, their labels, face UVs)."""
    from scipy.spatial import Delaunay, cKDTree

    c = float(opt.patch_cell_m)
    nv = len(v)
    out_v, out_f, out_lab, out_tc = [], [], [], []
    fxy = v[f][:, :, :2]
    fz = v[f][:, :, 2].mean(axis=1)
    bv = np.unique(border_edges(f))
    for inst in instances:
        cen, length, width, yaw = inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg
        m = opt.margin_m
        a = np.radians(yaw)
        ax_u, ax_v = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        us = np.arange(-(length / 2 + m), length / 2 + m + 1e-9, c)
        vs = np.arange(-(width / 2 + m), width / 2 + m + 1e-9, c)
        gu, gv = np.meshgrid(us, vs)
        pts = cen + gu.ravel()[:, None] * ax_u + gv.ravel()[:, None] * ax_v
        near = _in_box(fxy.reshape(-1, 2), cen, length, width, yaw, m + 1.0).reshape(-1, 3).any(axis=1)
        near &= fz - grid.at(fxy.mean(axis=1)) < 0.5  # ground-level surfaces only
        tri_xy = fxy[near]
        unc = ~_covered(pts, tri_xy)
        bnear = bv[_in_box(v[bv, :2], cen, length, width, yaw, m + c)]
        if len(bnear):
            d, _ = cKDTree(v[bnear, :2]).query(pts)
            unc &= d >= 0.5 * c
        if unc.sum() < 3 and (max_edge_m is None or unc.sum() + len(bnear) < 3):
            continue
        p_new = pts[unc]
        p2 = np.vstack([v[bnear, :2], p_new])
        z = np.concatenate([v[bnear, 2], grid.at(p_new)])
        try:
            tri = Delaunay(p2).simplices
        except Exception:
            continue
        tc2 = p2[tri]
        centre = tc2.mean(axis=1)
        edge = np.max(np.linalg.norm(tc2 - np.roll(tc2, 1, axis=1), axis=2), axis=1)
        keep = (_in_box(centre, cen, length, width, yaw, m) & (edge <= (max_edge_m or 3.0 * c))
                & ~_covered(centre, tri_xy))
        tri = tri[keep]
        if len(tri) == 0:
            continue
        e1, e2 = tc2[keep, 1] - tc2[keep, 0], tc2[keep, 2] - tc2[keep, 0]
        cw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
        tri[cw] = tri[cw][:, [0, 2, 1]]
        used = np.unique(tri)
        nb = len(bnear)
        ids = np.empty(len(p2), np.int64)
        ids[:nb] = bnear
        new_pts = used[used >= nb]
        ids[new_pts] = nv + len(out_v) + np.arange(len(new_pts))
        for k in new_pts:
            out_v.append(np.array([p2[k, 0], p2[k, 1], z[k]]))
        faces_new = ids[tri]
        lab_ring = lab[bnear] if nb else lab[f[near].ravel()]
        gl = lab_ring[np.isin(lab_ring, GROUND)]
        cls = int(np.bincount(gl).argmax()) if len(gl) else 0
        out_lab.extend([cls] * len(new_pts))
        out_f.append(faces_new)
        if tc is not None:
            gf = np.nonzero(near)[0]
            gf = gf[np.isin(lab[f[gf]], GROUND).all(axis=1)] if len(gf) else gf
            if len(gf):
                _, nn = cKDTree(fxy[gf].mean(axis=1)).query(p2[tri].mean(axis=1))
                out_tc.append(np.asarray(tc)[gf[nn]])
            else:
                out_tc.append(np.zeros((len(tri), 6), np.float32))
    if not out_f:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.uint8), np.zeros((0, 6), np.float32)
    return (np.asarray(out_v).reshape(-1, 3), np.vstack(out_f), np.asarray(out_lab, np.uint8),
            np.vstack(out_tc).astype(np.float32) if out_tc else np.zeros((0, 6), np.float32))


def _box_owner(v: np.ndarray, instances: list[Instance], margin_m: float) -> np.ndarray:
    """Per vertex, the id of the first instance whose footprint widened by ``margin_m`` holds it, else -1."""
    owner = np.full(len(v), -1, np.int64)
    for inst in instances[::-1]:
        owner[_in_box(v[:, :2], inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg, margin_m)] = inst.id
    return owner


def _peel_fins(v: np.ndarray, f: np.ndarray, h: np.ndarray, face_owner: np.ndarray, instances: list[Instance],
               opt: LiftOptions) -> int:
    """Fins: what stays of an object's skin at its foot. Faces with a corner below the cut stay in the
    static mesh, and at a car's lower corner they can stand as a flap up to ``flatten_feet_m`` high, joined
    to the road, with an open edge along its top (seed 3 of the demo: 0.32 m at a lifted car's corner, open
    border over a driving lane; on seed 0 a motorcycle's front wheel, 0.94 m, beside a 0.3 m hole under a
    sidewalk lane). A fin is a connected piece of the faces that stay inside an object's footprint +
    ``margin_m`` + ``debris_margin_m`` and reach more than ``fin_min_m`` (above a kerb) but no higher than
    the object + ``margin_m``, that has an open edge and touches nothing else that stands up (a wall or a
    pole beside the car runs on beyond the footprint or above the object and stays; a closed thing has no
    open edge and stays). Fins go
    with the object; the hole closing that follows closes what they leave on the ground. Faces assigned
    in place (``face_owner``); returns how many."""
    from twinkit.mesh.topology import edge_face_incidence

    if opt.fin_min_m <= 0 or not instances:
        return 0
    boxes = _box_owner(v, instances, opt.margin_m + opt.debris_margin_m)
    near = _box_owner(v, instances, opt.margin_m)  # the footprint + margin_m alone: where a tall piece may be a fin
    tops = np.array([inst.size[2] for inst in instances]) + opt.margin_m
    rest = np.nonzero(face_owner < 0)[0]
    hmax = h[f[rest]].max(axis=1)
    fb = boxes[f[rest]]
    cand = (fb >= 0).all(axis=1) & (hmax > opt.fin_min_m)
    tall = cand & (hmax > opt.flatten_feet_m)
    # a piece higher than the feet: only within the footprint + margin_m, no higher than the object itself
    tall_ok = (near[f[rest]] >= 0).all(axis=1)
    tall_ok[tall_ok] &= hmax[tall_ok] <= tops[near[f[rest[tall_ok], 0]]]
    cand &= ~tall | tall_ok
    if not cand.any():
        return 0
    high_v = np.zeros(len(v), bool)  # what stands up and is no candidate: a wall, a pole, a sign beside the object
    high_v[f[rest[~cand & (hmax > opt.fin_min_m)]].ravel()] = True
    _, fe, counts = edge_face_incidence(f[rest])
    on_border = (counts[fe] == 1).any(axis=1)
    ci = np.nonzero(cand)[0]
    comp = edge_components(f[rest[ci]])
    n = int(comp.max()) + 1
    has_border = np.bincount(comp, weights=on_border[ci], minlength=n) > 0
    touches_high = np.bincount(comp, weights=high_v[f[rest[ci]]].any(axis=1), minlength=n) > 0
    take = rest[ci[(has_border & ~touches_high)[comp]]]
    if len(take) == 0:
        return 0
    owner = boxes[f[take, 0]]
    face_owner[take] = owner
    by_id = {inst.id: inst for inst in instances}
    for k in np.unique(owner):
        by_id[int(k)].faces = np.concatenate([by_id[int(k)].faces, take[owner == k]])
    return int(len(take))


def lift_movables(mesh: Mesh, labels: np.ndarray, opt: LiftOptions | None = None, log=None) -> LiftResult:
    """Cut the movable objects out of ``mesh`` (per-vertex ``labels``); see the module doc."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from twinkit.mesh.topology import boundary_loops, components

    opt = opt or LiftOptions()
    labels = np.asarray(labels).astype(np.uint8)
    v = np.array(mesh.vertices, float)  # a copy: the objects' feet are lowered onto the ground below
    f = np.asarray(mesh.faces, np.int64)
    normals = mesh.normals if mesh.normals is not None else vertex_normals(v, f)
    normals = np.asarray(normals, float)
    grid = GroundGrid(v, normals, opt)
    h = v[:, 2] - grid.at(v[:, :2])
    mov = np.isin(labels, MOVABLE)
    cand = np.nonzero(mov & (h > opt.min_height_m))[0]
    rep: dict = {"movable_vertices": int(mov.sum()), "candidate_vertices": int(len(cand)),
                 "ground_cells": int(grid.has_ground.sum())}
    instances: list[Instance] = []
    rejected: dict[str, int] = {}
    rejected_at: list[dict] = []  # the largest rejected clusters, where and why (the report's table)
    face_owner = np.full(len(f), -1, np.int64)
    if len(cand):
        pairs = cKDTree(v[cand]).query_pairs(opt.cluster_gap_m, output_type="ndarray")
        g = coo_matrix((np.ones(len(pairs), bool), (pairs[:, 0], pairs[:, 1])), shape=(len(cand), len(cand)))
        ncl, cl = connected_components(g, directed=False)
        # vertex -> faces (CSR) for the growth
        order = np.argsort(f.ravel(), kind="stable")
        starts = np.searchsorted(f.ravel()[order], np.arange(len(v) + 1))
        sizes = np.bincount(cl, minlength=ncl)
        queue = deque(cand[cl == k] for k in np.argsort(-sizes))
        while queue:
            vid = queue.popleft()
            cls_counts = np.bincount(labels[vid], minlength=256)
            top = float(h[vid].max())
            centre, length, width, yaw = oriented_box(v[vid, :2])
            vert_share = float(np.mean(np.abs(normals[vid, 2]) < 0.5))
            cid, why, class_by = choose_class(cls_counts, len(vid), top, length, width, vert_share, opt)
            if why == "too_long":
                # objects standing close (cars parked bumper to bumper) make one cluster: cut it where its
                # height along the long axis dips between two of them, and judge each piece on its own
                pieces = split_along(v[vid, :2], h[vid], yaw)
                if pieces is not None:
                    queue.extendleft(vid[p] for p in pieces[::-1])
                    continue
                cid, why, class_by = choose_class(cls_counts, len(vid), top, length, width, vert_share, opt,
                                                  split_tried=True)
            if why:
                rejected[why] = rejected.get(why, 0) + 1
                if len(rejected_at) < 40 and len(vid) >= CLASS_LIMITS[cid][3]:
                    rejected_at.append({"class": NAMES[cid], "why": why, "vertices": int(len(vid)),
                                        "x": round(float(centre[0]), 2), "y": round(float(centre[1]), 2),
                                        "length_m": round(float(length), 2), "width_m": round(float(width), 2),
                                        "top_m": round(top, 2), "wall_share": round(vert_share, 2)})
                continue
            # grow over faces above the cut, inside the widened footprint, below the top
            inside = _in_box(v[:, :2], centre, length, width, yaw, opt.margin_m)
            allowed_v = inside & (h > opt.cut_height_m) & (h <= top + opt.margin_m)
            seed_f = np.unique(order[np.concatenate([np.arange(starts[i], starts[i + 1]) for i in vid])] // 3)
            seed_f = seed_f[face_owner[seed_f] < 0]
            allowed_f = allowed_v[f].all(axis=1) & (face_owner < 0)
            allowed_f[seed_f] = True
            sel = np.nonzero(allowed_f)[0]
            if len(sel) == 0 or len(seed_f) == 0:
                rejected["no_faces"] = rejected.get("no_faces", 0) + 1
                continue
            _, comp = components(len(v), f[sel])
            keep_comp = np.unique(comp[np.isin(sel, seed_f)])
            mine = sel[np.isin(comp, keep_comp)]
            face_owner[mine] = len(instances)
            gz = float(np.median(grid.at(v[vid, :2])))
            ov = np.unique(f[mine])
            body = ov[h[ov] > opt.cut_height_m]  # the box: the body above the cut (not the wall feet on the ground)
            body = body if len(body) >= 3 else ov
            topz = float(v[ov, 2].max())
            c2, length, width, yaw = oriented_box(v[body, :2])
            share = float(cls_counts[cid] / len(vid))
            cid = refine_class(cid, cls_counts, length, width)
            instances.append(Instance(
                id=len(instances), class_id=cid, faces=mine,
                center=np.array([c2[0], c2[1], (gz + topz) / 2]), size=np.array([length, width, topz - gz]),
                yaw_deg=yaw, ground_z=gz, label_share=share, vertices=int(len(ov)), class_by=class_by))
    rep["clusters_rejected"] = rejected
    rep["clusters_rejected_at"] = rejected_at
    # debris: remaining surface inside a footprint that does not reach the ground outside it (the
    # reconstructed underside, slivers at the cut)
    removed = face_owner >= 0
    if instances:
        rest = np.nonzero(~removed)[0]
        comp = edge_components(f[rest])
        ncomp = int(comp.max()) + 1 if len(comp) else 0
        total = np.bincount(comp, minlength=ncomp)
        for inst in instances:
            inside = _in_box(v[:, :2], inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg,
                             opt.margin_m + opt.debris_margin_m)
            fin = inside[f[rest]].all(axis=1)
            within = np.bincount(comp[fin], minlength=ncomp)
            debris = np.nonzero((within == total) & (total > 0) & (total <= opt.debris_max_faces))[0]
            cand_f = rest[np.isin(comp, debris) & (face_owner[rest] < 0)]
            if len(cand_f):
                face_owner[cand_f] = inst.id
                inst.faces = np.concatenate([inst.faces, cand_f])
        peeled = _peel_fins(v, f, h, face_owner, instances, opt)
        if peeled:
            rep["fin_faces_peeled"] = peeled
        removed = face_owner >= 0
    rep["faces_lifted"] = int(removed.sum())
    # static mesh: the rest, holes closed
    touched = np.zeros(len(v), bool)
    touched[f[removed].ravel()] = True
    kept = f[~removed]
    kept_tc = None if mesh.face_attrs.get("texcoord") is None else np.asarray(mesh.face_attrs["texcoord"])[~removed]
    new_labels = labels.copy()
    # labels left: movable-labelled vertices that stay take the nearest non-movable label
    stay_mov = np.zeros(len(v), bool)
    stay_mov[np.unique(kept)] = True
    stay_mov &= mov
    nonmov = np.nonzero(~mov & (labels != 255))[0]
    ground_v = np.nonzero(np.isin(labels, GROUND))[0]
    if stay_mov.any() and len(nonmov):
        q = np.nonzero(stay_mov)[0]
        low = h[q] <= opt.min_height_m
        if len(ground_v) and low.any():
            _, nn = cKDTree(v[ground_v]).query(v[q[low]])
            new_labels[q[low]] = labels[ground_v[nn]]
        if (~low).any():
            _, nn = cKDTree(v[nonmov]).query(v[q[~low]])
            new_labels[q[~low]] = labels[nonmov[nn]]
    rep["relabelled_vertices"] = int(stay_mov.sum())
    loops = boundary_loops(kept) if len(kept) else []
    add_v, add_f, add_tc, add_lab = [], [], [], []
    filled = unfilled = flattened = small_closed = 0
    open_why: dict[str, float] = {}
    open_after_m = 0.0
    nv = len(v)
    if instances and loops:
        boxes = [(i.center[:2], i.size[0], i.size[1], i.yaw_deg) for i in instances]
        # kept faces per vertex (the ring of a loop: its texture and class come from there)
        korder = np.argsort(kept.ravel(), kind="stable")
        kstarts = np.searchsorted(kept.ravel()[korder], np.arange(len(v) + 1))
        kcen = v[kept].mean(axis=1)
        for lp in loops:
            pts = v[lp, :2]
            hits = [b for b in boxes if _in_box(pts, b[0], b[1], b[2], b[3], opt.margin_m).any()]
            if not hits and not touched[lp].any():
                continue  # an open border elsewhere: not ours
            ok_box = any(_in_box(pts, c_, l_, w_, y_, opt.margin_m + opt.max_fill_extent_m).all()
                         for c_, l_, w_, y_ in (hits or boxes))
            res = None
            if ok_box and _signed_area(v[lp[::-1], :2]) > 0:
                if opt.flatten_feet_m > 0 and hits:
                    # the object's cut-off feet (its faces with a corner below the cut stay in the static mesh,
                    # a ridge up to ~0.4 m a wheel would hit): border vertices inside its footprint go down to
                    # the ground, which flattens those faces onto the road
                    gl = grid.at(v[lp, :2])
                    hl = v[lp, 2] - gl
                    foot = np.zeros(len(lp), bool)
                    for c_, l_, w_, y_ in hits:
                        foot |= _in_box(pts, c_, l_, w_, y_, opt.margin_m)
                    foot &= (hl > 0.02) & (hl <= opt.flatten_feet_m)
                    v[lp[foot], 2] = gl[foot]
                    flattened += int(foot.sum())
                # on the ground: the inside follows the road, joined to the border
                res = fill_loop_on_ground(v, lp, grid.at, opt.fill_cell_m) if opt.fill_cell_m > 0 else None
                if res is None:
                    res = _fill_loop(v, lp)
                    if res is not None:
                        res = (res[0], np.zeros((0, 3)) if res[1] is None else np.asarray(res[1])[None])
            ln = float(np.linalg.norm(v[lp] - v[np.roll(lp, -1)], axis=1).sum())
            if res is None and ok_box and hits and ln <= opt.small_loop_m:
                # a small loop at an object's foot that is no hole seen from above (a fold of the cut-off feet,
                # 0.5 m round on the default demo, over a driving lane): a fan closes it whatever its orientation
                ccw = lp[::-1]  # against the surface's own half-edges, as _fill_loop's fan
                nb = np.roll(np.arange(len(ccw)), -1)
                res = (np.stack([np.full(len(ccw), nv), ccw, ccw[nb]], axis=1), v[lp].mean(axis=0)[None])
                small_closed += 1
            if res is None:
                unfilled += 1
                open_after_m += ln
                why = "beyond_footprint" if not ok_box else "not_a_hole" if _signed_area(v[lp[::-1], :2]) <= 0 \
                    else "not_simple"
                open_why[why] = round(open_why.get(why, 0.0) + ln, 3)
                continue
            faces_new, new_pts = res
            ring = np.unique(korder[np.concatenate([np.arange(kstarts[i], kstarts[i + 1]) for i in lp])] // 3)
            lab_ring = new_labels[lp]
            gl = lab_ring[np.isin(lab_ring, GROUND)]
            ground_class = int(np.bincount(gl).argmax()) if len(gl) else int(np.bincount(lab_ring).argmax())
            if len(new_pts):
                base = nv + len(add_v)
                faces_new = np.where(faces_new >= nv, faces_new - nv + base, faces_new)
                add_v.extend(list(new_pts))
                add_lab.extend([ground_class] * len(new_pts))
            add_f.append(faces_new)
            if kept_tc is not None and len(ring):
                rg = ring[np.isin(new_labels[kept[ring]], GROUND).all(axis=1)]
                rg = rg if len(rg) else ring
                cen = np.concatenate([v, np.asarray(add_v).reshape(-1, 3)])[faces_new].mean(axis=1)
                _, nn = cKDTree(kcen[rg]).query(cen)
                add_tc.append(kept_tc[rg[nn]])
            elif kept_tc is not None:
                add_tc.append(np.zeros((len(faces_new), 6), np.float32))
            filled += 1
    rep.update(loops_filled=filled, loops_left_open=unfilled, open_border_left_m=round(open_after_m, 3),
               small_loops_closed=small_closed,
               feet_vertices_flattened=flattened,
               open_border_left_by_reason_m=open_why)
    # second pass: ground still missing inside a footprint (the hole ran into a scan shadow reaching the
    # scan's edge, so no loop could be closed safely): a patch on the uncovered part of the footprint
    def current():
        """The static mesh so far: vertices, faces, vertex labels, face UVs (None without a texture)."""
        cur_tc = (np.vstack([kept_tc] + add_tc) if add_tc else kept_tc) if kept_tc is not None else None
        return (np.vstack([v] + ([np.asarray(add_v)] if add_v else [])),
                np.vstack([kept] + add_f) if add_f else kept,
                np.concatenate([new_labels, np.asarray(add_lab, np.uint8)]), cur_tc)

    def append(pv, pf, plab, ptc):
        if len(pf):
            add_v.extend(list(pv))
            add_lab.extend(np.asarray(plab).tolist())
            add_f.append(pf)
            if kept_tc is not None:
                add_tc.append(ptc)

    if instances and opt.patch_cell_m > 0:
        cur_v, cur_f, cur_lab, cur_tc = current()
        pv, pf, plab, ptc = _patch_footprints(cur_v, cur_f, cur_lab, cur_tc, grid, instances, opt)
        append(pv, pf, plab, ptc)
        rep["patch_faces"] = int(len(pf))
    # third pass: every other hole of the ground up to the ground fill's limit (a crack at a kerb's foot, a
    # notch the simplification or the trim left): closed on the ground, so a wheel or a foot never drops in
    if opt.ground_hole_max_m > 0:
        from twinkit.surface.groundfill import close_ground_holes

        cur_v, cur_f, cur_lab, cur_tc = current()
        gv, gf, gloops, grep = close_ground_holes(cur_v, cur_f, grid.at, max_extent_m=opt.ground_hole_max_m,
                                                  cell_m=opt.fill_cell_m or 0.1)
        if len(gf):
            # each new vertex takes the class of the nearest ground vertex of the mesh (road, sidewalk, terrain)
            gvid = np.nonzero(np.isin(cur_lab, GROUND))[0]
            gvid = gvid if len(gvid) else np.arange(len(cur_v))
            fill_lab = cur_lab[gvid[cKDTree(cur_v[gvid]).query(gv)[1]]] if len(gv) else np.zeros(0, np.uint8)
            gtc = None
            if cur_tc is not None:  # the UVs of the nearest ground face
                ground_f = np.nonzero(np.isin(cur_lab[cur_f], GROUND).all(axis=1))[0]
                ground_f = ground_f if len(ground_f) else np.arange(len(cur_f))
                all_v = np.vstack([cur_v, gv]) if len(gv) else cur_v
                _, nn = cKDTree(cur_v[cur_f[ground_f]].mean(axis=1)).query(all_v[gf].mean(axis=1))
                gtc = cur_tc[ground_f[nn]]
            append(gv, gf, fill_lab, gtc)
        rep["ground_holes"] = grep
        # what no loop could close (a hole whose border climbs an object's foot or crosses itself seen from
        # above): small spots a ray at the ground falls through, with surface all round, get a patch
        cur_v, cur_f, cur_lab, cur_tc = current()
        gaps = _ground_gaps(cur_v, cur_f, grid, opt.gap_cell_m, opt.gap_max_m) if opt.gap_max_m > 0 else []
        rep["ground_gaps"] = len(gaps)
        if gaps:
            popt = dataclasses.replace(opt, patch_cell_m=opt.gap_cell_m, margin_m=opt.gap_cell_m)
            pv, pf, plab, ptc = _patch_footprints(cur_v, cur_f, cur_lab, cur_tc, grid, gaps, popt, max_edge_m=0.3)
            append(pv, pf, plab, ptc)
            rep["ground_gap_faces"] = int(len(pf))
    verts = np.vstack([v] + ([np.asarray(add_v)] if add_v else []))
    faces = np.vstack([kept] + add_f) if add_f else kept
    labs = np.concatenate([new_labels, np.asarray(add_lab, np.uint8)])
    face_attrs = {}
    if kept_tc is not None:
        face_attrs["texcoord"] = np.vstack([kept_tc] + add_tc).astype(np.float32) if add_tc else kept_tc
    attrs = {}
    if mesh.normals is not None:
        nrm = np.vstack([np.asarray(mesh.normals, np.float32)] + ([np.tile(np.float32([0, 0, 1]), (len(add_v), 1))]
                                                                   if add_v else []))
        if add_f:
            fresh = vertex_normals(verts, faces)
            moved = np.zeros(len(verts), bool)
            moved[np.vstack(add_f).ravel()] = True
            nrm[moved] = fresh[moved]
        attrs["normals"] = nrm
    attrs["label"] = labs
    before = {tuple(e) for e in border_edges(f).tolist()}
    after = border_edges(faces)
    new = np.array([tuple(e) not in before for e in after.tolist()], bool) if len(after) else np.zeros(0, bool)
    rep["new_open_border_m"] = round(float(np.linalg.norm(verts[after[new, 0]] - verts[after[new, 1]], axis=1).sum())
                                     if new.any() else 0.0, 3)
    out = compact(Mesh(vertices=verts, faces=faces, attrs=attrs, face_attrs=face_attrs,
                       comments=list(mesh.comments), texture=mesh.texture))
    out_labels = out.attrs.pop("label")
    rep.update(instances=len(instances), faces_added=int(sum(len(a) for a in add_f)),
               by_class={NAMES[c]: sum(1 for i in instances if i.class_id == c) for c in MOVABLE
                         if any(i.class_id == c for i in instances)})
    if log is not None:
        log.info("lifted %d movable objects (%d faces); %d loops filled, %d left open; %d labels moved to "
                 "the surrounding class", len(instances), rep["faces_lifted"], filled, unfilled,
                 rep["relabelled_vertices"])
    return LiftResult(out, out_labels, instances, mesh, labels, rep)


def edge_components(faces: np.ndarray) -> np.ndarray:
    """(m,) component label per face, faces connected through shared edges (not through a lone
    shared vertex: a triangle hanging on one vertex is its own piece)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from twinkit.mesh.topology import edge_face_incidence

    m = len(faces)
    if m == 0:
        return np.zeros(0, np.int64)
    _, fe, counts = edge_face_incidence(np.asarray(faces, np.int64))
    e = fe.ravel()
    fid = np.repeat(np.arange(m), 3)
    order = np.argsort(e, kind="stable")
    es, fs = e[order], fid[order]
    same = es[1:] == es[:-1]
    a, b = fs[:-1][same], fs[1:][same]
    g = coo_matrix((np.ones(len(a), bool), (a, b)), shape=(m, m))
    return connected_components(g, directed=False)[1]


def border_edges(faces: np.ndarray) -> np.ndarray:
    """(k, 2) sorted vertex pairs of the edges used by one face only."""
    from twinkit.mesh.topology import edge_face_incidence

    if len(faces) == 0:
        return np.zeros((0, 2), np.int64)
    edges, _, counts = edge_face_incidence(np.asarray(faces, np.int64))
    return edges[counts == 1]


def open_border_near(mesh_faces: np.ndarray, vertices: np.ndarray, instances: list[Instance],
                     margin_m: float = 1.0) -> float:
    """Length (m) of open border (edges of one face) inside the instances' footprints widened by
    ``margin_m``: the measure of a hole left by the lift."""
    from twinkit.mesh.topology import edge_face_incidence

    if len(mesh_faces) == 0 or not instances:
        return 0.0
    edges, _, counts = edge_face_incidence(np.asarray(mesh_faces, np.int64))
    b = edges[counts == 1]
    mid = vertices[b].mean(axis=1)[:, :2]
    near = np.zeros(len(b), bool)
    for i in instances:
        near |= _in_box(mid, i.center[:2], i.size[0], i.size[1], i.yaw_deg, margin_m)
    return float(np.linalg.norm(vertices[b[near, 0]] - vertices[b[near, 1]], axis=1).sum())


# ----------------------------------------------------------------------------- CARLA blueprints

#: CARLA 0.9.16 blueprints per class, with nominal (length, width, height) in metres. The ids are those of
#: carla-simulator/carla Docs/catalogue_vehicles.md and Docs/bp_library.md (0.9.16); the sizes are the
#: real models' nominal dimensions (manufacturer figures, rounded), not CARLA's bounding boxes, which a
#: running simulator reports (``actor.bounding_box``) -- close enough to pick a model by size.
BLUEPRINTS: dict[int, list[tuple[str, tuple[float, float, float]]]] = {
    13: [("vehicle.micro.microlino", (2.52, 1.47, 1.50)),
         ("vehicle.mini.cooper_s_2021", (3.88, 1.73, 1.43)),
         ("vehicle.nissan.micra", (3.78, 1.67, 1.52)),
         ("vehicle.audi.a2", (3.83, 1.67, 1.55)),
         ("vehicle.citroen.c3", (3.94, 1.73, 1.52)),
         ("vehicle.seat.leon", (4.28, 1.82, 1.46)),
         ("vehicle.toyota.prius", (4.54, 1.76, 1.49)),
         ("vehicle.bmw.grandtourer", (4.56, 1.80, 1.61)),
         ("vehicle.tesla.model3", (4.69, 1.85, 1.44)),
         ("vehicle.ford.mustang", (4.78, 1.92, 1.38)),
         ("vehicle.audi.etron", (4.90, 1.94, 1.63)),
         ("vehicle.lincoln.mkz_2020", (4.93, 1.86, 1.48)),
         ("vehicle.dodge.charger_2020", (5.04, 1.91, 1.48)),
         ("vehicle.nissan.patrol_2021", (5.17, 1.99, 1.94))],
    14: [("vehicle.mercedes.sprinter", (5.93, 2.02, 2.59)),
         ("vehicle.ford.ambulance", (6.40, 2.30, 2.80)),
         ("vehicle.carlamotors.carlacola", (5.20, 2.60, 2.60)),
         ("vehicle.carlamotors.firetruck", (8.50, 2.50, 3.30))],
    15: [("vehicle.mitsubishi.fusorosa", (10.30, 2.40, 3.20))],
    17: [("vehicle.vespa.zx125", (1.80, 0.70, 1.15)),
         ("vehicle.yamaha.yzf", (2.05, 0.70, 1.10)),
         ("vehicle.kawasaki.ninja", (2.00, 0.75, 1.10)),
         ("vehicle.harley-davidson.low_rider", (2.35, 0.90, 1.10))],
    18: [("vehicle.bh.crossbike", (1.75, 0.60, 1.05)),
         ("vehicle.diamondback.century", (1.75, 0.55, 1.05)),
         ("vehicle.gazelle.omafiets", (1.85, 0.65, 1.15))],
    11: [("walker.pedestrian.0001", (0.5, 0.5, 1.8))],
    12: [("walker.pedestrian.0001", (0.5, 0.5, 1.8))],  # CARLA has no rider; a walker, the bicycle is its own actor
}


def suggest_blueprint(class_id: int, size) -> dict | None:
    """The blueprint of the class whose nominal size is closest to ``size`` (length, width, height)
    by the sum of |log ratio| per axis; None for classes CARLA has no blueprint for (train)."""
    opts = BLUEPRINTS.get(int(class_id))
    if not opts:
        return None
    s = np.maximum(np.asarray(size, float), 0.05)
    best = min(opts, key=lambda o: float(np.abs(np.log(s / np.asarray(o[1]))).sum()))
    err = np.abs(np.log(s / np.asarray(best[1])))
    return {"id": best[0], "nominal_size_m": list(best[1]), "size_mismatch": round(float(err.max()), 3)}
