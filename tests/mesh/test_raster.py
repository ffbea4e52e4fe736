import numpy as np

from twinkit.mesh.raster import face_mask, face_raster


def test_face_raster_centres_in_closed_triangle_and_top_wins():
    # two overlapping triangles on a 1 m grid; pixel centres at x = 0.5, 1.5, ..., y = 9.5, 8.5, ...
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [2, 2, 5], [9, 2, 5], [2, 9, 5]], float)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    top = face_raster(v, f, 0.0, 10.0, 1.0, (10, 10), order=v[f][:, :, 2].mean(1))
    below = face_raster(v, f[::-1], 0.0, 10.0, 1.0, (10, 10))  # no key: the later face (the low one) wins
    cx, cy = np.meshgrid(np.arange(10) + 0.5, 10 - (np.arange(10) + 0.5))
    in_big = cx + cy <= 10
    in_small = (cx >= 2) & (cy >= 2) & (cx + cy <= 11)
    assert np.array_equal(top, np.where(in_small, 1, np.where(in_big, 0, -1)))
    assert np.array_equal(below, np.where(in_big, 1, np.where(in_small, 0, -1)))
    assert np.array_equal(face_mask(v, f, 0.0, 10.0, 1.0, (10, 10)), in_big | in_small)


def test_face_raster_matches_brute_force_and_skips_flat_faces():
    rng = np.random.default_rng(3)
    v = rng.uniform(-2, 12, (60, 3))
    f = rng.integers(0, 60, (40, 3))
    f[0] = [1, 1, 2]  # a degenerate face covers nothing
    got = face_raster(v, f, 0.0, 10.0, 0.5, (20, 20), max_candidates=50)
    want = np.full((20, 20), -1)
    cx, cy = np.meshgrid((np.arange(20) + 0.5) * 0.5, 10 - (np.arange(20) + 0.5) * 0.5)
    for i, (a, b, c) in enumerate(v[f][:, :, :2]):
        def e(p, q):
            return (q[0] - p[0]) * (cy - p[1]) - (q[1] - p[1]) * (cx - p[0])

        s = np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

        if s == 0:
            continue
        ins = (s * e(a, b) >= -1e-9) & (s * e(b, c) >= -1e-9) & (s * e(c, a) >= -1e-9)
        want[ins] = i
    assert np.array_equal(got, want)


def test_scanline_rule_gives_pillow_polygon_pixels():
    # the roads' masks were drawn with ImageDraw.polygon; the scanline rule must give the same pixels, for
    # large, tiny (sub-pixel, many with vertices on one pixel) and whole-pixel triangles, and painter's order
    from PIL import Image, ImageDraw

    rng = np.random.default_rng(7)
    tris = [rng.integers(0, 50, (3, 2)).astype(float) for _ in range(150)]
    tris += [rng.uniform(0, 50, (3, 2)) for _ in range(150)]
    tris += [rng.uniform(20, 23.5, (3, 2)) for _ in range(300)]
    for t in tris:
        im = Image.new("L", (48, 40), 0)
        ImageDraw.Draw(im).polygon([tuple(map(float, q)) for q in t], fill=1)
        got = face_mask(np.c_[t[:, 0] * 0.5 + 3.0, 7.0 - t[:, 1] * 0.5], [[0, 1, 2]], 3.0, 7.0, 0.5, (40, 48),
                        rule="scanline")
        assert np.array_equal(got, np.asarray(im) > 0), t.tolist()
    pts = rng.uniform(0, 40, (300, 3))
    f = rng.integers(0, 300, (120, 3))
    key = pts[f, 2].mean(1)
    im = Image.new("L", (40, 40), 255)
    d = ImageDraw.Draw(im)
    for i in np.argsort(key, kind="stable"):
        d.polygon([tuple(map(float, pts[j, :2])) for j in f[i]], fill=int(i))
    got = face_raster(np.c_[pts[:, 0], -pts[:, 1]], f, 0.0, 0.0, 1.0, (40, 40), order=key, rule="scanline")
    assert np.array_equal(np.where(got < 0, 255, got), np.asarray(im))
