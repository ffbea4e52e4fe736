"""Detection of the movable objects: clusters of movable-labelled vertices that stand up, each grown over
the mesh into the faces of one object (:class:`Instance`), with the debris and the fins left at its foot.

Site frame: metres, x east, y north, z up; ``h`` is a vertex's height above the ground grid."""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from twinkit.street.ground import LocalGround

from .cues import object_cues, why_not_by_cues
from .kinds import CLASS_LIMITS, MOVABLE, NAMES, choose_class, refine_class
from .options import LiftOptions


@dataclass
class Instance:
    """One movable object: its faces in the input mesh and its oriented box (site frame, metres)."""

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
    cues: dict | None = None  # what else says it is an object (.cues.object_cues)

    @property
    def name(self) -> str:
        return f"{NAMES.get(self.class_id, f'Class{self.class_id}')}_{self.id:03d}"


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


def in_box(xy: np.ndarray, centre, length, width, yaw_deg, margin) -> np.ndarray:
    """(k,) bool: the points ``xy`` (k, 2) lie in the box (centre (2,), length, width, yaw in degrees)
    widened by ``margin`` on every side."""
    a = np.radians(yaw_deg)
    d = xy - centre
    u = d @ np.array([np.cos(a), np.sin(a)])
    v = d @ np.array([-np.sin(a), np.cos(a)])
    return (np.abs(u) <= length / 2 + margin) & (np.abs(v) <= width / 2 + margin)


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

def find_instances(v: np.ndarray, f: np.ndarray, h: np.ndarray, normals: np.ndarray, labels: np.ndarray,
                   grid: LocalGround, opt: LiftOptions, rep: dict,
                   votes: np.ndarray | None = None) -> tuple[list[Instance], np.ndarray]:
    """The objects: movable-labelled vertices ``h`` > ``min_height_m`` above the ground, clustered in 3D
    (``cluster_gap_m``), each cluster judged by its shape (:func:`choose_class`, cut in two where it is too
    long, :func:`split_along`), grown over the mesh (:func:`grow_faces`) and kept only when its other cues
    agree (:mod:`.cues`: ground contact, the geometry ``votes`` (n, 19) or None). ``v`` (n, 3), ``f`` (m, 3),
    ``normals`` (n, 3), ``labels`` (n,) uint8. Returns (instances, per face the id of its instance or -1);
    adds ``candidate_vertices``, ``clusters_rejected`` and ``clusters_rejected_at`` to ``rep``."""
    from twinkit.surface.linked import linked_groups

    cand = np.nonzero(np.isin(labels, MOVABLE) & (h > opt.min_height_m))[0]
    rep["candidate_vertices"] = int(len(cand))
    instances: list[Instance] = []
    rejected: dict[str, int] = {}
    rejected_at: list[dict] = []  # the largest rejected clusters, where and why (the report's table)
    face_owner = np.full(len(f), -1, np.int64)
    if len(cand):
        ncl, cl = linked_groups(v[cand], opt.cluster_gap_m)
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
            mine, cues = None, None
            if not why:
                seed_f = np.unique(order[np.concatenate([np.arange(starts[i], starts[i + 1]) for i in vid])] // 3)
                mine = grow_faces(v, f, h, seed_f, face_owner, (centre, length, width, yaw), top, opt)
                if mine is None:
                    why = "no_faces"
                else:
                    cues = object_cues(vid, np.unique(f[mine]), h, votes)
                    why = why_not_by_cues(cues, opt, refine_class(cid, cls_counts, length, width), width)
            if why:
                rejected[why] = rejected.get(why, 0) + 1
                if len(rejected_at) < 40 and len(vid) >= CLASS_LIMITS[cid][3]:
                    rejected_at.append({"class": NAMES[cid], "why": why, "vertices": int(len(vid)),
                                        "x": round(float(centre[0]), 2), "y": round(float(centre[1]), 2),
                                        "length_m": round(float(length), 2), "width_m": round(float(width), 2),
                                        "top_m": round(top, 2), "wall_share": round(vert_share, 2), **(cues or {})})
                continue
            face_owner[mine] = len(instances)
            instances.append(_instance(len(instances), v, f, h, vid, mine, grid, cid, cls_counts, class_by, opt))
            instances[-1].cues = cues
    rep["clusters_rejected"] = rejected
    rep["clusters_rejected_at"] = rejected_at
    return instances, face_owner


def grow_faces(v: np.ndarray, f: np.ndarray, h: np.ndarray, seed_f: np.ndarray, face_owner: np.ndarray, box,
               top: float, opt: LiftOptions) -> np.ndarray | None:
    """The faces of one object: from the cluster's faces ``seed_f`` over faces no instance owns yet whose
    corners all lie above ``cut_height_m``, inside the ``box`` (centre, length, width, yaw) widened by
    ``margin_m`` and below ``top`` + ``margin_m``, whatever their label. (k,) face ids, None when none."""
    from twinkit.mesh.topology import components

    centre, length, width, yaw = box
    inside = in_box(v[:, :2], centre, length, width, yaw, opt.margin_m)
    allowed_v = inside & (h > opt.cut_height_m) & (h <= top + opt.margin_m)
    seed_f = seed_f[face_owner[seed_f] < 0]
    allowed_f = allowed_v[f].all(axis=1) & (face_owner < 0)
    allowed_f[seed_f] = True
    sel = np.nonzero(allowed_f)[0]
    if len(sel) == 0 or len(seed_f) == 0:
        return None

    def reached(sel):  # the faces of ``sel`` connected to a seed face
        _, comp = components(len(v), f[sel])
        return sel[np.isin(comp, np.unique(comp[np.isin(sel, seed_f)]))]

    grown = reached(sel)
    column = columns_through(v, f, h, grown, allowed_f, top + opt.margin_m)
    if not column.any():
        return grown
    grown = reached(grown[~column]) if (~column).any() else grown[:0]  # the object without the columns
    return grown if len(grown) else None


#: a grown face this close (m, seen from above) to where the growth ran into something taller stays static
COLUMN_M = 0.25


def columns_through(v: np.ndarray, f: np.ndarray, h: np.ndarray, grown: np.ndarray, allowed_f: np.ndarray,
                    limit: float) -> np.ndarray:
    """Which of the ``grown`` faces belong to something that runs on above the object: a pole or a wall beside
    a car, whose foot the growth took (the growth stops at the object's top, not at the pole). Where a grown
    face shares a vertex with a face the growth could not take that reaches above ``limit`` (the object's top
    + margin), the growth ran up the tall thing; the grown faces within ``COLUMN_M`` of those shared vertices,
    seen from above, are its foot (a pole's faces lie under its cut ring). (k,) bool per grown face
    (docs/export.md, step 3 of the lift)."""
    from scipy.spatial import cKDTree

    above = ~allowed_f & (h[f].max(axis=1) > limit)
    if not above.any() or not len(grown):
        return np.zeros(len(grown), bool)
    in_grown = np.zeros(len(v), bool)
    in_grown[f[grown].ravel()] = True
    in_above = np.zeros(len(v), bool)
    in_above[f[above].ravel()] = True
    joint = np.nonzero(in_grown & in_above)[0]
    if not len(joint):
        return np.zeros(len(grown), bool)
    d, _ = cKDTree(v[joint, :2]).query(v[f[grown]].mean(axis=1)[:, :2], distance_upper_bound=COLUMN_M)
    return np.isfinite(d)


def _instance(k: int, v, f, h, vid, mine, grid: LocalGround, cid: int, cls_counts, class_by: str,
              opt: LiftOptions) -> Instance:
    """Instance ``k`` of the cluster ``vid`` whose faces are ``mine``: its box is that of its body above the
    cut (not the wall feet on the ground), from the ground under the cluster to its top."""
    gz = float(np.median(grid.at(v[vid, :2])))
    ov = np.unique(f[mine])
    body = ov[h[ov] > opt.cut_height_m]
    body = body if len(body) >= 3 else ov
    topz = float(v[ov, 2].max())
    c2, length, width, yaw = oriented_box(v[body, :2])
    share = float(cls_counts[cid] / len(vid))
    cid = refine_class(cid, cls_counts, length, width)
    return Instance(id=k, class_id=cid, faces=mine, center=np.array([c2[0], c2[1], (gz + topz) / 2]),
                    size=np.array([length, width, topz - gz]), yaw_deg=yaw, ground_z=gz, label_share=share,
                    vertices=int(len(ov)), class_by=class_by)


def claim_debris(v: np.ndarray, f: np.ndarray, h: np.ndarray, face_owner: np.ndarray, instances: list[Instance],
                 opt: LiftOptions, rep: dict) -> None:
    """Debris: what remains inside a footprint (+ ``margin_m`` + ``debris_margin_m``), no higher than the object
    (+ ``margin_m``: not a lamp head over a parked car), that does not reach the ground outside it (the
    reconstructed underside, slivers at the cut; at most ``debris_max_faces``), then the fins
    (:func:`peel_fins`), go with the object. ``face_owner`` and the instances' faces are updated in place;
    ``fin_faces_peeled`` goes to ``rep``."""
    removed = face_owner >= 0
    rest = np.nonzero(~removed)[0]
    comp = edge_components(f[rest])
    ncomp = int(comp.max()) + 1 if len(comp) else 0
    total = np.bincount(comp, minlength=ncomp)
    for inst in instances:
        inside = in_box(v[:, :2], inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg,
                        opt.margin_m + opt.debris_margin_m) & (h <= inst.size[2] + opt.margin_m)
        fin = inside[f[rest]].all(axis=1)
        within = np.bincount(comp[fin], minlength=ncomp)
        debris = np.nonzero((within == total) & (total > 0) & (total <= opt.debris_max_faces))[0]
        cand_f = rest[np.isin(comp, debris) & (face_owner[rest] < 0)]
        if len(cand_f):
            face_owner[cand_f] = inst.id
            inst.faces = np.concatenate([inst.faces, cand_f])
    peeled = peel_fins(v, f, h, face_owner, instances, opt)
    if peeled:
        rep["fin_faces_peeled"] = peeled


def box_owner(v: np.ndarray, instances: list[Instance], margin_m: float) -> np.ndarray:
    """Per vertex, the id of the first instance whose footprint widened by ``margin_m`` holds it, else -1."""
    owner = np.full(len(v), -1, np.int64)
    for inst in instances[::-1]:
        owner[in_box(v[:, :2], inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg, margin_m)] = inst.id
    return owner


def peel_fins(v: np.ndarray, f: np.ndarray, h: np.ndarray, face_owner: np.ndarray, instances: list[Instance],
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
    boxes = box_owner(v, instances, opt.margin_m + opt.debris_margin_m)
    near = box_owner(v, instances, opt.margin_m)  # the footprint + margin_m alone: where a tall piece may be a fin
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
