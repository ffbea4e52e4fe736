"""The fast paths of render_views give the pixels the plain ones give: frustum culling against drawing
every face, the compiled hole mask and fill against scipy's distance transforms, the vertex-map file."""
import numpy as np
import pytest

from twinkit_segmentation import viewholes
from twinkit_segmentation.synthetic import egl_available, street_scene

needs_egl = pytest.mark.skipif(not egl_available(), reason="no headless EGL (Mesa) for moderngl")
needs_numba = pytest.mark.skipif(viewholes._sq_dist_compiled() is None, reason="numba not installed")


def _masks(seed, n=40):
    """Random hit masks from sparse specks to nearly full, some with wide bands of background."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        h, w = rng.integers(8, 90, 2)
        hit = rng.random((h, w)) > rng.choice([0.03, 0.2, 0.5, 0.9])
        if rng.random() < 0.5:
            y = rng.integers(0, h)
            hit[y:y + rng.integers(1, 30)] = False  # a gap wider than some max_gap_px
        below = np.arange(h)[:, None] >= rng.integers(0, h)
        yield hit, np.broadcast_to(below, (h, w)).copy()


@needs_numba
@pytest.mark.parametrize("gap", [0.0, 1.0, 1.5, 2.0, np.sqrt(8.0), 4.7, 16.0])
def test_compiled_hole_mask_is_scipys(gap):
    for hit, below in _masks(int(gap * 10)):
        grown = viewholes._sq_dist_compiled()(np.ascontiguousarray(hit)) <= viewholes._within(gap)
        if grown.all() or hit.all() or not hit.any():
            continue  # scipy's phantom pixel (module docstring); tested below
        a = viewholes.ground_holes(hit, below, gap, method="scipy")
        b = viewholes.ground_holes(hit, below, gap, method="numba")
        assert np.array_equal(a, b)


@needs_numba
def test_squared_distances_are_exact():
    from scipy.ndimage import distance_transform_edt

    for hit, _ in _masks(5):
        if not hit.any():
            continue
        d2 = viewholes._sq_dist_compiled()(np.ascontiguousarray(hit))
        assert np.array_equal(d2, np.rint(distance_transform_edt(~hit) ** 2).astype(np.int64))
    none = viewholes._sq_dist_compiled()(np.zeros((5, 7), bool))
    assert (none == 5 * 5 + 7 * 7 + 1).all()


@needs_numba
def test_a_view_without_wide_gaps_has_every_low_gap_as_hole():
    hit = np.ones((40, 60), bool)
    hit[30, 10:13] = False  # a crack in the ground
    hit[2, 1] = False  # a speck near the top-left corner, below the horizon too
    holes = viewholes.ground_holes(hit, np.ones_like(hit), 4.0, method="numba")
    assert np.array_equal(holes, ~hit)


@needs_numba
def test_compiled_fill_picks_scipys_nearest_pixel():
    rng = np.random.default_rng(3)
    for hit, _ in _masks(7):
        if not hit.any():
            continue
        rgb = rng.integers(0, 255, hit.shape + (3,)).astype(np.uint8)
        holes = ~hit & (rng.random(hit.shape) < 0.7)
        a, b = rgb.copy(), rgb.copy()
        assert viewholes.fill_from_nearest(a, holes, hit, method="scipy") == int(holes.sum())
        viewholes.fill_from_nearest(b, holes, hit, method="numba")
        assert np.array_equal(a, b)
    rgb = np.zeros((5, 5, 3), np.uint8)
    hit = np.zeros((5, 5), bool)
    hit[0, 4], hit[4, 0] = True, True  # equally far from the centre: the smaller column wins
    rgb[0, 4], rgb[4, 0] = 10, 20
    viewholes.fill_from_nearest(rgb, ~hit, hit, method="numba")
    assert rgb[2, 2, 0] == 20


def test_signal_std_is_the_grey_levels_std():
    from twinkit_segmentation.render import signal_std

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (30, 40, 3)).astype(np.uint8)
    on = rng.random((30, 40)) < 0.6
    assert signal_std(rgb, on) == float(rgb[on].astype(np.float32).mean(axis=1).std())
    assert signal_std(rgb, np.zeros_like(on)) == 0.0


def test_vertex_map_file_round_trip(tmp_path):
    from twinkit_segmentation.render import write_vertex_map

    vm = np.full((12, 20), -1, np.int32)
    vm[3:9, 2:17] = np.arange(6 * 15).reshape(6, 15) + 250_000
    write_vertex_map(tmp_path / "v_vertex.npz", vm)
    back = np.load(tmp_path / "v_vertex.npz")["vertex"]
    assert back.dtype == np.int32 and np.array_equal(back, vm)


@needs_egl
def test_culled_draw_equals_drawing_every_face(monkeypatch):
    import twinkit_segmentation.render as R
    from twinkit_segmentation.views import view_matrices

    v, f, _, _ = street_scene(step=1.0)
    r = R.Renderer(v, f, None, None, 96, 48)
    views = [{"position": [-15, 0, 1.5], "heading_deg": h, "pitch_deg": p, "hfov_deg": 75.0, "width": 96,
              "height": 48} for h in (0.0, 90.0, 200.0) for p in (-5.0, -89.0, 60.0)]
    views.append({"position": [-60, 3, 8.0], "heading_deg": 0.0, "pitch_deg": -10.0, "hfov_deg": 40.0,
                  "width": 96, "height": 48})  # from outside the street, looking at it
    culled, drawn = [], []
    for view in views:
        culled.append(r.render(*view_matrices(view)))
        drawn.append(r.drawn_faces)
    assert min(drawn) < 0.6 * len(f)  # culling takes faces away
    monkeypatch.setattr(R, "visible_cells", lambda lo, hi, mvp: np.ones(len(lo), bool))
    for view, (rgb, vid) in zip(views, culled):
        rgb_all, vid_all = r.render(*view_matrices(view))
        assert r.drawn_faces == len(f)
        assert np.array_equal(vid, vid_all) and np.array_equal(rgb, rgb_all)
    r.release()
    assert any((vid >= 0).mean() > 0.3 for _, vid in culled)


@needs_egl
def test_nearest_cells_first_gives_the_mesh_orders_pixels():
    """Drawing the visible cells nearest first (fewer hidden fragments shaded) gives the pixels of drawing the
    faces in the mesh's order, on a scene without faces at equal depth; its draw starts at the camera."""
    import twinkit_segmentation.render as R
    from twinkit_segmentation.views import view_matrices

    v, f, _, _ = street_scene(step=1.0)
    near, plain = R.Renderer(v, f, None, None, 96, 48), R.Renderer(v, f, None, None, 96, 48, front_to_back=False)
    for h in (0.0, 90.0, 200.0):
        view = {"position": [-15, 0, 1.5], "heading_deg": h, "pitch_deg": -5.0, "hfov_deg": 75.0, "width": 96,
                "height": 48}
        (rgb_a, vid_a), (rgb_b, vid_b) = near.render(*view_matrices(view)), plain.render(*view_matrices(view))
        assert near.drawn_faces == plain.drawn_faces
        assert np.array_equal(vid_a, vid_b) and np.array_equal(rgb_a, rgb_b) and (vid_a >= 0).mean() > 0.2
        vm, pm = view_matrices(view)
        idx = near._draw_order(R.visible_cells(near._lo, near._hi, pm @ vm), vm)
        first = v[f[idx[0, 0] // 3]].mean(axis=0)
        last = v[f[idx[-1, 0] // 3]].mean(axis=0)
        assert np.linalg.norm(first[:2] - [-15, 0]) < np.linalg.norm(last[:2] - [-15, 0])
    near.release()
    plain.release()


def test_compiled_vertex_lookup_is_numpys():
    from twinkit.surface.compiled import compiled
    from twinkit_segmentation.render import _ids_to_vertices

    rng = np.random.default_rng(0)
    lut = np.concatenate([[-1], rng.integers(0, 10_000, 300)]).astype(np.int32)
    ids = rng.integers(0, len(lut), (17, 23)).astype(np.uint32)
    out = np.empty(ids.shape, np.int32)
    (compiled(_ids_to_vertices) or _ids_to_vertices)(lut, ids, out)
    assert np.array_equal(out, np.take(lut, ids[::-1]))
