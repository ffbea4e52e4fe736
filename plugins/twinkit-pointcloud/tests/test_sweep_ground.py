"""A sparse lidar sweep's road: its normals face up near the ground, so that the ground fill and Poisson take it
for ground (issue 46, item 1: holes under the lanes of single sweeps)."""
from __future__ import annotations

import numpy as np


def _ground(x0, x1, y0, y1, z=0.0, step=0.05):
    x, y = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    p = np.c_[x.ravel(), y.ravel(), np.full(x.size, z)]
    return p, np.tile([0.0, 0.0, 1.0], (len(p), 1))


def test_near_horizontal_normals_near_the_ground_face_up_higher_ones_keep_their_sign():
    from twinkit_pointcloud.normals import face_up_near_ground

    g, gn = _ground(0, 10, 0, 10)
    gn[::3] *= -1  # a third of the road upside down (segments flipped by the propagation)
    roof, rn = _ground(2, 4, 2, 4, z=0.8)  # a car's roof, seen from above
    rn[:] = [0, 0, -1]
    slab, sn = _ground(6, 8, 6, 8, z=3.0)  # a canopy seen from below
    sn[:] = [0, 0, -1]
    wall = np.c_[np.full(50, 9.0), np.linspace(0, 5, 50), np.linspace(0.1, 2.0, 50)]
    wn = np.tile([-1.0, 0.0, 0.0], (50, 1))
    p = np.vstack([g, roof, slab, wall])
    n = np.vstack([gn, rn, sn, wn])
    out = face_up_near_ground(p, n)
    k = np.cumsum([len(g), len(roof), len(slab), len(wall)])
    assert (out[:k[0], 2] > 0).all()  # the road
    assert (out[k[0]:k[1], 2] > 0).all()  # the roof 0.8 m up
    assert (out[k[1]:k[2], 2] < 0).all()  # the canopy 3 m up keeps facing down
    assert np.array_equal(out[k[2]:], wn.astype(np.float32))  # vertical surfaces untouched
    assert (n[:len(g):3, 2] < 0).all()  # the input is not changed in place


def test_orient_mst_turns_a_sweeps_road_up():
    """A lidar sweep's rings (one line of points each, far apart at range): the propagation over the
    neighbour graph alone leaves ring segments of road facing down."""
    from twinkit_pointcloud.normals import estimate_normals, orient_normals

    rng = np.random.default_rng(3)
    rings = []
    for r in 4.0 * 1.12 ** np.arange(22):  # ring spacing growing with the range, as a spinning lidar's
        a = np.arange(0, 2 * np.pi, 0.003)
        rings.append(np.c_[r * np.cos(a), r * np.sin(a), -1.7 + 0.004 * rng.standard_normal(len(a))])
    p = np.vstack(rings)
    p = p[np.hypot(p[:, 0], p[:, 1]) < 60]
    n = estimate_normals(p, k=24)
    o, used = orient_normals(p, n, "mst")
    horiz = np.abs(o[:, 2]) >= 0.85
    assert used == "mst" and horiz.sum() > 5000
    assert (o[horiz, 2] > 0).all()
