"""The CPU PatchMatch stereo on a synthetic walked street (forward motion, a road seen at a grazing angle)."""
from __future__ import annotations

import numpy as np

from synthetic_street import render_street
from twinkit_photo import dense as D
from twinkit_photo.patchmatch import PMOptions


def _views(photos, cams):
    views = []
    for i, (c, p) in enumerate(zip(cams, photos)):
        v = D.View(f"{i}.jpg", c["K"], c["R_world_from_camera"], c["center"], p,
                   (np.dstack([p] * 3) * 255).astype(np.uint8))
        v.dmin, v.dmax = 1.0, 60.0
        views.append(v)
    return views


def test_patchmatch_recovers_a_forward_walked_street():
    photos, cams, depths = render_street(n_photos=5, size=(160, 120), f_px=140.0)
    views = _views(photos, cams)
    r = views[2]
    depth, score = D.patchmatch_view(r, [views[i] for i in (0, 1, 3, 4)], D.DenseOptions(threads=1),
                                     PMOptions(threads=1))
    gt = depths[2]
    near = (gt > 0) & (gt < 20)  # farther, 1-2 m of forward motion moves a pixel by a fraction of a pixel
    err = np.abs(depth - gt) / np.maximum(gt, 1e-6)
    good = (depth > 0) & (err < 0.05)
    # measured 0.56 (the plane sweep on the same photos: 0.48); the road is most of these pixels
    assert good[near].mean() > 0.5
    road = near.copy()
    road[: depth.shape[0] * 2 // 3] = False  # the lower third: road seen at a grazing angle
    assert good[road].mean() > 0.6
    # normals: where the depth is right on the road, the normal points up (world z)
    n = r.normal[good & road]
    assert np.median(n[:, 2]) > 0.9


def test_near_limit_reaches_the_road_in_front_of_the_photo():
    """The SfM points of a street photo are mostly far: the depth range from them cuts off the road."""
    photos, cams, depths = render_street(n_photos=2, size=(160, 120), f_px=140.0)
    views = _views(photos, cams)
    for v in views:
        v.dmin, v.dmax = 10.0, 60.0  # as if the sparse points started 10 m away
    D.near_limit_from_ground(views, (0.0, 0.0, 1.0), 0.0)
    for v, gt in zip(views, depths):
        nearest_road = gt[-1][gt[-1] > 0].min()
        assert v.dmin < nearest_road  # the road at the photo's bottom edge is inside the search range
        assert v.dmin > 0.5 * nearest_road
