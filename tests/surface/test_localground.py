"""twinkit.surface.localground: the ground under a car, on a slope, and curb steps."""
import numpy as np

from twinkit.surface.localground import LocalGround


def _grid(z_of, half=8.0, step=0.25):
    xs = np.arange(-half, half + 1e-9, step)
    X, Y = np.meshgrid(xs, xs)
    v = np.column_stack([X.ravel(), Y.ravel(), z_of(X.ravel(), Y.ravel())])
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))  # every sample faces up (a roof too)
    return v, n


def test_opening_removes_a_car_and_keeps_a_slope():
    car = lambda x, y: (np.abs(x) <= 2.2) & (np.abs(y) <= 0.9)  # noqa: E731
    v, n = _grid(lambda x, y: 0.05 * y + np.where(car(x, y), 1.4, 0.0))
    g = LocalGround(v, n, window_m=3.0)
    h = g.height(v)
    # no ground is seen under the roof: there the ground is interpolated, within slope x window / 2
    assert np.abs(h[car(v[:, 0], v[:, 1])] - 1.4).max() < 0.05 * 1.5 + 0.02
    inner = (np.abs(v[:, 0]) < 6.5) & (np.abs(v[:, 1]) < 6.5) & ~((np.abs(v[:, 0]) <= 2.7) & (np.abs(v[:, 1]) <= 1.4))
    assert np.abs(h[inner]).max() < 0.02
    # a window as small as the car keeps the roof as ground
    assert np.abs(LocalGround(v, n, window_m=1.0).height(v)[car(v[:, 0], v[:, 1])]).max() < 0.1


def test_steps_mark_a_curb_top_not_a_slope():
    v, n = _grid(lambda x, y: np.where(x >= 0, 0.15, 0.0) + 0.04 * y)
    g = LocalGround(v, n, window_m=3.0)
    st = g.steps(0.05, 0.5)
    j, i = np.nonzero(st)
    x = g.lo[0] + (i + 0.5) * g.cell
    assert st.any() and np.all((x > -0.1) & (x < 0.6))  # the top edge of the curb only
    assert not LocalGround(*_grid(lambda x, y: 0.06 * x), window_m=3.0).steps(0.05, 0.5).any()
    assert g.near(st, np.array([[0.3, 0.0, 0.15], [5.0, 0.0, 0.15]]), 1.0).tolist() == [True, False]
