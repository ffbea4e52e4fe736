"""A small synthetic labelled street mesh: a cross of carriageways with raised sidewalks (tests of road_source=scan)."""
from __future__ import annotations

import numpy as np

ROAD, SIDEWALK, TERRAIN = 0, 1, 9


def cross_mesh(half_m: float = 40.0, main_half_m: float = 8.7, side_half_m: float = 3.25, sidewalk_m: float = 3.5,
               curb_m: float = 0.12, step_m: float = 0.5, side_arms: str = "ns"):
    """Vertices (n, 3), triangles (m, 3) and per-vertex CityScapes labels of a four-way (``side_arms="ns"``)
    or three-way (``"n"``) junction: a main road along x (half width ``main_half_m``), a side street
    along y, sidewalks ``sidewalk_m`` wide raised by ``curb_m``, grass behind them. Returns also the true
    lane centre lines (lanes of 3.25 m from the centre, the main road with a parking strip at each curb)."""
    edges = [main_half_m, main_half_m + sidewalk_m, side_half_m, side_half_m + sidewalk_m]
    xs = np.arange(-half_m, half_m + 1e-9, step_m)
    extra = [s * e + d for e in edges for s in (-1, 1) for d in (-0.002, 0.002)]
    xs = np.unique(np.r_[xs, extra])
    X, Y = np.meshgrid(xs, xs)
    x, y = X.ravel(), Y.ravel()
    on_main = np.abs(y) < main_half_m
    on_side = (np.abs(x) < side_half_m) & ((y > 0) if side_arms == "n" else True)
    road = on_main | on_side
    walk = ~road & ((np.abs(y) < main_half_m + sidewalk_m)
                    | ((np.abs(x) < side_half_m + sidewalk_m) & ((y > 0) if side_arms == "n" else True)))
    z = np.where(road, 0.0, curb_m)
    lab = np.where(road, ROAD, np.where(walk, SIDEWALK, TERRAIN)).astype(np.uint8)
    v = np.stack([x, y, z], 1)
    n = len(xs)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    truth = [np.array([[-half_m, yl], [half_m, yl]]) for yl in (-4.875, -1.625, 1.625, 4.875)]
    y0 = -half_m if side_arms != "n" else main_half_m
    truth += [np.array([[xl, y0], [xl, half_m]]) for xl in (-1.625, 1.625)]
    return v, f.astype(np.int64), lab, truth
