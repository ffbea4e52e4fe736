"""A car parked on a lane of a close-range scan is not a wall: the lane check judges the ground under it (the
car is taken out later), so the road is not cut there (issue 46: roads from a scan that cover the street)."""
from __future__ import annotations

import numpy as np
from scan_fixtures import cross_mesh

from twinkit.cityscapes import CAR
from twinkit_roads import scan

PROJ = "+proj=tmerc +lat_0=0 +lon_0=0 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _with_car(v, f, lab, x0, x1, y0, y1, h=1.5):
    """The mesh with a closed box (a car, labelled CAR) standing on the road."""
    box = np.array([[x, y, z] for z in (0.0, h) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))], float)
    tri = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                    [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return (np.vstack([v, box]), np.vstack([f, tri + len(v)]),
            np.r_[lab, np.full(8, CAR, lab.dtype)])


def test_a_parked_car_on_a_lane_does_not_cut_the_road(tmp_path):
    v, f, lab, _ = cross_mesh(step_m=1.0)
    p = scan.ScanSourceParams()
    net = scan.derive_network(v, f, lab, p)
    scan.add_sidewalks(net, v, f, lab, p)
    scan.add_heights_and_signals(net, v, f, lab, p)
    nod, edg = scan.write_plain(net, p, PROJ, tmp_path / "plain")
    scan.netconvert_plain(nod, edg, tmp_path / "scan.xodr", p)
    text = (tmp_path / "scan.xodr").read_text(encoding="utf-8")
    v2, f2, lab2 = _with_car(v, f, lab, 0.2, 2.2, 20.0, 24.5)  # on the north side street's lane
    as_wall = scan.check_lanes(net, text, v2, f2, p)
    assert as_wall["bad_points"], "without the labels the car is an obstacle"
    parked = scan.parked_faces(f2, lab2, curbs=True)
    assert parked is not None and parked[len(f):].all() and not parked[:len(f)].any()
    as_car = scan.check_lanes(net, text, v2, f2, p, parked=parked)
    assert not as_car["bad_points"] and as_car["on_share"] > 0.99
    # from the air (no curbs to see) a car-labelled lump stays an obstacle
    assert scan.parked_faces(f2, lab2, curbs=False) is None
    assert scan.parked_faces(f2, None, curbs=True) is None
