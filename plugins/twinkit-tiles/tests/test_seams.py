"""Cut, stitch and merge on analytic meshes and on a real (open3d Poisson) synthetic street block."""
from __future__ import annotations

import numpy as np
import pytest

from twinkit.mesh import Mesh, face_areas

from twinkit_tiles.cut import cut_halfspace, cut_to_box
from twinkit_tiles.edges import boundary_half_edges, edge_counts, seam_planes
from twinkit_tiles.seam_stats import faces_outside_core, seam_boundary_edges
from twinkit_tiles.stitch import close_seam_holes, merge_grid, plane_chains, stitch


def grid_mesh(x0, x1, y0, y1, step, z=lambda x, y: 0.1 * np.sin(x) * np.cos(y), jitter=0.0, seed=0):
    """A height-field triangulation (counter-clockwise seen from above), optionally jittered in xy."""
    xs = np.arange(x0, x1 + step / 2, step)
    ys = np.arange(y0, y1 + step / 2, step)
    X, Y = np.meshgrid(xs, ys)
    if jitter:
        rng = np.random.default_rng(seed)
        X = X + rng.uniform(-jitter, jitter, X.shape)
        Y = Y + rng.uniform(-jitter, jitter, Y.shape)
    V = np.stack([X.ravel(), Y.ravel(), z(X.ravel(), Y.ravel())], axis=1)
    nx = len(xs)
    F = []
    for j in range(len(ys) - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i
            F += [(a, b, c), (a, c, d)]
    col = np.full((len(V), 3), 200, np.uint8)
    return Mesh(vertices=V, faces=np.asarray(F, np.int64), attrs={"colors": col, "density": V[:, 2].astype(np.float32)})


def test_cut_puts_border_exactly_on_plane_and_keeps_area():
    m = grid_mesh(0, 4, 0, 3, 0.37, jitter=0.1)
    lo = cut_halfspace(m, 0, 1.913, "below")
    hi = cut_halfspace(m, 0, 1.913, "above")
    assert lo.vertices[:, 0].max() == 1.913 and hi.vertices[:, 0].min() == 1.913
    area = face_areas(m.vertices, m.faces).sum()
    assert abs(face_areas(lo.vertices, lo.faces).sum() + face_areas(hi.vertices, hi.faces).sum() - area) < 1e-9
    # both halves' borders on the plane are the same polyline, traversed in opposite directions
    ca, cb = plane_chains(lo, 0, 1.913), plane_chains(hi, 0, 1.913)
    assert len(ca) == 1 and len(cb) == 1
    np.testing.assert_allclose(lo.vertices[ca[0]], hi.vertices[cb[0][::-1]], atol=1e-12)
    assert set(lo.attrs) == {"colors", "density"} and len(lo.attrs["density"]) == lo.n_vertices


def test_cut_to_box_leaves_outer_sides_alone():
    m = grid_mesh(0, 4, 0, 4, 0.5)
    c = cut_to_box(m, [1.25, None, None, 2.75])
    assert c.vertices[:, 0].min() == 1.25 and c.vertices[:, 1].max() == 2.75
    assert c.vertices[:, 0].max() == 4.0 and c.vertices[:, 1].min() == 0.0


def test_stitch_closes_the_seam_between_different_triangulations():
    a = cut_halfspace(grid_mesh(0, 3.2, 0, 3, 0.2, jitter=0.05, seed=1), 0, 2.0, "below")
    b = cut_halfspace(grid_mesh(1.0, 4, 0, 3, 0.27, jitter=0.05, seed=2), 0, 2.0, "above")
    before = edge_counts(np.vstack([a.faces, b.faces + a.n_vertices]))
    m, st = stitch(a, b, 0, 2.0, max_gap_m=0.5)
    assert st.pairs == 1 and st.stitched_faces > 0
    assert seam_boundary_edges(m, [(0, 2.0)]) == 2  # only the two strip ends on the outer border (y=0, y=3)
    ec = edge_counts(m.faces)
    assert ec["non_manifold_edges"] == 0
    assert ec["boundary_edges"] < before["boundary_edges"]
    # consistent orientation: every interior edge is used once in each direction
    he = np.stack([m.faces[:, [0, 1]], m.faces[:, [1, 2]], m.faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    assert len(np.unique(he, axis=0)) == len(he)


def test_stitch_leaves_far_apart_borders_open():
    a = cut_halfspace(grid_mesh(0, 3, 0, 3, 0.2), 0, 1.5, "below")
    b = cut_halfspace(grid_mesh(0, 3, 0, 3, 0.2, z=lambda x, y: 1.0 + 0 * x), 0, 1.5, "above")  # 1 m higher
    m, st = stitch(a, b, 0, 1.5, max_gap_m=0.1)
    assert st.pairs == 0 and st.stitched_faces == 0
    assert seam_boundary_edges(m, [(0, 1.5)]) > 0


def test_grid_of_four_is_closed_at_the_corner():
    tiles, meshes = [], []
    steps = [0.21, 0.17, 0.19, 0.23]
    for k, (ix, iy) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        core = [2.0 if ix else None, 2.0 if iy else None, None if ix else 2.0, None if iy else 2.0]
        full = grid_mesh(-0.5 + 2 * ix, 2.5 + 2 * ix, -0.5 + 2 * iy, 2.5 + 2 * iy, steps[k], jitter=0.04, seed=k)
        tiles.append({"ix": ix, "iy": iy, "core": core})
        meshes.append(cut_to_box(full, core))
    merged, seams = merge_grid(tiles, meshes, 0.3)
    planes = seam_planes(tiles)
    assert planes == [(0, 2.0), (1, 2.0)]
    assert seam_boundary_edges(merged, planes, tile_faces_only=True) == 0
    assert faces_outside_core(merged, tiles) == 0
    assert edge_counts(merged.faces)["non_manifold_edges"] == 0
    assert len(seams) == 3


def test_close_seam_holes_only_touches_seams():
    m = grid_mesh(0, 4, 0, 4, 0.25)
    # punch a hole at the seam x = 2 and another away from it
    c = m.vertices[m.faces].mean(axis=1)
    hole1 = (c[:, 0] > 2.0) & (c[:, 0] < 2.3) & (np.abs(c[:, 1] - 2.0) < 0.3)  # one side on x = 2
    hole2 = (np.abs(c[:, 0] - 0.9) < 0.3) & (np.abs(c[:, 1] - 2.0) < 0.3)
    from twinkit.mesh import compact as compact_mesh

    m = compact_mesh(m, ~(hole1 | hole2))
    m.face_attrs = {"tile": np.zeros(m.n_faces, np.int32)}
    assert seam_boundary_edges(m, [(0, 2.0)], tol_m=1e-6) > 0
    out, n = close_seam_holes(m, [(0, 2.0)], 60, tol_m=1e-6)
    assert n == 1
    assert seam_boundary_edges(out, [(0, 2.0)], tol_m=1e-6) == 0
    assert edge_counts(out.faces)["boundary_edges"] > edge_counts(grid_mesh(0, 4, 0, 4, 0.25).faces)["boundary_edges"]


@pytest.mark.parametrize("tile_m", [7.0])
def test_poisson_tiles_merge_without_cracks(tile_m):
    """Real open3d Poisson per padded tile on the synthetic street block, against the untiled run."""
    from twinkit.surface.cleanup import CleanOptions, clean_mesh
    from twinkit.surface.metrics import cloud_to_mesh

    from twinkit_tiles.synthetic import street_block
    from twinkit_tiles.tiling import choose_grid, exact_voxel_poisson, in_box

    P, N, C = street_block(size_m=20.0, spacing_m=0.1)
    grid, why = choose_grid(P[:, :2], tile_m, 1.5, 4.0, 0.1)
    tiles = grid.tiles()
    assert (why["nx"], why["ny"]) == (3, 3)
    meshes = []
    for t in tiles:
        s = in_box(P[:, :2], t["padded"])
        m, _, _ = exact_voxel_poisson(P[s], N[s], C[s], 0.1, threads=1)
        m, _ = clean_mesh(m, P[s], CleanOptions(max_dist_m=0.15, threads=1))
        meshes.append(cut_to_box(m, t["core"]))
    planes = seam_planes(tiles)
    merged, seams = merge_grid(tiles, meshes, 0.1)
    merged, _ = close_seam_holes(merged, planes, 120)
    assert seam_boundary_edges(merged, planes, tile_faces_only=True) == 0
    assert faces_outside_core(merged, tiles) == 0
    whole, _, _ = exact_voxel_poisson(P, N, C, 0.1, threads=1)
    whole, _ = clean_mesh(whole, P, CleanOptions(max_dist_m=0.15, threads=1))
    d_tiled = cloud_to_mesh(P, merged.vertices, merged.faces).mean()
    d_whole = cloud_to_mesh(P, whole.vertices, whole.faces).mean()
    assert abs(d_tiled - d_whole) < 0.001, (d_tiled, d_whole)
    # same amount of open border as the untiled mesh, within 10 %
    bt, bw = edge_counts(merged.faces)["boundary_edges"], edge_counts(whole.faces)["boundary_edges"]
    assert bt <= 1.1 * bw + 20, (bt, bw)


def test_boundary_half_edges_of_a_single_triangle():
    he, fid = boundary_half_edges(np.array([[0, 1, 2]]))
    assert sorted(map(tuple, he.tolist())) == [(0, 1), (1, 2), (2, 0)] and (fid == 0).all()


def test_figure_eight_loops_are_split_into_simple_loops():
    from twinkit_tiles.edges import _simple_loops

    parts = _simple_loops(np.array([1, 2, 3, 4, 2, 5, 6]))
    assert [p.tolist() for p in parts] == [[2, 3, 4], [1, 2, 5, 6]]
    assert [p.tolist() for p in _simple_loops(np.array([7, 8, 9]))] == [[7, 8, 9]]


def test_open_seam_edges_are_told_apart_by_what_lies_across():
    """An open edge on a seam faces either the other tile's surface (a real gap) or nothing (the
    other tile trimmed that surface away, so the mesh simply ends on the seam)."""
    from twinkit_tiles.edges import boundary_half_edges
    from twinkit_tiles.seam_stats import classify_open_seam_edges
    from twinkit_tiles.stitch import _concat

    a = cut_halfspace(grid_mesh(0, 3, 0, 3, 0.2), 0, 2.0, "below")
    b = cut_halfspace(grid_mesh(1, 4, 0, 3, 0.25), 0, 2.0, "above")
    bc = b.vertices[b.faces].mean(axis=1)
    from twinkit.mesh import compact as compact_mesh
    b = compact_mesh(b, bc[:, 1] < 1.5)  # the neighbour has surface only for y < 1.5
    a.face_attrs = {"tile": np.zeros(a.n_faces, np.int64)}
    b.face_attrs = {"tile": np.ones(b.n_faces, np.int64)}
    m = _concat(a, b)
    planes = [(0, 2.0)]
    total = seam_boundary_edges(m, planes, tile_faces_only=True)
    k = classify_open_seam_edges(m, planes, reach_m=0.3)
    assert k["facing_surface"] + k["surface_ends"] == total
    he, _ = boundary_half_edges(m.faces)
    X = m.vertices
    on = (np.abs(X[he[:, 0], 0] - 2.0) < 1e-6) & (np.abs(X[he[:, 1], 0] - 2.0) < 1e-6)
    y = X[he[on]].mean(axis=1)[:, 1]
    assert k["surface_ends"] >= int((y > 1.8).sum()) > 0
    assert k["facing_surface"] >= int((y < 1.2).sum()) > 0


def test_open_seam_runs_locate_and_measure_the_gaps_and_the_map_marks_them(tmp_path):
    """The open edges on a seam come back as runs with a place, a length and a kind, and the seam
    map circles them: the neighbour below has surface up to y = 1.5 only, so a run of the upper tile's
    border with nothing across starts there, and the seam map shows it in orange."""
    from PIL import Image

    from twinkit.mesh import compact as compact_mesh
    from twinkit_tiles.seam_map import seam_map_png
    from twinkit_tiles.seam_stats import open_seam_runs, seam_border_length
    from twinkit_tiles.stitch import _concat

    a = cut_halfspace(grid_mesh(0, 3, 0, 3, 0.2), 0, 2.0, "below")
    b = cut_halfspace(grid_mesh(1, 4, 0, 3, 0.25), 0, 2.0, "above")
    b = compact_mesh(b, b.vertices[b.faces].mean(axis=1)[:, 1] < 1.5)
    a.face_attrs = {"tile": np.zeros(a.n_faces, np.int64)}
    b.face_attrs = {"tile": np.ones(b.n_faces, np.int64)}
    m, st = stitch(a, b, 0, 2.0, max_gap_m=0.3)
    planes = [(0, 2.0)]
    runs = open_seam_runs(m, planes, reach_m=0.2)
    ends = [r for r in runs if r["kind"] == "surface_ends"]
    assert len(ends) == 1
    r = ends[0]
    # the upper tile's border from about y = 1.5 to 3 is open, nothing lies across it
    assert r["plane"] == ["x", 2.0] and 1.2 < r["length_m"] < 1.8 and r["tile_edges"] >= r["edges"] - 1  # (+ the strip's last edge)
    assert 2.0 < r["centre"][1] < 2.5
    assert abs(sum(x["length_m"] for x in runs) - seam_border_length(m, planes)) < 1e-3
    # before the stitch both borders are open: the lower tile's 1.5 m and the upper tile's 3 m
    assert abs(seam_border_length(_concat(a, b), planes) - 4.5) < 0.15
    png = tmp_path / "tile_seams.png"
    seam_map_png(m, planes, runs, png, title="test")
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    orange = (img[..., 0] > 230) & (np.abs(img[..., 1] - 140) < 20) & (img[..., 2] < 30)
    assert orange.sum() > 20
    cols = np.flatnonzero(orange.any(axis=0))
    # the circle sits on the seam plane (x = 2 of an x extent 0..4, 1600 px wide)
    assert abs(cols.mean() / img.shape[1] - 0.5) < 0.05


def test_cut_moves_near_plane_vertices_onto_it_so_no_sliver_edge_stays_on_the_seam():
    from twinkit_tiles.cut import ON_PLANE_M

    m = grid_mesh(0, 2, 0, 2, 0.25)
    m.vertices[m.vertices[:, 0] == 1.0, 0] = 1.0 + 2e-4  # a column of vertices 0.2 mm off the plane
    assert ON_PLANE_M > 2e-4
    lo = cut_halfspace(m, 0, 1.0, "below")
    on = np.abs(lo.vertices[:, 0] - 1.0) <= 1e-12
    assert on.sum() == 9  # the snapped column, no extra crossing vertex beside each of them
    he, _ = boundary_half_edges(lo.faces)
    L = np.linalg.norm(lo.vertices[he[:, 0]] - lo.vertices[he[:, 1]], axis=1)
    assert L.min() > 0.1


def test_seam_band_trim_applies_the_distance_rule_near_seams_only():
    from twinkit_tiles.seam_trim import trim_seam_bands

    m = grid_mesh(-2, 2, 0, 2, 0.05, z=lambda x, y: 0 * x)
    m.face_attrs = {"tile": np.where(m.vertices[m.faces].mean(axis=1)[:, 0] < 0, 0, 1).astype(np.int32)}
    rng = np.random.default_rng(1)
    P = np.c_[rng.uniform(-2, 2, 40000), rng.uniform(0, 1, 40000), np.zeros(40000)]  # points only for y < 1
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    out, rep = trim_seam_bands(m, [(0, 0.0)], P, N, band_m=0.5, max_dist_m=0.1, max_hole_edges=0,
                               min_component_faces=0)
    X = out.vertices
    band = np.abs(X[:, 0]) <= 0.5
    assert rep["vertices_trimmed"] > 0
    assert X[band, 1].max() <= 1.1 + 1e-9  # trimmed near the seam ...
    assert X[~band, 1].max() == pytest.approx(2.0)  # ... and nowhere else
    assert X[band, 1].max() >= 1.0  # the surface near the points stays


def test_a_strip_left_bare_on_one_side_counts_as_a_crack():
    """A strip's along-the-border edge left open (the faces of that tile beside the seam were trimmed
    away) is a crack, like an open edge of a tile face; only strip edges crossing the gap are not."""
    from twinkit_tiles.seam_stats import classify_open_seam_edges, open_seam_runs

    a = cut_halfspace(grid_mesh(0, 3.2, 0, 3, 0.2, jitter=0.05, seed=1), 0, 2.0, "below")
    b = cut_halfspace(grid_mesh(1.0, 4, 0, 3, 0.27, jitter=0.05, seed=2), 0, 2.0, "above")
    m, _ = merge_grid([{"ix": 0, "iy": 0, "core": [None, None, 2.0, None]},
                       {"ix": 1, "iy": 0, "core": [2.0, None, None, None]}], [a, b], max_gap_m=0.5)
    planes = [(0, 2.0)]
    assert seam_boundary_edges(m, planes, tile_faces_only=True) == 0
    # tile 1 loses its faces along the seam for 1 < y < 2, as a trim would take them
    X, F, t = m.vertices, m.faces, m.face_attrs["tile"]
    c = X[F].mean(axis=1)
    on = np.abs(X[:, 0] - 2.0) <= 1e-9
    gone = (t == 1) & on[F].any(axis=1) & (c[:, 1] > 1.0) & (c[:, 1] < 2.0)
    m.faces, m.face_attrs = F[~gone], {"tile": t[~gone]}
    he, fid = boundary_half_edges(m.faces)
    on_seam = on[he[:, 0]] & on[he[:, 1]]
    assert (on_seam & (m.face_attrs["tile"][fid] >= 0)).sum() == 0  # no tile face is open on the seam ...
    n = seam_boundary_edges(m, planes, tile_faces_only=True)
    assert n >= 3  # ... but the strip is: about 1 m of tile 1's border is bare
    k = classify_open_seam_edges(m, planes)
    assert k["facing_surface"] + k["surface_ends"] == n and k["facing_surface"] > 0  # tile 0 lies across
    runs = open_seam_runs(m, planes)
    crack = [r for r in runs if r["kind"] == "facing_surface"]
    assert len(crack) == 1 and 0.8 < crack[0]["tile_edges_length_m"] < 1.4 and 1.0 < crack[0]["centre"][1] < 2.0


def test_open_near_lines_sees_a_slot_along_a_line_only():
    from twinkit_tiles.seam_stats import _section_length, open_near_lines

    m = grid_mesh(0, 4, 0, 2, 0.1, z=lambda x, y: 0 * x)
    assert _section_length(m.vertices, m.faces, 0, 2.03) == pytest.approx(2.0)
    c = m.vertices[m.faces].mean(axis=1)
    slot = (np.abs(c[:, 0] - 2.0) < 0.1) & (c[:, 1] < 1.0)  # a 20 cm wide gap along x = 2 for y < 1
    m.faces = m.faces[~slot]
    at_slot = open_near_lines(m, [(0, 2.0)], 0.05)
    elsewhere = open_near_lines(m, [(0, 1.0), (0, 3.0)], 0.05)
    assert at_slot["section_m"] == pytest.approx(1.0, abs=0.01)  # the line cuts only the surface above y = 1
    # in the band: the slot's end (10 cm) and the mesh's outer border at y = 2 (10 cm); the slot's sides lie outside
    assert at_slot["open_m"] == pytest.approx(0.2, abs=0.01)
    wide = open_near_lines(m, [(0, 2.0)], 0.15)
    assert wide["open_m"] > 2.0  # with a wider band both 1 m sides of the slot count
    # elsewhere only the mesh's outer border crosses the lines: 2 x 10 cm per line, per 2 m of surface
    assert elsewhere["open_m"] == pytest.approx(0.4, abs=1e-6) and elsewhere["open_per_section"] == pytest.approx(0.1)
    assert wide["open_per_section"] > 10 * elsewhere["open_per_section"]


def _two_tile_ground(half_m: float, n_points: int, seed: int):
    """A flat 5 cm grid over x -half_m..half_m, y 0..2 (tile 0 west of x = 0, tile 1 east), and
    points with upward normals that cover it only up to y = 1."""
    m = grid_mesh(-half_m, half_m, 0, 2, 0.05, z=lambda x, y: 0 * x)
    m.face_attrs = {"tile": np.where(m.vertices[m.faces].mean(axis=1)[:, 0] < 0, 0, 1).astype(np.int32)}
    rng = np.random.default_rng(seed)
    P = np.c_[rng.uniform(-half_m, half_m, n_points), rng.uniform(0, 1, n_points), np.zeros(n_points)]
    return m, P, np.tile([0.0, 0.0, 1.0], (n_points, 1))


def test_seam_band_trim_keeps_what_a_tile_voted_for():
    from twinkit_tiles.seam_trim import trim_seam_bands

    m, P, N = _two_tile_ground(2, 40000, 1)
    # a tile whose own surface passed the trim up to y = 1.5 on both sides of the seam
    vy, vx = np.meshgrid(np.arange(1.0, 1.5, 0.02), np.arange(-0.6, 0.6, 0.02))
    votes = np.c_[vx.ravel(), vy.ravel(), np.zeros(vx.size), np.tile([0.0, 0.0, 1.0], (vx.size, 1))]
    kw = dict(band_m=0.5, max_dist_m=0.1, max_hole_edges=0, min_component_faces=0)
    plain, _ = trim_seam_bands(m, [(0, 0.0)], P, N, **kw)
    voted, rep = trim_seam_bands(m, [(0, 0.0)], P, N, votes=votes, vote_radius_m=0.05, **kw)
    band = lambda X: np.abs(X[:, 0]) <= 0.5  # noqa: E731
    assert plain.vertices[band(plain.vertices), 1].max() <= 1.1 + 1e-9
    assert voted.vertices[band(voted.vertices), 1].max() >= 1.45
    assert rep["vertices_kept_by_votes"] > 0
    far = voted.vertices[band(voted.vertices)]
    assert far[:, 1].max() <= 1.55  # beyond the votes the points decide as before
    # a vote keeps surface on its own tangent plane, not a bubble 4 cm above it
    lifted = Mesh(vertices=m.vertices + [0.0, 0.0, 0.04], faces=m.faces, attrs=dict(m.attrs),
                  face_attrs=dict(m.face_attrs))
    bubble, rep_b = trim_seam_bands(lifted, [(0, 0.0)], P, N, votes=votes, vote_radius_m=0.05, vote_plane_m=0.02, **kw)
    assert rep_b["vertices_kept_by_votes"] == 0
    assert bubble.vertices[band(bubble.vertices), 1].max() <= 1.1 + 1e-9


def _vote_grid(x0, x1, y0, y1, step, keep, tile):
    vy, vx = np.meshgrid(np.arange(y0, y1 + 1e-9, step), np.arange(x0, x1 + 1e-9, step))
    n = vx.size
    return np.c_[vx.ravel(), vy.ravel(), np.zeros(n), np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, float(keep)),
                 np.full(n, float(tile))]


def test_seam_band_trim_takes_each_tiles_nearest_vote():
    from twinkit_tiles.seam_trim import trim_seam_bands

    m, P, N = _two_tile_ground(1, 20000, 2)
    # tile 0's full-resolution surface (a vertex every 12 cm, as in sparse ground) passed the trim up to
    # y = 1.5 and failed beyond; tile 1's failed where the points are (y 0.2..0.5)
    votes = np.vstack([_vote_grid(-0.6, 0.6, 1.02, 1.5, 0.12, True, 0), _vote_grid(-0.6, 0.6, 1.62, 1.98, 0.12, False, 0),
                       _vote_grid(-0.6, 0.6, 0.2, 0.5, 0.12, False, 1)])
    kw = dict(band_m=0.5, max_dist_m=0.1, max_hole_edges=0, min_component_faces=0, votes=votes)
    band = lambda X: np.abs(X[:, 0]) <= 0.5  # noqa: E731
    rows = lambda X: np.count_nonzero((X[:, 1] > 1.12) & (X[:, 1] < 1.45))  # noqa: E731
    all_rows = rows(m.vertices[band(m.vertices)])
    near, _ = trim_seam_bands(m, [(0, 0.0)], P, N, vote_radius_m=0.05, vote_reach_m=0.0, **kw)
    # a 5 cm radius misses between votes 12 cm apart: holes between 1.1 and 1.5
    assert rows(near.vertices[band(near.vertices)]) < 0.8 * all_rows
    reach, rep = trim_seam_bands(m, [(0, 0.0)], P, N, **kw)  # the default: each tile's nearest vote within 15 cm
    X = reach.vertices[band(reach.vertices)]
    assert rows(X) == all_rows  # every vertex kept, nothing missing
    assert X[:, 1].max() <= 1.55 + 1e-9  # the nearest vote beyond 1.56 says drop
    # where tile 1's surface failed and no tile passed, the points' verdict is overruled
    assert np.count_nonzero((X[:, 1] > 0.25) & (X[:, 1] < 0.45)) == 0
    assert rep["vertices_dropped_by_votes"] >= 4 * 20 and rep["vertices_kept_by_votes"] > 0
    # outside the band nothing is judged here (the tiles trimmed it themselves)
    out = reach.vertices[~band(reach.vertices)]
    assert np.count_nonzero((out[:, 1] > 0.25) & (out[:, 1] < 0.45)) > 0


def test_seam_band_trim_never_leaves_the_surface_ending_on_a_seam():
    """Where the trim removes one tile's side of a seam and keeps the other's, the kept faces hanging
    on the seam go too (the trim's boundary crosses the seam instead of running along it); a border
    the zipper could not pair (open before the trim) stays open and counted."""
    from twinkit_tiles.seam_stats import _tile_border
    from twinkit_tiles.seam_trim import trim_seam_bands

    lift = lambda x, y: np.where((y > 0.4) & (y < 1.1), 0.03, 0.0)  # noqa: E731  tile 1 floats 3 cm up there
    a = cut_halfspace(grid_mesh(0, 3.2, 0, 3, 0.1, z=lambda x, y: 0 * x, jitter=0.02, seed=1), 0, 2.0, "below")
    b = cut_halfspace(grid_mesh(1.0, 4, 0, 3, 0.13, z=lift, jitter=0.02, seed=2), 0, 2.0, "above")
    # tile 1 has no surface beside the seam for 1.5 < y < 1.8: nothing for the zipper to pair there
    cb = b.vertices[b.faces].mean(axis=1)
    hole = (cb[:, 0] < 2.3) & (cb[:, 1] > 1.5) & (cb[:, 1] < 1.8)
    b.faces = b.faces[~hole]
    m, _ = merge_grid([{"ix": 0, "iy": 0, "core": [None, None, 2.0, None]},
                       {"ix": 1, "iy": 0, "core": [2.0, None, None, None]}], [a, b], max_gap_m=0.1)
    planes = [(0, 2.0)]

    def open_on_seam(mesh, y0, y1):
        he, fid = boundary_half_edges(mesh.faces)
        X = mesh.vertices
        on = (np.abs(X[he[:, 0], 0] - 2.0) <= 1e-6) & (np.abs(X[he[:, 1], 0] - 2.0) <= 1e-6)
        y = X[he, 1].mean(axis=1)
        return int((on & (y > y0) & (y < y1) & _tile_border(mesh, he, fid)).sum())  # the cracks there

    unpaired = open_on_seam(m, 1.4, 1.9)
    assert unpaired >= 2 and open_on_seam(m, 0.3, 1.2) == 0
    rng = np.random.default_rng(3)
    P = np.c_[rng.uniform(0, 4, 120_000), rng.uniform(0, 3, 120_000), np.zeros(120_000)]
    kw = dict(band_m=0.5, max_dist_m=0.02, max_hole_edges=0, min_component_faces=0)
    plain, rep0 = trim_seam_bands(m, planes, P, None, **kw)
    assert rep0["hanging_faces_removed"] == 0
    assert open_on_seam(plain, 0.3, 1.2) >= 5  # tile 0's border left bare where tile 1 was trimmed away
    fixed, rep = trim_seam_bands(m, planes, P, None, hanging_tol_m=1e-3, **kw)
    assert open_on_seam(fixed, 0.3, 1.2) == 0
    assert open_on_seam(fixed, 1.4, 1.9) == unpaired  # the zipper's leftovers are not hidden
    assert 0 < rep["hanging_faces_removed"] <= 2 * open_on_seam(plain, 0.3, 1.2) + 4
    # only the faces on the seam went: tile 0's surface 10 cm back from it is whole
    back = lambda mesh: (mesh.vertices[mesh.faces][:, :, 0].max(axis=1) < 1.89).sum()  # noqa: E731
    assert back(fixed) == back(plain) == back(m)
    assert edge_counts(fixed.faces)["non_manifold_edges"] == 0
