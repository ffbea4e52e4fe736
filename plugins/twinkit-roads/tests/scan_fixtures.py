"""A small synthetic labelled street mesh: a cross of carriageways with raised sidewalks (tests of road_source=scan)."""
from __future__ import annotations

import numpy as np

from twinkit.cityscapes import ROAD, SIDEWALK, TERRAIN


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


def aerial_lane(half_m: float = 40.0, road_half_m: float = 3.0, bank_m: float = 0.4, slope: float = 0.05,
                spill_m: float = 10.0, step_m: float = 0.5, specks: float = 0.0, river_m: float = 0.0,
                sidewalk_share: float = 0.0, seed: int = 0):
    """What an aerial scan of a rural street gives (issue 28, the IGN village): a grey lane ``2 x road_half_m``
    wide along x on a low embankment (``bank_m`` above the fields, so the carriageway is not the local lowest
    level), no curbs, the whole ground sloping ``slope`` along x, green fields either side. The labels take
    the lane as road and spill ``spill_m`` onto the field north of it (a street-level model reading a field
    from above). Options for what real aerial scans add:

    - ``specks``: this share of the field's vertices grey and labelled road (shadows, gravel, path stones);
    - ``sidewalk_share``: this share of the lane's vertices labelled sidewalk (a model looking down at a
      street without kerbs calls much of it sidewalk);
    - ``river_m``: a band of water this wide south of the lane (from y = -20 m), flat, 0.3 m below the
      fields, grey and labelled sidewalk: lidar gets few returns from water (``water`` in the returned
      mask marks its vertices, for a cloud thinned there).

    Returns vertices, triangles, labels, RGB colours, the true axis (y = 0) and the water mask."""
    rng = np.random.default_rng(seed)
    xs = np.arange(-half_m, half_m + 1e-9, step_m)
    X, Y = np.meshgrid(xs, xs)
    x, y = X.ravel(), Y.ravel()
    road = np.abs(y) < road_half_m
    # the embankment's shoulders slope down over 1.5 m
    shoulder = np.clip((np.abs(y) - road_half_m) / 1.5, 0.0, 1.0)
    z = slope * x + bank_m * (1.0 - shoulder)
    lab = np.where(road | ((y > 0) & (y < road_half_m + spill_m)), ROAD, TERRAIN).astype(np.uint8)
    rgb = np.where(road[:, None], np.array([118, 116, 112]), np.array([92, 140, 58])).astype(np.uint8)
    water = (y <= -20.0) & (y > -20.0 - river_m)
    if river_m > 0:
        z = np.where(water, slope * x - 0.3, z)
        lab[water] = SIDEWALK
        rgb[water] = (96, 98, 101)
    if specks > 0:
        sp = ~road & ~water & (rng.random(len(x)) < specks)
        lab[sp] = ROAD
        rgb[sp] = (120, 118, 116)
    if sidewalk_share > 0:
        lab[road & (rng.random(len(x)) < sidewalk_share)] = SIDEWALK
    v = np.stack([x, y, z], 1)
    n = len(xs)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return v, f.astype(np.int64), lab, rgb, np.array([[-half_m, 0.0], [half_m, 0.0]]), water


def cambered_street(half_m: float = 40.0, road_half_m: float = 7.0, camber: float = 0.02, grade: float = 0.03,
                    tilt: float = 0.02, sidewalk_m: float = 3.0, curb_m: float = 0.14, step_m: float = 0.5):
    """A straight street along x as real streets are: cambered (the crown on the axis, falling ``camber``
    to each curb), on a ``grade`` along its length and across a hillside (``tilt``: the north side higher),
    sidewalks ``curb_m`` above the gutters. Returns
    vertices, triangles, labels and the carriageway's height function z(x, y)."""
    xs = np.arange(-half_m, half_m + 1e-9, step_m)
    ys = np.unique(np.r_[np.arange(-road_half_m - sidewalk_m, road_half_m + sidewalk_m + 1e-9, step_m),
                         [-road_half_m - 0.002, -road_half_m + 0.002, road_half_m - 0.002, road_half_m + 0.002]])
    X, Y = np.meshgrid(xs, ys)
    x, y = X.ravel(), Y.ravel()
    road = np.abs(y) < road_half_m

    def surface(x, y):
        return grade * x - camber * np.abs(y) + tilt * y

    z = np.where(road, surface(x, y), surface(x, road_half_m) + curb_m)
    lab = np.where(road, ROAD, SIDEWALK).astype(np.uint8)
    v = np.stack([x, y, z], 1)
    nx, ny = len(xs), len(ys)
    i, j = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)])
    return v, f.astype(np.int64), lab, surface


def write_aerial_meta(path, spacing_m: float = 0.3) -> None:
    """A points_meta.json (through the artefact catalogue) of an aerial cloud with median spacing ``spacing_m``."""
    from twinkit import artefacts as A

    A.write_points_meta(path, {"source": {"reader": "test"}, "counts": {}, "fields": {}, "frame": {},
                               "bounds_m": [], "density": {"points": 0, "spacing_m": spacing_m, "capture": "aerial"}})
