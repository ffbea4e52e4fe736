"""The one hole closer on the ground (twinkit.street.holes): its modes on small generated holes."""
from __future__ import annotations

import numpy as np

from tests.mesh.meshes import grid_mesh
from twinkit.mesh import compact, face_normals
from twinkit.mesh.topology import boundary_loops
from twinkit.street import cdt, holes
from twinkit.surface.watertight import drop_test, open_edges


def _holed(size_cells=(4, 3)):
    """A 3 x 3 m ground grid (10 cm) at z = 0 with a rectangular hole of ``size_cells`` cells near its
    middle: (vertices, faces, the hole's loop)."""
    m = grid_mesh(31, size=3.0)
    c = m.vertices[m.faces].mean(axis=1)
    w, h = size_cells[0] * 0.1, size_cells[1] * 0.1
    hole = (np.abs(c[:, 0] - 1.5) < w / 2) & (np.abs(c[:, 1] - 1.5) < h / 2)
    m = compact(m, ~hole)
    loops = [lp for lp in boundary_loops(m.faces) if len(lp) < 100]
    assert len(loops) == 1
    return m.vertices.copy(), m.faces, loops[0]


def _closed(v, f, res):
    faces, new = res
    return np.vstack([v, new]), np.vstack([f, faces]), faces


def test_ground_mode_follows_the_ground_and_leaves_no_open_border():
    v, f, lp = _holed((12, 10))
    v[lp, 2] = 0.2  # the border stands 20 cm up (a car's cut-off feet)
    res = holes.close_hole(v, lp, lambda xy: np.full(len(xy), -0.05), 0.1)
    assert res is not None
    allv, allf, faces = _closed(v, f, res)
    assert len(res[1]) > 50 and np.allclose(res[1][:, 2], -0.05)
    assert (face_normals(allv, faces)[:, 2] > 0).all()  # counter-clockwise seen from above
    inner = open_edges(allf)
    assert not (np.abs(allv[inner].mean(axis=1)[:, :2] - 1.5) < 1.0).all(axis=1).any()


def test_border_mode_adds_no_vertex():
    v, f, lp = _holed()
    for res in (holes.close_hole(v, lp), holes.close_hole(v, lp, lambda xy: np.zeros(len(xy)), 0.0)):
        assert res is not None and len(res[1]) == 0 and len(res[0]) == len(lp) - 2
        allv, allf, faces = _closed(v, f, res)
        assert (face_normals(allv, faces)[:, 2] > 0).all()
        gx, gy = np.meshgrid(np.arange(1.33, 1.68, 0.05), np.arange(1.38, 1.63, 0.05))
        rays = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]  # over the 0.4 x 0.3 m hole
        assert drop_test(allv, allf, rays).all()


def test_a_loop_with_two_vertices_on_one_vertical_line_is_left_to_the_fan():
    v, f, lp = _holed()
    v[lp[1]] = [v[lp[0], 0], v[lp[0], 1], 0.25]
    assert holes.close_hole(v, lp, lambda xy: np.zeros(len(xy)), 0.1) is None
    faces, centre = holes.fan(v, lp)
    assert len(faces) == len(lp) and (faces[:, 0] == len(v)).all()
    assert np.allclose(centre[0], v[lp].mean(axis=0))
    assert not len(np.setdiff1d(open_edges(np.vstack([f, faces])), open_edges(f)))  # no new open edge


def test_only_a_hole_seen_from_above_is_one():
    v, f, lp = _holed()
    assert holes.is_hole_from_above(v, lp) and not holes.is_hole_from_above(v, lp[::-1])


def test_patch_keeps_the_selected_triangles_and_only_the_points_they_use():
    v, f, lp = _holed((6, 6))
    g = np.arange(1.225, 1.8, 0.05)
    xy = np.c_[np.repeat(g, len(g)), np.tile(g, len(g))]
    xy = xy[(np.abs(xy - 1.5) < 0.27).all(axis=1)]
    res = holes.patch(v, lp, xy, np.zeros(len(xy)), lambda t: (np.abs(t.mean(axis=1) - 1.5) < 0.3).all(axis=1))
    assert res is not None
    faces, new, cen = res
    assert len(new) == len(xy) and len(cen) == len(faces)
    allv = np.vstack([v, new])
    assert (face_normals(allv, faces)[:, 2] > 0).all()
    assert holes.patch(v, lp, xy, np.zeros(len(xy)), lambda t: np.zeros(len(t), bool)) is None


def test_grid_patch_two_triangles_per_block():
    cells = np.zeros((4, 5), bool)
    cells[1:3, 1:4] = True  # 2 x 3 cells: 2 blocks of 2 x 2
    v, f = holes.grid_patch(cells, np.full(cells.shape, 0.3), np.array([10.0, 20.0]), 0.5)
    assert len(v) == 6 and len(f) == 4 and np.allclose(v[:, 2], 0.3)
    assert np.allclose(v[:, :2].min(axis=0), [10.75, 20.75])
    assert (face_normals(v, f)[:, 2] > 0).all()


def test_close_ground_holes_closes_a_crack_and_leaves_a_hole_up_a_wall():
    v, f, lp = _holed()
    nv, nf, done, rep = holes.close_ground_holes(v, f, lambda xy: np.zeros(len(xy)))
    assert rep["closed"] == 1 and len(done) == 1
    v2 = v.copy()
    v2[:, 2] = 2.0  # the same hole, 2 m above the ground
    _, nf2, done2, rep2 = holes.close_ground_holes(v2, f, lambda xy: np.zeros(len(xy)))
    assert rep2["closed"] == 0 and len(nf2) == 0 and rep2["left_open_m"]["not_on_the_ground"] > 0


def test_span_fans_a_star_shaped_loop_and_ear_clips_another():
    a = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    hexa = np.c_[np.cos(a), np.sin(a), 0.1 * np.sin(3 * a)]  # star-shaped round its centroid
    lp = np.arange(8)[::-1]  # clockwise seen from above: a hole in an up-facing surface
    faces, new = holes.span(hexa, lp)
    assert len(new) == 1 and len(faces) == 8 and np.allclose(new[0], hexa.mean(axis=0))
    ell = np.array([[0, 0, 0], [3, 0, 0], [3, 1, 0], [1, 1, 0], [1, 3, 0], [0, 3, 0]], float)  # an L
    ell[2:4] += [0, 0, 0.2]
    lp = np.arange(6)[::-1]
    assert holes.close_hole(ell, lp, lambda xy: np.zeros(len(xy)), 0.25) is not None
    faces, new = holes.span(ell, lp)  # no point sees the whole L: ear clipping, the loop's own vertices
    assert len(new) == 0 and len(faces) == 4
    assert (face_normals(ell, faces)[:, 2] > 0).all()
    assert holes.span(ell, lp[::-1]) is None  # no hole seen from above


def test_new_faces_that_break_the_surface_are_found():
    """stitch's check of its new faces: one running an edge the same way as an old face (overlapping or flipped),
    one making an edge of three faces, and one that only closes a gap cleanly."""
    import numpy as np

    from twinkit.street.holes import _bad_new_faces

    old = np.array([[0, 1, 2], [0, 2, 3]])  # a square, its diagonal 0-2 shared
    new = np.array([[1, 4, 2],   # edge 1-2 run 2 -> 1, against the 1 -> 2 of the old face: a clean join
                    [0, 1, 5],   # runs 0 -> 1 as face 0 does: overlapping
                    [2, 0, 6]])  # a third face on the diagonal 0-2
    bad = _bad_new_faces(np.vstack([old, new]), len(old))
    assert bad.tolist() == [False, True, True]
    assert not _bad_new_faces(old, len(old)).any() and len(_bad_new_faces(old, len(old))) == 0


# border edges that pythoncdt cannot resolve, found by fuzzing ``stitch``: ends a hair apart and crossings at
# near-zero angles, where the crossing the library computes lies outside both edges ("computed split vertex is
# invalid"); a seventh edge, (10, 11), crosses nothing and is no Delaunay edge (grid point (1000.75, 1002.65)
# stands just above its middle)
_TANGLE_XY = np.array([[1000.5827912714722, 1000.2453599910612], [1000.6151315098433, 1000.3458865496199],
                       [1000.5795607682278, 1000.2107618596859], [1000.1081174241292, 1000.8169534114862],
                       [1000.4438893490255, 1000.0809471107964], [1000.4438893490245, 1000.0809471107971],
                       [1000.3918369091892, 1000.1129509991226], [1000.1225646792968, 1000.4656597562621],
                       [1000.3617859561015, 1000.466715223888], [1000.4625837718919, 1000.0988345319219],
                       [999.0, 1002.5], [1002.5, 1002.6]])
_TANGLE_EDGES = np.array([[0, 6], [1, 4], [2, 5], [3, 9], [5, 7], [8, 9], [10, 11]])


def test_stitch_leaves_unresolvable_crossing_border_edges_free_instead_of_failing(caplog):
    import pythoncdt
    import pytest

    v = np.c_[_TANGLE_XY, np.zeros(len(_TANGLE_XY))]
    gxy = np.array([[998.0, 998.0], [998.0, 1003.0], [1003.0, 998.0], [1003.0, 1003.0], [1000.75, 1002.65]])
    rep_id, e = holes._border_from_above(v, _TANGLE_EDGES)
    raw = pythoncdt.Triangulation(pythoncdt.VertexInsertionOrder.AUTO,
                                 pythoncdt.IntersectingConstraintEdges.TRY_RESOLVE, 0.0)
    raw.insert_vertices(np.ascontiguousarray(np.vstack([_TANGLE_XY[rep_id], gxy])))
    with pytest.raises(RuntimeError, match="can not be resolved"):
        raw.insert_edges(e.astype(np.uintc))  # the library alone fails on what stitch gives it
    rep: dict = {}
    with caplog.at_level("WARNING", logger="twinkit.street.holes"):
        newv, nf = holes.stitch(v, np.zeros((0, 3), np.int64), _TANGLE_EDGES, gxy, np.zeros(len(gxy)),
                                lambda cen, edge: np.ones(len(cen), bool), 1e-9, report=rep)
    assert rep["border_edges_freed"] == 2  # the pair the library names: the crossings it can resolve stay
    assert "2 of 7 border edges left free" in caplog.text
    # the five grid points and the split vertices of the crossings the library resolved
    assert len(newv) > 5 and nf.max() < len(v) + len(newv)
    # the edge in no conflict stays fixed
    edges = np.sort(np.vstack([nf[:, [0, 1]], nf[:, [1, 2]], nf[:, [2, 0]]]), axis=1)
    assert (edges == [10, 11]).all(axis=1).any()
    # a proper triangulation: every face counter-clockwise seen from above, together covering the 5 m x 5 m
    # square once (no overlap, no gap)
    p = np.vstack([v, newv])[:, :2]
    a, b, c = p[nf[:, 0]], p[nf[:, 1]], p[nf[:, 2]]
    area2 = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    assert (area2 > 0).all()
    assert abs(0.5 * area2.sum() - 25.0) < 1e-6


def test_edges_in_conflict_are_crossings_and_ends_on_another_edge_not_shared_ends():
    p = np.array([[0, 0], [2, 0], [1, -1], [1, 1], [3, 0], [2, 1], [4, -1], [5, 0], [4.5, 0.0]], float)
    e = np.array([[0, 1],   # crossed by (2, 3)
                  [2, 3],
                  [1, 4],   # shares an end with (0, 1) and (1, 5): not in conflict by that
                  [1, 5],
                  [6, 7],   # near (4, 8) but apart from it
                  [4, 8],   # collinear with (1, 4), beyond it: they meet only at the shared end 4
                  ])
    bad = cdt.edges_in_conflict(p, e)
    assert bad.tolist() == [True, True, False, False, False, False]
    # an end within the tolerance of another edge's interior (a T) is a conflict
    p2 = np.array([[0, 0], [2, 0], [1, 1e-9], [1, 1]], float)
    assert cdt.edges_in_conflict(p2, np.array([[0, 1], [2, 3]])).tolist() == [True, True]
    assert not cdt.edges_in_conflict(p2, np.array([[0, 1]])).any()


def test_when_freeing_the_named_edges_does_not_do_every_edge_in_conflict_is_freed():
    """Past its tries with the edges the library names, the fallback frees every edge that crosses or touches
    another (here 6 of the 7), then triangulates; the edge in no conflict stays fixed."""
    v = np.c_[_TANGLE_XY, np.zeros(len(_TANGLE_XY))]
    rep_id, e = holes._border_from_above(v, _TANGLE_EDGES)
    pts = np.vstack([_TANGLE_XY[rep_id], [[998.0, 998.0], [998.0, 1003.0], [1003.0, 998.0], [1003.0, 1003.0],
                                           [1000.75, 1002.65]]])
    tri, free, first = cdt.cdt_freeing(pts, e, max_tries=0)
    assert free.sum() == 6 and "can not be resolved" in first
    kept = e[~free][0]
    t = np.asarray(tri.triangles_array()["vertices"], np.int64).reshape(-1, 3)
    edges = np.sort(np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    assert (edges == np.sort(kept)).all(axis=1).any()
