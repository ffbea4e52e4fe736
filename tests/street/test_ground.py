"""twinkit.street.ground.LocalGround: each mode on a small sloped street with a kerb, a parked car and an
unscanned patch; the per-cell statistics, the fills, the disc mode, and bad input."""
import numpy as np
import pytest

from twinkit.street.ground import LocalGround

SLOPE = 0.04  # the street rises 4 % along x
KERB = 0.15  # the pavement (y >= 2) stands a kerb above the carriageway
ROOF = 1.4  # a parked car's roof above the road


def car(x, y):
    return (np.abs(x) <= 2.2) & (np.abs(y + 1.0) <= 0.9)


def hole(x, y):  # an unscanned patch of carriageway (a shadow)
    return (x >= 5.0) & (x <= 7.0) & (y >= -3.0) & (y <= -1.0)


def street(step=0.25):
    """(points, up): samples every ``step`` m over x -10..10, y -6..6; every sample faces up (a roof too)."""
    xs = np.arange(-10, 10 + 1e-9, step)
    ys = np.arange(-6, 6 + 1e-9, step)
    X, Y = (a.ravel() for a in np.meshgrid(xs, ys))
    keep = ~hole(X, Y)
    X, Y = X[keep], Y[keep]
    z = SLOPE * X + np.where(Y >= 2.0, KERB, 0.0) + np.where(car(X, Y), ROOF, 0.0)
    return np.column_stack([X, Y, z]), np.ones(len(X), bool)


def truth(x, y):
    return SLOPE * x + np.where(y >= 2.0, KERB, 0.0)


def interior(p, margin=1.6):
    x, y = p[:, 0], p[:, 1]
    return (np.abs(x) < 10 - margin) & (np.abs(y) < 6 - margin) & (np.abs(y - 2.0) > margin)


def test_opening_removes_the_car_keeps_slope_and_kerb_and_fills_the_shadow():
    p, up = street()
    # a window wider than a car (1.8 m), narrower than the pavement (4 m)
    g = LocalGround(p, up, cell_m=0.25, window="opening", window_m=2.75)
    h = g.height(p)
    assert np.array_equal(g.height(), h)  # without points: the samples' own heights
    roof = car(p[:, 0], p[:, 1]) & (np.abs(p[:, 0]) < 2.0) & (np.abs(p[:, 1] + 1.0) < 0.7)
    assert np.abs(h[roof] - ROOF).max() < SLOPE * 1.5 + 0.02  # the roof stands above the ground
    ok = interior(p) & ~car(p[:, 0], p[:, 1])
    assert np.abs(h[ok]).max() < 0.02  # the carriageway and the pavement are the ground, the slope is kept
    # the shadow: no sample, its cells take the nearest surface
    q = np.array([[6.0, -2.0]])
    assert not g.has_surface[g.cells(q)].any()
    assert abs(g.at(q)[0] - SLOPE * 6.0) < SLOPE * 1.0 + 0.01


def test_opening_steps_mark_the_kerb_top_not_the_slope():
    p, up = street()
    g = LocalGround(p, up, cell_m=0.25, window="opening", window_m=2.75)
    st = g.steps(0.05, 0.5, 0.30)
    j, i = np.nonzero(st)
    y = g.lo[1] + (j + 0.5) * g.cell
    x = g.lo[0] + (i + 0.5) * g.cell
    on_kerb = (y > 1.9) & (y < 2.6)
    on_car = car(x, y + 0.0) | car(x, y - 0.25) | car(x, y + 0.25)  # around the car the step is its roof
    assert on_kerb.any() and np.all(on_kerb | on_car)
    assert g.near(st, np.array([[-8.0, 2.2, KERB], [-8.0, -4.0, 0.0]]), 1.0).tolist() == [True, False]


def test_window_minimum_sinks_on_the_slope_and_leaves_far_cells_empty():
    p, up = street()
    w = 2.75
    g = LocalGround(p, up, cell_m=0.25, window="min", window_m=w)
    assert g.window_cells == 11
    h = g.height(p)
    ok = interior(p) & ~car(p[:, 0], p[:, 1]) & (p[:, 1] < 2.0 - w)
    # a window minimum sinks below a slope by about slope x window / 2
    assert np.allclose(h[ok], SLOPE * 5 * g.cell, atol=SLOPE * g.cell + 1e-9)
    # a small window leaves the shadow's middle without ground (inf), unless filled
    small = dict(cell_m=0.25, window="min", window_m=0.75)
    q = np.array([[6.0, -2.0]])
    assert np.isinf(LocalGround(p, up, **small).at(q)[0])
    near = LocalGround(p, up, fill="nearest", **small).at(q)[0]
    assert abs(near - SLOPE * 6.0) < SLOPE * 1.25 + 1e-9
    low = LocalGround(p, up, fill="lowest", **small)
    assert low.at(q)[0] == p[:, 2].min() and not low.has_z[low.cells(q)].any()


def test_percentile_floor_ignores_a_drain():
    p, up = street()
    drain = (np.abs(p[:, 0] + 6.0) < 0.1) & (np.abs(p[:, 1] + 3.0) < 0.1)
    p = p.copy()
    p[drain, 2] -= 0.5
    kw = dict(cell_m=1.0, window="min", window_m=5.0, odd_window=False, pad_cells=0)
    near_drain = (np.abs(p[:, 0] + 6.0) < 2.0) & (np.abs(p[:, 1] + 3.0) < 2.0) & ~drain
    plain = LocalGround(p, up, **kw).height(p)
    floored = LocalGround(p, up, floor_pct=10, floor_below_m=0.07, **kw).height(p)
    assert plain[near_drain].min() > 0.4  # the drain pulls the plain minimum down around it
    assert floored[near_drain].max() < 0.07 + SLOPE * 5.0 + 1e-9


def test_per_cell_statistic_is_the_order_statistic():
    z = np.array([4.0, 0.0, 3.0, 1.0, 2.0])
    p = np.column_stack([np.full(5, 0.3), np.full(5, 0.3), z])
    for pct, want in ((0, 0.0), (5, 0.0), (50, 2.0), (99, 3.0), (100, 4.0)):
        g = LocalGround(p, cell_m=1.0, window="min", window_m=1.0, pct=pct)
        assert g.at(p[:1, :2])[0] == want, pct


def test_ground_points_lowest_or_mean():
    p, up = street()
    extra = np.array([[-7.9, -3.9, SLOPE * -7.9 + 0.1], [-7.9, -3.9, SLOPE * -7.9 + 0.6]])
    p2, up2 = np.vstack([p, extra]), np.r_[up, True, True]
    kw = dict(cell_m=0.25, window="min", window_m=2.75, ground_tol_m=0.25)
    lowest = LocalGround(p2, up2, ground_stat="lowest", **kw)
    mean = LocalGround(p2, up2, ground_stat="mean", fill="nearest", **kw)
    assert not lowest.ground_points[-1] and lowest.ground_points[-2]  # 0.6 m up is no ground
    assert not lowest.ground_points[car(p2[:, 0], p2[:, 1]) & (np.abs(p2[:, 0]) < 1.0)].any()  # nor the roof
    q = extra[:1, :2]
    base = p[(np.abs(p[:, 0] + 8.0) < 1e-9) & (np.abs(p[:, 1] + 4.0) < 1e-9), 2][0]  # the sample of that cell
    assert lowest.at(q)[0] == base
    assert mean.at(q)[0] == pytest.approx((base + extra[0, 2]) / 2)
    assert np.isfinite(mean.z).all() and mean.has_z.sum() < mean.z.size  # filled, and it says where


def test_no_up_facing_sample():
    p, _ = street()
    none = np.zeros(len(p), bool)
    assert np.isinf(LocalGround(p, none, window="min", window_m=1.0).z).all()
    assert (LocalGround(p, none, window="min", window_m=1.0, fill="nearest").z == p[:, 2].min()).all()
    assert (LocalGround(p, none, window="opening").z == p[:, 2].min()).all()
    every = LocalGround(p, none, window="min", window_m=1.0, if_none_up="all")
    assert np.array_equal(every.z, LocalGround(p, None, window="min", window_m=1.0).z)


def test_grid_reaches_cover_and_pad():
    p, up = street()
    g = LocalGround(p, up, window="min", window_m=1.0, cell_m=0.5, pad_cells=0,
                    cover_xy=np.array([[-12.0, 0.0], [14.0, 9.0]]))
    assert np.allclose(g.lo, [-12.0, -6.0])
    assert g.cells(np.array([[14.0, 9.0]]))[1][0] == g.nx - 1 == 52
    assert np.isinf(g.at(np.array([[13.0, 8.0]]))[0])  # covered, but no ground within the window
    assert np.allclose(LocalGround(p, up, cell_m=0.5).lo, [-10.5, -6.5])  # one empty cell around by default


def test_window_cells_rule():
    p, up = street()
    assert LocalGround(p, up, window="min", window_m=1.0, cell_m=0.25).window_cells == 5
    assert LocalGround(p, up, window="min", window_m=1.0, cell_m=0.25, odd_window=False).window_cells == 4
    assert LocalGround(p, up, window="min", window_m=0.1, cell_m=0.25).window_cells == 1
    assert LocalGround(p, up, window="min", window_m=0.1, cell_m=0.25, min_window_cells=3).window_cells == 3


def test_disc_mode_is_a_percentile_of_the_samples_within_reach():
    p, _ = street()
    g = LocalGround(p, window="disc", window_m=6.0, pct=2)
    c = np.array([1.0, -1.0])
    near = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) <= 3.0
    assert g.at(c)[0] == np.percentile(p[near, 2], 2)
    assert SLOPE * (c[0] - 3.0) <= g.at(c)[0] <= SLOPE * c[0]  # on a car's roof, the ground is still the road's
    assert np.isnan(g.at(np.array([40.0, 0.0]))[0])
    assert g.tree.n == len(p)


@pytest.mark.parametrize("bad", [
    dict(points=np.array([[0.0, 0.0, np.nan], [1.0, 1.0, 0.0]])),
    dict(points=np.array([[0.0, np.inf, 0.0]])),
    dict(points=np.zeros((0, 3))),
    dict(points=np.zeros((0, 3)), window="disc"),
    dict(points=np.zeros((4, 2))),
    dict(points=np.zeros((4, 3)), window="max"),
    dict(points=np.zeros((4, 3)), fill="mean"),
    dict(points=np.zeros((4, 3)), up=np.ones(3, bool)),
])
def test_bad_input_is_an_error(bad):
    with pytest.raises(ValueError):
        LocalGround(**bad)


def test_empty_points_with_cover_is_an_empty_grid():
    g = LocalGround(np.zeros((0, 3)), window="min", window_m=1.0, cover_xy=np.array([[0.0, 0.0], [3.0, 3.0]]))
    assert np.isinf(g.z).all() and not g.has_surface.any()
