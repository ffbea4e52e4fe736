"""Closing the ground where the movable objects stood: every loop of open border the cut opened is
closed on the ground (:func:`twinkit.street.holes.close_hole`; at the ring's heights,
:func:`twinkit.street.holes.span`, where the outline is no simple polygon seen from above), footprints still uncovered get a ground patch, then every other hole of the ground and
the spots a ray at the ground falls through. Each new face copies the UVs of the nearest ground face of its
ring, each new vertex takes the ring's majority ground class (road, sidewalk, terrain).

Site frame: metres, z up. Faces index the static mesh's vertices (the input's, then the added ones)."""
from __future__ import annotations

import dataclasses

import numpy as np

from twinkit.street.ground import LocalGround
from twinkit.street.holes import close_hole, fan, is_hole_from_above, patch, span

from .detect import Instance, in_box
from .kinds import GROUND
from .options import LiftOptions


class Additions:
    """The static mesh as the hole closing grows it: the input's vertices ``v`` (n, 3) float64 (the objects'
    feet are lowered in place), the ``kept`` faces (m, 3) int64, per-vertex ``labels`` (n,) uint8, per-face
    UVs ``kept_tc`` (m, 6) float32 or None without a texture; and what each fill adds (``add_*``)."""

    def __init__(self, v: np.ndarray, kept: np.ndarray, labels: np.ndarray, kept_tc: np.ndarray | None):
        self.v, self.kept, self.labels, self.kept_tc = v, kept, labels, kept_tc
        self.add_v: list = []
        self.add_f: list = []
        self.add_tc: list = []
        self.add_lab: list = []

    def current(self):
        """The static mesh so far: vertices, faces, vertex labels, face UVs (None without a texture)."""
        kept_tc, add_tc = self.kept_tc, self.add_tc
        cur_tc = (np.vstack([kept_tc] + add_tc) if add_tc else kept_tc) if kept_tc is not None else None
        return (np.vstack([self.v] + ([np.asarray(self.add_v)] if self.add_v else [])),
                np.vstack([self.kept] + self.add_f) if self.add_f else self.kept,
                np.concatenate([self.labels, np.asarray(self.add_lab, np.uint8)]), cur_tc)

    def append(self, pv, pf, plab, ptc) -> None:
        """Add vertices ``pv`` (k, 3) with labels ``plab`` and faces ``pf`` (indexing the mesh so far) with UVs
        ``ptc`` (f, 6)."""
        if len(pf):
            self.add_v.extend(list(pv))
            self.add_lab.extend(np.asarray(plab).tolist())
            self.add_f.append(pf)
            if self.kept_tc is not None:
                self.add_tc.append(ptc)


def close_object_holes(sm: Additions, touched: np.ndarray, grid: LocalGround, instances: list[Instance],
                       opt: LiftOptions, rep: dict) -> None:
    """Close the loops of open border the cut opened (a loop near a footprint, below the object's top, or through
    a vertex of a lifted face, ``touched`` (n,) bool: a street light's open lamp head over a parked car is no hole
    the car left) that reach no farther than ``max_fill_extent_m`` beyond the footprint: the object's
    remnants inside it (:func:`lower_remnants`) and its cut-off feet up to ``flatten_feet_m`` are lowered onto
    the ground, then the hole is closed on the ground (:func:`close_hole` on a ``fill_cell_m`` grid at
    ``grid``'s height; at the ring's heights, :func:`span`, where the outline is no simple polygon seen from
    above or ``fill_cell_m`` is 0). A loop of at most ``small_loop_m`` at an object's foot that is no hole seen
    from above (a fold of the cut-off feet) is closed by a fan. Counts go to ``rep``."""
    from twinkit.mesh.topology import boundary_loops

    v, kept = sm.v, sm.kept
    rep["remnant_vertices_lowered"] = lower_remnants(v, kept, grid, instances, opt) if opt.flatten_feet_m > 0 else 0
    loops = boundary_loops(kept) if len(kept) else []
    cnt = dict(filled=0, unfilled=0, flattened=0, small=0)
    open_why: dict[str, float] = {}
    open_after_m = 0.0
    if instances and loops:
        boxes = [(i.center[:2], i.size[0], i.size[1], i.yaw_deg) for i in instances]
        tops = [float(i.size[2]) for i in instances]
        # kept faces per vertex (the ring of a loop: its texture and class come from there)
        korder = np.argsort(kept.ravel(), kind="stable")
        kstarts = np.searchsorted(kept.ravel()[korder], np.arange(len(v) + 1))
        kcen = v[kept].mean(axis=1)
        for lp in loops:
            pts = v[lp, :2]
            hl = v[lp, 2] - grid.at(pts)
            hits = [b for b, top in zip(boxes, tops)
                    if (in_box(pts, b[0], b[1], b[2], b[3], opt.margin_m) & (hl <= top + opt.margin_m)).any()]
            if not hits and not touched[lp].any():
                continue  # an open border elsewhere: not ours
            ok_box = any(in_box(pts, c_, l_, w_, y_, opt.margin_m + opt.max_fill_extent_m).all()
                         for c_, l_, w_, y_ in (hits or boxes))
            res = None
            if ok_box and is_hole_from_above(v, lp):
                if opt.flatten_feet_m > 0 and hits:
                    cnt["flattened"] += _flatten_feet(v, lp, hits, grid, opt)
                # on the ground: the inside follows the road, joined to the border
                res = (close_hole(v, lp, grid.at, opt.fill_cell_m) if opt.fill_cell_m > 0 else None) or span(v, lp)
            ln = float(np.linalg.norm(v[lp] - v[np.roll(lp, -1)], axis=1).sum())
            if res is None and ok_box and hits and ln <= opt.small_loop_m:
                # a small loop at an object's foot that is no hole seen from above (a fold of the cut-off feet,
                # 0.5 m round on the default demo, over a driving lane): a fan closes it whatever its orientation
                res = fan(v, lp)
                cnt["small"] += 1
            if res is None:
                cnt["unfilled"] += 1
                open_after_m += ln
                why = "beyond_footprint" if not ok_box else "not_a_hole"
                open_why[why] = round(open_why.get(why, 0.0) + ln, 3)
                continue
            ring = np.unique(korder[np.concatenate([np.arange(kstarts[i], kstarts[i + 1]) for i in lp])] // 3)
            _add_fill(sm, lp, ring, kcen, *res)
            cnt["filled"] += 1
    rep.update(loops_filled=cnt["filled"], loops_left_open=cnt["unfilled"], open_border_left_m=round(open_after_m, 3),
               small_loops_closed=cnt["small"], feet_vertices_flattened=cnt["flattened"],
               open_border_left_by_reason_m=open_why)


def lower_remnants(v: np.ndarray, kept: np.ndarray, grid: LocalGround, instances: list[Instance],
                   opt: LiftOptions) -> int:
    """What stays of an object's skin inside its footprint where its faces reach the ground (a sill's sliver
    under a car's side, joined to the road, so neither cut nor peeled: on the full-density `large` site spikes
    0.3-0.46 m high put 65-153 points of road inside two cars' boxes): a connected piece of the static mesh's
    raised vertices (more than ``min_height_m`` above the object's ground: higher than a kerb) that lies inside
    the footprints and no higher than ``flatten_feet_m`` goes down to the ground (in place in ``v``); a wall's
    lower band runs on beyond the footprint and stays. Returns how many vertices."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from twinkit.mesh.core import edges

    if not instances or not len(kept):
        return 0
    idx = np.unique(kept)
    g = grid.at(v[idx, :2])
    base, inside = g.copy(), np.zeros(len(idx), bool)
    for i in instances[::-1]:
        b = in_box(v[idx, :2], i.center[:2], i.size[0], i.size[1], i.yaw_deg, 0.0)
        base[b], inside[b] = i.ground_z, True
    raised = (v[idx, 2] - g > 0.02) & (v[idx, 2] - base > opt.min_height_m)
    if not (raised & inside).any():
        return 0
    sub = np.full(len(v), -1)
    sub[idx[raised]] = np.arange(int(raised.sum()))
    e = sub[edges(kept, len(v))]
    e = e[(e >= 0).all(axis=1)]
    n = int(raised.sum())
    _, comp = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
    ok = np.bincount(comp, weights=~inside[raised] | (v[idx[raised], 2] - g[raised] > opt.flatten_feet_m),
                     minlength=comp.max() + 1) == 0
    low = np.nonzero(raised)[0][ok[comp]]
    v[idx[low], 2] = g[low]
    return int(len(low))


def _flatten_feet(v: np.ndarray, lp: np.ndarray, hits: list, grid: LocalGround, opt: LiftOptions) -> int:
    """The object's cut-off feet (its faces with a corner below the cut stay in the static mesh, a ridge up to
    ~0.4 m a wheel would hit): the loop's vertices inside a footprint it ``hits``, 2 cm to ``flatten_feet_m``
    above the ground, go down to the ground (in place in ``v``), which flattens those faces onto the road.
    Returns how many."""
    pts = v[lp, :2]
    gl = grid.at(pts)
    hl = v[lp, 2] - gl
    foot = np.zeros(len(lp), bool)
    for c_, l_, w_, y_ in hits:
        foot |= in_box(pts, c_, l_, w_, y_, opt.margin_m)
    foot &= (hl > 0.02) & (hl <= opt.flatten_feet_m)
    v[lp[foot], 2] = gl[foot]
    return int(foot.sum())


def _add_fill(sm: Additions, lp: np.ndarray, ring: np.ndarray, kcen: np.ndarray, faces_new: np.ndarray,
              new_pts: np.ndarray) -> None:
    """Append one loop's fill: its new vertices take the ring's majority ground class (a ring without one: the
    class of the mesh's ground vertex nearest the loop, road without any; never the class of what stood
    there, which would put the fill in that class's static mesh under the lifted object), its faces the UVs
    of the nearest ground face of the ``ring`` (kept faces at the loop; ``kcen`` their centres)."""
    from scipy.spatial import cKDTree

    v, nv = sm.v, len(sm.v)
    lab_ring = sm.labels[lp]
    gl = lab_ring[np.isin(lab_ring, GROUND)]
    if len(gl):
        ground_class = int(np.bincount(gl).argmax())
    else:
        gv = np.nonzero(np.isin(sm.labels, GROUND))[0]
        ground_class = int(sm.labels[gv[cKDTree(v[gv]).query(v[lp].mean(axis=0))[1]]]) if len(gv) else int(GROUND[0])
    if len(new_pts):
        base = nv + len(sm.add_v)
        faces_new = np.where(faces_new >= nv, faces_new - nv + base, faces_new)
        sm.add_v.extend(list(new_pts))
        sm.add_lab.extend([ground_class] * len(new_pts))
    sm.add_f.append(faces_new)
    if sm.kept_tc is not None and len(ring):
        rg = ring[np.isin(sm.labels[sm.kept[ring]], GROUND).all(axis=1)]
        rg = rg if len(rg) else ring
        cen = np.concatenate([v, np.asarray(sm.add_v).reshape(-1, 3)])[faces_new].mean(axis=1)
        _, nn = cKDTree(kcen[rg]).query(cen)
        sm.add_tc.append(sm.kept_tc[rg[nn]])
    elif sm.kept_tc is not None:
        sm.add_tc.append(np.zeros((len(faces_new), 6), np.float32))


def close_other_holes(sm: Additions, grid: LocalGround, instances: list[Instance], opt: LiftOptions,
                      rep: dict) -> None:
    """After the loops under the objects: a ground patch where a footprint is still uncovered (the hole ran
    into a scan shadow reaching the scan's edge, so no loop could be closed safely; ``patch_cell_m``), every
    other hole of the ground up to ``ground_hole_max_m`` (a crack at a kerb's foot, a notch the
    simplification or the trim left: :func:`twinkit.street.holes.close_ground_holes`), then the spots a ray at
    the ground still falls through (``gap_max_m``). Counts go to ``rep``."""
    if instances and opt.patch_cell_m > 0:
        pv, pf, plab, ptc = patch_footprints(*sm.current(), grid, instances, opt)
        sm.append(pv, pf, plab, ptc)
        rep["patch_faces"] = int(len(pf))
    if opt.ground_hole_max_m <= 0:
        return
    _close_ground_holes(sm, grid, opt, rep)
    # what no loop could close (a hole whose border climbs an object's foot or crosses itself seen from
    # above): small spots a ray at the ground falls through, with surface all round, get a patch
    cur_v, cur_f, cur_lab, cur_tc = sm.current()
    gaps = ground_gaps(cur_v, cur_f, grid, opt.gap_cell_m, opt.gap_max_m) if opt.gap_max_m > 0 else []
    rep["ground_gaps"] = len(gaps)
    if gaps:
        popt = dataclasses.replace(opt, patch_cell_m=opt.gap_cell_m, margin_m=opt.gap_cell_m)
        pv, pf, plab, ptc = patch_footprints(cur_v, cur_f, cur_lab, cur_tc, grid, gaps, popt, max_edge_m=0.3)
        sm.append(pv, pf, plab, ptc)
        rep["ground_gap_faces"] = int(len(pf))


def _close_ground_holes(sm: Additions, grid: LocalGround, opt: LiftOptions, rep: dict) -> None:
    """Every other hole of the ground, closed at its border's heights; each new vertex takes the class of the
    nearest ground vertex of the mesh (road, sidewalk, terrain), each new face the UVs of the nearest ground
    face."""
    from scipy.spatial import cKDTree

    from twinkit.street.holes import close_ground_holes

    cur_v, cur_f, cur_lab, cur_tc = sm.current()
    gv, gf, _, grep = close_ground_holes(cur_v, cur_f, grid.at, max_extent_m=opt.ground_hole_max_m,
                                         cell_m=opt.fill_cell_m or 0.1)
    if len(gf):
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
        sm.append(gv, gf, fill_lab, gtc)
    rep["ground_holes"] = grep


def covered(pts: np.ndarray, tri_xy: np.ndarray) -> np.ndarray:
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


def ground_gaps(v: np.ndarray, f: np.ndarray, grid: LocalGround, cell_m: float, max_extent_m: float) -> list:
    """Small places where a vertical ray at the ground finds no surface within 0.5 m of the ground (a wheel
    or a foot would drop in) with surface all round them: the remains of a hole whose border is no
    simple loop (it runs up an object's foot, or crosses itself seen from above). Each as a box
    (``center``, ``size``, ``yaw_deg`` 0) for :func:`patch_footprints`."""
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


#: a patch joins the surfaces and open border at most this high above the ground
PATCH_LEVEL_M = 0.5


def patch_footprints(v, f, lab, tc, grid: LocalGround, instances, opt: LiftOptions, max_edge_m: float | None = None):
    """Ground patches where a footprint is still uncovered (:func:`twinkit.street.holes.patch` of the static
    mesh's border vertices there, up to ``PATCH_LEVEL_M`` above the ground, and of ``patch_cell_m`` grid points
    at the ground height, keeping the triangles over uncovered ground inside the footprint). ``v`` (n, 3),
    ``f`` (m, 3), ``lab`` (n,), ``tc`` (m, 6) or None. Returns (new vertices, faces, their labels, face UVs)."""
    from scipy.spatial import cKDTree

    c = float(opt.patch_cell_m)
    nv = len(v)
    out_v, out_f, out_lab, out_tc = [], [], [], []
    fxy = v[f][:, :, :2]
    fcen = fxy.mean(axis=1)
    low = np.nonzero(v[f][:, :, 2].mean(axis=1) - grid.at(fcen) < PATCH_LEVEL_M)[0]  # ground-level surfaces only
    # faces near a box are looked up around its centre: a face's vertices lie within `reach` of its centre
    reach = float(np.linalg.norm(fxy[low] - fcen[low, None], axis=2).max()) if len(low) else 0.0
    low_tree = cKDTree(fcen[low]) if len(low) else None
    bv = np.unique(border_edges(f))
    bv = bv[v[bv, 2] - grid.at(v[bv, :2]) < PATCH_LEVEL_M]  # not the open border of a lamp head above the spot
    for inst in instances:
        cen, length, width, yaw = inst.center[:2], inst.size[0], inst.size[1], inst.yaw_deg
        m = opt.margin_m
        a = np.radians(yaw)
        ax_u, ax_v = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        us = np.arange(-(length / 2 + m), length / 2 + m + 1e-9, c)
        vs = np.arange(-(width / 2 + m), width / 2 + m + 1e-9, c)
        gu, gv = np.meshgrid(us, vs)
        pts = cen + gu.ravel()[:, None] * ax_u + gv.ravel()[:, None] * ax_v
        near = np.zeros(len(f), bool)
        if low_tree is not None:
            cand = low[np.sort(np.asarray(low_tree.query_ball_point(
                cen, float(np.hypot(length / 2 + m + 1.0, width / 2 + m + 1.0)) + reach + 1e-6), np.int64))]
            near[cand[in_box(fxy[cand].reshape(-1, 2), cen, length, width, yaw, m + 1.0).reshape(-1, 3).any(axis=1)]] = True
        tri_xy = fxy[near]
        unc = ~covered(pts, tri_xy)
        bnear = bv[in_box(v[bv, :2], cen, length, width, yaw, m + c)]
        if len(bnear):
            d, _ = cKDTree(v[bnear, :2]).query(pts)
            unc &= d >= 0.5 * c
        if unc.sum() < 3 and (max_edge_m is None or unc.sum() + len(bnear) < 3):
            continue
        p_new = pts[unc]

        def keep(tc2, cen=cen, length=length, width=width, yaw=yaw, m=m, tri_xy=tri_xy):
            centre = tc2.mean(axis=1)
            edge = np.max(np.linalg.norm(tc2 - np.roll(tc2, 1, axis=1), axis=2), axis=1)
            return (in_box(centre, cen, length, width, yaw, m) & (edge <= (max_edge_m or 3.0 * c))
                    & ~covered(centre, tri_xy))

        res = patch(v, bnear, p_new, grid.at(p_new), keep)
        if res is None:
            continue
        faces_new, new_v, tri_cen = res
        faces_new = np.where(faces_new >= nv, faces_new + len(out_v), faces_new)
        out_v.extend(list(new_v))
        nb = len(bnear)
        lab_ring = lab[bnear] if nb else lab[f[near].ravel()]
        gl = lab_ring[np.isin(lab_ring, GROUND)]
        cls = int(np.bincount(gl).argmax()) if len(gl) else 0
        out_lab.extend([cls] * len(new_v))
        out_f.append(faces_new)
        if tc is not None:
            gf = np.nonzero(near)[0]
            gf = gf[np.isin(lab[f[gf]], GROUND).all(axis=1)] if len(gf) else gf
            if len(gf):
                _, nn = cKDTree(fxy[gf].mean(axis=1)).query(tri_cen)
                out_tc.append(np.asarray(tc)[gf[nn]])
            else:
                out_tc.append(np.zeros((len(faces_new), 6), np.float32))
    if not out_f:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.uint8), np.zeros((0, 6), np.float32)
    return (np.asarray(out_v).reshape(-1, 3), np.vstack(out_f), np.asarray(out_lab, np.uint8),
            np.vstack(out_tc).astype(np.float32) if out_tc else np.zeros((0, 6), np.float32))


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
        near |= in_box(mid, i.center[:2], i.size[0], i.size[1], i.yaw_deg, margin_m)
    return float(np.linalg.norm(vertices[b[near, 0]] - vertices[b[near, 1]], axis=1).sum())
