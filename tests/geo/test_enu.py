"""twinkit.geo.enu: the ENU reading rule of geospatial scene schemas and the site frame -> ENU similarity."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("pyproj")

from twinkit.geo import SiteFrame  # noqa: E402
from twinkit.geo.enu import enu_to_lonlat, lonlat_to_enu, site_to_enu  # noqa: E402

DEMO = {"name": "demo", "crs": "EPSG:3067", "base_point": {"lat": 60.16945, "lon": 24.93365, "alt": 12.0}}


def test_enu_round_trip_and_axes():
    p = np.array([[150.0, 0.0, 0.0], [0.0, 150.0, 0.0], [30.0, -40.0, 5.0]])
    ll = enu_to_lonlat(p, 60.16945, 24.93365, 12.0)
    assert ll[0, 0] > 24.93365 and abs(ll[0, 1] - 60.16945) < 1e-5  # east: longitude grows
    assert ll[1, 1] > 60.16945 and abs(ll[1, 0] - 24.93365) < 1e-9  # north: latitude grows on the meridian
    assert np.allclose(lonlat_to_enu(ll, 60.16945, 24.93365, 12.0), p, atol=1e-6)


def test_site_frame_to_enu_takes_out_the_grid_convergence():
    """TM35FIN at 24.93 E: grid north is 1.79 deg east of true north, grid metres 0.99976 true; the fitted
    similarity turns the site frame by +1.79 deg and scales by 1/k, leaving < 1 mm over 150 m."""
    from pyproj import Geod

    frame = SiteFrame.from_site(DEMO)
    f = site_to_enu(frame, 12.0)
    assert math.degrees(f.rotation_rad) == pytest.approx(1.7928, abs=1e-3)
    assert f.scale == pytest.approx(1.000241, abs=2e-6) and f.residual_m < 1e-3
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    xyz = np.c_[150 * np.cos(a), 150 * np.sin(a), np.zeros_like(a)]
    truth = frame.local_to_lonlat(xyz[:, :2])
    g = Geod(ellps="WGS84")
    for pts, lo, hi in ((xyz, 4.0, 5.0), (f.apply(xyz), 0.0, 1e-3)):  # read as ENU unchanged / after the transform
        got = enu_to_lonlat(pts, frame.lat, frame.lon, 12.0)
        err = np.abs(g.inv(got[:, 0], got[:, 1], truth[:, 0], truth[:, 1])[2]).max()
        assert lo <= err <= hi
