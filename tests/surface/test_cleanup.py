"""The shared surface clean-up, simplification and ground fill (twinkit.surface) on small meshes made by code."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.mesh import Mesh, boundary_loops, edge_face_incidence
from twinkit.surface import cleanup as C

from tests.mesh.meshes import grid_mesh


def test_distance_trim_removes_bubbles():
    m = grid_mesh(30)
    bubble = grid_mesh(5, size=0.2, z=0.5)  # a surface half a metre above the cloud
    faces = np.vstack([m.faces, bubble.faces + m.n_vertices])
    mesh = Mesh(np.vstack([m.vertices, bubble.vertices]), faces,
                attrs={"colors": np.vstack([m.colors, bubble.colors])})
    points = m.vertices + np.random.default_rng(0).normal(0, 0.001, m.vertices.shape)
    out, rep = C.clean_mesh(mesh, points, C.CleanOptions(max_dist_m=0.05, min_component_faces=1))
    assert out.vertices[:, 2].max() < 0.01
    assert out.n_faces == m.n_faces
    assert out.attrs["dist_to_cloud_m"].max() < 0.01


def test_loose_region_trimmed_loosely_and_its_exact_verdict_reported():
    m = grid_mesh(30)  # 1 x 1 m; the cloud covers only x < 0.5
    pts = m.vertices[m.vertices[:, 0] < 0.5]
    loose = lambda V: V[:, 1] > 0.7  # noqa: E731
    opt = C.CleanOptions(max_dist_m=0.05, min_component_faces=1, max_hole_edges=0, loose_dist_m=1.0)
    out, rep = C.clean_mesh(m, pts, opt, loose=loose)
    X = out.vertices
    assert X[X[:, 1] <= 0.7, 0].max() < 0.55  # trimmed exactly outside the loose region ...
    assert X[X[:, 1] > 0.7, 0].max() == pytest.approx(1.0)  # ... and only beyond 1 m in it
    s = rep["loose_samples"]
    assert len(s["points"]) == int(loose(m.vertices).sum()) == len(s["keep"]) == len(s["normals"])
    np.testing.assert_allclose(np.abs(s["normals"][:, 2]), 1.0, atol=1e-5)  # the flat grid's normal
    # the verdict the exact rule would have given there: keep where the cloud is, drop elsewhere
    assert np.array_equal(s["keep"], s["points"][:, 0] < 0.5 + 0.05)
    _, rep2 = C.clean_mesh(m, pts, C.CleanOptions(max_dist_m=0.05, min_component_faces=1))
    assert "loose_samples" not in rep2


def test_small_components_removed():
    m = grid_mesh(20)
    small = grid_mesh(3, size=0.05)
    small.vertices[:, 0] += 2.0
    mesh = Mesh(np.vstack([m.vertices, small.vertices]), np.vstack([m.faces, small.faces + m.n_vertices]))
    out, n, kept = C.keep_large_components(mesh, min_faces=50)
    assert n == 2 and kept == 1 and out.n_faces == m.n_faces


def test_non_manifold_edge_repaired():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0.2, 0.5]], float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # edge 0-1 shared by three faces; face 2 is smallest
    out, removed = C.repair_non_manifold_edges(Mesh(v, f))
    assert removed == 1 and out.n_faces == 2
    _, _, counts = edge_face_incidence(out.faces)
    assert counts.max() <= 2


def test_small_holes_closed_large_boundary_kept():
    m = grid_mesh(20)
    # cut a hole: remove the two faces of one interior quad and the ones around it
    centre = np.array([0.5, 0.5])
    cen = m.vertices[m.faces].mean(axis=1)[:, :2]
    keep = np.linalg.norm(cen - centre, axis=1) > 0.08
    holed = Mesh(m.vertices, m.faces[keep], attrs=dict(m.attrs))
    loops_before = boundary_loops(holed.faces)
    assert len(loops_before) == 2
    out, closed = C.close_small_holes(holed, max_edges=30)
    assert closed == 1
    assert len(boundary_loops(out.faces)) == 1  # the outer border stays open
    assert out.colors is not None and len(out.colors) == out.n_vertices
    # consistent orientation: all normals still up
    from twinkit.mesh import face_normals

    assert (face_normals(out.vertices, out.faces)[:, 2] > 0.99).all()


def test_quadric_simplify_keeps_border_and_clustering_fallback():
    from twinkit.surface.simplify import simplify_mesh

    m = grid_mesh(80)
    m.vertices[:, 2] = 0.05 * np.sin(6 * m.vertices[:, 0])
    s, method = simplify_mesh(m, 2000, method="auto")
    assert method == "quadric" and s.n_faces <= 2000
    assert np.allclose(s.vertices[:, :2].min(axis=0), 0) and np.allclose(s.vertices[:, :2].max(axis=0), 1)
    assert s.colors is not None and (s.colors == 100).all()
    s2, method2 = simplify_mesh(m, 2000, method="auto", cluster_above_faces=5000)
    assert method2 == "clustering" and s2.n_faces <= 2400


def test_gap_rule_keeps_plane_between_sparse_scan_lines():
    """Far-range ground: scan lines 0.8 m apart, 2 cm apart along each line. Poisson's surface
    between the lines is on the ground plane (kept with the gap rule, cut by the plain distance
    trim); a flap 0.3 m above the ground is off the plane and goes either way."""
    ground = grid_mesh(81, size=4.0)  # 5 cm grid over 4 x 4 m
    flap = grid_mesh(9, size=0.4, z=0.3)
    flap.vertices[:, :2] += 1.8
    m = Mesh(np.vstack([ground.vertices, flap.vertices]),
             np.vstack([ground.faces, flap.faces + ground.n_vertices]))
    xs = np.arange(0, 4.0001, 0.02)
    pts = np.vstack([np.c_[xs, np.full_like(xs, y), np.zeros_like(xs)] for y in np.arange(0, 4.0001, 0.8)])
    nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    opt = dict(max_dist_m=0.10, min_component_faces=1, max_hole_edges=0, repair_non_manifold=False)
    plain, _ = C.clean_mesh(m, pts, C.CleanOptions(**opt), normals=nrm)
    gap, rep = C.clean_mesh(m, pts, C.CleanOptions(gap_dist_m=0.5, gap_plane_m=0.02, **opt), normals=nrm)
    assert rep["distance_trim"]["kept_on_plane"] > 0
    assert (np.abs(plain.vertices[:, 2]) < 1e-9).mean() == 1.0  # flap gone
    assert (np.abs(gap.vertices[:, 2]) < 1e-9).mean() == 1.0  # flap gone with the gap rule too
    # plain trim keeps only 10 cm strips around the lines; the gap rule keeps the whole ground
    assert plain.n_faces < 0.4 * ground.n_faces
    assert gap.n_faces == ground.n_faces
    # without normals the gap rule is off (same as plain)
    nonorm, _ = C.clean_mesh(m, pts, C.CleanOptions(gap_dist_m=0.5, **opt))
    assert nonorm.n_faces == plain.n_faces


def test_vertex_plane_distance():
    pts = np.c_[np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)]
    nrm = np.tile([0.0, 0.0, 1.0], (50, 1))
    v = np.array([[0.5, 0.3, 0.0], [0.5, 0.3, 0.2], [0.5, 3.0, 0.0]])
    d = C.vertex_plane_distance(v, pts, nrm, k=4, max_dist_m=1.0)
    assert d[0] < 1e-6 and abs(d[1] - 0.2) < 1e-6 and np.isinf(d[2])


def _ground_scene():
    """Ground points (5 cm) on 12 x 12 m at z = 0 with (a) a 2 x 2 m shadow at x, y in [2, 4] with no
    points and (b) a 3 x 3 m building at x, y in [7, 10]: walls (horizontal normals, 3 m high), no
    ground inside."""
    g = np.arange(0, 12.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    p = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    shadow = (p[:, 0] > 2) & (p[:, 0] < 4) & (p[:, 1] > 2) & (p[:, 1] < 4)
    inside = (p[:, 0] >= 7) & (p[:, 0] <= 10) & (p[:, 1] >= 7) & (p[:, 1] <= 10)
    p = p[~shadow & ~inside]
    n = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    walls, wn = [], []
    s = np.arange(7, 10.0001, 0.05)
    for z in np.arange(0.05, 3.0, 0.1):
        for xy, nn in (((s, np.full_like(s, 7.0)), (0, -1)), ((s, np.full_like(s, 10.0)), (0, 1)),
                       ((np.full_like(s, 7.0), s), (-1, 0)), ((np.full_like(s, 10.0), s), (1, 0))):
            walls.append(np.c_[xy[0], xy[1], np.full_like(s, z)])
            wn.append(np.tile([nn[0], nn[1], 0.0], (len(s), 1)))
    return np.vstack([p] + walls), np.vstack([n] + wn)


def test_ground_fill_fills_shadow_not_building():
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes

    pts, nrm = _ground_scene()
    mesh = grid_mesh(121, size=12.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    gone = ((c[:, 0] > 2) & (c[:, 0] < 4) & (c[:, 1] > 2) & (c[:, 1] < 4)) | (
        (c[:, 0] > 7) & (c[:, 0] < 10) & (c[:, 1] > 7) & (c[:, 1] < 10))
    from twinkit.mesh import compact

    mesh = compact(mesh, ~gone)
    cols = np.full((len(pts), 3), 77, np.uint8)
    out, rep = fill_ground_holes(mesh, pts, nrm, cols, GroundFillOptions(cell_m=0.1))
    new = out.vertices[mesh.n_vertices:]
    assert 2.5 < rep["area_m2"] < 4.5  # the 2 x 2 m shadow (cells touching its border included)
    assert (np.abs(new[:, 2]) < 0.01).all()  # on the ground plane
    assert ((new[:, 0] > 1.8) & (new[:, 0] < 4.2) & (new[:, 1] > 1.8) & (new[:, 1] < 4.2)).all()  # nowhere else
    assert (out.colors[mesh.n_vertices:] == 77).all()
    # through clean_mesh (off by default there, on with fill_ground_cell_m)
    plain, rep0 = C.clean_mesh(mesh, pts, C.CleanOptions(max_dist_m=0, max_hole_edges=0), normals=nrm)
    filled, rep1 = C.clean_mesh(mesh, pts, C.CleanOptions(max_dist_m=0, max_hole_edges=0, fill_ground_cell_m=0.1),
                                normals=nrm)
    assert "ground_fill" not in rep0 and rep1["ground_fill"]["faces_added"] > 0
    assert filled.n_faces > plain.n_faces


def test_ground_fill_heights_carry_no_streak_from_one_high_ground_cell():
    """Each filled cell's height is interpolated along its row and its column: one ground cell at the shadow's
    edge 8 cm high (its points a noise layer) raised its whole row across the shadow, a streak one cell wide
    that fails the drop test's continuity (sweeps: 27-49 % of the discontinuous rays on the clean mesh). The
    fill's heights are the median of the cells around; a kerb's step would stay."""
    from twinkit.mesh import compact
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes

    pts, nrm = _ground_scene()
    high = (pts[:, 0] > 1.93) & (pts[:, 0] < 2.01) & (pts[:, 1] > 2.93) & (pts[:, 1] < 3.09) & (pts[:, 2] < 0.01)
    pts = pts.copy()
    pts[high, 2] = 0.08
    mesh = grid_mesh(121, size=12.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    mesh = compact(mesh, ~((c[:, 0] > 2) & (c[:, 0] < 4) & (c[:, 1] > 2) & (c[:, 1] < 4)))
    tops = {}
    for size in (0, 5):
        out, _ = fill_ground_holes(mesh, pts, nrm, None, GroundFillOptions(cell_m=0.1, smooth_cells=size))
        new = out.vertices[mesh.n_vertices:]
        inner = (new[:, 0] > 2.3) & (new[:, 0] < 3.7) & (new[:, 1] > 2.3) & (new[:, 1] < 3.7)
        tops[size] = float(new[inner, 2].max())
    assert tops[0] > 0.02, tops  # the streak: the row through the high cell, across the shadow
    assert tops[5] < 0.005, tops


def _two_levels(rise_m: float):
    """Up-facing points on 14 x 6 m: z = 0 for x <= 4, z = ``rise_m`` for x >= 9, nothing in between (5 m);
    the mesh the same without faces over the gap."""
    g = np.arange(0, 14.0001, 0.05)
    X, Y = np.meshgrid(g, np.arange(0, 6.0001, 0.05))
    p = np.c_[X.ravel(), Y.ravel(), np.where(X.ravel() >= 9, rise_m, 0.0)]
    p = p[(p[:, 0] <= 4) | (p[:, 0] >= 9)]
    mesh = grid_mesh(141, size=14.0)
    mesh.vertices[:, 2] = np.where(mesh.vertices[:, 0] >= 9 - 1e-9, rise_m, 0.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    from twinkit.mesh import compact

    mesh = compact(mesh, ((c[:, 0] < 4) | (c[:, 0] > 9)) & (c[:, 1] < 6))
    return mesh, p, np.tile([0.0, 0.0, 1.0], (len(p), 1))


def test_ground_fill_does_not_ramp_between_ground_at_different_levels():
    """A shadow in the ground joins two sides no more than a kerb step plus a street's steepest slope over
    the gap apart (0.3 m + 0.15 x 5 m here). On a photo walk a hedge's top or a car roof with no lower ground
    within the local window counts as ground; the fill ramped 1.6 m up to it and covered a third of a
    held-out photo with a sheet textured from other photos."""
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes

    for rise, fills in ((0.5, True), (1.5, False)):
        mesh, pts, nrm = _two_levels(rise)
        out, rep = fill_ground_holes(mesh, pts, nrm, None, GroundFillOptions(cell_m=0.1))
        new = out.vertices[mesh.n_vertices:]
        gap = (new[:, 0] > 4.3) & (new[:, 0] < 8.7)
        assert gap.any() == fills, (rise, rep)
        if fills:  # the ramp between the two levels
            assert rep["hole_cells"] > 1500 and new[gap, 2].min() >= 0 and new[gap, 2].max() <= rise


def test_pin_holes_after_simplification_are_closed():
    from twinkit.surface.simplify import close_collapse_holes

    m = grid_mesh(30)
    c = m.vertices[m.faces].mean(axis=1)
    # two pin-holes (one face, two faces) like those edge collapses leave, and a 12 x 12 cell hole
    drop = np.zeros(m.n_faces, bool)
    drop[np.argmin(np.linalg.norm(c[:, :2] - [0.2, 0.2], axis=1))] = True
    drop[np.argsort(np.linalg.norm(c[:, :2] - [0.7, 0.3], axis=1))[:2]] = True
    drop |= (np.abs(c[:, 0] - 0.5) < 0.2) & (np.abs(c[:, 1] - 0.75) < 0.2)
    holed = Mesh(m.vertices, m.faces[~drop])
    loops = [len(lp) for lp in boundary_loops(holed.faces)]
    out, closed = close_collapse_holes(holed, max_edges=12)
    assert closed == 2
    left = sorted(len(lp) for lp in boundary_loops(out.faces))
    assert left == sorted(n for n in loops if n > 12)  # the outer border and the big hole stay open


def _box(lo, hi):
    """A closed box (8 vertices, 12 faces facing out) from corner ``lo`` to ``hi``."""
    v = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for k in (0, 1) for j in (0, 1) for i in (0, 1)],
                 float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3],
                  [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], np.int64)
    return v, f


def test_ground_fill_runs_over_a_thin_shell_on_the_ground_instead_of_stopping_short_of_it():
    """A lone scan line on ground the trim removed around it keeps Poisson's closed skin (2-3 cm thick, a few cm
    wide): the fill saw its top as surface and its outline as no open border to join, stopped short of it on
    every side, and left a slit along it that a wheel falls through (the sweeps: 531 such shells on
    seq00_000000; 844 -> 277 driving-lane rays failing on its clean mesh once they go). A thin shell on the
    ground is taken out and the fill runs over it; a kerb stone's block (0.25 m) and a thin panel 1.5 m up
    stay."""
    from twinkit.mesh import compact
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes
    from twinkit.surface.watertight import drop_test

    pts, nrm = _ground_scene()  # ground points everywhere outside the shadow and the building
    mesh = grid_mesh(121, size=12.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    mesh = compact(mesh, ~((c[:, 0] > 1) & (c[:, 0] < 6) & (c[:, 1] > 5) & (c[:, 1] < 6)))  # a 5 x 1 m cut
    parts = [(mesh.vertices, mesh.faces)]
    for lo, hi in (((1.5, 5.47, -0.01), (3.0, 5.53, 0.02)),  # the skin around a scan line: 3 cm thick
                   ((3.5, 5.4, 0.0), (4.2, 5.6, 0.25)),  # a kerb stone
                   ((4.6, 5.3, 1.5), (5.6, 5.7, 1.53))):  # a panel overhead
        parts.append(_box(np.array(lo), np.array(hi)))
    v = np.vstack([p[0] for p in parts])
    f = np.vstack([p[1] + sum(len(q[0]) for q in parts[:i]) for i, p in enumerate(parts)])
    shelled = Mesh(v, f)
    xs, ys = np.meshgrid(np.arange(1.52, 2.98, 0.02), np.arange(5.41, 5.6, 0.02))  # along the skin and beside it
    rays = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    hit = {}
    for thick in (0.0, 0.1):
        out, rep = fill_ground_holes(shelled, pts, nrm, None, GroundFillOptions(cell_m=0.1, sliver_max_m=thick))
        hit[thick] = drop_test(out.vertices, out.faces, rays, 0.05)
        if thick:
            assert rep["slivers_removed"] == {"components": 1, "faces": 12}
            kept = out.vertices[out.faces].mean(axis=1)
            assert ((kept[:, 2] > 0.2) & (kept[:, 2] < 0.26)).sum() >= 2  # the kerb stone's top
            assert (kept[:, 2] > 1.49).sum() == 12  # the panel
    assert hit[0.0].mean() < 0.9, hit[0.0].mean()  # the slit beside the skin
    assert hit[0.1].all(), hit[0.1].mean()


def test_ground_beneath_objects_is_filled_in_passes_like_the_shadows():
    """The ground beneath objects is filled row by row and column by column between ground cells, like the
    shadows; it took one pass where the shadows take three. A band whose rows end at the scan's edge on one side
    (a sweep's far range: seq00_000001, 2 x 6 m under a road, 532 of its failing driving-lane rays) lies between
    ground filled beneath objects north and south of it, which counted as ground only for the shadows: the band
    stayed open. Now the cells filled beneath objects count as ground in the next pass too."""
    from twinkit.mesh import compact
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes
    from twinkit.surface.watertight import drop_test

    g = np.arange(0, 10.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    p = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    band = (p[:, 1] > 3.9) & (p[:, 1] < 6.1)
    ground = p[((p[:, 0] <= 1) & ~band) | (p[:, 0] >= 8)]  # no ground west of the band: the scan's edge
    fy = np.arange(0, 10.0001, 0.05)
    fence = np.vstack([np.c_[np.full_like(fy, x), fy, np.full_like(fy, z)]  # a low fence across every row
                       for x in (3.0, 3.1) for z in np.arange(0.3, 0.9, 0.1)])
    wx = np.arange(0, 1.0001, 0.05)  # a house's wall closes the band's west end on its north side
    wall = np.vstack([np.c_[wx, np.full_like(wx, 3.95), np.full_like(wx, z)] for z in np.arange(0.3, 3.6, 0.1)])
    pts = np.vstack([ground, fence, wall])
    nrm = np.vstack([np.tile([0.0, 0.0, 1.0], (len(ground), 1)), np.tile([1.0, 0.0, 0.0], (len(fence), 1)),
                     np.tile([0.0, 1.0, 0.0], (len(wall), 1))])
    mesh = grid_mesh(101, size=10.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    mesh = compact(mesh, ((c[:, 0] < 1) & ((c[:, 1] < 3.9) | (c[:, 1] > 6.1))) | (c[:, 0] > 8))
    xs, ys = np.meshgrid(np.arange(4.0, 7.0, 0.1), np.arange(4.3, 5.8, 0.1))
    rays = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    hit = {}
    for passes in (1, 3):
        out, rep = fill_ground_holes(mesh, pts, nrm, None, GroundFillOptions(cell_m=0.1, passes=passes,
                                                                             diagonal_gap_m=0.0))
        hit[passes] = drop_test(out.vertices, out.faces, rays, 0.05)
        north = drop_test(out.vertices, out.faces, rays + [0.0, 3.0, 0.0], 0.05)
        assert north.all(), (passes, rep)  # beneath the fence where ground lies on both sides: either way
    assert not hit[1].any(), hit[1].mean()
    assert hit[3].all(), hit[3].mean()


def test_ground_fill_reaches_past_a_staircase_along_the_diagonals():
    """Where the ground's edge runs askew to the grid (a sweep's far range), a fill along rows and columns only
    stops at a staircase: a cell in a step's notch has ground on one side of its row and of its column, nothing on
    the other. A lane along that edge fell through the notches (spvnas_sample_000000: 206 of its 300 failing
    driving-lane rays). Along the diagonals the notch lies between two steps: filled, up to the line through the
    steps' corners and never beyond it."""
    from twinkit.mesh import compact
    from twinkit.surface.groundfill import GroundFillOptions, fill_ground_holes
    from twinkit.surface.watertight import drop_test

    g = np.arange(0, 12.0001, 0.05)
    X, Y = np.meshgrid(g, g)
    step = 1.6  # the staircase: ground where (x // step + y // step) * step < 8 m, its edge running at -45 deg
    inside = (np.floor(X / step) + np.floor(Y / step)) * step < 8.0 - 1e-9
    p = np.c_[X[inside], Y[inside], np.zeros(inside.sum())]
    nrm = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    mesh = grid_mesh(121, size=12.0)
    c = mesh.vertices[mesh.faces].mean(axis=1)
    mesh = compact(mesh, (np.floor(c[:, 0] / step) + np.floor(c[:, 1] / step)) * step < 8.0 - 1e-9)
    # rays in the notches: just outside each step's corner, inside the line through the outer corners
    corners = [(i * step, (5 - i) * step) for i in range(1, 5)]
    notch = np.array([[x + 0.3, y + 0.3, 0.0] for x, y in corners] + [[x + 0.5, y + 0.2, 0.0] for x, y in corners])
    beyond = np.array([[x + 1.2, y + 1.2, 0.0] for x, y in corners])  # past the line through the corners
    hit = {}
    for gap in (0.0, GroundFillOptions().diagonal_gap_m):  # off, the default
        out, rep = fill_ground_holes(mesh, p, nrm, None, GroundFillOptions(cell_m=0.1, diagonal_gap_m=gap))
        hit[gap] = drop_test(out.vertices, out.faces, notch, 0.05)
        assert not drop_test(out.vertices, out.faces, beyond, 0.05).any(), (gap, rep)
        assert (rep["diagonal_cells"] > 0) == (gap > 0), rep
    assert not hit[0.0].any(), hit[0.0]
    assert hit[GroundFillOptions().diagonal_gap_m].all(), hit
