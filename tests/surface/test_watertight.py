"""The ground fill joined to the mesh (no seam), the open-border measure and the drop test."""
from __future__ import annotations

import numpy as np

from tests.mesh.meshes import grid_mesh
from twinkit.mesh import compact
from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes
from twinkit.surface.watertight import Footprint, drop_test, ground_border, open_edges

BOX = (3.0, 4.0, 4.0, 6.0)  # x0, x1, y0, y1 of a parked box (a car), 1.5 m high
SHADOW = (4.0, 6.5, 4.0, 6.0)  # the ground behind it, as seen from a scanner at x < 3


def _scene():
    """Ground points every 5 cm on 10 x 10 m at z = 0, none in the box's footprint or its shadow; the box's
    sides as points with horizontal normals. The mesh: a ground grid with 13 cm spacing (not aligned with
    the 10 cm fill cells) less the faces over the box and the shadow."""
    g = np.arange(0, 10.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    p = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]

    def inside(q, r, pad=0.0):
        return (q[:, 0] > r[0] - pad) & (q[:, 0] < r[1] + pad) & (q[:, 1] > r[2] - pad) & (q[:, 1] < r[3] + pad)

    p = p[~inside(p, BOX) & ~inside(p, SHADOW)]
    n = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    side, sn = [], []
    ys = np.arange(BOX[2], BOX[3] + 1e-9, 0.05)
    xs = np.arange(BOX[0], BOX[1] + 1e-9, 0.05)
    for z in np.arange(0.3, 1.5, 0.1):  # the scanner sees the front and the two ends (the body starts 0.3 m up)
        side.append(np.c_[np.full_like(ys, BOX[0]), ys, np.full_like(ys, z)])
        sn.append(np.tile([-1.0, 0.0, 0.0], (len(ys), 1)))
        for y, ny in ((BOX[2], -1.0), (BOX[3], 1.0)):
            side.append(np.c_[xs, np.full_like(xs, y), np.full_like(xs, z)])
            sn.append(np.tile([0.0, ny, 0.0], (len(xs), 1)))
    pts = np.vstack([p] + side)
    nrm = np.vstack([n] + sn)
    mesh = grid_mesh(78, size=10.0)  # 13 cm spacing
    c = mesh.vertices[mesh.faces].mean(axis=1)
    mesh = compact(mesh, ~(inside(c, BOX, 0.05) | inside(c, SHADOW, 0.05)))
    return mesh, pts, nrm, inside


def _open_in_shadow(out, inside):
    """Open edges whose middle lies in the shadow or within 30 cm around it, away from the box (which has no
    mesh of its own in this scene, so its footprint stays open)."""
    e = open_edges(out.faces)
    mid = out.vertices[e].mean(axis=1)
    near_shadow = inside(mid, SHADOW, 0.3)
    by_box = inside(mid, BOX, 0.3)
    return e[near_shadow & ~by_box]


def test_stitched_fill_leaves_no_open_edge_in_the_shadow():
    mesh, pts, nrm, inside = _scene()
    cols = np.full((len(pts), 3), 90, np.uint8)
    before = _open_in_shadow(mesh, inside)
    assert len(before) > 50  # the shadow's border is open to begin with
    out, rep = fill_ground_holes(mesh, pts, nrm, cols, GroundFillOptions(cell_m=0.1))
    assert rep["faces_added"] > 0 and rep["border_vertices_joined"] > 20
    assert len(_open_in_shadow(out, inside)) == 0
    new = out.vertices[mesh.n_vertices:]
    assert (np.abs(new[:, 2]) < 0.01).all()  # on the ground
    # the ground runs on beneath the box (a car 1.5 m high: low enough to stand on the ground, not a building)
    assert inside(new, BOX, -0.15).sum() > 0.8 * (0.7 * 1.7) / 0.01
    plain, _ = fill_ground_holes(mesh, pts, nrm, cols, GroundFillOptions(cell_m=0.1, under_objects=False))
    assert not inside(plain.vertices[mesh.n_vertices:], BOX, -0.15).any()  # without: the box blocks, no fill
    # the fill joins the mesh's own border vertices: every edge is used by at most two faces, consistently
    e = np.sort(np.stack([out.faces[:, [0, 1]], out.faces[:, [1, 2]], out.faces[:, [2, 0]]], 1).reshape(-1, 2), 1)
    _, cnt = np.unique(e, axis=0, return_counts=True)
    assert cnt.max() <= 2
    # the separate grid patches of before leave a seam all around the shadow
    old, _ = fill_ground_holes(mesh, pts, nrm, cols, GroundFillOptions(cell_m=0.1, stitch=False))
    assert len(_open_in_shadow(old, inside)) > 50


def test_ground_border_splits_inside_from_site_edge():
    mesh, pts, nrm, inside = _scene()
    fp = Footprint.from_points(pts, fill_limit_m=8.0)
    gv = np.ones(mesh.n_vertices, bool)
    rep = ground_border(mesh.vertices, mesh.faces, fp, gv)
    # inside: the box footprint and the shadow, one 3.5 x 2 m hole (11 m around, up to twice that along the
    # triangles' saw-tooth edge); the square's own edge (40 m) is the site's edge
    assert 11.0 < rep["inside_m"] < 26.0
    assert 38.0 < rep["site_edge_m"] < 42.0
    assert rep["inside_chains"] == 1
    out, _ = fill_ground_holes(mesh, pts, nrm, np.zeros((len(pts), 3), np.uint8), GroundFillOptions(cell_m=0.1))
    after = ground_border(out.vertices, out.faces, fp, np.ones(out.n_vertices, bool))
    assert after["inside_m"] < 0.6 * rep["inside_m"]  # only the box footprint's border is left
    assert abs(after["site_edge_m"] - rep["site_edge_m"]) < 1.0


def _lane_samples(x0, x1, y0, y1, z=0.0, step=0.1):
    xs = np.arange(x0 + step / 2, x1, step)
    ys = np.arange(y0 + step / 2, y1, step)
    X, Y = np.meshgrid(xs, ys)
    return np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]


def test_drop_test_finds_a_30cm_hole_in_a_lane_and_passes_once_filled():
    ground = grid_mesh(101, size=10.0)  # 10 cm spacing
    lane = _lane_samples(0.0, 10.0, 3.0, 6.5)
    assert drop_test(ground.vertices, ground.faces, lane).all()
    c = ground.vertices[ground.faces].mean(axis=1)
    hole = (np.abs(c[:, 0] - 5.0) < 0.15) & (np.abs(c[:, 1] - 4.5) < 0.15)
    holed = compact(ground, ~hole)
    hit = drop_test(holed.vertices, holed.faces, lane)
    assert 4 <= (~hit).sum() <= 16  # a 30 x 30 cm hole on a 10 cm grid of rays
    miss = lane[~hit]
    assert (np.abs(miss[:, 0] - 5.0) < 0.2).all() and (np.abs(miss[:, 1] - 4.5) < 0.2).all()
    # a lane 8 cm above the surface is not "on" it (5 cm tolerance)
    assert not drop_test(ground.vertices, ground.faces, lane + [0, 0, 0.08]).any()
    # filled by the ground fill (ground points all around it, none in it)
    g = np.arange(0, 10.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    p = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    p = p[~((np.abs(p[:, 0] - 5.0) < 0.15) & (np.abs(p[:, 1] - 4.5) < 0.15))]
    out, rep = fill_ground_holes(holed, p, np.tile([0.0, 0.0, 1.0], (len(p), 1)), None,
                                 GroundFillOptions(cell_m=0.1))
    assert rep["faces_added"] > 0
    assert drop_test(out.vertices, out.faces, lane).all()


def test_hole_under_a_lifted_object_is_closed_on_the_ground():
    from twinkit.mesh.topology import boundary_loops
    from twinkit.street.holes import close_hole, fan

    ground = grid_mesh(61, size=6.0)  # 10 cm spacing
    c = ground.vertices[ground.faces].mean(axis=1)
    car = (c[:, 0] > 1.5) & (c[:, 0] < 4.5) & (c[:, 1] > 2.0) & (c[:, 1] < 4.0)
    m = compact(ground, ~car)
    # the feet of the car's walls stay behind along one side: its border stands 0.1-0.3 m above the road
    v = m.vertices.copy()
    feet = (np.abs(v[:, 1] - 2.0) < 0.06) & (v[:, 0] > 1.5) & (v[:, 0] < 4.5)
    v[feet, 2] = 0.1 + 0.2 * (v[feet, 0] - 1.5) / 3.0
    loops = [lp for lp in boundary_loops(m.faces) if len(lp) < 200]
    assert len(loops) == 1
    res = close_hole(v, loops[0], lambda xy: np.zeros(len(xy)), 0.1)
    assert res is not None
    faces, new = res
    assert len(new) > 400 and np.allclose(new[:, 2], 0.0)  # 3 x 2 m of ground points
    allf = np.vstack([m.faces, faces])
    allv = np.vstack([v, new])
    inner = open_edges(allf)
    assert not (np.abs(allv[inner].mean(axis=1)[:, :2] - [3.0, 3.0]) < [2.0, 1.5]).all(axis=1).any()
    # upward faces, and the lane under the car finds the road away from the raised border
    from twinkit.mesh import face_normals

    assert (face_normals(allv, faces)[:, 2] > 0).all()
    lane = _lane_samples(1.8, 4.2, 2.3, 3.7)
    assert drop_test(allv, allf, lane).all()
    # the fan of before spans the hole at the border's heights: the same lane misses along the raised side
    ff, centre = fan(v, loops[0])
    assert not drop_test(np.vstack([v, centre]), np.vstack([m.faces, ff]), lane).all()


def test_border_picture_splats_the_highest_surface_over_each_pixel():
    """draw_border's compiled splat paints each pixel with its highest point within one pixel (3 x 3), ground light
    and the rest dark, in one pass: a roof point over a ground point wins wherever their splats overlap, and a
    point outside the picture paints nothing."""
    from twinkit.surface.compiled import compiled
    from twinkit.surface.watertight import _splat_highest

    splat = compiled(_splat_highest)
    if splat is None:
        import pytest

        pytest.skip("numba is not installed: draw_border runs its numpy splats")
    arr = np.full((6, 8, 3), 255, np.uint8)
    q = np.array([[2, 2], [3, 2], [7, 5], [20, 20]])
    z = np.array([0.0, 3.0, 0.0, 9.0])
    ground = np.array([True, False, True, False])
    light, dark = np.array([222, 222, 222], np.uint8), np.array([170, 170, 180], np.uint8)
    splat(arr, q, z, ground, light, dark)
    assert (arr[2, 2] == dark).all() and (arr[1, 4] == dark).all()  # the roof's splat covers the ground's
    assert (arr[2, 1] == light).all()  # only the ground point reaches here
    assert (arr[5, 7] == light).all() and (arr[4, 6] == light).all()  # a corner point's splat, clipped
    assert (arr[0, 0] == 255).all() and (arr[5, 0] == 255).all()  # nothing there


def test_open_ground_is_what_reaches_the_scans_edge_or_no_hole_fill_spans():
    """On a 30 x 30 m ground: a 1 m hole (a car's shadow: the lift closes it), a 12 m hole (wider than the
    8 m a hole fill spans), a 2 m band from the west edge (a sweep's far range between rings) and a slit 0.2 m
    wide joining the 1 m hole to the band (a crack along a ring: it must not open the hole to the outside).
    Only the band and the wide hole are ground the scan never measured."""
    from twinkit.surface.watertight import OpenGround

    m = grid_mesh(121, size=30.0)
    c = m.vertices[m.faces].mean(axis=1)
    small = (np.abs(c[:, 0] - 20.0) < 0.5) & (np.abs(c[:, 1] - 20.0) < 0.5)
    wide = (np.abs(c[:, 0] - 15.0) < 6.0) & (np.abs(c[:, 1] - 7.0) < 2.5)
    band = (c[:, 0] < 10.0) & (np.abs(c[:, 1] - 20.0) < 1.0)
    slit = (c[:, 0] >= 10.0) & (c[:, 0] < 20.0) & (np.abs(c[:, 1] - 20.0) < 0.1)
    kept = m.faces[~(small | wide | band | slit)]
    og = OpenGround.of_mesh(m.vertices, kept, open_gap_m=8.0)
    pts = np.array([[20.0, 20.0], [15.0, 7.0], [4.0, 20.0], [25.0, 25.0], [5.0, 5.0], [-5.0, 0.0], [15.0, 20.0]])
    assert og.at(pts).tolist() == [False, True, True, False, False, True, False]
    assert not OpenGround.of_mesh(m.vertices, kept, open_gap_m=15.0).at(pts[1:2]).any()  # a fill spans 15 m
